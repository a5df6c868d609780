"""cycles_reference.py - an independent reference for the Cornell box, rendered by Blender Cycles.

Dev-time tool only (Blender is never a build or test dependency of mcpt).  Run:
    blender -b --factory-startup --python scripts/cycles_reference.py -- \
        --obj scenes/models/CornellBox-Original.obj --out OUT.json [--spp N] [--size W] \
        [--seeds K] [--threads T] [--exr-dir DIR]

The scene is built here from the OBJ/MTL values, so the conventions are exactly mcpt's:
- geometry: every OBJ face fan-triangulated (c0, ci, ci+1) as obj.c does, flat shaded, and
  mapped from OBJ's Y-up frame to Blender's Z-up frame by the rotation (x, y, z) -> (x, -z, y)
  (det +1, so winding and geometric normals are kept); the camera goes through the same map;
- material: Diffuse BSDF (Lambertian, rho/pi, roughness 0) with colour Kd; where Ke != 0, plus an
  Emission shader of colour Ke and strength 1 (emitted radiance = Ke) on the front side only
  (Geometry.Backfacing mixes it to black), front = the side the winding normal points to;
- world: black; camera: pinhole at (0,1,3.9) looking at (0,1,0), up +Y, 40 degrees vertical fov;
- Cycles: path tracing, no denoising, no clamping, no adaptive sampling, no path guiding, caustics
  on, 1024 bounces of every kind, light threshold 0, box pixel filter of width 1 px;
- film: opaque, exposure 0, view transform Standard, look None; 32-bit float OpenEXR (linear).
K seeds are rendered at N spp each; the per-channel image mean is their average and its standard
error is std(seed means) / sqrt(K).  Pixel data is read with scripts/exr_mean.py.
"""

import argparse
import json
import math
import os
import sys
import tempfile
import time

import bpy

sys.dont_write_bytecode = True  # no scripts/__pycache__ in the tree
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import exr_mean  # noqa: E402  (same folder)

BOUNCES = 1024


def y_up_to_z_up(p):
    """OBJ (Y up, camera looks down -Z) -> Blender (Z up): (x, y, z) -> (x, -z, y)."""
    return (p[0], -p[2], p[1])


def parse_mtl(path):
    mats = {}
    cur = None
    with open(path, encoding="latin-1") as f:
        for line in f:
            tok = line.split("#", 1)[0].split()
            if not tok:
                continue
            if tok[0] == "newmtl":
                cur = {"Kd": (0.8, 0.8, 0.8), "Ke": (0.0, 0.0, 0.0)}  # obj.c's defaults
                mats[tok[1]] = cur
            elif tok[0] in ("Kd", "Ke") and cur is not None:
                v = [float(x) for x in tok[1:4]]
                cur[tok[0]] = tuple(v) if len(v) == 3 else (v[0], v[0], v[0])
    return mats


def parse_obj(path):
    """Returns (positions, triangles [(i0, i1, i2, material name)], {name: {Kd, Ke}})."""
    positions, tris, mats = [], [], {}
    cur_mat = None
    base = os.path.dirname(os.path.abspath(path))
    with open(path, encoding="latin-1") as f:
        for line in f:
            tok = line.split("#", 1)[0].split()
            if not tok:
                continue
            if tok[0] == "v":
                positions.append(tuple(float(x) for x in tok[1:4]))
            elif tok[0] == "mtllib":
                mats.update(parse_mtl(os.path.join(base, tok[1])))
            elif tok[0] == "usemtl":
                cur_mat = tok[1]
            elif tok[0] == "f":
                idx = []
                for c in tok[1:]:
                    k = int(c.split("/")[0])
                    idx.append(k - 1 if k > 0 else len(positions) + k)
                for i in range(1, len(idx) - 1):  # fan from the first corner, as obj.c
                    tris.append((idx[0], idx[i], idx[i + 1], cur_mat))
    return positions, tris, mats


def drop_duplicate_triangles(positions, tris):
    """Removes triangles that repeat an earlier triangle's three positions and material.

    CornellBox-Original.obj repeats one face of each box as its "Bottom Face".  A repeated
    triangle is the same surface, so the light transport is unchanged, and mcpt's spawned-ray
    offsets (PBRT 4e error bounds) step off both copies.  Cycles 3.4 instead skips only the
    primitive a ray leaves, so a coincident copy occludes every ray leaving the face and the face
    renders black.  Dropping the copy gives Cycles the same surface without that artefact."""
    seen, kept, dropped = set(), [], 0
    for t in tris:
        key = (frozenset(positions[i] for i in t[:3]), t[3])
        if key in seen:
            dropped += 1
            continue
        seen.add(key)
        kept.append(t)
    return kept, dropped


def make_material(name, kd, ke):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.target = "CYCLES"
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (kd[0], kd[1], kd[2], 1.0)
    diffuse.inputs["Roughness"].default_value = 0.0  # Lambertian (not Oren-Nayar)
    surface = diffuse.outputs["BSDF"]
    if any(c > 0.0 for c in ke):
        # Le = Ke on the front side, 0 on the back: Mix(fac = Backfacing, Emission, black)
        emit = nt.nodes.new("ShaderNodeEmission")
        emit.inputs["Color"].default_value = (ke[0], ke[1], ke[2], 1.0)
        emit.inputs["Strength"].default_value = 1.0
        black = nt.nodes.new("ShaderNodeEmission")
        black.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        black.inputs["Strength"].default_value = 0.0
        geom = nt.nodes.new("ShaderNodeNewGeometry")
        mix = nt.nodes.new("ShaderNodeMixShader")
        nt.links.new(geom.outputs["Backfacing"], mix.inputs["Fac"])
        nt.links.new(emit.outputs["Emission"], mix.inputs[1])
        nt.links.new(black.outputs["Emission"], mix.inputs[2])
        add = nt.nodes.new("ShaderNodeAddShader")
        nt.links.new(diffuse.outputs["BSDF"], add.inputs[0])
        nt.links.new(mix.outputs["Shader"], add.inputs[1])
        surface = add.outputs["Shader"]
        if hasattr(mat.cycles, "sample_as_light"):  # Blender <= 3.4
            mat.cycles.sample_as_light = True
        if hasattr(mat.cycles, "emission_sampling"):  # Blender >= 3.5: sample the front only
            mat.cycles.emission_sampling = "FRONT"
    nt.links.new(surface, out.inputs["Surface"])
    return mat


def build_scene(args, geometry=True):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    if geometry:
        add_obj(scene, args.obj)
    add_camera(scene, args.fov)
    set_world_and_render(scene, args)
    return scene


def add_obj(scene, obj_path):
    positions, tris, mtl = parse_obj(obj_path)
    tris, n_dropped = drop_duplicate_triangles(positions, tris)
    print("cycles_reference: %d triangles, %d duplicates dropped" % (len(tris), n_dropped))
    names = []
    for t in tris:
        if t[3] not in names:
            names.append(t[3])
    mesh = bpy.data.meshes.new("obj")
    verts = [y_up_to_z_up(p) for p in positions]
    mesh.from_pydata(verts, [], [t[:3] for t in tris])
    for name in names:
        m = mtl.get(name, {"Kd": (0.8, 0.8, 0.8), "Ke": (0.0, 0.0, 0.0)})
        mesh.materials.append(make_material(name, m["Kd"], m["Ke"]))
    for poly, t in zip(mesh.polygons, tris):
        poly.material_index = names.index(t[3])
        poly.use_smooth = False
    # no mesh.validate(): it would delete the OBJ's duplicated box faces, which mcpt keeps
    mesh.update()
    if len(mesh.polygons) != len(tris):
        raise RuntimeError("expected %d triangles, got %d" % (len(tris), len(mesh.polygons)))
    obj = bpy.data.objects.new("obj", mesh)
    scene.collection.objects.link(obj)


def add_camera(scene, fov_deg):
    # camera: eye (0,1,3.9), look-at (0,1,0), up +Y in OBJ space -> eye (0,-3.9,1), looking +Y,
    # up +Z in Blender space.  A Blender camera looks down its local -Z with local +Y up;
    # rotating by +90 degrees about X takes -Z to +Y and +Y to +Z.
    cam_data = bpy.data.cameras.new("camera")
    cam_data.type = "PERSP"
    cam_data.lens_unit = "FOV"
    cam_data.sensor_fit = "VERTICAL"
    cam_data.angle_y = math.radians(fov_deg)
    cam_data.clip_start = 1e-4
    cam_data.clip_end = 1e4
    cam_data.shift_x = cam_data.shift_y = 0.0
    cam = bpy.data.objects.new("camera", cam_data)
    cam.location = y_up_to_z_up((0.0, 1.0, 3.9))
    cam.rotation_mode = "XYZ"
    cam.rotation_euler = (math.pi / 2.0, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam


def set_world_and_render(scene, args):
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bg.inputs["Strength"].default_value = 0.0
    scene.world = world

    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x = r.resolution_y = args.size
    r.resolution_percentage = 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    r.film_transparent = False
    r.use_border = False
    r.use_motion_blur = False
    r.use_persistent_data = False
    r.threads_mode = "FIXED"
    r.threads = args.threads
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_mode = "RGBA"
    r.image_settings.color_depth = "32"
    r.image_settings.exr_codec = "ZIP"
    r.use_compositing = False
    r.use_sequencer = False
    r.dither_intensity = 0.0

    vs = scene.view_settings
    vs.view_transform = "Standard"
    vs.look = "None"
    vs.exposure = 0.0
    vs.gamma = 1.0
    vs.use_curve_mapping = False

    c = scene.cycles
    c.device = "CPU"
    c.feature_set = "SUPPORTED"
    c.samples = args.spp
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.use_animated_seed = False
    c.sample_offset = 0
    c.time_limit = 0.0
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.caustics_reflective = True
    c.caustics_refractive = True
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = BOUNCES
    c.transmission_bounces = c.volume_bounces = BOUNCES
    c.transparent_max_bounces = BOUNCES
    c.min_light_bounces = 0
    c.min_transparent_bounces = 0
    c.light_sampling_threshold = 0.0
    c.direct_light_sampling_type = "MULTIPLE_IMPORTANCE_SAMPLING"
    c.use_fast_gi = False
    c.use_guiding = False
    c.auto_scrambling_distance = False
    c.scrambling_distance = 1.0
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.film_exposure = 1.0  # a linear factor in Cycles: 1 = unchanged
    c.use_camera_cull = c.use_distance_cull = False
    if hasattr(c, "use_light_tree"):  # Blender >= 3.5 only; 3.4 samples lights by area
        c.use_light_tree = False
    for vl in scene.view_layers:
        vl.cycles.denoising_store_passes = False
        vl.samples = 0  # use the scene's sample count
        vl.use_pass_combined = True


def convention_checks(args):
    """Renders three tiny scenes whose exact answers are known, to pin Cycles' conventions:
    (1) a camera facing the front of a large emissive quad (Ke = 17,12,4) must read Ke exactly;
    (2) the same quad seen from its back must read 0 (one-sided emission);
    (3) a large diffuse quad (Kd = 0.725,0.71,0.68) facing the camera under a constant white
        world of radiance 1 must read Kd (Lambertian f = rho/pi: integral of f cos = rho),
        up to the sky hidden by the quad's finite size (~1e-6 here).
    Returns a list of dicts {name, expected, got}."""
    checks = []
    cases = [
        ("emission front = Ke", (17.0, 12.0, 4.0), (0.0, 0.0, 0.0), False, 0.0, (17.0, 12.0, 4.0)),
        ("emission back = 0", (17.0, 12.0, 4.0), (0.0, 0.0, 0.0), True, 0.0, (0.0, 0.0, 0.0)),
        ("diffuse under sky 1 = Kd", (0.0, 0.0, 0.0), (0.725, 0.71, 0.68), False, 1.0,
         (0.725, 0.71, 0.68)),
    ]
    for name, ke, kd, flip, sky, expected in cases:
        sub = argparse.Namespace(**vars(args))
        sub.size, sub.spp = 16, 64
        scene = build_scene(sub, geometry=False)
        # quad in OBJ space at z = 0, camera at (0,1,3.9) looking down -z: front faces +z
        h = 1e3
        quad = [(-h, -h, 0.0), (h, -h, 0.0), (h, h, 0.0), (-h, h, 0.0)]
        if flip:
            quad.reverse()
        mesh = bpy.data.meshes.new("quad")
        mesh.from_pydata([y_up_to_z_up(p) for p in quad], [], [(0, 1, 2), (0, 2, 3)])
        mesh.materials.append(make_material("quad", kd, ke))
        obj = bpy.data.objects.new("quad", mesh)
        scene.collection.objects.link(obj)
        bg = scene.world.node_tree.nodes["Background"]
        bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        bg.inputs["Strength"].default_value = sky
        path = os.path.join(tempfile.mkdtemp(prefix="cycles_check_"), "check.exr")
        got, _ = render_seed(scene, 1, path)
        os.remove(path)
        checks.append({"name": name, "expected": list(expected), "got": got})
        print("cycles_reference: check %-26s expected %s got %s"
              % (name, expected, ["%.6f" % g for g in got]), flush=True)
    return checks


def render_seed(scene, seed, path):
    scene.cycles.seed = seed
    scene.render.filepath = path
    t0 = time.time()
    bpy.ops.render.render(write_still=True)
    secs = time.time() - t0
    stats = exr_mean.image_stats(path)
    return stats["mean"], secs


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    ap = argparse.ArgumentParser(prog="cycles_reference.py")
    ap.add_argument("--obj", required=True)
    ap.add_argument("--out", required=True, help="JSON file written with the result")
    ap.add_argument("--spp", type=int, default=256, help="samples per pixel per seed")
    ap.add_argument("--size", type=int, default=512, help="square image width = height")
    ap.add_argument("--seeds", type=int, default=8, help="independent renders (K)")
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--fov", type=float, default=40.0, help="vertical field of view, degrees")
    ap.add_argument("--exr-dir", default=None, help="keep the per-seed EXRs here")
    ap.add_argument("--no-checks", action="store_true", help="skip the convention checks")
    args = ap.parse_args(argv)

    checks = [] if args.no_checks else convention_checks(args)

    scene = build_scene(args)
    exr_dir = args.exr_dir or tempfile.mkdtemp(prefix="cycles_ref_")
    os.makedirs(exr_dir, exist_ok=True)
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    per_seed, total_secs = [], 0.0
    for s in seeds:
        path = os.path.join(exr_dir, "seed%d.exr" % s)
        mean, secs = render_seed(scene, s, path)
        total_secs += secs
        per_seed.append(mean)
        print("cycles_reference: seed %d: mean %.6f %.6f %.6f (%.1f s)" % (s, *mean, secs),
              flush=True)
        if not args.exr_dir:
            os.remove(path)
    k = len(per_seed)
    mean = [math.fsum(m[c] for m in per_seed) / k for c in range(3)]
    if k > 1:
        se = [math.sqrt(math.fsum((m[c] - mean[c]) ** 2 for m in per_seed) / (k - 1) / k)
              for c in range(3)]
    else:
        se = [float("nan")] * 3
    result = {
        "scene": "scenes/cornell-box.txt",
        "obj": args.obj,
        "renderer": "Blender Cycles (CPU, path tracing)",
        "blender_version": bpy.app.version_string,
        "quantity": "per-channel mean over all pixels of linear radiance (R, G, B)",
        "mean": mean,
        "se": se,
        "se_relative": [se[c] / mean[c] for c in range(3)],
        "spp_per_seed": args.spp,
        "seeds": seeds,
        "spp_total": args.spp * k,
        "width": args.size,
        "height": args.size,
        "per_seed_mean": per_seed,
        "render_seconds": round(total_secs, 1),
        "threads": args.threads,
        "settings": {
            "fov_vertical_deg": args.fov, "pixel_filter": "BOX width 1 px",
            "bounces": BOUNCES, "clamp": 0, "denoising": False, "adaptive_sampling": False,
            "light_sampling_threshold": 0, "path_guiding": False, "caustics": True,
            "direct_light_sampling": "MULTIPLE_IMPORTANCE_SAMPLING",
            "sampling_pattern": scene.cycles.sampling_pattern,
            "emission": "Ke, strength 1, front side only", "bsdf": "Diffuse BSDF Kd, roughness 0",
            "world": "black", "view_transform": "Standard", "exposure": 0,
        },
        "convention_checks": checks,
        "command": "blender -b --factory-startup --python scripts/cycles_reference.py -- "
                   + " ".join(argv),
    }
    with open(args.out, "w") as f:
        json.dump(result, f, indent=2)
        f.write("\n")
    print("cycles_reference: mean %.6f %.6f %.6f  SE %.2e %.2e %.2e" % (*mean, *se))


if __name__ == "__main__":
    main()
