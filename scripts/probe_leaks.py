#!/usr/bin/env python3
"""probe_leaks.py - random probes of issue 12's classes: closed meshes that must let no sky in,
sheared quads that must render exactly, and images that must not depend on scale or position.

Python standard library only; renders with an mcpt binary in a scratch folder.  Modes:

  cubes    a closed cube (camera inside, diffuse walls, constant white sky) under a random
           rotation (--no-turn: none), scale 1e-15..1e15 and offset up to 1e4 sizes; every pixel
           must be exactly 0.  --cells N cuts each face into an N x N grid whose faces share
           their edges' vertices; --strips N into N strips, as tests/extremes_test.c does, whose
           ends are T-junctions on the next face's edge (scene.c, tj_pass, closes them).
  wedges   a closed wedge (a triangular prism of 8 triangles sharing vertices, its apex edge a
           groove of 0.5..45 degrees seen from inside) under a random rotation, scale 1e-8..1e8
           and offset up to 1e4 sizes, wound either way, the camera inside; every pixel must be
           exactly 0 (scene.c, grooves).  --soup gives each triangle its own three vertices.
  sheared  a closed parallelepiped of six quads whose faces meet at 2..45 degrees along one edge,
           turned, scaled 1e-6..1e6 and moved up to 1e4 sizes, corners and edges written to 17
           digits, the camera inside near that edge; every pixel must be exactly 0.  --boxes N
           puts N - 1 copies of quads in a row beside it (N = 200: 1200 quads).
  standing an open-bottomed cube of 10 mesh triangles standing on a plane or a quad (a floor
           statement; --mesh-floor: two triangles of another mesh), turned, scaled 1e-6..1e6 and
           moved up to 1e3 sizes, the camera inside, down to 1e-4 of its size above the floor;
           every pixel must be exactly 0.
  spheres  a closed analytic sphere (camera inside, diffuse walls, white sky) of radius 1e-15..1e15
           moved up to 2^20 radii from the origin in a random direction (down to the smallest
           radius scene.c accepts there); every pixel must be exactly 0.
  planes   a closed box of six infinite planes (camera inside, white sky), turned (half of them
           with one face normal on the x axis), scaled 1e-10..1e10 and moved 10^(D-1)..10^D box
           sizes (--decade D) along some axes; every pixel must be exactly 0.  Planes have no
           edges to keep their points from (docs/theory.md, "What no scheme can promise").
  quads    a parallelogram of albedo 0.8 under a sky of 2, sheared to 0.1..20 degrees, turned,
           scaled 1e-12..1e12 and moved up to 100 sizes, seen from either side: every pixel 1.6.
  offset   CornellBox-Original rounded to a grid of 1/G, moved by each --offsets value (camera
           too), against the same at the origin: image means and their z (independent sampler).
  scales   an OBJ (--obj) scaled by 1e-15, 1e-6, 1e6, 1e15 (camera too) against scale 1.
  scene    a scene file (--scene, default every one of scenes/) scaled by each --factors value
           (every length: camera, lens, radii, corners, edges, planes, checker periods, meshes;
           point-light intensity by the square), or with --move moved by it along x, at 48 x 36
           and --spp independent samples, against the scene as written (image means and z).

  python3 scripts/probe_leaks.py cubes --cells 10 --cases 50 --seed 22
  python3 scripts/probe_leaks.py cubes --strips 30 --cases 50 --seed 21
  python3 scripts/probe_leaks.py wedges --cases 60 --seed 1
  python3 scripts/probe_leaks.py wedges --cases 60 --seed 1 --soup
  python3 scripts/probe_leaks.py sheared --cases 70 --seed 1
  python3 scripts/probe_leaks.py standing --cases 40 --seed 1
  python3 scripts/probe_leaks.py spheres --cases 50 --seed 3
  python3 scripts/probe_leaks.py planes --cases 30 --decade 5 --seed 1
  python3 scripts/probe_leaks.py quads --cases 100 --seed 2
  python3 scripts/probe_leaks.py offset --grid 32 --offsets 1e5,2e5,4e5
  python3 scripts/probe_leaks.py scales --obj ../shared/models/cornell-box/CornellBox-Sphere.obj
  python3 scripts/probe_leaks.py scene --factors 1e-15,1e-6,1e6,1e15 --spp 256
  python3 scripts/probe_leaks.py scene --move --factors 1e3,1e4,1e5 --spp 256
"""

import argparse
import math
import os
import random
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from exr_mean import image_stats, read_exr  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def fmt(v):
    return ",".join("%.9g" % x for x in v)


def normalize(v):
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def rotation(axis, degrees):
    """Rodrigues' rotation about the unit axis, the sense of the scene format's rotate=."""
    ux, uy, uz = axis
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))

    def rot(p):
        x, y, z = p
        d = ux * x + uy * y + uz * z
        cx, cy, cz = uy * z - uz * y, uz * x - ux * z, ux * y - uy * x
        return [x * c + cx * s + ux * d * (1 - c), y * c + cy * s + uy * d * (1 - c),
                z * c + cz * s + uz * d * (1 - c)]
    return rot


def render(mcpt, scene, seed=0, refusal_ok=False):
    """The EXR mcpt renders of scene; None where it refuses the scene (exit 2) and refusal_ok."""
    exr = scene + ".exr"
    r = subprocess.run([mcpt, scene, "-o", exr, "--threads", "2", "--seed", str(seed)],
                       capture_output=True, text=True)
    if r.returncode == 2 and refusal_ok:
        return None
    if r.returncode != 0:
        sys.exit("%s: %s" % (scene, r.stderr.strip()))
    return exr


def cube_obj(path, cells, strips, inward, quad_faces=()):
    """The cube [-1, 1]^3: a grid of cells x cells per face sharing vertices by index, or strips
    per face (T-junctions where they end on the next face).  The faces numbered in quad_faces
    (2 axis + (sign > 0)) are left out and returned as quads' (corner, edge1, edge2), facing as
    the mesh's faces do."""
    n, m = (strips, 1) if strips else (cells, cells)
    verts, out_v, out_f, quads = {}, [], [], []

    def vid(p):
        if p not in verts:
            verts[p] = len(verts) + 1
            out_v.append("v %.9g %.9g %.9g" % tuple(-1 + 2 * c / (n * m) for c in p))
        return verts[p]
    for axis in range(3):
        for sign in (-1, 1):
            u, w = (axis + 1) % 3, (axis + 2) % 3
            if 2 * axis + (sign > 0) in quad_faces:
                c, e1, e2 = [-1, -1, -1], [0, 0, 0], [0, 0, 0]
                c[axis], e1[u], e2[w] = sign, 2, 2
                quads.append((c, e1, e2) if (sign > 0) != inward else (c, e2, e1))  # e1 x e2 = +axis
                continue
            for i in range(n):
                for j in range(m):
                    def corner(a, b):
                        p = [0, 0, 0]
                        p[axis] = 0 if sign < 0 else n * m
                        p[u], p[w] = a * m, b * n
                        return vid(tuple(p))
                    a, b, c, d = corner(i, j), corner(i + 1, j), corner(i + 1, j + 1), corner(i, j + 1)
                    if (sign > 0) == inward:
                        out_f.append("f %d %d %d\nf %d %d %d" % (a, c, b, a, d, c))
                    else:
                        out_f.append("f %d %d %d\nf %d %d %d" % (a, b, c, a, c, d))
    with open(path, "w") as f:
        f.write("\n".join(out_v + out_f) + "\n")
    return quads


def closed_scene(path, camera, shapes):
    """A camera inside a closed surface of albedo 0.9 (material m) under a constant white sky:
    camera is the statement's parameters, shapes its statements."""
    with open(path, "w") as f:
        f.write("camera %s\n" % camera)
        f.write("film width=24 height=24\nrender spp=64 sampler=independent\n")
        f.write("material name=m type=diffuse albedo=0.9,0.9,0.9\n")
        f.write("".join(line + "\n" for line in shapes))
        f.write("sky type=constant radiance=1,1,1\n")


def brightest(args, scene, refusal_ok=False):
    """The brightest pixel mcpt renders of scene (0 when no sky gets in); None where it refuses
    the scene and refusal_ok (the eye rounds onto look-at)."""
    out = render(args.mcpt, scene, refusal_ok=refusal_ok)
    return None if out is None else max(read_exr(out)[2]["R"])


def probe_cubes(args, tmp):
    rng = random.Random(args.seed)
    leaks = ran = 0
    for it in range(args.cases):
        inward = rng.random() < 0.5
        obj = os.path.join(tmp, "cube-%d.obj" % inward)
        quad_faces = rng.sample(range(6), args.quad_faces)
        quads = cube_obj(obj, args.cells, args.strips, inward, quad_faces)
        s = 10 ** rng.uniform(-15, 15)
        t = [rng.uniform(-1, 1) * s * rng.choice([0, 1, 10, 100, 1000, 1e4]) for _ in range(3)]
        axis = normalize([rng.gauss(0, 1) for _ in range(3)])
        angle = rng.uniform(0, 360) if args.turn else 0.0
        rot = rotation(axis, angle)
        # the camera inside, down to 64 float steps of the coordinates (or 1e-6) from a wall
        rel = max(abs(x) for x in t) / s + 2
        lo = math.log10(max(1e-6, 64 * 2 ** -23 * rel))
        if lo > -1 or rel * s > 1e17:  # no room for the camera, or beyond the scene's range
            continue
        e = [rng.choice([rng.uniform(-0.99, 0.99), rng.choice([-1, 1]) * (1 - 10 ** rng.uniform(lo, -1))])
             for _ in range(3)]
        la = [rng.uniform(-1, 1) for _ in range(3)]
        eye = [v * s + o for v, o in zip(rot(e), t)]
        at = [v * s + o for v, o in zip(rot(la), t)]
        if max(abs(a - b) for a, b in zip(eye, at)) < 1e-3 * s:
            continue
        scene = os.path.join(tmp, "cube.txt")
        closed_scene(scene, "eye=%s look-at=%s up=0.1,1,0.2 fov=%.3f" % (fmt(eye), fmt(at), rng.uniform(30, 150)),
                     ["mesh file=%s material=m rotate=%s,%.9g scale=%.9g translate=%s"
                      % (obj, fmt(axis), angle, s, fmt(t))]
                     + ["quad corner=%s edge1=%s edge2=%s material=m rotate=%s,%.9g scale=%.9g translate=%s"
                        % (fmt(c), fmt(e1), fmt(e2), fmt(axis), angle, s, fmt(t)) for c, e1, e2 in quads])
        ran += 1
        b = brightest(args, scene)
        if b != 0:
            leaks += 1
            print("leak: case %d, scale %.3g, brightest pixel %.3g" % (it, s, b))
    print("cubes: %d of %d let sky in" % (leaks, ran))
    return leaks == 0


def groove_leak(args, scene, it, deg, s):
    """1 (and a line) where sky gets into the closed scene of case it, else 0."""
    b = brightest(args, scene)
    if b != 0:
        print("leak: case %d, %g degrees, scale %.3g, brightest pixel %.3g" % (it, deg, s, b))
    return int(b != 0)


def random_placement(rng, scales, moves):
    """A random rotation, a scale 10^-scales..10^scales and a move of up to 10^moves scaled sizes
    (or none), as a function of a local point, and the scale."""
    rot = rotation(normalize([rng.gauss(0, 1) for _ in range(3)]), rng.uniform(0, 360))
    s = 10 ** rng.uniform(-scales, scales)
    t = [rng.uniform(-1, 1) * 10 ** rng.uniform(0, moves) * s * rng.choice([0, 1]) for _ in range(3)]
    return (lambda p: [v * s + o for v, o in zip(rot(p), t)]), s


def probe_wedges(args, tmp):
    rng = random.Random(args.seed)
    leaks = 0
    faces = [(1, 2, 3), (4, 6, 5), (1, 4, 5), (1, 5, 2), (1, 3, 6), (1, 6, 4), (2, 5, 6), (2, 6, 3)]
    for it in range(args.cases):
        deg = rng.choice([0.5, 2, 5, 10, 20, 30, 45])
        h = 2 * math.tan(math.radians(deg / 2))
        local = [(0, 0, -1), (2, h, -1), (2, -h, -1), (0, 0, 1), (2, h, 1), (2, -h, 1)]
        place, s = random_placement(rng, 8, 4)
        flip = rng.random() < 0.5
        obj = os.path.join(tmp, "wedge.obj")
        with open(obj, "w") as f:
            if args.soup:  # every face its own three vertices, at the same coordinates
                for a, b, c in faces:
                    for k in ((a, c, b) if flip else (a, b, c)):
                        f.write("v %s\n" % fmt(place(local[k - 1])).replace(",", " "))
                f.write("".join("f %d %d %d\n" % (3 * i + 1, 3 * i + 2, 3 * i + 3) for i in range(len(faces))))
            else:
                f.write("".join("v %s\n" % fmt(place(p)).replace(",", " ") for p in local))
                f.write("".join("f %d %d %d\n" % ((a, c, b) if flip else (a, b, c)) for a, b, c in faces))
        x = rng.uniform(0.6, 1.9)
        eye, at = place((x, 0, rng.uniform(-0.5, 0.5))), place((0, 0, rng.uniform(-0.5, 0.5)))
        up = [a - b for a, b in zip(place((0, 1, 0)), place((0, 0, 0)))]
        scene = os.path.join(tmp, "wedge.txt")
        closed_scene(scene, "eye=%s look-at=%s up=%s fov=70" % (fmt(eye), fmt(at), fmt(up)),
                     ["mesh file=%s material=m" % obj])
        leaks += groove_leak(args, scene, it, deg, s)
    print("wedges: %d of %d let sky in" % (leaks, args.cases))
    return leaks == 0


def probe_sheared(args, tmp):
    rng = random.Random(args.seed)
    leaks = 0
    for it in range(args.cases):
        deg = rng.choice([float(x) for x in args.degrees.split(",")])
        a, b, c = (2, 0, 0), (2 * math.cos(math.radians(deg)), 2 * math.sin(math.radians(deg)), 0), (0, 0, 2)
        rot = rotation(normalize([rng.gauss(0, 1) for _ in range(3)]), rng.uniform(0, 360))
        s = 10 ** rng.uniform(-6, 6)
        t = [rng.uniform(-1, 1) * 10 ** rng.uniform(0, 4) * s * rng.choice([0, 1]) for _ in range(3)]
        vec = [[x * s for x in rot(e)] for e in (a, b, c)]
        far = [o + sum(v[i] for v in vec) for i, o in enumerate(t)]
        f17 = lambda v: ",".join("%.17g" % x for x in v)  # noqa: E731
        quads, mesh = [], []
        for k in range(1, args.boxes):  # copies beside it, 3 sizes apart along a (quads only)
            o = [x + 3 * k * v for x, v in zip(t, vec[0])]
            fo = [x + 3 * k * v for x, v in zip(far, vec[0])]
            for corner, sign in ((o, 1), (fo, -1)):
                for i, j in ((0, 1), (1, 2), (2, 0)):
                    quads.append("quad corner=%s edge1=%s edge2=%s material=m"
                                 % (f17(corner), f17([sign * x for x in vec[i]]), f17([sign * x for x in vec[j]])))
        for corner, sign in ((t, 1), (far, -1)):
            for i, j in ((0, 1), (1, 2), (2, 0)):
                e1, e2 = [sign * x for x in vec[i]], [sign * x for x in vec[j]]
                if rng.random() < 0.5:
                    e1, e2 = e2, e1
                if args.mixed and rng.random() < 0.5:  # this face as two triangles of a mesh
                    p = [corner, [a + b for a, b in zip(corner, e1)],
                         [a + b + c for a, b, c in zip(corner, e1, e2)], [a + b for a, b in zip(corner, e2)]]
                    mesh.append(p)
                    continue
                quads.append("quad corner=%s edge1=%s edge2=%s material=m" % (f17(corner), f17(e1), f17(e2)))
        u, w = rng.uniform(0.3, 0.9), rng.uniform(0.2, 0.8)
        eye = [o + 0.55 * u * vec[0][i] + 0.45 * u * vec[1][i] + w * vec[2][i] for i, o in enumerate(t)]
        at = [o + 0.01 * vec[0][i] + 0.01 * vec[1][i] + 0.5 * vec[2][i] for i, o in enumerate(t)]
        if mesh:
            obj = os.path.join(tmp, "sheared.obj")
            with open(obj, "w") as f:
                f.write("".join("v %s\n" % f17(p).replace(",", " ") for face in mesh for p in face))
                f.write("".join("f %d %d %d\n" % (4 * i + 1, 4 * i + 2, 4 * i + 3)
                                + "f %d %d %d\n" % (4 * i + 1, 4 * i + 3, 4 * i + 4) for i in range(len(mesh))))
            quads.append("mesh file=%s material=m" % obj)
        scene = os.path.join(tmp, "sheared.txt")
        closed_scene(scene, "eye=%s look-at=%s up=%s fov=70" % (f17(eye), f17(at), f17(vec[2])), quads)
        leaks += groove_leak(args, scene, it, deg, s)
    print("sheared: %d of %d let sky in" % (leaks, args.cases))
    return leaks == 0


def probe_standing(args, tmp):
    rng = random.Random(args.seed)
    leaks = 0
    # an open-bottomed cube [-1, 1] x [0, 2] x [-1, 1]: 10 triangles, the bottom corners 0..3
    local = [(x, y, z) for y in (0, 2) for x in (-1, 1) for z in (-1, 1)]
    faces = [(4, 6, 7), (4, 7, 5), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6)]
    for it in range(args.cases):
        place, s = random_placement(rng, 6, 3)
        flip = rng.random() < 0.5
        obj = os.path.join(tmp, "standing.obj")
        with open(obj, "w") as f:
            f.write("".join("v %s\n" % fmt(place(p)).replace(",", " ") for p in local))
            f.write("".join("f %d %d %d\n" % tuple(k + 1 for k in ((a, c, b) if flip else (a, b, c)))
                            for a, b, c in faces))
        up = [a - b for a, b in zip(place((0, 1, 0)), place((0, 0, 0)))]
        if args.mesh_floor:  # two triangles of another mesh
            floor_obj = os.path.join(tmp, "floor.obj")
            with open(floor_obj, "w") as f:
                f.write("".join("v %s\n" % fmt(place(p)).replace(",", " ")
                                for p in ((-3, 0, -3), (3, 0, -3), (3, 0, 3), (-3, 0, 3))))
                f.write("f 1 3 2\nf 1 4 3\n")
            floor = "mesh file=%s material=m" % floor_obj
        elif rng.random() < 0.5:
            floor = "plane point=%s normal=%s material=m" % (fmt(place((0, 0, 0))), fmt(up))
        else:
            c = place((-3, 0, -3))
            e1 = [a - b for a, b in zip(place((3, 0, -3)), c)]
            e2 = [a - b for a, b in zip(place((-3, 0, 3)), c)]
            floor = "quad corner=%s edge1=%s edge2=%s material=m" % (fmt(c), fmt(e1), fmt(e2))
        eye = place((rng.uniform(-0.9, 0.9), 10 ** rng.uniform(-4, 0.2), rng.uniform(-0.9, 0.9)))
        at = place((rng.uniform(-1, 1), 0, rng.uniform(-1, 1)))
        scene = os.path.join(tmp, "standing.txt")
        closed_scene(scene, "eye=%s look-at=%s up=%s fov=%.1f" % (fmt(eye), fmt(at), fmt(up), rng.uniform(40, 150)),
                     ["mesh file=%s material=m" % obj, floor])
        b = brightest(args, scene)
        if b != 0:
            leaks += 1
            print("leak: case %d, %s, scale %.3g, brightest pixel %.3g" % (it, floor.split()[0], s, b))
            if args.save:  # the case as standing-SEED-CASE.txt and .obj, the OBJ named relatively
                name = os.path.join(args.save, "standing-%d-%d" % (args.seed, it))
                text = open(scene).read()
                for src, suffix in ((obj, ".obj"), (os.path.join(tmp, "floor.obj"), "-floor.obj")):
                    if src in text:
                        with open(src) as f, open(name + suffix, "w") as g:
                            g.write(f.read())
                        text = text.replace(src, os.path.basename(name) + suffix)
                with open(name + ".txt", "w") as g:
                    g.write(text)
    print("standing: %d of %d let sky in" % (leaks, args.cases))
    return leaks == 0


def probe_spheres(args, tmp):
    rng = random.Random(args.seed)
    leaks = ran = 0
    for it in range(args.cases):
        r = 10 ** rng.uniform(-15, 15)
        # half of them along an axis: there one coordinate's rounding is large and the others'
        # small, the case where a point off sideways can sit outside the curved surface
        d = normalize([rng.gauss(0, 1) for _ in range(3)])
        if rng.random() < 0.5:
            d = [0.0, 0.0, 0.0]
            d[rng.randrange(3)] = rng.choice([-1.0, 1.0])
        far = r * 2 ** rng.uniform(0, 20) if rng.random() < 0.8 else 0.0
        c = [x * far for x in d]
        if max(abs(x) for x in c) + r > 1e17:
            continue
        e = normalize([rng.gauss(0, 1) for _ in range(3)])
        k = rng.uniform(0, 0.95)
        eye = [c[i] + k * r * e[i] for i in range(3)]
        at = [c[i] + r * rng.gauss(0, 1) for i in range(3)]
        scene = os.path.join(tmp, "sphere.txt")
        closed_scene(scene, "eye=%s look-at=%s up=0.1,1,0.2 fov=%.3f" % (fmt(eye), fmt(at), rng.uniform(30, 150)),
                     ["sphere center=%s radius=%.9g material=m" % (fmt(c), r)])
        b = brightest(args, scene, refusal_ok=True)
        if b is None:
            continue
        ran += 1
        if b != 0:
            leaks += 1
            print("leak: case %d, radius %.3g at %.3g radii, brightest pixel %.3g"
                  % (it, r, far / r, b))
    print("spheres: %d of %d let sky in" % (leaks, ran))
    return leaks == 0


def probe_planes(args, tmp):
    rng = random.Random(args.seed)
    leaks = ran = 0
    for it in range(args.cases):
        s = 10 ** rng.uniform(-10, 10)
        off = [rng.choice([0, 1, -1]) * s * 10 ** rng.uniform(args.decade - 1, args.decade)
               for _ in range(3)]
        a = normalize([rng.gauss(0, 1) for _ in range(3)])
        if rng.random() < 0.5:
            a = [1.0, 0.0, 0.0]
        b = normalize(cross(a, [rng.gauss(0, 1) for _ in range(3)]))
        c = cross(a, b)
        eye = [off[i] + s * (0.3 * a[i] + 0.1 * b[i] - 0.2 * c[i]) for i in range(3)]
        at = [off[i] + s * (0.5 * a[i] - 0.7 * b[i] + 0.4 * c[i]) for i in range(3)]
        scene = os.path.join(tmp, "planes.txt")
        closed_scene(scene, "eye=%s look-at=%s up=%s fov=120" % (fmt(eye), fmt(at), fmt(b)),
                     ["plane point=%s normal=%s material=m"
                      % (fmt([off[i] + sg * s * ax[i] for i in range(3)]), fmt([sg * x for x in ax]))
                      for ax in (a, b, c) for sg in (1, -1)])
        bright = brightest(args, scene, refusal_ok=True)
        if bright is None:
            continue
        ran += 1
        if bright != 0:
            leaks += 1
            print("leak: case %d, size %.3g moved %.3g sizes, brightest pixel %.3g"
                  % (it, s, max(abs(x) for x in off) / s, bright))
    print("planes: %d of %d let sky in" % (leaks, ran))
    return leaks == 0


def probe_quads(args, tmp):
    rng = random.Random(args.seed)
    bad = ran = 0
    for it in range(args.cases):
        s = 10 ** rng.uniform(-12, 12)
        theta = math.radians(10 ** rng.uniform(-1, 1.3))
        a = normalize([rng.gauss(0, 1) for _ in range(3)])
        t = normalize(cross(a, [rng.gauss(0, 1) for _ in range(3)]))
        b = [math.cos(theta) * x + math.sin(theta) * y for x, y in zip(a, t)]
        la, lb = rng.uniform(0.3, 3), rng.uniform(0.3, 3)
        e1, e2 = [x * la * s for x in a], [x * lb * s for x in b]
        c = [rng.uniform(-1, 1) * s * rng.choice([0, 1, 10, 100]) for _ in range(3)]
        n = normalize(cross(e1, e2))
        al, be = rng.uniform(0.3, 0.7), rng.uniform(0.3, 0.7)
        p = [c[k] + al * e1[k] + be * e2[k] for k in range(3)]
        side = rng.choice([1, -1])
        v = normalize([side * n[k] + 0.5 * rng.gauss(0, 1) for k in range(3)])
        if sum(v[k] * n[k] for k in range(3)) * side < 0.5:
            continue
        dist = s * 10 ** rng.uniform(-1, 2)
        eye = [p[k] + dist * v[k] for k in range(3)]
        # the view's footprint well inside the parallelogram
        h = min(la, lb) * s * math.sin(theta) * min(al, be, 1 - al, 1 - be)
        fov = 2 * math.degrees(math.atan(0.2 * h / dist / 1.5))
        if fov < 1e-4:
            continue
        up = normalize(cross(v, [rng.gauss(0, 1) for _ in range(3)]))
        scene = os.path.join(tmp, "quad.txt")
        with open(scene, "w") as f:
            f.write("camera eye=%s look-at=%s up=%s fov=%.6g\n" % (fmt(eye), fmt(p), fmt(up), fov))
            f.write("film width=16 height=16\nrender spp=64 sampler=independent\n")
            f.write("material name=f type=diffuse albedo=0.8,0.8,0.8\n")
            f.write("quad corner=%s edge1=%s edge2=%s material=f\n" % (fmt(c), fmt(e1), fmt(e2)))
            f.write("sky type=constant radiance=2,2,2\n")
        ran += 1
        _, _, planes = read_exr(render(args.mcpt, scene))
        # 1.6 to the float rounding of a pixel's mean of 64 samples
        if not all(abs(x - 1.6) < 1e-6 for x in planes["R"]):
            bad += 1
            print("case %d: scale %.3g, %.3g degrees: pixels %.7g..%.7g"
                  % (it, s, math.degrees(theta), min(planes["R"]), max(planes["R"])))
    print("quads: %d of %d not exactly 1.6" % (bad, ran))
    return bad == 0


def compare_means(base, others):
    ok = True
    for label, st in others:
        z = [(st["mean"][c] - base["mean"][c]) / math.hypot(st["se"][c], base["se"][c]) for c in range(3)]
        rel = [st["mean"][c] / base["mean"][c] - 1 for c in range(3)]
        print("%s: %s" % (label, ", ".join("%+.2f%% (z %.1f)" % (100 * r, x) for r, x in zip(rel, z))))
        ok &= all(abs(x) <= 4 for x in z)
    return ok


def probe_offset(args, tmp):
    src = os.path.join(ROOT, "scenes", "models", "CornellBox-Original.obj")
    obj = os.path.join(tmp, "grid.obj")
    with open(src) as f, open(obj, "w") as out:
        for line in f:
            if line.startswith("v "):
                v = [round(float(x) * args.grid) / args.grid for x in line.split()[1:4]]
                line = "v %r %r %r\n" % tuple(v)
            elif line.startswith("mtllib"):
                line = "mtllib %s\n" % os.path.join(ROOT, "scenes", "models", "CornellBox-Original.mtl")
            out.write(line)
    stats = []
    for k, off in enumerate([0.0] + [float(x) for x in args.offsets.split(",")]):
        scene = os.path.join(tmp, "offset-%d.txt" % k)
        with open(scene, "w") as f:
            f.write("camera eye=%.9g,%.9g,%.9g look-at=%.9g,%.9g,%.9g up=0,1,0 fov=40\n"
                    % (off, off + 1, off + 3.906, off, off + 1, off))
            f.write("film width=32 height=32\nrender spp=%d max-depth=6 sampler=independent\n" % args.spp)
            f.write("mesh file=%s translate=%.9g,%.9g,%.9g\n" % (obj, off, off, off))
        stats.append(("offset %g" % off, image_stats(render(args.mcpt, scene, seed=5 + k))))
    return compare_means(stats[0][1], stats[1:])


def probe_scales(args, tmp):
    stats = []
    for k, s in enumerate([1, 1e-15, 1e-6, 1e6, 1e15]):
        scene = os.path.join(tmp, "scale-%d.txt" % k)
        with open(scene, "w") as f:
            f.write("camera eye=0,%.9g,%.9g look-at=0,%.9g,0 up=0,1,0 fov=40\n" % (s, 3.9 * s, s))
            f.write("film width=32 height=32\nrender spp=%d sampler=independent\n" % args.spp)
            f.write("mesh file=%s scale=%g\n" % (os.path.abspath(args.obj), s))
        stats.append(("scale %g" % s, image_stats(render(args.mcpt, scene, seed=1 + k))))
    return compare_means(stats[0][1], stats[1:])


# The parameters that are lengths, per statement: points (moved by --move) and vectors.
SCENE_POINTS = {("camera", "eye"), ("camera", "look-at"), ("sphere", "center"), ("quad", "corner"),
                ("plane", "point"), ("light", "position"), ("mesh", "translate"),
                ("quad", "translate"), ("sphere", "translate")}
SCENE_VECTORS = {("quad", "edge1"), ("quad", "edge2")}
SCENE_NUMBERS = {("camera", "aperture"), ("camera", "focus-dist"), ("sphere", "radius"),
                 ("material", "checker-scale")}


def transformed_scene(src, s, move, spp):
    """The scene file src scaled by s (or moved by s along x), at 48 x 36 and spp independent
    samples; mesh paths made absolute."""
    out = []
    for line in open(src):
        words = line.split("#")[0].split()
        if not words:
            continue
        st, new = words[0], [words[0]]
        scaled_mesh = False
        for w in words[1:]:
            k, v = w.split("=", 1)
            nums = v.split(",")
            if (st, k) in SCENE_POINTS:
                v = ",".join("%.17g" % (float(x) + (s if i == 0 else 0.0) if move else float(x) * s)
                             for i, x in enumerate(nums))
            elif (st, k) in SCENE_VECTORS or (st, k) in SCENE_NUMBERS or (st, k) == ("mesh", "scale"):
                v = ",".join("%.17g" % (float(x) * (1.0 if move else s)) for x in nums)
                scaled_mesh = scaled_mesh or st == "mesh"
            elif st == "light" and k == "intensity" and not move:
                v = ",".join("%.17g" % (float(x) * s * s) for x in nums)
            elif st == "mesh" and k == "file":
                v = os.path.abspath(os.path.join(os.path.dirname(src), v))
            elif st == "film" or (st == "render" and k in ("spp", "sampler")):
                continue
            new.append(k + "=" + v)
        if st == "mesh" and not move and not scaled_mesh:
            new.append("scale=%.17g" % s)
        if st == "mesh" and move and not any(w.startswith("translate=") for w in new):
            new.append("translate=%.17g,0,0" % s)
        out.append(" ".join(new))
    out = [l for l in out if not l.startswith("render")] + \
        ["render spp=%d sampler=independent %s" % (spp, " ".join(
            w for l in out if l.startswith("render") for w in l.split()[1:]))]
    out = [l for l in out if not l.startswith("film")] + ["film width=48 height=36"]
    return "\n".join(out) + "\n"


def probe_scene(args, tmp):
    scenes = [args.scene] if args.scene else sorted(
        os.path.join(ROOT, "scenes", f) for f in os.listdir(os.path.join(ROOT, "scenes"))
        if f.endswith(".txt"))
    ok = True
    for src in scenes:
        stats = []
        for k, s in enumerate([0.0 if args.move else 1.0] + [float(x) for x in args.factors.split(",")]):
            path = os.path.join(tmp, "scene-%d.txt" % k)
            with open(path, "w") as f:
                f.write(transformed_scene(src, s, args.move, args.spp))
            out = render(args.mcpt, path, seed=1 + k, refusal_ok=True)
            if out is None:
                print("%s at %g: refused (exit 2)" % (os.path.basename(src), s))
                continue
            stats.append(("%s %s %g" % (os.path.basename(src), "moved" if args.move else "scale", s),
                          image_stats(out)))
        if stats:
            ok &= compare_means(stats[0][1], stats[1:])
    return ok


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=["cubes", "wedges", "sheared", "standing", "spheres", "planes", "quads",
                                     "offset", "scales", "scene"])
    ap.add_argument("--mcpt", default=os.path.join(ROOT, "mcpt"))
    ap.add_argument("--cases", type=int, default=50)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--cells", type=int, default=3, help="cubes: grid cells per face side")
    ap.add_argument("--strips", type=int, default=0, help="cubes: strips per face instead")
    ap.add_argument("--quad-faces", type=int, default=0, help="cubes: this many faces as quads")
    ap.add_argument("--no-turn", dest="turn", action="store_false", help="cubes: no rotation")
    ap.add_argument("--decade", type=int, default=4, help="planes: moved 10^(D-1)..10^D sizes")
    ap.add_argument("--soup", action="store_true",
                    help="wedges: every triangle its own vertices (no index shared)")
    ap.add_argument("--degrees", default="2,5,10,20,30,45", help="sheared: the angles drawn from")
    ap.add_argument("--mixed", action="store_true",
                    help="sheared: each face a quad or two triangles of one mesh, by chance")
    ap.add_argument("--boxes", type=int, default=1,
                    help="sheared: this many boxes in a row (of quads but the first), camera in the first")
    ap.add_argument("--mesh-floor", action="store_true", help="standing: the floor two triangles of a mesh")
    ap.add_argument("--save", help="standing: copy each case that lets sky in into this folder")
    ap.add_argument("--grid", type=int, default=32, help="offset: vertices on the grid of 1/G")
    ap.add_argument("--offsets", default="1e5,2e5,4e5")
    ap.add_argument("--obj", default=os.path.join(ROOT, "scenes", "models", "CornellBox-Original.obj"))
    ap.add_argument("--spp", type=int, default=4096)
    ap.add_argument("--scene", help="scene: one scene file (default: every one of scenes/)")
    ap.add_argument("--factors", default="1e-15,1e-6,1e6,1e15", help="scene: scales or moves")
    ap.add_argument("--move", action="store_true", help="scene: move along x instead of scaling")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        ok = {"cubes": probe_cubes, "wedges": probe_wedges, "sheared": probe_sheared, "standing": probe_standing,
              "spheres": probe_spheres, "planes": probe_planes,
              "quads": probe_quads, "offset": probe_offset,
              "scales": probe_scales, "scene": probe_scene}[args.mode](args, tmp)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
