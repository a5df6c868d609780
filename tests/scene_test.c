/* scene_test.c - tests for scene.c, the scene-file parser (docs/scene-format.md).
 * Checks: every statement parses to its exact values and defaults; transforms follow scale,
 * then Rodrigues rotation, then translation, with normals by the inverse transpose (PBRT 4e,
 * ch. 3, "Applying Transformations") and mirrored winding kept front-facing; MTL records map to
 * mcpt materials; the light list holds emissive triangles, quads, spheres, then point lights;
 * every error gives its exact "file:line:col: error: expected ..., got ..." message (golden
 * strings); the Cornell box scene loads as the standard view.  Issue 15: a UTF-8 byte order
 * mark is skipped, mesh files that cannot be opened (missing, a folder, a FIFO) are errors of
 * the scene line, tiny and huge camera vectors work, points beyond 1e18 are refused with the
 * reason, underflowing numbers are the zero they are, and material names are hashed (a
 * quadratic lookup would hit the test's hang cap). */
#ifndef _DEFAULT_SOURCE
#define _DEFAULT_SOURCE /* mkdtemp, rmdir */
#endif
#include "scene.h"

#include "obj.h"
#include "test_util.h"

#include <criterion/criterion.h>
#include <fcntl.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

#define CAM "camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=40\n"
#define MAT "material name=red type=diffuse albedo=0.5,0.5,0.5\n"

static void assert_vec3(vec3 a, float x, float y, float z, const char *what)
{
    cr_assert(a.x == x && a.y == y && a.z == z,
              "%s: expected (%.9g, %.9g, %.9g), got (%.9g, "
              "%.9g, %.9g)",
              what, x, y, z, a.x, a.y, a.z);
}

static void assert_vec3_near(vec3 a, float x, float y, float z, const char *what)
{
    cr_assert(fabsf(a.x - x) <= 1e-6f && fabsf(a.y - y) <= 1e-6f && fabsf(a.z - z) <= 1e-6f,
              "%s: expected (%g, %g, %g), got (%.9g, %.9g, %.9g)", what, x, y, z, a.x, a.y, a.z);
}

static void assert_zeroed(const struct scene *sc)
{
    static const struct scene zero;
    cr_assert(memcmp(sc, &zero, sizeof zero) == 0, "a failed load must leave the scene zeroed");
}

/* Writes len bytes of text as scene.txt in a fresh temporary folder and loads it.  Returns
 * scene_load's result; on failure *msg holds the formatted error with the folder cut off, so
 * golden strings read "scene.txt:line:col: error: ...". */
static bool load_text(const char *text, size_t len, struct scene *sc, char *msg, size_t msg_bytes)
{
    char dir[] = "/tmp/mcpt-scene-test-XXXXXX";
    cr_assert_not_null(mkdtemp(dir));
    char path[64];
    snprintf(path, sizeof path, "%s/scene.txt", dir);
    FILE *f = fopen(path, "wb");
    cr_assert_not_null(f);
    cr_assert_eq(fwrite(text, 1, len, f), len);
    cr_assert_eq(fclose(f), 0);
    struct mcpt_error err = {0};
    bool ok = scene_load(path, sc, &err);
    remove(path);
    rmdir(dir);
    if (!ok) {
        char full[MCPT_ERROR_LINE_BYTES];
        mcpt_error_format(&err, full, sizeof full);
        size_t n_dir = strlen(dir);
        cr_assert(strncmp(full, dir, n_dir) == 0 && full[n_dir] == '/', "%s", full);
        snprintf(msg, msg_bytes, "%s", full + n_dir + 1);
    }
    return ok;
}

/* Loads text (with possible NUL bytes) and requires the exact error message golden. */
static void check_error_n(const char *text, size_t len, const char *golden)
{
    struct scene sc;
    memset(&sc, 0xa5, sizeof sc);
    char msg[640];
    cr_assert(!load_text(text, len, &sc, msg, sizeof msg), "expected an error for:\n%s", text);
    cr_assert_str_eq(msg, golden);
    assert_zeroed(&sc);
}

#define check_error(text, golden) check_error_n((text), sizeof(text) - 1, (golden))

/* Loads a fixture file and requires the exact error message golden. */
static void check_file_error(const char *path, const char *golden)
{
    struct scene sc;
    struct mcpt_error err = {0};
    char msg[MCPT_ERROR_LINE_BYTES];
    cr_assert(!scene_load(path, &sc, &err), "expected an error for %s", path);
    mcpt_error_format(&err, msg, sizeof msg);
    cr_assert_str_eq(msg, golden);
    assert_zeroed(&sc);
}

static void load_ok(const char *text, struct scene *sc)
{
    char msg[640] = "";
    cr_assert(load_text(text, strlen(text), sc, msg, sizeof msg), "unexpected error: %s", msg);
}

/* ---- valid scenes ---------------------------------------------------------------------- */

/* Every statement of tests/data/scene/full.txt, value by value: camera, film, render, the
 * material table (scene-file materials, then the mesh's MTL records and "default"), two meshes
 * (one rotated 90 degrees about y, scaled 2 and translated; one mirrored by scale=-1,1,1),
 * spheres (scaled and translated), quads (rotated 180 degrees; mirrored), a plane, point
 * lights, the sky and the light list.  The transforms chosen are exact in float, so positions
 * compare exactly: p' = R (s p) + t with R_y(90) (x, y, z) -> (z, y, -x). */
Test(scene, full_scene_values)
{
    struct scene sc;
    struct mcpt_error err = {0};
    bool ok = scene_load("tests/data/scene/full.txt", &sc, &err);
    cr_assert(ok, "%s:%d:%d: %s", err.file, err.line, err.col, err.msg);

    assert_vec3(sc.camera.eye, 0, 1, 3.9f, "eye");
    assert_vec3(sc.camera.look_at, 0, 1, 0, "look-at");
    assert_vec3(sc.camera.up, 0, 1, 0, "up");
    cr_assert_eq(sc.camera.fov_deg, 40.0f);
    cr_assert_eq(sc.camera.aperture, 0.05f);
    cr_assert_eq(sc.camera.focus_dist, 3.5f);
    cr_assert_eq(sc.width, 320);
    cr_assert_eq(sc.height, 240);
    cr_assert_eq(sc.render.spp, 16);
    cr_assert_eq(sc.render.max_depth, 5);

    /* materials */
    cr_assert_eq(sc.n_materials, 12);
    const struct material *m = sc.materials;
    cr_assert_str_eq(m[0].name, "red");
    cr_assert_eq(m[0].kind, MAT_DIFFUSE);
    assert_vec3(m[0].albedo, 0.63f, 0.065f, 0.05f, "red albedo");
    assert_vec3(m[0].Le, 0, 0, 0, "red Le");
    cr_assert(!m[0].two_sided_emission);
    cr_assert_str_eq(m[1].name, "lamp");
    assert_vec3(m[1].albedo, 0, 0, 0, "lamp albedo");
    assert_vec3(m[1].Le, 17, 12, 4, "lamp Le");
    cr_assert(m[1].two_sided_emission);
    cr_assert_str_eq(m[2].name, "chrome");
    cr_assert_eq(m[2].kind, MAT_MIRROR);
    assert_vec3(m[2].specular, 0.9f, 0.9f, 0.9f, "chrome specular");
    cr_assert_str_eq(m[3].name, "glass");
    cr_assert_eq(m[3].kind, MAT_DIELECTRIC);
    cr_assert_eq(m[3].ior, 1.33f);
    assert_vec3(m[3].specular, 1, 1, 1, "glass specular default");
    assert_vec3(m[3].Le, 0, 0, 0.5f, "glass Le");
    cr_assert_str_eq(m[4].name, "plain-glass");
    cr_assert_eq(m[4].ior, 1.5f, "default ior");
    /* tiny.mtl, mapped as docs/scene-format.md "MTL materials" says */
    cr_assert_str_eq(m[5].name, "tiny.obj:white");
    cr_assert_eq(m[5].kind, MAT_DIFFUSE);
    assert_vec3(m[5].albedo, 0.5f, 0.6f, 0.7f, "white Kd");
    cr_assert_str_eq(m[6].name, "tiny.obj:lamp");
    assert_vec3(m[6].Le, 4, 5, 6, "lamp Ke");
    cr_assert(!m[6].two_sided_emission);
    cr_assert_str_eq(m[7].name, "tiny.obj:chrome");
    cr_assert_eq(m[7].kind, MAT_MIRROR, "illum 5 -> mirror");
    assert_vec3(m[7].specular, 0.9f, 0.8f, 0.7f, "chrome Ks");
    cr_assert_str_eq(m[8].name, "tiny.obj:glass");
    cr_assert_eq(m[8].kind, MAT_DIELECTRIC, "illum 7 -> dielectric");
    cr_assert_eq(m[8].ior, 1.33f);
    assert_vec3(m[8].specular, 0.9f, 1, 1, "glass Tf");
    cr_assert_str_eq(m[9].name, "tiny.obj:crown");
    cr_assert_eq(m[9].kind, MAT_DIELECTRIC, "illum 4 -> dielectric");
    cr_assert_eq(m[9].ior, 1.5f, "Ni 1 (absent) -> 1.5");
    cr_assert_str_eq(m[10].name, "tiny.obj:bright");
    cr_assert_eq(m[10].kind, MAT_DIFFUSE, "illum 1 -> diffuse");
    assert_vec3(m[10].albedo, 1, 0.25f, 1, "Kd clamped to [0, 1]");
    assert_vec3(m[10].Le, 0, 0, 3, "Ke clamped to >= 0");
    cr_assert_str_eq(m[11].name, "default");
    cr_assert_eq(m[11].kind, MAT_DIFFUSE);
    assert_vec3(m[11].albedo, 0.8f, 0.8f, 0.8f, "default albedo");

    /* mesh 1: translate=1,2,3 rotate=0,1,0,90 scale=2; mesh 2: scale=-1,1,1 */
    cr_assert_eq(sc.n_positions, 12);
    const float pos[12][3] = {{1, 2, 3}, {1, 2, 1},  {1, 4, 1},  {1, 4, 3}, {3, 2, 3}, {1, 2, -1},
                              {0, 0, 0}, {-1, 0, 0}, {-1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {-2, 0, 0}};
    for (int i = 0; i < 12; i++)
        assert_vec3(sc.positions[i], pos[i][0], pos[i][1], pos[i][2], "position");
    cr_assert_eq(sc.n_normals, 4);
    assert_vec3(sc.normals[0], 1, 0, 0, "normal (0,0,2): S^-1, R_y(90), renormalised");
    assert_vec3(sc.normals[1], 0, 0, 0, "zero-length normal kept");
    assert_vec3(sc.normals[2], 0, 0, 1, "normal under the mirror");
    assert_vec3(sc.normals[3], 0, 0, 0, "zero-length normal kept");
    cr_assert_eq(sc.n_uvs, 8);
    cr_assert(sc.uvs[2].x == 1 && sc.uvs[2].y == 1 && sc.uvs[7].x == 0 && sc.uvs[7].y == 1);

    cr_assert_eq(sc.n_tris, 10);
    const struct scene_tri tris[10] = {
        {{0, 1, 4}, {-1, -1, -1}, {-1, -1, -1}, 11}, /* no usemtl: "default" */
        {{0, 1, 2}, {0, 0, 0}, {0, 1, 2}, 5},
        {{0, 2, 3}, {0, 0, 0}, {0, 2, 3}, 5},
        {{0, 2, 4}, {-1, -1, -1}, {-1, -1, -1}, 6}, /* zero normal: vn dropped */
        {{0, 1, 5}, {-1, -1, -1}, {-1, -1, -1}, 6},
        {{6, 10, 7}, {-1, -1, -1}, {-1, -1, -1}, 0}, /* mirrored: corners 0, 2, 1 */
        {{6, 8, 7}, {2, 2, 2}, {4, 6, 5}, 0},
        {{6, 9, 8}, {2, 2, 2}, {4, 7, 6}, 0},
        {{6, 10, 8}, {-1, -1, -1}, {-1, -1, -1}, 0},
        {{6, 11, 7}, {-1, -1, -1}, {-1, -1, -1}, 0},
    };
    for (int i = 0; i < 10; i++) {
        const struct scene_tri *a = &sc.tris[i], *e = &tris[i];
        for (int k = 0; k < 3; k++) {
            cr_assert_eq(a->v[k], e->v[k], "tri %d v[%d]", i, k);
            cr_assert_eq(a->vn[k], e->vn[k], "tri %d vn[%d]", i, k);
            cr_assert_eq(a->vt[k], e->vt[k], "tri %d vt[%d]", i, k);
        }
        cr_assert_eq(a->mat_idx, e->mat_idx, "tri %d mat_idx", i);
    }
    /* the mirrored copy keeps its front side: winding normal agrees with the shading normal */
    vec3 p0 = sc.positions[sc.tris[6].v[0]];
    vec3 ng = v3_cross(v3_sub(sc.positions[sc.tris[6].v[1]], p0),
                       v3_sub(sc.positions[sc.tris[6].v[2]], p0));
    cr_assert_gt(v3_dot(ng, sc.normals[2]), 0.0f);

    /* spheres: center' = 2 (1,0,0) + (0,1,0), radius' = 0.5 |2| */
    cr_assert_eq(sc.n_spheres, 2);
    assert_vec3(sc.spheres[0].center, 2, 1, 0, "sphere 0 center");
    cr_assert_eq(sc.spheres[0].radius, 1.0f);
    cr_assert_eq(sc.spheres[0].mat_idx, 1);
    assert_vec3(sc.spheres[1].center, 0, 0, 0, "sphere 1 center");
    cr_assert_eq(sc.spheres[1].radius, 1.0f);
    cr_assert_eq(sc.spheres[1].mat_idx, 3);

    /* quads: R_x(180) = diag(1,-1,-1) then translate; the mirrored one swaps its edges */
    cr_assert_eq(sc.n_quads, 2);
    assert_vec3(d3_to_float(sc.quads[0].corner), 0, 2, 0, "quad 0 corner");
    assert_vec3(d3_to_float(sc.quads[0].e1), 1, 0, 0, "quad 0 e1");
    assert_vec3(d3_to_float(sc.quads[0].e2), 0, 0, -1, "quad 0 e2");
    cr_assert_eq(sc.quads[0].mat_idx, 1);
    assert_vec3(d3_to_float(sc.quads[1].corner), -1, 0, 5, "quad 1 corner");
    assert_vec3(d3_to_float(sc.quads[1].e1), 0, 1, 0, "quad 1 e1");
    assert_vec3(d3_to_float(sc.quads[1].e2), -1, 0, 0, "quad 1 e2");
    assert_vec3(v3_cross(d3_to_float(sc.quads[1].e1), d3_to_float(sc.quads[1].e2)), 0, 0, 1,
                "quad 1 front normal");
    cr_assert_eq(sc.quads[1].mat_idx, 0);

    cr_assert_eq(sc.n_planes, 1);
    assert_vec3(sc.planes[0].point, 0, -1, 0, "plane point");
    assert_vec3(sc.planes[0].n, 0, 1, 0, "plane normal normalised");
    cr_assert_eq(sc.planes[0].mat_idx, 0);

    cr_assert_eq(sc.sky.kind, SKY_GRADIENT);
    assert_vec3(sc.sky.horizon, 1, 1, 1, "horizon");
    assert_vec3(sc.sky.zenith, 0.2f, 0.4f, 0.8f, "zenith");

    /* lights: tri 3 (tri 4 has zero area), quad 0, spheres 0 and 1, then the point lights */
    cr_assert_eq(sc.n_lights, 6);
    const enum light_kind kinds[6] = {LIGHT_TRIANGLE, LIGHT_QUAD,  LIGHT_SPHERE,
                                      LIGHT_SPHERE,   LIGHT_POINT, LIGHT_POINT};
    const uint32_t prims[6] = {3, 0, 0, 1, 0, 1};
    for (int i = 0; i < 6; i++) {
        cr_assert_eq(sc.lights[i].kind, kinds[i], "light %d kind", i);
        cr_assert_eq(sc.lights[i].prim_idx, prims[i], "light %d prim_idx", i);
    }
    assert_vec3(sc.lights[4].position, 0, 1.9f, 0, "point 0 position");
    assert_vec3(sc.lights[4].intensity, 1, 2, 3, "point 0 intensity");
    assert_vec3(sc.lights[5].position, 1, 1, 1, "point 1 position");
    assert_vec3(sc.lights[5].intensity, 0.5f, 0.5f, 0.5f, "point 1 intensity");
    scene_free(&sc);
    assert_zeroed(&sc);
}

/* A scene with only a camera gets the documented defaults: 512x512 film, spp 64, max-depth
 * inf (UINT32_MAX), pinhole (aperture 0, focus-dist 0), no sky, nothing allocated. */
Test(scene, defaults)
{
    struct scene sc;
    load_ok(CAM, &sc);
    cr_assert_eq(sc.width, 512);
    cr_assert_eq(sc.height, 512);
    cr_assert_eq(sc.render.spp, 64);
    cr_assert_eq(sc.render.max_depth, UINT32_MAX);
    cr_assert_eq(sc.camera.aperture, 0.0f);
    cr_assert_eq(sc.camera.focus_dist, 0.0f);
    cr_assert_eq(sc.sky.kind, SKY_NONE);
    cr_assert(sc.n_materials == 0 && sc.n_tris == 0 && sc.n_lights == 0 && !sc.lights);
    scene_free(&sc);
}

/* CRLF endings, tabs between words, blank lines, whole-line and trailing comments and a missing
 * final newline are all accepted. */
Test(scene, crlf_tabs_comments)
{
    struct scene sc;
    struct mcpt_error err = {0};
    cr_assert(scene_load("tests/data/scene/crlf.txt", &sc, &err), "%s:%d:%d: %s", err.file,
              err.line, err.col, err.msg);
    assert_vec3(sc.camera.eye, 0, 0, 5, "eye");
    cr_assert_eq(sc.camera.fov_deg, 40.0f);
    cr_assert_eq(sc.sky.kind, SKY_CONSTANT);
    assert_vec3(sc.sky.radiance, 0.5f, 0.25f, 0.125f, "radiance (the commented sky is skipped)");
    scene_free(&sc);
}

/* Range ends are inclusive where documented: a 4096-byte line, 65535-pixel film, spp
 * 4294967295, max-depth 0; a leading '+' and exponents are numbers. */
Test(scene, range_boundaries)
{
    char text[4400];
    int n = snprintf(text, sizeof text, "%s#", CAM);
    memset(text + n, 'x', 4095); /* '#' + 4095 bytes = 4096 */
    snprintf(text + n + 4095, sizeof text - (size_t)(n + 4095),
             "\r\nfilm width=65535 height=+1\nrender spp=4294967295 max-depth=0\n"
             "material name=m type=dielectric ior=2.5e-1\n");
    struct scene sc;
    load_ok(text, &sc);
    cr_assert_eq(sc.width, 65535);
    cr_assert_eq(sc.height, 1);
    cr_assert_eq(sc.render.spp, UINT32_MAX);
    cr_assert_eq(sc.render.max_depth, 0);
    cr_assert_eq(sc.materials[0].ior, 0.25f);
    scene_free(&sc);
    load_ok(CAM "render max-depth=inf spp=1\n", &sc);
    cr_assert_eq(sc.render.max_depth, UINT32_MAX);
    cr_assert_eq(sc.render.spp, 1);
    scene_free(&sc);
}

/* Rodrigues' rotation about a non-axis direction: 120 degrees about (1,1,1) permutes the
 * axes x -> y -> z -> x; the axis is normalised first. */
Test(scene, rotation_rodrigues)
{
    struct scene sc;
    load_ok(CAM MAT "quad corner=1,0,0 edge1=0,1,0 edge2=0,0,1 material=red rotate=2,2,2,120\n",
            &sc);
    assert_vec3_near(d3_to_float(sc.quads[0].corner), 0, 1, 0, "corner");
    assert_vec3_near(d3_to_float(sc.quads[0].e1), 0, 0, 1, "e1");
    assert_vec3_near(d3_to_float(sc.quads[0].e2), 1, 0, 0, "e2");
    scene_free(&sc);
    /* -90 about z, written as 270: (1,0,0) -> (0,-1,0) exactly; scale applies before */
    load_ok(CAM MAT "quad corner=1,0,0 edge1=0,1,0 edge2=0,0,1 material=red rotate=0,0,1,270 "
                    "scale=3,1,1 translate=0,0,1\n",
            &sc);
    assert_vec3(d3_to_float(sc.quads[0].corner), 0, -3, 1, "corner");
    assert_vec3(d3_to_float(sc.quads[0].e1), 1, 0, 0, "e1");
    assert_vec3(d3_to_float(sc.quads[0].e2), 0, 0, 1, "e2");
    scene_free(&sc);
}

/* Normals transform by the inverse transpose of the linear part (PBRT 4e, ch. 3, "Applying
 * Transformations"): under a non-uniform scale and a rotation the stored unit normal stays
 * perpendicular to the transformed triangle (the matrix itself would tilt it). */
Test(scene, normals_inverse_transpose)
{
    struct scene sc;
    struct mcpt_error err = {0};
    cr_assert(scene_load("tests/data/scene/nonuniform.txt", &sc, &err), "%s:%d:%d: %s", err.file,
              err.line, err.col, err.msg);
    cr_assert(sc.n_tris == 1 && sc.n_normals == 1);
    vec3 n = sc.normals[sc.tris[0].vn[0]];
    vec3 p0 = sc.positions[sc.tris[0].v[0]];
    vec3 e1 = v3_normalize(v3_sub(sc.positions[sc.tris[0].v[1]], p0));
    vec3 e2 = v3_normalize(v3_sub(sc.positions[sc.tris[0].v[2]], p0));
    cr_assert_float_eq(v3_length(n), 1.0f, 1e-6f);
    cr_assert_float_eq(v3_dot(n, e1), 0.0f, 1e-6f);
    cr_assert_float_eq(v3_dot(n, e2), 0.0f, 1e-6f);
    cr_assert_gt(v3_dot(n, v3_cross(e1, e2)), 0.0f, "same side as the winding");
    scene_free(&sc);
}

/* normals=smooth: angle-weighted vertex normals (Thurmer & Wuthrich 1998).  At each corner of
 * a box the three faces meet at right angles, so each adds pi/2 times its normal whether it is
 * cut into one or two triangles there: the corner normal is (+-1, +-1, +-1) / sqrt(3), pointing
 * out, although the 12-triangle cube has corners with 1 triangle of a face and corners with 2
 * (a face-count or area weighting would tilt it).  The box is stretched 2x along x after
 * loading: the normals are those of the world-space faces.  A bad value names both choices. */
Test(scene, normals_smooth_angle_weighted)
{
    struct scene sc;
    struct mcpt_error err = {0};
    cr_assert(scene_load("tests/data/scene/smooth-cube.txt", &sc, &err), "%s:%d:%d: %s", err.file,
              err.line, err.col, err.msg);
    cr_assert_eq(sc.n_tris, 12);
    cr_assert_eq(sc.n_normals, 8, "one normal per vertex, the OBJ has none");
    const float s = 0.57735026919f; /* 1 / sqrt(3) */
    for (uint32_t i = 0; i < sc.n_tris; i++)
        for (int k = 0; k < 3; k++) {
            cr_assert_geq(sc.tris[i].vn[k], 0);
            vec3 p = sc.positions[sc.tris[i].v[k]];
            vec3 n = sc.normals[sc.tris[i].vn[k]];
            assert_vec3_near(n, copysignf(s, p.x), copysignf(s, p.y), copysignf(s, p.z),
                             "corner normal");
        }
    scene_free(&sc);
    check_error(CAM MAT "mesh file=x.obj material=red normals=round\n",
                "scene.txt:3:38: error: expected file or smooth for 'normals', got 'round'");
}

/* scenes/cornell-box.txt: the standard view of McGuire's CornellBox-Original; 18 quads = 36
 * triangles, 8 MTL materials (every face has a usemtl, so no "default"), and the two triangles
 * of the light quad (y = 1.98, Ke 17 12 4) are the only lights. */
Test(scene, cornell_box)
{
    struct scene sc;
    struct mcpt_error err = {0};
    cr_assert(scene_load("scenes/cornell-box.txt", &sc, &err), "%s:%d:%d: %s", err.file, err.line,
              err.col, err.msg);
    assert_vec3(sc.camera.eye, 0, 1, 3.9f, "eye");
    assert_vec3(sc.camera.look_at, 0, 1, 0, "look-at");
    assert_vec3(sc.camera.up, 0, 1, 0, "up");
    cr_assert_eq(sc.camera.fov_deg, 40.0f);
    cr_assert_eq(sc.camera.aperture, 0.0f);
    cr_assert(sc.width == 512 && sc.height == 512);
    cr_assert_eq(sc.render.spp, 256);
    cr_assert_eq(sc.render.max_depth, UINT32_MAX);
    cr_assert_eq(sc.n_tris, 36);
    cr_assert_eq(sc.n_positions, 72);
    cr_assert_eq(sc.n_materials, 8);
    cr_assert_eq(sc.n_lights, 2);
    for (uint32_t i = 0; i < 2; i++) {
        const struct light *l = &sc.lights[i];
        cr_assert_eq(l->kind, LIGHT_TRIANGLE);
        cr_assert_eq(l->prim_idx, 34 + i, "the light quad is the last face");
        const struct scene_tri *t = &sc.tris[l->prim_idx];
        const struct material *m = &sc.materials[t->mat_idx];
        cr_assert_str_eq(m->name, "CornellBox-Original.obj:light");
        assert_vec3(m->Le, 17, 12, 4, "light Le");
        for (int k = 0; k < 3; k++)
            cr_assert_eq(sc.positions[t->v[k]].y, 1.98f);
    }
    cr_assert_str_eq(sc.materials[sc.tris[0].mat_idx].name, "CornellBox-Original.obj:floor");
    assert_vec3(sc.materials[sc.tris[0].mat_idx].albedo, 0.725f, 0.71f, 0.68f, "floor Kd");
    scene_free(&sc);
}

/* scene_free is safe on a zeroed scene and twice in a row. */
Test(scene, free_zeroed)
{
    struct scene sc = {0};
    scene_free(&sc);
    scene_free(&sc);
    assert_zeroed(&sc);
}

/* ---- errors: statements and parameters --------------------------------------------------- */

/* Unknown statement keyword: the message lists the valid ones. */
Test(scene, error_unknown_statement)
{
    check_error(CAM "cam eye=1\n",
                "scene.txt:2:1: error: expected a statement (camera, film, render, material, "
                "mesh, sphere, quad, plane, light, sky), got 'cam'");
}

/* Unknown parameter: the message lists the statement's parameters (for a typed statement,
 * those of its type). */
Test(scene, error_unknown_parameter)
{
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=40 zoom=2\n",
                "scene.txt:1:48: error: expected a parameter of 'camera' (eye, look-at, up, fov, "
                "aperture, focus-dist), got 'zoom'");
    check_error(CAM "material name=m type=diffuse albedo=1,1,1 ior=1.5\n",
                "scene.txt:2:43: error: expected a parameter of 'material type=diffuse' (name, "
                "type, albedo, emission, two-sided, checker, checker-scale, checker-uv), got "
                "'ior'");
    check_error(CAM MAT "sphere center=0,0,0 radius=1 material=red rotate=0,1,0,9\n",
                "scene.txt:3:43: error: expected a parameter of 'sphere' (center, radius, "
                "material, translate, scale), got 'rotate'");
}

/* A parameter given twice, and a word without '='. */
Test(scene, error_duplicate_parameter_and_missing_equals)
{
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=40 fov=50\n",
                "scene.txt:1:48: error: expected 'fov' at most once, got it twice");
    check_error(CAM "film width 512 height=512\n",
                "scene.txt:2:6: error: expected 'key=value', got 'width'");
    check_error("camera eye= look-at=0,0,0 up=0,1,0 fov=40\n",
                "scene.txt:1:12: error: expected a value after 'eye=', got nothing");
}

/* Missing required parameters are reported at the statement keyword. */
Test(scene, error_missing_parameter)
{
    check_error("camera eye=0,0,5 up=0,1,0 fov=40\n",
                "scene.txt:1:1: error: expected parameter 'look-at' for 'camera', got none");
    check_error(CAM "  material name=x albedo=1,1,1\n",
                "scene.txt:2:3: error: expected parameter 'type' for 'material', got none");
    check_error(CAM "material name=x type=diffuse\n",
                "scene.txt:2:1: error: expected parameter 'albedo' for 'material type=diffuse', "
                "got none");
    check_error(CAM "sky type=gradient horizon=1,1,1\n",
                "scene.txt:2:1: error: expected parameter 'zenith' for 'sky type=gradient', "
                "got none");
}

/* A value of the wrong type: number, vector, name, bool, integer; and wrong vector arity. */
Test(scene, error_wrong_type)
{
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=1,2,3\n",
                "scene.txt:1:45: error: expected a number for 'fov', got '1,2,3'");
    check_error("camera eye=here look-at=0,0,0 up=0,1,0 fov=40\n",
                "scene.txt:1:12: error: expected 3 comma-separated numbers for 'eye', got "
                "'here'");
    check_error("camera eye=0,1 look-at=0,0,0 up=0,1,0 fov=40\n",
                "scene.txt:1:12: error: expected 3 comma-separated numbers for 'eye', got '0,1'");
    check_error("camera eye=0,,1 look-at=0,0,0 up=0,1,0 fov=40\n",
                "scene.txt:1:12: error: expected 3 comma-separated numbers for 'eye', got "
                "'0,,1'");
    check_error(CAM MAT "sphere center=0,0,0 radius=1 material=1,2,3\n",
                "scene.txt:3:39: error: expected a material name of letters, digits, '_', '-' "
                "and '.', got '1,2,3'");
    check_error(CAM "material name=m type=mirror two-sided=yes\n",
                "scene.txt:2:39: error: expected true or false for 'two-sided', got 'yes'");
    check_error(CAM "film width=1.5 height=2\n",
                "scene.txt:2:12: error: expected an integer for 'width', got '1.5'");
    check_error(CAM "render max-depth=deep\n",
                "scene.txt:2:18: error: expected an integer or 'inf' for 'max-depth', got "
                "'deep'");
    check_error(CAM MAT "quad corner=0,0,0 edge1=1,0,0 edge2=0,1,0 material=red rotate=0,1,0\n",
                "scene.txt:3:63: error: expected 4 comma-separated numbers (axis x,y,z, angle in "
                "degrees) for 'rotate', got '0,1,0'");
    check_error(CAM MAT "quad corner=0,0,0 edge1=1,0,0 edge2=0,1,0 material=red scale=1,2\n",
                "scene.txt:3:62: error: expected 1 or 3 comma-separated numbers for 'scale', got "
                "'1,2'");
    /* '#' inside a value is part of the value, not a comment */
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=40#wide\n",
                "scene.txt:1:45: error: expected a number for 'fov', got '40#wide'");
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=0x10\n",
                "scene.txt:1:45: error: expected a number for 'fov', got '0x10'");
}

/* NaN, infinity and literals beyond float range are rejected. */
Test(scene, error_non_finite)
{
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=nan\n",
                "scene.txt:1:45: error: expected a finite number for 'fov', got 'nan'");
    check_error("camera eye=0,-INF,5 look-at=0,0,0 up=0,1,0 fov=40\n",
                "scene.txt:1:12: error: expected finite numbers for 'eye', got '0,-INF,5'");
    check_error(CAM MAT "sphere center=0,0,0 radius=1e39 material=red\n",
                "scene.txt:3:28: error: expected a finite number for 'radius', got '1e39'");
}

/* Out-of-range values, each with its documented range. */
Test(scene, error_out_of_range)
{
    check_error(CAM MAT "sphere center=0,0,0 radius=0 material=red\n",
                "scene.txt:3:28: error: expected 'radius' > 0, got 0");
    check_error(CAM MAT "sphere center=0,0,0 radius=-1 material=red\n",
                "scene.txt:3:28: error: expected 'radius' > 0, got -1");
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=180\n",
                "scene.txt:1:45: error: expected 'fov' in (0, 180) degrees, got 180");
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=0\n",
                "scene.txt:1:45: error: expected 'fov' in (0, 180) degrees, got 0");
    check_error(CAM "film width=0 height=4\n",
                "scene.txt:2:12: error: expected 'width' in 1..65535, got 0");
    check_error(CAM "film width=640 height=65536\n",
                "scene.txt:2:23: error: expected 'height' in 1..65535, got 65536");
    check_error(CAM "render spp=0\n",
                "scene.txt:2:12: error: expected 'spp' in 1..4294967295, got 0");
    check_error(CAM "render spp=-4\n",
                "scene.txt:2:12: error: expected 'spp' in 1..4294967295, got -4");
    check_error(CAM "render spp=4294967296\n",
                "scene.txt:2:12: error: expected 'spp' in 1..4294967295, got 4294967296");
    check_error(CAM "render max-depth=-1\n",
                "scene.txt:2:18: error: expected 'max-depth' in 0..4294967295 or 'inf', got -1");
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=40 aperture=-0.1\n",
                "scene.txt:1:57: error: expected 'aperture' >= 0, got -0.1");
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=40 focus-dist=-1\n",
                "scene.txt:1:59: error: expected 'focus-dist' >= 0, got -1");
    check_error(CAM "material name=m type=diffuse albedo=1.2,0,0\n",
                "scene.txt:2:37: error: expected 'albedo' components in [0, 1], got 1.2,0,0");
    check_error(CAM "material name=m type=mirror specular=1,1,1.5\n",
                "scene.txt:2:38: error: expected 'specular' components in [0, 1], got 1,1,1.5");
    check_error(CAM "material name=m type=mirror emission=-1,0,0\n",
                "scene.txt:2:38: error: expected 'emission' components >= 0, got -1,0,0");
    check_error(CAM "light type=point position=0,1,0 intensity=1,-2,3\n",
                "scene.txt:2:43: error: expected 'intensity' components >= 0, got 1,-2,3");
    check_error(CAM "sky type=constant radiance=-1,0,0\n",
                "scene.txt:2:28: error: expected 'radiance' components >= 0, got -1,0,0");
    check_error(CAM "material name=g type=dielectric ior=0\n",
                "scene.txt:2:37: error: expected 'ior' > 0, got 0");
}

/* Materials: a duplicate name, a reference before the definition or to no definition, names of
 * MTL materials (not referable), a name too long, an unknown type. */
Test(scene, error_materials)
{
    check_error(CAM MAT "material name=red type=mirror\n",
                "scene.txt:3:15: error: expected a new material name, got 'red' (defined on "
                "line 2)");
    check_error(CAM "sphere center=0,0,0 radius=1 material=red\n" MAT,
                "scene.txt:2:39: error: expected a material defined on an earlier line, got "
                "'red'");
    check_error(CAM MAT "plane point=0,0,0 normal=0,1,0 material=blue\n",
                "scene.txt:3:41: error: expected a material defined on an earlier line, got "
                "'blue'");
    check_error(CAM MAT "plane point=0,0,0 normal=0,1,0 material=tiny.obj:white\n",
                "scene.txt:3:41: error: expected a material name of letters, digits, '_', '-' "
                "and '.', got 'tiny.obj:white'");
    check_error(CAM "material name=m234567890123456789012345678901234567890123456789012345678901234"
                    " type=mirror\n",
                "scene.txt:2:15: error: expected a material name of at most 63 bytes, got 64");
    check_error(CAM "material name=m type=metal\n",
                "scene.txt:2:22: error: expected a material type (diffuse, mirror, dielectric, "
                "diffuse-uniform, conductor, plastic, unity), got 'metal'");
    check_error(CAM "light type=area position=0,0,0 intensity=1,1,1\n",
                "scene.txt:2:12: error: expected a light type (point), got 'area'");
}

/* The meshes' "default" material is not referable by name either. */
Test(scene, error_default_material_not_referable)
{
    check_file_error("tests/data/scene/default-ref.txt",
                     "tests/data/scene/default-ref.txt:3:39: error: expected a material defined "
                     "on an earlier line, got 'default'");
}

/* Statements that may appear once, and the required camera. */
Test(scene, error_statement_count)
{
    check_error(CAM CAM,
                "scene.txt:2:1: error: expected at most one 'camera' statement, got a second "
                "(the first is on line 1)");
    check_error(CAM "sky type=constant radiance=1,1,1\n\n\tsky type=constant radiance=1,1,1\n",
                "scene.txt:4:2: error: expected at most one 'sky' statement, got a second (the "
                "first is on line 2)");
    check_error("film width=4 height=4\n",
                "scene.txt: error: expected a 'camera' statement, got none");
    check_error("", "scene.txt: error: expected a 'camera' statement, got none");
}

/* A camera looking at its own eye, or with up parallel to the view direction. */
Test(scene, error_camera_geometry)
{
    check_error("camera eye=1,2,3 look-at=1,2,3 up=0,1,0 fov=40\n",
                "scene.txt:1:26: error: expected 'look-at' different from 'eye', got 1,2,3 for "
                "both");
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,0,-2 fov=40\n",
                "scene.txt:1:35: error: expected 'up' not parallel to the view direction, got "
                "0,0,-2");
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,0,0 fov=40\n",
                "scene.txt:1:35: error: expected a nonzero 'up', got 0,0,0");
}

/* Shapes and transforms: zero rotation axis, zero scale, non-uniform sphere scale, emissive or
 * degenerate plane, parallel quad edges. */
Test(scene, error_shapes_and_transforms)
{
    check_error(CAM MAT "quad corner=0,0,0 edge1=1,0,0 edge2=0,1,0 material=red rotate=0,0,0,90\n",
                "scene.txt:3:63: error: expected a nonzero axis for 'rotate', got 0,0,0,90");
    check_error(CAM MAT "quad corner=0,0,0 edge1=1,0,0 edge2=0,1,0 material=red scale=1,0,1\n",
                "scene.txt:3:62: error: expected nonzero 'scale' components, got 1,0,1");
    check_error(CAM MAT "sphere center=0,0,0 radius=1 material=red scale=1,2,1\n",
                "scene.txt:3:49: error: expected a uniform 'scale' for 'sphere', got 1,2,1");
    check_error(CAM "material name=lamp type=diffuse albedo=0,0,0 emission=1,1,1\n"
                    "plane point=0,0,0 normal=0,1,0 material=lamp\n",
                "scene.txt:3:41: error: expected a non-emissive material for 'plane' (an "
                "infinite emitter), got 'lamp'");
    check_error(CAM MAT "plane point=0,0,0 normal=0,0,0 material=red\n",
                "scene.txt:3:26: error: expected a nonzero 'normal', got 0,0,0");
    check_error(CAM MAT "quad corner=0,0,0 edge1=1,0,0 edge2=-2,0,0 material=red\n",
                "scene.txt:3:37: error: expected 'edge2' not parallel to 'edge1', got -2,0,0");
    check_error(CAM MAT "quad corner=0,0,0 edge1=1e30,0,0 edge2=0,1,0 material=red scale=1e30\n",
                "scene.txt:3:1: error: expected the quad's corners inside [-1e18, 1e18] after its "
                "transform (squared distances and areas must stay finite in single precision), "
                "got corner 0,0,0 and edges 1e+60,0,0 and 0,1e+30,0");
}

/* ---- errors: the file itself ------------------------------------------------------------ */

/* A file that cannot be opened names the reason (strerror). */
Test(scene, error_unreadable_file)
{
    check_file_error("tests/data/scene/no-such-scene.txt",
                     "tests/data/scene/no-such-scene.txt: error: expected a readable file, got "
                     "'No such file or directory'");
}

/* Binary bytes (NUL, other control bytes, a lone carriage return) and overlong lines. */
Test(scene, error_binary_and_long_lines)
{
    check_error("camera eye=0\0,0,5 look-at=0,0,0 up=0,1,0 fov=40\n",
                "scene.txt:1:13: error: expected text, got the byte 0x00");
    check_error(CAM "\x7f"
                    "ELF\n",
                "scene.txt:2:1: error: expected text, got the byte 0x7f");
    check_error(CAM "film width=4\rheight=4\n",
                "scene.txt:2:13: error: expected text, got the byte 0x0d");
    char text[6000];
    int n = snprintf(text, sizeof text, "%s#", CAM);
    memset(text + n, 'x', 4096); /* '#' + 4096 bytes = 4097 */
    text[n + 4096] = '\n';
    check_error_n(text, (size_t)n + 4097,
                  "scene.txt:2:4097: error: expected a line of at most 4096 bytes, got a longer "
                  "one");
}

/* ---- errors: meshes ---------------------------------------------------------------------- */

/* A mesh without faces is an error at its file value. */
Test(scene, error_mesh_without_faces)
{
    check_file_error("tests/data/scene/empty-mesh.txt",
                     "tests/data/scene/empty-mesh.txt:2:11: error: expected at least one face in "
                     "'empty.obj', got none");
}

/* Errors inside an OBJ pass through unchanged: the message is obj_load's, naming the OBJ file
 * and line.  A mesh that cannot be opened is an error of the scene line that names it (issue
 * 14, item 6), at the file= value, with the path it looked for. */
Test(scene, error_mesh_passes_obj_errors)
{
    struct obj_mesh mesh = {0};
    struct mcpt_error obj_err = {0};
    cr_assert(!obj_load("tests/data/scene/bad.obj", &mesh, &obj_err));
    char golden[MCPT_ERROR_LINE_BYTES];
    mcpt_error_format(&obj_err, golden, sizeof golden);
    cr_assert(strncmp(golden, "tests/data/scene/bad.obj:2:", 27) == 0, "%s", golden);
    check_file_error("tests/data/scene/bad-mesh.txt", golden);

    check_file_error("tests/data/scene/missing-mesh.txt",
                     "tests/data/scene/missing-mesh.txt:2:11: error: cannot open mesh "
                     "'no-such-file.obj' (tests/data/scene/no-such-file.obj): No such file or "
                     "directory");
}

/* ---- materials and light-transport settings of the light-transport issue ------------------ */

/* Each material type maps its parameters as docs/scene-format.md says: plastic's
 * metallic/reflectance parametrisation (F0 = (1 - m) 0.16 r^2 + m base, diffuse = (1 - m) base),
 * the Unity-style mapping (glass; specular-prob 0: diffuse; else plastic with F0 = P specular,
 * roughness 1 - smoothness), conductor defaults, and the checker texture. */
Test(scene, light_transport_materials)
{
    struct scene sc;
    load_ok(CAM "material name=a type=diffuse-uniform albedo=0.5,0.5,0.5\n"
                "material name=b type=conductor specular=0.9,0.6,0.3\n"
                "material name=c type=plastic albedo=1,0.5,0 metallic=0.25 reflectance=0.5 "
                "roughness=0.3 checker=0,0,1 checker-scale=2 checker-uv=true\n"
                "material name=d type=unity albedo=0.2,0.4,0.6 glass=true ior=1.33\n"
                "material name=e type=unity albedo=0.2,0.4,0.6 checker=true\n"
                "material name=f type=unity albedo=0.2,0.4,0.6 specular=1,0.5,0.5 "
                "specular-prob=0.5 smoothness=0.75\n"
                "render direct=hemisphere light-samples=16 split=indirect rr=0.75 rr-depth=3\n",
            &sc);
    cr_assert_eq(sc.n_materials, 6u);
    const struct material *m = sc.materials;
    cr_assert_eq(m[0].kind, MAT_DIFFUSE_UNIFORM);
    cr_assert_eq(m[1].kind, MAT_CONDUCTOR);
    assert_vec3(m[1].specular, 0.9f, 0.6f, 0.3f, "conductor F0");
    cr_assert_eq(m[1].roughness, 0.5f, "default roughness");
    cr_assert_eq(m[2].kind, MAT_PLASTIC);
    assert_vec3_near(m[2].albedo, 0.75f, 0.375f, 0.0f, "plastic diffuse = (1 - m) base");
    float f0 = 0.75f * 0.16f * 0.25f;
    assert_vec3_near(m[2].specular, f0 + 0.25f, f0 + 0.125f, f0, "plastic F0");
    cr_assert_eq(m[2].roughness, 0.3f);
    assert_vec3_near(m[2].checker_albedo, 0.0f, 0.0f, 0.75f, "checker colour, diffuse share");
    cr_assert(m[2].checker_scale == 2.0f && m[2].checker_uv);
    cr_assert_eq(m[3].kind, MAT_DIELECTRIC);
    cr_assert_eq(m[3].ior, 1.33f);
    assert_vec3(m[3].specular, 0.2f, 0.4f, 0.6f, "glass tint");
    cr_assert_eq(m[4].kind, MAT_DIFFUSE);
    assert_vec3_near(m[4].checker_albedo, 0.1f, 0.2f, 0.3f, "checker=true: half the albedo");
    cr_assert(m[4].checker_scale == 1.0f && !m[4].checker_uv);
    cr_assert_eq(m[5].kind, MAT_PLASTIC);
    assert_vec3(m[5].albedo, 0.2f, 0.4f, 0.6f, "unity diffuse");
    assert_vec3(m[5].specular, 0.5f, 0.25f, 0.25f, "unity F0 = P specular");
    cr_assert_eq(m[5].roughness, 0.25f);
    cr_assert_eq(sc.render.direct, RENDER_DIRECT_HEMISPHERE);
    cr_assert_eq(sc.render.light_samples, 16u);
    cr_assert_eq(sc.render.split, RENDER_SPLIT_INDIRECT);
    cr_assert_eq(sc.render.rr_prob, 0.75f);
    cr_assert_eq(sc.render.rr_depth, 3u);
    scene_free(&sc);
    load_ok(CAM "render rr=throughput rr-threshold=0.5\n", &sc);
    cr_assert_eq(sc.render.rr_prob, 0.0f);
    cr_assert_eq(sc.render.rr_threshold, 0.5f);
    cr_assert_eq(sc.render.direct, RENDER_DIRECT_MIS, "the default");
    scene_free(&sc);
}

/* The new parameters' error messages (golden strings, as in docs/scene-format.md). */
Test(scene, error_light_transport_parameters)
{
    check_error(CAM "material name=m type=diffuse albedo=1,1,1 checker-scale=2\n",
                "scene.txt:2:43: error: expected 'checker' for 'checker-scale' to apply to, got "
                "none");
    check_error(CAM "material name=m type=unity albedo=1,1,1 glass=true checker=true\n",
                "scene.txt:2:52: error: expected no 'checker' with 'glass=true' (glass has no "
                "albedo), got 'checker=true'");
    check_error(CAM "material name=m type=unity albedo=1,1,1 checker=yes\n",
                "scene.txt:2:49: error: expected true, false or 3 comma-separated numbers for "
                "'checker', got 'yes'");
    check_error(CAM "material name=m type=conductor roughness=2\n",
                "scene.txt:2:42: error: expected 'roughness' in [0, 1], got 2");
    check_error(CAM "material name=m type=conductor albedo=1,1,1\n",
                "scene.txt:2:32: error: expected a parameter of 'material type=conductor' (name, "
                "type, specular, emission, two-sided, roughness), got 'albedo'");
    check_error(CAM "render direct=nee\n",
                "scene.txt:2:15: error: expected mis, light, bsdf, cosine or hemisphere for "
                "'direct', got 'nee'");
    check_error(CAM "render rr=0\n",
                "scene.txt:2:11: error: expected 'throughput' or a probability in (0, 1] for "
                "'rr', got '0'");
    check_error(CAM "render split=both\n",
                "scene.txt:2:14: error: expected full, direct or indirect for 'split', got "
                "'both'");
    check_error(CAM "render light-samples=2000\n",
                "scene.txt:2:22: error: expected 'light-samples' in 1..1024, got 2000");
}

/* ---- issue 15: text encodings, mesh files, extremes, scale ------------------------------- */

/* Writes scene.txt (scene_text) and the files[] (name, text pairs, NULL-terminated) in a fresh
 * temporary folder and loads the scene; like load_text. */
static bool load_with_files(const char *scene_text, const char *const *files, struct scene *sc,
                            char *msg, size_t msg_bytes)
{
    char dir[] = "/tmp/mcpt-scene-test-XXXXXX";
    cr_assert_not_null(mkdtemp(dir));
    char path[600];
    for (int i = 0; files[i]; i += 2) {
        snprintf(path, sizeof path, "%s/%s", dir, files[i]);
        FILE *f = fopen(path, "wb");
        cr_assert_not_null(f);
        fputs(files[i + 1], f);
        cr_assert_eq(fclose(f), 0);
    }
    snprintf(path, sizeof path, "%s/scene.txt", dir);
    FILE *f = fopen(path, "wb");
    cr_assert_not_null(f);
    fputs(scene_text, f);
    cr_assert_eq(fclose(f), 0);
    struct mcpt_error err = {0};
    bool ok = scene_load(path, sc, &err);
    char full[MCPT_ERROR_LINE_BYTES], cmd[100];
    mcpt_error_format(&err, full, sizeof full);
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    cr_assert_eq(system(cmd), 0);
    size_t n_dir = strlen(dir), n = 0;
    for (const char *c = full; *c && n + 1 < msg_bytes;) { /* the folder cut out everywhere */
        if (strncmp(c, dir, n_dir) == 0 && c[n_dir] == '/')
            c += n_dir + 1;
        else
            msg[n++] = *c++;
    }
    msg[n] = '\0';
    return ok;
}

/* A UTF-8 byte order mark (what Windows editors write) is skipped, before a comment or right
 * before the first keyword; columns count from after it.  UTF-16 is named as such, and bytes
 * that are not UTF-8 are shown as \xNN in messages. */
Test(scene, byte_order_mark_and_encodings)
{
    struct scene sc;
    load_ok("\xef\xbb\xbf# a scene saved by Notepad\n" CAM, &sc);
    scene_free(&sc);
    load_ok("\xef\xbb\xbf" CAM, &sc);
    assert_vec3(sc.camera.eye, 0, 0, 5, "eye");
    scene_free(&sc);
    check_error("\xef\xbb\xbf"
                "cam eye=1\n",
                "scene.txt:1:1: error: expected a statement (camera, film, render, material, "
                "mesh, sphere, quad, plane, light, sky), got 'cam'");
    check_error_n("\xff\xfe"
                  "c\0a\0",
                  6,
                  "scene.txt:1:1: error: expected UTF-8 text, got UTF-16 (byte order mark 0xff "
                  "0xfe)");
    check_error("\xef\xbb"
                "camera eye=1\n",
                "scene.txt:1:1: error: expected a statement (camera, film, render, material, "
                "mesh, sphere, quad, plane, light, sky), got '\\xef\\xbbcamera'");
    check_error(CAM "material name=caf\xc3\xa9 type=mirror\n",
                "scene.txt:2:15: error: expected a material name of letters, digits, '_', '-' "
                "and '.', got 'caf\xc3\xa9'");
}

/* A mesh that cannot be opened is reported at the scene line and the file= value, with the
 * path looked for when it differs from what was written: missing, a folder, a FIFO (refused at
 * once, not waited on), a device. */
Test(scene, mesh_file_errors_point_at_the_scene, .timeout = TEST_TIMEOUT_S(10))
{
    char dir[] = "/tmp/mcpt-scene-test-XXXXXX";
    cr_assert_not_null(mkdtemp(dir));
    cr_assert_eq(chdir(dir), 0); /* a scene path without a folder, as the user typed it */
    cr_assert_eq(mkfifo("pipe.obj", 0600), 0);
    FILE *f = fopen("scene.txt", "w");
    fputs(CAM "\n  mesh file=does-not-exist.obj\n", f);
    fclose(f);
    check_file_error("scene.txt", "scene.txt:3:13: error: cannot open mesh 'does-not-exist.obj': "
                                  "No such file or directory");
    const char *cases[][2] = {
        {CAM "mesh file=.\n", "scene.txt:2:11: error: expected a regular file for mesh '.', got "
                              "a directory"},
        {CAM "mesh file=pipe.obj\n", "scene.txt:2:11: error: expected a regular file for mesh "
                                     "'pipe.obj', got a FIFO"},
        {CAM "mesh file=/dev/null\n", "scene.txt:2:11: error: expected a regular file for mesh "
                                      "'/dev/null', got a character device"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        f = fopen("scene.txt", "w");
        fputs(cases[i][0], f);
        fclose(f);
        check_file_error("scene.txt", cases[i][1]);
    }
    unlink("pipe.obj");
    unlink("scene.txt");
    cr_assert_eq(chdir("/"), 0);
    rmdir(dir);
}

/* The scene file itself: a folder is refused; a FIFO is read as a pipe, and one with no
 * writer reads as empty at once instead of blocking in open(). */
Test(scene, scene_file_kinds, .timeout = TEST_TIMEOUT_S(10))
{
    check_file_error("tests/data/scene", "tests/data/scene: error: expected a regular file, got "
                                         "a directory");
    char dir[] = "/tmp/mcpt-scene-test-XXXXXX", fifo[64];
    cr_assert_not_null(mkdtemp(dir));
    snprintf(fifo, sizeof fifo, "%s/scene.txt", dir);
    cr_assert_eq(mkfifo(fifo, 0600), 0);
    struct scene sc;
    struct mcpt_error err = {0};
    cr_assert_not(scene_load(fifo, &sc, &err));
    cr_assert_str_eq(err.msg, "expected a 'camera' statement, got none");
    unlink(fifo);
    rmdir(dir);
}

/* A path longer than 255 bytes (PATH_MAX is 4096) is named whole: err.file held 256 bytes and
 * cut the scene's and the OBJ's paths, so the message named a file that did not exist. */
Test(scene, error_names_a_long_path_whole, .timeout = TEST_TIMEOUT_S(10))
{
    char dir[] = "/tmp/mcpt-scene-test-XXXXXX", deep[700], scene[760], obj[760], want[800];
    cr_assert_not_null(mkdtemp(dir));
    int n = snprintf(deep, sizeof deep, "%s", dir);
    for (int level = 0; level < 3; level++) {
        n += snprintf(deep + n, sizeof deep - (size_t)n, "/%0200d", level);
        cr_assert_lt((size_t)n, sizeof deep, "the test's own buffer");
        cr_assert_eq(mkdir(deep, 0700), 0, "%s", deep);
    }
    cr_assert_lt((size_t)snprintf(scene, sizeof scene, "%s/scene.txt", deep), sizeof scene);
    cr_assert_lt((size_t)snprintf(obj, sizeof obj, "%s/bad.obj", deep), sizeof obj);
    FILE *f = fopen(scene, "w");
    cr_assert_not_null(f, "%s", scene);
    fputs(CAM "film width=8 width=8\n", f);
    cr_assert_eq(fclose(f), 0);
    struct scene sc;
    struct mcpt_error err = {0};
    cr_assert_not(scene_load(scene, &sc, &err));
    cr_assert_str_eq(err.file, scene);
    cr_assert(err.line == 2 && err.col == 14, "%d:%d", err.line, err.col);
    f = fopen(obj, "w");
    cr_assert_not_null(f, "%s", obj);
    fputs("v 0 0 0\nf 1 2 3\n", f);
    cr_assert_eq(fclose(f), 0);
    f = fopen(scene, "w");
    cr_assert_not_null(f, "%s", scene);
    fputs(CAM "mesh file=bad.obj\n", f);
    cr_assert_eq(fclose(f), 0);
    cr_assert_not(scene_load(scene, &sc, &err));
    cr_assert_str_eq(err.file, obj);
    char line[MCPT_ERROR_LINE_BYTES];
    mcpt_error_format(&err, line, sizeof line);
    snprintf(want, sizeof want, "%s:2:5: error: ", obj);
    cr_assert(strncmp(line, want, strlen(want)) == 0, "%s", line);
    unlink(obj);
    unlink(scene);
    for (int level = 0; level < 3; level++) {
        rmdir(deep);
        *strrchr(deep, '/') = '\0';
    }
    rmdir(dir);
}

/* Camera vectors far from 1 that computing the frame after an exact power-of-two scaling makes
 * well defined: look-at 1e-30 from the eye, up of length 1e-30 or 3e38, a denormal up. */
Test(scene, camera_tiny_and_huge_vectors_load)
{
    const char *ok_cams[] = {
        "camera eye=0,0,0 look-at=1e-30,0,0 up=0,1,0 fov=40\n",
        "camera eye=0,0,5 look-at=0,0,0 up=0,1e-30,0 fov=40\n",
        "camera eye=0,0,5 look-at=0,0,0 up=0,3e38,0 fov=40\n",
        "camera eye=0,0,5 look-at=0,0,0 up=1e-45,1e-44,0 fov=40\n",
        "camera eye=1e18,-1e18,1e18 look-at=-1e18,1e18,-1e18 up=0,1,0 fov=179.9999\n",
    };
    for (size_t i = 0; i < sizeof ok_cams / sizeof ok_cams[0]; i++) {
        struct scene sc;
        load_ok(ok_cams[i], &sc);
        scene_free(&sc);
    }
}

/* Points beyond 1e18 make squared distances and areas overflow single precision: refused at
 * the value (or at the statement when a transform took them there), saying the bound and
 * why.  The quad of area 4e38 and the OBJ vertex at 1e20 of issue 15 among them. */
Test(scene, error_points_beyond_1e18)
{
    check_error("camera eye=-3e38,0,0 look-at=3e38,0,0 up=0,1,0 fov=40\n",
                "scene.txt:1:12: error: expected 'eye' components in [-1e18, 1e18] (squared "
                "distances and areas must stay finite in single precision), got -3e38,0,0");
    check_error(CAM "material name=lamp type=diffuse albedo=0,0,0 emission=1,1,1\n"
                    "quad corner=0,0,0 edge1=2e19,0,0 edge2=0,2e19,0 material=lamp\n",
                "scene.txt:3:1: error: expected the quad's corners inside [-1e18, 1e18] (squared "
                "distances and areas must stay finite in single precision), got corner 0,0,0 "
                "and edges 2e+19,0,0 and 0,2e+19,0");
    check_error(CAM MAT "sphere center=0,0,0 radius=1e30 material=red\n",
                "scene.txt:3:1: error: expected the sphere inside [-1e18, 1e18] (squared "
                "distances and areas must stay finite in single precision), got center 0,0,0 and "
                "radius 1e+30");
    check_error(CAM MAT "sphere center=0,0,0 radius=1 material=red translate=0,2e18,0\n",
                "scene.txt:3:1: error: expected the sphere inside [-1e18, 1e18] after its "
                "transform (squared distances and areas must stay finite in single precision), "
                "got center 0,2e+18,0 and radius 1");
    check_error(CAM "light type=point position=0,1e19,0 intensity=1,1,1\n",
                "scene.txt:2:27: error: expected 'position' components in [-1e18, 1e18] "
                "(squared distances and areas must stay finite in single precision), got "
                "0,1e19,0");
    check_error(CAM MAT "plane point=0,-5e30,0 normal=0,1,0 material=red\n",
                "scene.txt:3:13: error: expected 'point' components in [-1e18, 1e18] (squared "
                "distances and areas must stay finite in single precision), got 0,-5e30,0");
    struct scene sc;
    char msg[700];
    const char *const big[] = {"big.obj", "v 0 0 0\nv 1e20 0 0\nv 0 1 0\nf 1 2 3\n", NULL};
    cr_assert_not(load_with_files(CAM "mesh file=big.obj\n", big, &sc, msg, sizeof msg));
    cr_assert_str_eq(msg, "scene.txt:2:1: error: expected vertices of 'big.obj' inside [-1e18, "
                          "1e18] (squared distances and areas must stay finite in single "
                          "precision), got 1e+20,0,0 (vertex 2)");
    /* the same mesh scaled into range loads: the bound is on the scene, not the file */
    cr_assert(load_with_files(CAM "mesh file=big.obj scale=1e-5\n", big, &sc, msg, sizeof msg),
              "%s", msg);
    cr_assert_eq(sc.positions[1].x, 1e15f);
    scene_free(&sc);
    /* the Cornell box scaled by 1e15 (issue 12's largest scale) is inside */
    load_ok("camera eye=0,1e15,3.9e15 look-at=0,1e15,0 up=0,1,0 fov=40\n" MAT
            "quad corner=-1e15,0,-1e15 edge1=2e15,0,0 edge2=0,0,2e15 material=red\n",
            &sc);
    scene_free(&sc);
}

/* The lens: an aperture or plane of focus beyond 1e18 is refused like a point; a plane of
 * focus so near that it rounds onto the lens point (below 2^-20 of the eye's largest
 * coordinate or the aperture) is refused; a tiny one at the origin works. */
Test(scene, error_lens_extremes)
{
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=40 aperture=1e30\n",
                "scene.txt:1:57: error: expected 'aperture' <= 1e18 (the lens lies in the scene: "
                "squared distances and areas must stay finite in single precision), got 1e30");
    check_error("camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=40 aperture=0.1 focus-dist=3e38\n",
                "scene.txt:1:72: error: expected 'focus-dist' <= 1e18 (the plane of focus lies in "
                "the scene: squared distances and areas must stay finite in single precision), "
                "got 3e38");
    check_error("camera eye=1e6,0,5 look-at=0,0,5 up=0,1,0 fov=40 aperture=0.1 focus-dist=0.5\n",
                "scene.txt:1:74: error: expected 'focus-dist' >= 0.953674 (2^-20 of the largest "
                "'eye' component or 'aperture': a plane of focus nearer the lens rounds onto it "
                "in single precision), got 0.5");
    struct scene sc;
    load_ok("camera eye=0,0,0 look-at=0,0,-1 up=0,1,0 fov=40 aperture=1e-30 "
            "focus-dist=1e-30\n",
            &sc);
    scene_free(&sc);
}

/* A number that underflows is the number it is: 1e-50 reads as 0 (strtof flags ERANGE, which
 * is not an error), accepted where 0 is legal; where it is not, the message says it rounds to
 * 0.  A product of two legal numbers that underflows is refused the same way. */
Test(scene, underflow_is_zero)
{
    struct scene sc;
    load_ok(CAM "material name=m type=diffuse albedo=1e-50,0.5,1e-40 emission=1e-46,0,0\n", &sc);
    cr_assert_eq(sc.materials[0].albedo.x, 0.0f);
    cr_assert_eq(sc.materials[0].albedo.z, 1e-40f, "a denormal stays as it is");
    cr_assert_eq(sc.materials[0].Le.x, 0.0f);
    scene_free(&sc);
    check_error(CAM MAT "sphere center=0,0,0 radius=1e-50 material=red\n",
                "scene.txt:3:28: error: expected 'radius' > 0, got 1e-50 (it rounds to 0 in "
                "single precision, whose smallest positive number is 1.4e-45)");
    check_error(CAM MAT "sphere center=0,0,0 radius=1e-30 material=red scale=1e-30\n",
                "scene.txt:3:53: error: expected 'radius' times 'scale' > 0, got 1e-60 (it rounds "
                "to 0 in single precision, whose smallest positive number is 1.4e-45)");
    check_error(CAM MAT "quad corner=0,0,0 edge1=1e-46,0,0 edge2=0,1,0 material=red\n",
                "scene.txt:3:25: error: expected a nonzero 'edge1', got 1e-46,0,0 (it rounds to 0 "
                "in single precision, whose smallest positive number is 1.4e-45)");
    check_error(CAM MAT "quad corner=0,0,0 edge1=1e-20,0,0 edge2=0,1e-20,0 material=red "
                        "scale=1e-30\n",
                "scene.txt:3:70: error: expected the quad's edges not parallel after 'scale', got "
                "0,0,0 and 0,0,0 (rounded to single precision)");
}

/* Warnings of a mesh (here an MTL 'spectral' colour) reach the scene for main to print. */
Test(scene, mesh_warnings_reach_the_scene)
{
    const char *const files[] = {"w.obj", "mtllib w.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
                                 "w.mtl", "newmtl a\nKd spectral a.rfl\n", NULL};
    struct scene sc;
    char msg[700];
    cr_assert(load_with_files(CAM "mesh file=w.obj\nmesh file=w.obj\n", files, &sc, msg,
                              sizeof msg),
              "%s", msg);
    cr_assert_eq(sc.n_warnings, 2, "one per mesh statement");
    const char *w = strstr(sc.warnings[0], "w.mtl:2:4: warning: 'Kd spectral' ignored");
    cr_assert_not_null(w, "%s", sc.warnings[0]);
    scene_free(&sc);
    cr_assert_eq(sc.n_warnings, 0);
}

/* A sphere under 16 float steps across at its centre's magnitude (radius < 2^-20 of the largest
 * coordinate) renders from outside but cannot keep a path inside it (shape.c, sphere_point):
 * a warning at its radius, none at the bound itself. */
Test(scene, tiny_sphere_far_out_warns)
{
    struct scene sc;
    load_ok(CAM MAT "sphere center=1e7,0,0 radius=1 material=red\n"
                    "sphere center=0,-1048576,0 radius=1 material=red\n",
            &sc);
    cr_assert_eq(sc.n_warnings, 1);
    const char *want = "/scene.txt:3:30: warning: sphere of radius 1 at center 1e+07,0,0 is "
                       "under 16 single-precision steps across (radius < 2^-20 of the centre's "
                       "largest coordinate, 9.53674): it renders from outside, but a path inside "
                       "it may escape";
    const char *w = strstr(sc.warnings[0], want);
    cr_assert(w && strlen(w) == strlen(want), "%s", sc.warnings[0]);
    scene_free(&sc);
}

/* 200k named materials and 200k spheres naming them: the name lookups were linear scans
 * (2e10 string compares, minutes; issue 15 measured 17 s for 100k); hashed, this loads in well
 * under a second.  The timeout is the hang cap, far above the linear time even under the
 * sanitizers and far below the quadratic one. */
Test(scene, many_materials_load_in_linear_time, .timeout = TEST_TIMEOUT_S(60))
{
    enum { N = 200000 };
    size_t cap = (size_t)N * 120 + 100, n = 0;
    char *text = malloc(cap);
    cr_assert_not_null(text);
    n += (size_t)snprintf(text, cap, CAM);
    for (int i = 0; i < N; i++)
        n += (size_t)snprintf(text + n, cap - n,
                              "material name=m%d type=diffuse albedo=0.5,0.5,0.5\n", i);
    for (int i = 0; i < N; i++)
        n += (size_t)snprintf(text + n, cap - n, "sphere center=%d,0,0 radius=0.5 material=m%d\n",
                              i, N - 1 - i);
    struct scene sc;
    char msg[640] = "";
    cr_assert(load_text(text, n, &sc, msg, sizeof msg), "%s", msg);
    cr_assert_eq(sc.n_materials, N);
    cr_assert_eq(sc.n_spheres, N);
    cr_assert_eq(sc.spheres[0].mat_idx, N - 1);
    cr_assert_eq(sc.spheres[N - 1].mat_idx, 0);
    scene_free(&sc);
    free(text);
    check_error(CAM MAT MAT, "scene.txt:3:15: error: expected a new material name, got 'red' "
                             "(defined on line 2)");
}

/* ---- T-junctions (scene.c, tj_pass) ------------------------------------------------------- */

/* A triangle whose long edge (0,0,0)-(2,0,0) carries the corner (1,0,0) of the two triangles
 * across it is fanned through that corner: two triangles wound as it was, the new corner's
 * normal and uv halfway along the edge's, the triangles across it untouched. */
Test(scene, t_junction_is_fanned)
{
    const char *const files[] = {"t.obj",
                                 "v 0 0 0\nv 2 0 0\nv 1 -1 0\nv 1 0 0\nv 0 1 0\nv 2 1 0\n"
                                 "vt 0 0\nvt 1 0\nvt 0.5 1\n"
                                 "vn 0 0.6 0.8\nvn 0 -0.6 0.8\nvn 0 0 1\n"
                                 "f 1/1/1 3/3/3 2/2/2\n"
                                 "f 1 4 5\nf 4 6 5\nf 4 2 6\n",
                                 NULL};
    struct scene sc;
    char msg[700];
    cr_assert(load_with_files(CAM MAT "mesh file=t.obj material=red\n", files, &sc, msg,
                              sizeof msg),
              "%s", msg);
    cr_assert_eq(sc.n_tris, 5);
    int fan[2] = {0, 4}; /* the fanned triangle keeps its slot, the other half goes last */
    float area = 0.0f;
    for (int k = 0; k < 2; k++) {
        const struct scene_tri *t = &sc.tris[fan[k]];
        vec3 a = sc.positions[t->v[0]], b = sc.positions[t->v[1]], c = sc.positions[t->v[2]];
        vec3 n = v3_cross(v3_sub(b, a), v3_sub(c, a));
        cr_assert_gt(n.z, 0.0f, "wound as the triangle it came from");
        area += 0.5f * v3_length(n);
        bool has_mid = false;
        for (int i = 0; i < 3; i++) {
            vec3 p = sc.positions[t->v[i]];
            if (p.x == 1.0f && p.y == 0.0f) {
                has_mid = true;
                vec3 ns = sc.normals[t->vn[i]];
                cr_assert_float_eq(ns.x, 0.0f, 1e-6f);
                cr_assert_float_eq(ns.y, 0.0f, 1e-6f);
                cr_assert_float_eq(ns.z, 1.0f, 1e-6f);
                vec2 uv = sc.uvs[t->vt[i]];
                cr_assert(uv.x == 0.5f && uv.y == 0.0f, "uv %g %g", uv.x, uv.y);
            }
        }
        cr_assert(has_mid, "triangle %d has the corner on the edge", fan[k]);
    }
    cr_assert_float_eq(area, 1.0f, 1e-6f);
    scene_free(&sc);
}

/* ---- meshes standing on planes and meshes (scene.c, contacts) ----------------------------- */

/* A wall standing on a plane: its two bottom corners, a rounding above the plane, are moved onto
 * it or the least way past it (never up, and here less than 4 2^-24 below), and its bottom edge
 * is listed as the plane's contact, m within the plane and across the edge.  The corners of a
 * triangle lying in the plane and the one corner on it of a triangle crossing it, as far off it
 * as the wall's, stay; a quad that the wall does not stand on has no contact. */
Test(scene, walls_standing_on_a_plane_are_seated_and_listed)
{
    /* the wall x in [0, 1], y = 0.3 (its bottom) .. 1.3, z = 0.5, its bottom 3 floats above
     * the plane y = 0.3f */
    const char *const files[] = {
        "w.obj",
        "v 0 0.3000001 0.5\nv 1 0.3000001 0.5\nv 0 1.3 0.5\n"
        "v 0 0.3000001 2\nv 1 0.3000001 2\nv 0 0.3000001 3\n"
        "v 0 0.3000001 4\nv 1 1.3 4\nv 0 -0.7 4.5\nv 5 5 5\nv 6 5 5\nv 5 6 5\n"
        "f 1 2 3\nf 4 5 6\nf 7 8 9\nf 10 11 12\n",
        NULL};
    struct scene sc;
    char msg[700];
    cr_assert(load_with_files(CAM MAT "mesh file=w.obj material=red\n"
                                      "plane point=7,0.3,-2 normal=0,1,0 material=red\n"
                                      "quad corner=-9,-9,-9 edge1=1,0,0 edge2=0,1,0 material=red\n",
                              files, &sc, msg, sizeof msg),
              "%s", msg);
    uint32_t n;
    const struct contact *c = scene_contacts(&sc, 0, &n);
    cr_assert_eq(n, 1, "the wall's bottom edge only");
    cr_assert_null(scene_contacts(&sc, 1, &n), "the quad has none");
    const float plane_y = 0.3f;
    for (int k = 0; k < 2; k++) {
        float y = sc.positions[k].y;
        cr_assert(y <= plane_y && y >= plane_y - 4 * 0x1p-24f, "corner %d: y %.9g", k, y);
    }
    cr_assert(c->a.y <= plane_y && c->b.y <= plane_y && fabs(c->m.y) < 1e-12 &&
                  fabs(fabs(c->m.z) - 1.0) < 1e-12 && c->g == 1.0,
              "a %g %g %g m %g %g %g g %g", c->a.x, c->a.y, c->a.z, c->m.x, c->m.y, c->m.z, c->g);
    const float above = 0.3000001f;
    cr_assert(sc.positions[3].y == above && sc.positions[4].y == above &&
                  sc.positions[5].y == above && sc.positions[6].y == above &&
                  sc.positions[9].y == 5.0f,
              "the others stay");
    scene_free(&sc);
}

/* A wall standing inside a triangle of another mesh (the floor y = 0, x, z in [0, 4]): its
 * bottom corners, 1e-7 above, are seated on the floor and its bottom edge is the floor
 * triangle's contact; a closed tetrahedron's base corners, as far above, stay (no open edge). */
Test(scene, walls_standing_on_a_mesh_are_seated_and_listed)
{
    const char *const files[] = {"f.obj", "v 0 0 0\nv 4 0 0\nv 0 0 4\nf 1 3 2\n", "w.obj",
                                 "v 0.5 1e-7 0.5\nv 1.5 1e-7 0.5\nv 0.5 1 0.5\nf 1 2 3\n", "b.obj",
                                 /* a closed tetrahedron with its base on the floor */
                                 "v 2 1e-7 0.2\nv 2.5 1e-7 0.2\nv 2 1e-7 0.7\nv 2 0.5 0.2\nf 1 2 "
                                 "3\nf 1 4 2\nf 2 4 3\nf 3 4 1\n",
                                 NULL};
    struct scene sc;
    char msg[700];
    cr_assert(load_with_files(CAM MAT "mesh file=f.obj material=red\n"
                                      "mesh file=w.obj material=red\n"
                                      "mesh file=b.obj material=red\n",
                              files, &sc, msg, sizeof msg),
              "%s", msg);
    uint32_t n;
    const struct contact *c = scene_contacts(&sc, 0, &n); /* the floor: triangle 0 */
    cr_assert_eq(n, 1);
    cr_assert(c->a.y <= 0.0 && c->b.y <= 0.0 && fabs(c->m.y) < 1e-12, "a %g b %g", c->a.y, c->b.y);
    for (int k = 3; k < 5; k++)
        cr_assert(sc.positions[k].y <= 0.0f && sc.positions[k].y >= -4 * 0x1p-24f,
                  "wall corner %d: y %g", k, sc.positions[k].y);
    for (uint32_t t = 1; t < sc.n_tris; t++)
        cr_assert_null(scene_contacts(&sc, t, &n), "triangle %u", t);
    cr_assert(sc.positions[6].y == 1e-7f && sc.positions[7].y == 1e-7f &&
                  sc.positions[8].y == 1e-7f,
              "the tetrahedron stays");
    scene_free(&sc);
}

/* ---- quads that meet meshes (scene.c, quads_to_triangles) ---------------------------------- */

/* A quad with an edge between two mesh vertices, and the quad sharing an edge with it, become
 * two triangles each, at their corners rounded to float, wound as e1 x e2, with the quad's uvs
 * and area; quads that meet a mesh at a corner only, by 1e-7 off, or inside a triangle stay. */
Test(scene, quads_meeting_a_mesh_become_triangles)
{
    const char *const files[] = {"t.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", NULL};
    struct scene sc;
    char msg[700];
    cr_assert(load_with_files(CAM MAT "mesh file=t.obj material=red\n"
                                      "quad corner=1,0,0 edge1=0,-1,0 edge2=-1,0,0 material=red\n"
                                      "quad corner=1,0,0 edge1=1,0,0 edge2=0,1,0 material=red\n"
                                      "quad corner=0,-1,0 edge1=1,0,0 edge2=0,0,1 material=red\n"
                                      "quad corner=1e-7,0,0 edge1=0,1,0 edge2=-1,0,0 "
                                      "material=red\n"
                                      "quad corner=0.1,0.1,0 edge1=0.1,0,0 edge2=0,0.1,0 "
                                      "material=red\n",
                              files, &sc, msg, sizeof msg),
              "%s", msg);
    cr_assert_eq(sc.n_quads, 3, "the quads that share no edge stay");
    cr_assert(sc.quads[0].corner.x == 1.0 && sc.quads[1].corner.x == 1e-7 &&
                  sc.quads[2].corner.x == 0.1,
              "in file order");
    cr_assert_eq(sc.n_tris, 5);
    const vec3 normal[2] = {{0, 0, -1}, {0, -1, 0}}; /* e1 x e2 of the two quads */
    for (int q = 0; q < 2; q++) {
        float area = 0.0f;
        for (int k = 0; k < 2; k++) {
            const struct scene_tri *t = &sc.tris[1 + 2 * q + k];
            vec3 a = sc.positions[t->v[0]], b = sc.positions[t->v[1]], c = sc.positions[t->v[2]];
            vec3 n = v3_cross(v3_sub(b, a), v3_sub(c, a));
            cr_assert_gt(v3_dot(n, normal[q]), 0.0f, "quad %d wound as e1 x e2", q);
            area += 0.5f * v3_length(n);
            for (int i = 0; i < 3; i++) { /* uv (alpha, beta): the point corner + a e1 + b e2 */
                vec2 uv = sc.uvs[t->vt[i]];
                vec3 p = sc.positions[t->v[i]];
                vec3 want = q == 0 ? (vec3){1.0f - uv.y, -uv.x, 0.0f} : (vec3){uv.x, -1.0f, uv.y};
                cr_assert(p.x == want.x && p.y == want.y && p.z == want.z,
                          "quad %d corner %g %g %g at uv %g %g", q, p.x, p.y, p.z, uv.x, uv.y);
            }
            cr_assert_eq(t->mat_idx, sc.tris[0].mat_idx);
        }
        cr_assert_float_eq(area, 1.0f, 1e-6f);
    }
    scene_free(&sc);
}

/* Chains of unshared collinear edges with long edges over them, each covering 100 of 2000
 * segments: the passes add at most as many triangles as the file had, and 2^16 more, and look
 * at a bounded number of list entries, so no input makes the load quadratic. */
Test(scene, t_junction_repair_is_bounded)
{
    enum { N = 2000, M = 100 };
    size_t cap = 64 * (2 * N + 4), n = 0;
    char *obj = malloc(cap);
    cr_assert_not_null(obj);
    for (int i = 0; i <= N; i++)
        n += (size_t)snprintf(obj + n, cap - n, "v %d 0 0\n", i);
    n += (size_t)snprintf(obj + n, cap - n, "v 0 1 0\n");
    for (int i = 0; i < N; i++)
        n += (size_t)snprintf(obj + n, cap - n, "f %d %d %d\n", i + 1, i + 2, N + 2);
    for (int k = 0; k + M <= N; k++)
        n += (size_t)snprintf(obj + n, cap - n, "v %d 0 -1\nf %d %d -1\n", k, k + 1, k + M + 1);
    cr_assert_lt(n, cap);
    const char *const files[] = {"chains.obj", obj, NULL};
    struct scene sc;
    char msg[700];
    cr_assert(load_with_files(CAM MAT "mesh file=chains.obj material=red\n", files, &sc, msg,
                              sizeof msg),
              "%s", msg);
    uint32_t n_file = N + (N - M + 1);
    cr_assert_gt(sc.n_tris, n_file, "some long edges fanned");
    cr_assert_leq(sc.n_tris, 2 * n_file + 65536);
    scene_free(&sc);
    free(obj);
}
