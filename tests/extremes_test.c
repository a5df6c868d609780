/* tests/extremes_test.c - numerical extremes of the whole renderer (scene.c, obj.c, bvh.c,
 * shape.c, trace.c, material.c, film.c) on the scenes in tests/extremes/.  Each statistical check
 * compares region means of two independent renders within 4 combined standard errors, the
 * standard errors coming from the film's own variance estimates (film_var_of_mean); exact checks
 * (a black mesh under a white sky renders exactly 0) need no tolerance.  Properties: scale
 * invariance of robust ray offsets (PBRT 4e, ch. 6, "Robust Spawned Ray Origins"); watertight
 * triangle intersection (Woop et al. 2013); an interface of IOR 1 is invisible (Fresnel R = 0,
 * no bending, eta^2 = 1); a GGX conductor of roughness 0 is a mirror; white furnace (albedo 1
 * in radiance 1 gives 1, microfacets of roughness 0 and 1 at most 1); linearity in Le;
 * double-precision accumulation (film.h); NaN and infinity dropped and counted, never added. */
#include <criterion/criterion.h>

#include <limits.h>
#include <stdlib.h>
#include <unistd.h>

#include "bvh.h"
#include "film.h"
#include "image.h"
#include "obj.h"
#include "scene.h"
#include "test_util.h"
#include "trace.h"

#define DIR "tests/extremes/"
#define N_SE 4.0 /* tolerance in combined standard errors */

/* Loads and renders path at its own film size, spp and depth with seed, on 2 threads. */
static void render_file(const char *path, uint64_t seed, struct film *film,
                        struct trace_result *res)
{
    struct scene scene;
    struct mcpt_error err;
    cr_assert(scene_load(path, &scene, &err), "%s:%d:%d: %s", err.file, err.line, err.col, err.msg);
    struct trace_scene *ts = trace_prepare(&scene, 2, &err);
    cr_assert_not_null(ts, "%s: %s", path, err.msg);
    cr_assert(film_init(film, scene.width, scene.height, &err));
    struct trace_options opt = {.spp = scene.render.spp,
                                .max_depth = scene.render.max_depth,
                                .seed = seed,
                                .sampler = scene.render.sampler,
                                .n_threads = 2};
    cr_assert(trace_render(ts, &opt, film, res, &err), "%s", err.msg);
    trace_free(ts);
    scene_free(&scene);
}

/* Mean over the pixels [x0, x1) x [y0, y1) of the pixel means of channel c, and the variance
 * of that mean: sum of the pixels' variances of the mean / n^2 (pixels are independent). */
struct estimate {
    double mean;
    double var;
};

static struct estimate region(const struct film *f, int x0, int y0, int x1, int y1, int c)
{
    double sum = 0.0, var = 0.0;
    int n = 0;
    for (int y = y0; y < y1; y++)
        for (int x = x0; x < x1; x++) {
            const struct film_pixel *p = &f->pixels[(size_t)y * (size_t)f->width + (size_t)x];
            sum += film_mean(p, c);
            var += film_var_of_mean(p, c);
            n++;
        }
    return (struct estimate){sum / n, var / ((double)n * n)};
}

/* The means of a and b agree within N_SE combined standard errors (plus a relative 1e-6 for
 * regions without noise) on each of the 2 x 2 quadrants and each channel: 12 comparisons. */
static void assert_same_image(const struct film *a, const struct film *b, const char *what)
{
    cr_assert(a->width == b->width && a->height == b->height);
    int w = a->width, h = a->height;
    for (int q = 0; q < 4; q++) {
        int x0 = q % 2 ? w / 2 : 0, x1 = q % 2 ? w : w / 2;
        int y0 = q / 2 ? h / 2 : 0, y1 = q / 2 ? h : h / 2;
        for (int c = 0; c < 3; c++) {
            struct estimate ea = region(a, x0, y0, x1, y1, c);
            struct estimate eb = region(b, x0, y0, x1, y1, c);
            double diff = fabs(ea.mean - eb.mean);
            double tol = N_SE * sqrt(ea.var + eb.var) + 1e-6 * fmax(fabs(ea.mean), fabs(eb.mean));
            cr_assert(diff <= tol,
                      "%s: quadrant %d channel %d: %.6g vs %.6g, |diff| %.3g > %.3g "
                      "(%.1f SE)",
                      what, q, c, ea.mean, eb.mean, diff, tol, diff / sqrt(ea.var + eb.var));
        }
    }
}

static uint64_t total_dropped(const struct film *f)
{
    uint64_t n = 0;
    for (size_t i = 0; i < (size_t)f->width * (size_t)f->height; i++)
        n += f->pixels[i].n_dropped;
    return n;
}

/* Renders a (seed 1) and b (seed 2), checks both finite with nothing dropped, compares. */
static void assert_same_scenes(const char *path_a, const char *path_b)
{
    struct film fa, fb;
    struct trace_result ra, rb;
    render_file(path_a, 1, &fa, &ra);
    render_file(path_b, 2, &fb, &rb);
    cr_assert_eq(ra.n_nonfinite, 0, "%s: %llu samples not finite", path_a,
                 (unsigned long long)ra.n_nonfinite);
    cr_assert_eq(rb.n_nonfinite, 0, "%s: %llu samples not finite", path_b,
                 (unsigned long long)rb.n_nonfinite);
    char what[300];
    snprintf(what, sizeof what, "%s vs %s", path_a, path_b);
    assert_same_image(&fa, &fb, what);
    film_free(&fa);
    film_free(&fb);
}

/* Every pixel of path's render is exactly 0: the scene's only light is a sky its camera
 * cannot see through a closed or gap-free black surface. */
static void assert_black(const char *path)
{
    struct film f;
    struct trace_result r;
    render_file(path, 1, &f, &r);
    cr_assert_eq(r.n_nonfinite, 0);
    for (size_t i = 0; i < (size_t)f.width * (size_t)f.height; i++)
        for (int c = 0; c < 3; c++)
            cr_assert(f.pixels[i].sum[c] == 0.0, "%s: pixel %zu,%zu channel %d sees %g", path,
                      i % (size_t)f.width, i / (size_t)f.width, c, film_mean(&f.pixels[i], c));
    film_free(&f);
}

/* ---- scale ---- */

/* The Cornell box at scale 1e-4 and 1e4 (camera scaled too) renders the image of scale 1:
 * ray offsets scale with the geometry, with no epsilon in scene units. */
Test(extremes, cornell_scale_1e_minus_4_and_1e4, .timeout = TEST_TIMEOUT_S(120))
{
    assert_same_scenes(DIR "cornell-1.txt", DIR "cornell-1e-4.txt");
    assert_same_scenes(DIR "cornell-1.txt", DIR "cornell-1e4.txt");
}

/* smallpt's box with walls of radius-1e5 spheres renders as the same box with planes: no
 * self-intersection (acne) from the large hit-point error, no light leaking past the walls. */
Test(extremes, smallpt_radius_1e5_walls, .timeout = TEST_TIMEOUT_S(120))
{
    assert_same_scenes(DIR "smallpt-planes.txt", DIR "smallpt-spheres.txt");
}

/* Issue 12: the Cornell box at scales 1e-15, 1e-6, 1e6 and 1e15 (camera scaled too) renders the
 * image of scale 1, one statistic per scale: the image's mean luminance against scale 1's
 * (independent seeds), within N_SE combined standard errors.  Ray offsets are the hit points'
 * rounding errors, areas and pdfs are formed in double, and what float cannot decide is decided
 * in double (docs/theory.md, "Self-intersection"). */
static struct estimate image_luminance(const struct film *f)
{
    double sum = 0.0, var = 0.0;
    size_t n = (size_t)f->width * (size_t)f->height;
    for (size_t i = 0; i < n; i++) {
        const struct film_pixel *p = &f->pixels[i];
        double m = film_sum_lum(p) / p->n;
        double s2 = (p->sum_lum_sq - film_sum_lum(p) * m) / (p->n - 1);
        sum += m;
        var += fmax(0.0, s2) / p->n;
    }
    return (struct estimate){sum / (double)n, var / ((double)n * (double)n)};
}

/* DIR stem-base.txt against stem-S.txt for each S of others, each with its own seed. */
static void assert_same_means(const char *stem, const char *base, const char *const *others,
                              int n_others)
{
    char path[128];
    snprintf(path, sizeof path, DIR "%s-%s.txt", stem, base);
    struct film f1;
    struct trace_result r1;
    render_file(path, 1, &f1, &r1);
    struct estimate e1 = image_luminance(&f1);
    for (int k = 0; k < n_others; k++) {
        snprintf(path, sizeof path, DIR "%s-%s.txt", stem, others[k]);
        struct film f;
        struct trace_result r;
        render_file(path, (uint64_t)(2 + k), &f, &r);
        cr_assert_eq(r.n_nonfinite, 0, "%s", path);
        struct estimate e = image_luminance(&f);
        double se = sqrt(e.var + e1.var);
        cr_log_info("%s: mean luminance %.6f, %s: %.6f, %.2f SE", path, e.mean, base, e1.mean,
                    (e.mean - e1.mean) / se);
        cr_assert(fabs(e.mean - e1.mean) <= N_SE * se, "%s: %.6f vs %.6f at %s (%.1f SE)", path,
                  e.mean, e1.mean, base, (e.mean - e1.mean) / se);
        film_free(&f);
    }
    film_free(&f1);
}

/* DIR stem-1.txt against stem-S.txt for S = 1e-15, 1e-6, 1e6 and 1e15. */
static void assert_scale_sweep(const char *stem)
{
    static const char *const scales[] = {"1e-15", "1e-6", "1e6", "1e15"};
    assert_same_means(stem, "1", scales, 4);
}

Test(extremes, cornell_scale_1e_minus_15_to_1e15, .timeout = TEST_TIMEOUT_S(180))
{
    assert_scale_sweep("cornell");
}

/* The neighbours of the Cornell sweep: every analytic primitive (plane, spheres, quads, a quad
 * light), a point light, the thin lens and a checker texture, scaled alike.  Their hit points'
 * error bounds, the lens and the texture's period scale with the scene; the point light's
 * intensity goes with the square of the scale. */
Test(extremes, analytic_scene_scale_1e_minus_15_to_1e15, .timeout = TEST_TIMEOUT_S(120))
{
    assert_scale_sweep("analytic");
}

/* The Cornell box moved by 1e3 and 1e5 on every axis, the camera with it, renders the image at
 * the origin.  Its vertices lie on the grid of 1/64, exact in float at each offset, so the
 * geometry is the same and only the precision of the numbers differs: at 1e5 a float holds the
 * box (2 units) to 256 steps and its lamp (0.47 units) to 60.  The points' margins from their
 * edges project the error on the edge's normal in the plane (shape.c, EDGE_MARGIN_E); summed over
 * the components, as before, they pulled every point of a wall near an edge towards its
 * triangle's centre and the image gained 6% at 1e5 (10% at 1e6).  With light samples measured
 * from the spawned origin, a float step or two off the surface, it gained 1.3% (2.6 SE here);
 * measured from the vertex's point, as now, 0.7% (1.4 SE), the rest being the pull of points
 * near edges (docs/theory.md, "Self-intersection"; docs/scene-format.md, "Far from the
 * origin"). */
Test(extremes, cornell_moved_far_from_the_origin, .timeout = TEST_TIMEOUT_S(120))
{
    static const char *const offsets[] = {"1e3", "1e5"};
    assert_same_means("cornell-moved", "0", offsets, 2);
}

/* A floor (a plane) lit by a small quad lamp 0.125 above it and beside the view, direct light
 * only, moved by 1e5 and 3e5 on every axis with the camera: the image at the origin.  The
 * coordinates are exact at each offset, and a plane has no edges to pull its points from, so
 * nothing but where light samples are measured from can move the image.  Measured from the
 * spawned origin, a float step or two above the floor (0.016 at 1e5), the lamp was seen from
 * that height: at 1e5 the image mean was 0.011240 against 0.013955 (-19%, -327 SE); from the
 * vertex's point the images agree within 1.5 SE (docs/theory.md, "Self-intersection"). */
Test(extremes, direct_light_far_from_the_origin_is_measured_from_the_surface,
     .timeout = TEST_TIMEOUT_S(120))
{
    static const char *const offsets[] = {"1e5", "3e5"};
    assert_same_means("lamp-beside", "0", offsets, 2);
}

/* Issue 12: a floor of two triangles of size 1e6, 1e7, 1e10 or 1e15 renders as the same floor
 * given as a plane: their hit points are as precise as the plane's (the ray's, where a triangle
 * is larger than the hit distance) and their error bounds as small.  At 1e15 (the camera 1e-15
 * of the floor's size above it) Woop's T is undecided even in double, and t comes from the
 * plane (bvh_tri_hit_double); before, the floor vanished (image mean 0.97 against 0.59). */
Test(extremes, huge_triangle_floor_is_the_plane, .timeout = TEST_TIMEOUT_S(120))
{
    assert_same_scenes(DIR "floor-plane.txt", DIR "floor-1e6.txt");
    assert_same_scenes(DIR "floor-plane.txt", DIR "floor-1e7.txt");
    assert_same_scenes(DIR "floor-plane.txt", DIR "floor-1e10.txt");
    assert_same_scenes(DIR "floor-plane.txt", DIR "floor-1e15.txt");
}

/* The same floor as one quad of size 1e7 (against the plane) and 1e15 (against the quad of
 * 1e7, both at 1024 spp).  At 1e15 a point rebuilt from the corner and the planar coordinates
 * is off by about 1 unit and its bound is that large: the ball's contact shadow was too bright
 * (the image mean 0.5928 against 0.5896, 34 SE) until the point came from the ray. */
Test(extremes, huge_quad_floor_is_the_plane, .timeout = TEST_TIMEOUT_S(120))
{
    assert_same_scenes(DIR "floor-plane.txt", DIR "quad-floor-1e7.txt");
    assert_same_scenes(DIR "quad-floor-1e7.txt", DIR "quad-floor-1e15.txt");
}

/* ---- triangles: slivers, tiny, duplicated, coplanar, closed ---- */

/* A floor of 400 slivers renders as the same floor of 2 triangles. */
Test(extremes, sliver_floor_renders_as_two_triangles, .timeout = TEST_TIMEOUT_S(120))
{
    assert_same_scenes(DIR "floor-once.txt", DIR "floor-slivers.txt");
}

/* A black sliver floor under a white sky seen from above: no ray leaks between slivers. */
Test(extremes, sliver_floor_does_not_leak) { assert_black(DIR "slivers-black.txt"); }

/* Triangles of area 1e-12 down to exactly 0, some emissive, change nothing and make no NaN. */
Test(extremes, tiny_and_zero_area_triangles, .timeout = TEST_TIMEOUT_S(120))
{
    assert_same_scenes(DIR "floor-once.txt", DIR "floor-tiny.txt");
}

/* Every face duplicated, and a coplanar copy triangulated the other way, render as if each
 * surface were there once: no stripes, no darkening from hitting the twin after a bounce. */
Test(extremes, duplicated_and_coplanar_faces, .timeout = TEST_TIMEOUT_S(120))
{
    assert_same_scenes(DIR "floor-once.txt", DIR "floor-duplicated.txt");
    assert_same_scenes(DIR "floor-once.txt", DIR "floor-coplanar.txt");
}

/* A camera inside a closed black mesh under a white sky sees exactly 0 everywhere. */
Test(extremes, camera_inside_closed_mesh_sees_no_sky) { assert_black(DIR "inside-mesh.txt"); }

/* Issue 12: the camera inside a closed cube of 12 triangles (diffuse, albedo 0.5) under a white
 * sky, wound outward and inward: every pixel is exactly 0.  A ray leaving a wall near a concave
 * edge meets the next wall at t ~ 1e-5, which the float test cannot place; it is decided in
 * double, never thrown away. */
Test(extremes, closed_cube_sees_no_sky, .timeout = TEST_TIMEOUT_S(120))
{
    assert_black(DIR "cube-outward.txt");
    assert_black(DIR "cube-inward.txt");
}

/* The same cube with each face cut into n strips of two triangles (slivers of aspect n), wound
 * outward or inward, written into dir; the scene's path goes to scene_path.  The strips of
 * neighbouring faces meet in T-junctions whose vertices lie exactly on the other face's edge
 * (the cube is axis-aligned: such a vertex differs from the edge's ends only in the coordinate
 * along the edge, however -1 + 2i/n rounds), so the mesh is closed.  A rotation would round
 * them off it (docs/theory.md, "What no scheme can promise"). */
static void write_strip_cube_quads(const char *dir, int n, bool inward, const double *move,
                                   unsigned quad_faces, char *scene_path, size_t bytes);

static void write_strip_cube(const char *dir, int n, bool inward, const double *move,
                             char *scene_path, size_t bytes)
{
    write_strip_cube_quads(dir, n, inward, move, 0, scene_path, bytes);
}

/* As write_strip_cube, with face 2 axis + (sign > 0) a quad statement (moved as the mesh, facing
 * as its strips do) where that bit of quad_faces is set. */
static void write_strip_cube_quads(const char *dir, int n, bool inward, const double *move,
                                   unsigned quad_faces, char *scene_path, size_t bytes)
{
    char obj_path[300], quads[6][160];
    int n_quads = 0;
    snprintf(obj_path, sizeof obj_path, "%s/cube-%d-%s.obj", dir, n, inward ? "in" : "out");
    FILE *f = fopen(obj_path, "w");
    cr_assert_not_null(f);
    int n_v = 0;
    for (int axis = 0; axis < 3; axis++)
        for (int sign = -1; sign <= 1; sign += 2) {
            int u = (axis + 1) % 3, w = (axis + 2) % 3;
            bool flip = (sign > 0) == inward;
            if (quad_faces >> (2 * axis + (sign > 0)) & 1) {
                int c[3] = {-1, -1, -1}, e[2][3] = {{0}};
                c[axis] = sign;
                e[flip][u] = e[!flip][w] = 2; /* e1 x e2 = +axis unflipped, as (a, b, c) */
                snprintf(quads[n_quads++], sizeof quads[0],
                         "quad corner=%d,%d,%d edge1=%d,%d,%d edge2=%d,%d,%d material=m", c[0],
                         c[1], c[2], e[0][0], e[0][1], e[0][2], e[1][0], e[1][1], e[1][2]);
                continue;
            }
            for (int i = 0; i <= n; i++)
                for (int j = 0; j < 2; j++) {
                    float p[3];
                    p[axis] = (float)sign;
                    p[u] = -1.0f + 2.0f * (float)i / (float)n;
                    p[w] = (float)(2 * j - 1);
                    fprintf(f, "v %.9g %.9g %.9g\n", p[0], p[1], p[2]);
                }
            /* (u, w) x-ordered: u x w = axis, so (a, b, c) faces +axis */
            for (int i = 0; i < n; i++) {
                int a = n_v + 2 * i + 1, b = a + 2, c = a + 3, d = a + 1;
                if (flip)
                    fprintf(f, "f %d %d %d\nf %d %d %d\n", a, c, b, a, d, c);
                else
                    fprintf(f, "f %d %d %d\nf %d %d %d\n", a, b, c, a, c, d);
            }
            n_v += 2 * (n + 1);
        }
    fclose(f);
    snprintf(scene_path, bytes, "%s/cube-%d-%s.txt", dir, n, inward ? "in" : "out");
    f = fopen(scene_path, "w");
    cr_assert_not_null(f);
    if (!move) {
        fprintf(f,
                "camera eye=0.1,0.05,0.02 look-at=0.5,0.3,-1 up=0,1,0 fov=100\n"
                "film width=48 height=48\nrender spp=64 sampler=independent\n"
                "material name=m type=diffuse albedo=0.5,0.5,0.5\n"
                "mesh file=%s material=m\nsky type=constant radiance=1,1,1\n",
                obj_path);
        for (int q = 0; q < n_quads; q++)
            fprintf(f, "%s\n", quads[q]);
    } else { /* turned about (1, 2, 3) by 37 degrees, scaled by move[0], moved by move[1..3] */
        const double a = 37.0 * 3.14159265358979323846 / 180.0, c = cos(a), sn = sin(a);
        const double ax[3] = {1.0 / sqrt(14.0), 2.0 / sqrt(14.0), 3.0 / sqrt(14.0)};
        const double local[3][3] = {{0.1, 0.05, 0.02}, {0.5, 0.3, -1.0}, {0.0, 1.0, 0.0}};
        double w[3][3]; /* eye, look-at, up */
        for (int i = 0; i < 3; i++) {
            const double *p = local[i];
            double d = ax[0] * p[0] + ax[1] * p[1] + ax[2] * p[2];
            double x[3] = {ax[1] * p[2] - ax[2] * p[1], ax[2] * p[0] - ax[0] * p[2],
                           ax[0] * p[1] - ax[1] * p[0]};
            for (int j = 0; j < 3; j++) /* Rodrigues' rotation, as scene.c's rotate= */
                w[i][j] = (p[j] * c + x[j] * sn + ax[j] * d * (1.0 - c)) * (i < 2 ? move[0] : 1.0) +
                          (i < 2 ? move[1 + j] : 0.0);
        }
        fprintf(f,
                "camera eye=%.17g,%.17g,%.17g look-at=%.17g,%.17g,%.17g up=%.17g,%.17g,%.17g "
                "fov=100\nfilm width=32 height=32\nrender spp=64 sampler=independent\n"
                "material name=m type=diffuse albedo=0.9,0.9,0.9\n"
                "mesh file=%s material=m rotate=1,2,3,37 scale=%.17g translate=%.17g,%.17g,%.17g\n"
                "sky type=constant radiance=1,1,1\n",
                w[0][0], w[0][1], w[0][2], w[1][0], w[1][1], w[1][2], w[2][0], w[2][1], w[2][2],
                obj_path, move[0], move[1], move[2], move[3]);
        for (int q = 0; q < n_quads; q++)
            fprintf(f, "%s rotate=1,2,3,37 scale=%.17g translate=%.17g,%.17g,%.17g\n", quads[q],
                    move[0], move[1], move[2], move[3]);
    }
    fclose(f);
}

/* Issue 12: the cube of 100 and 1000 strips per face (triangles of aspect 100 and 1000), wound
 * outward and inward, camera inside: every pixel is exactly 0. */
Test(extremes, strip_cubes_see_no_sky, .timeout = TEST_TIMEOUT_S(240))
{
    char dir[64], scene_path[400];
    test_make_dir(dir, sizeof dir, "strips");
    const int strips[] = {100, 1000};
    for (int k = 0; k < 2; k++)
        for (int inward = 0; inward < 2; inward++) {
            write_strip_cube(dir, strips[k], inward, NULL, scene_path, sizeof scene_path);
            assert_black(scene_path);
        }
    test_remove_dir(dir);
}

/* The cube of 30 strips turned, scaled and moved: the rotation rounds the T-junctions' vertices
 * off the next face's edge, leaving cracks (10 of 11 such cubes let sky in, `python3
 * scripts/probe_leaks.py cubes --strips 30 --cases 12 --seed 21`), which the load closes by
 * fanning each long edge's triangle through the corners on it (scene.c, tj_pass).  Every pixel
 * is exactly 0. */
Test(extremes, turned_strip_cubes_see_no_sky, .timeout = TEST_TIMEOUT_S(120))
{
    static const double moves[][4] = {
        /* s, t */
        {1.0, 0.0, 0.0, 0.0},      {4.93e5, 1.3e9, -2.1e8, 0.0},    {1.92e-6, 0.0, 1.1e-2, -7.3e-3},
        {7.65e3, 0.0, 0.0, 4.4e7}, {1.68e-11, 2.9e-8, 0.0, 1.2e-8},
    };
    char dir[64], scene_path[400];
    test_make_dir(dir, sizeof dir, "turned-strips");
    for (size_t k = 0; k < sizeof moves / sizeof moves[0]; k++) {
        write_strip_cube(dir, 30, k % 2 == 1, moves[k], scene_path, sizeof scene_path);
        assert_black(scene_path);
    }
    test_remove_dir(dir);
}

/* The turned strip cubes with two or three faces quads: each quad shares its edges with the
 * strips of the faces around it, which end on them in T-junctions, so the load makes it two
 * triangles of the mesh (scene.c, quads_to_triangles) and fans them through the strips' corners
 * (tj_pass).  8 of these 10 let sky in before (`python3 scripts/probe_leaks.py cubes
 * --quad-faces 2 --strips 30 --cases 20 --seed 42`: 13 of 20).  Every pixel is exactly 0. */
Test(extremes, turned_strip_cubes_with_quad_faces_see_no_sky, .timeout = TEST_TIMEOUT_S(120))
{
    static const double moves[][4] = {
        /* s, t */
        {1.0, 0.0, 0.0, 0.0},      {4.93e5, 1.3e9, -2.1e8, 0.0},    {1.92e-6, 0.0, 1.1e-2, -7.3e-3},
        {7.65e3, 0.0, 0.0, 4.4e7}, {1.68e-11, 2.9e-8, 0.0, 1.2e-8},
    };
    static const unsigned masks[] = {005, 042, 030, 007, 050};
    char dir[64], scene_path[400];
    test_make_dir(dir, sizeof dir, "quad-strips");
    for (size_t k = 0; k < 2 * sizeof moves / sizeof moves[0]; k++) {
        write_strip_cube_quads(dir, 30, k % 2 == 1, moves[k / 2], masks[(k + k / 2) % 5],
                               scene_path, sizeof scene_path);
        assert_black(scene_path);
    }
    test_remove_dir(dir);
}

/* The 12-triangle cube, wound outward and inward, turned (rotate=1,2,3,37), scaled by s and moved
 * by t, the camera inside (its position and target moved with it): every pixel is exactly 0.
 * The offsets reach 10^5 times the cube's size, where a float holds the cube's corners to a few
 * parts in 10^3 of its edge: the spawned origins' bounds are relative to the coordinates, not to
 * the cube, so no unit or position lets sky in. */
Test(extremes, moved_closed_cube_sees_no_sky, .timeout = TEST_TIMEOUT_S(120))
{
    static const double moves[][4] = {
        /* s, t */
        {1e-6, 0.3, 0.2, 0.1}, {1e-3, 1.0, 2.0, 3.0},      {1.0, 1000.0, 2000.0, -3000.0},
        {1.0, 1e5, 0.0, 0.0},  {1e3, 1e6, 2e6, -1e6},       {1e6, 0.0, 0.0, 0.0},
    };
    char dir[64], scene_path[300];
    test_make_dir(dir, sizeof dir, "moved_cube");
    for (int inward = 0; inward < 2; inward++) {
        char obj[PATH_MAX];
        cr_assert_not_null(realpath(inward ? DIR "cube-inward.obj" : DIR "cube-outward.obj", obj));
        for (size_t k = 0; k < sizeof moves / sizeof moves[0]; k++) {
            const double *m = moves[k];
            snprintf(scene_path, sizeof scene_path, "%s/cube-%d-%zu.txt", dir, inward, k);
            FILE *f = fopen(scene_path, "w");
            cr_assert_not_null(f);
            fprintf(f,
                    "camera eye=%.9g,%.9g,%.9g look-at=%.9g,%.9g,%.9g up=0,1,0 fov=100\n"
                    "film width=32 height=32\nrender spp=64 sampler=independent\n"
                    "material name=m type=diffuse albedo=0.5,0.5,0.5\n"
                    "mesh file=%s material=m rotate=1,2,3,37 scale=%.9g translate=%.9g,%.9g,%.9g\n"
                    "sky type=constant radiance=1,1,1\n",
                    m[1] + 0.1 * m[0], m[2] + 0.05 * m[0], m[3] + 0.02 * m[0], m[1] + 0.5 * m[0],
                    m[2] + 0.3 * m[0], m[3] - m[0], obj, m[0], m[1], m[2], m[3]);
            fclose(f);
            assert_black(scene_path);
        }
    }
    test_remove_dir(dir);
}

/* A closed wedge (a triangular prism of 8 triangles, its apex edge a groove of deg degrees seen
 * from inside), turned about (1, 2, 3) by 37 degrees, scaled by m[0] and moved by (m[1], m[2],
 * m[3]), written in double to 9 digits with the camera inside, wound inward or outward: every
 * pixel is exactly 0.  A point near a sharp groove must be pulled further from the edge than
 * the margin of a right angle, since the push of its spawned origin along the normal heads into
 * the neighbour (scene.c, grooves; shape.c, edge_margin_groove): before the groove factors,
 * wedges of 30 degrees and less let sky in (`python3 scripts/probe_leaks.py wedges --cases 60
 * --seed 1`: 16 of 60 before, 0 after).  layout: how the OBJ shares the corners. */
enum wedge_layout {
    WEDGE_SHARED,     /* one mesh, six vertices shared by index */
    WEDGE_TWO_MESHES, /* the groove's two sides in two meshes, each with its six vertices */
    WEDGE_SOUP,       /* one mesh, each triangle its own three vertices */
};

static void write_wedge(const char *dir, int k, double deg, const double m[4], bool inward,
                        enum wedge_layout layout, char *scene_path, size_t n)
{
    const double a = 37.0 * 3.14159265358979323846 / 180.0, c = cos(a), s = sin(a);
    const double ax[3] = {1.0 / sqrt(14.0), 2.0 / sqrt(14.0), 3.0 / sqrt(14.0)};
    const double h = 2.0 * tan(deg * 3.14159265358979323846 / 360.0);
    const double local[8][3] = {{0, 0, -1}, {2, h, -1}, {2, -h, -1},   {0, 0, 1},
                                {2, h, 1},  {2, -h, 1}, {1.5, 0, 0.3}, {0, 0, 0.1}};
    double w[8][3]; /* the six corners, then the eye and the point it looks at */
    for (int i = 0; i < 8; i++) {
        const double *p = local[i];
        double d = ax[0] * p[0] + ax[1] * p[1] + ax[2] * p[2];
        double x[3] = {ax[1] * p[2] - ax[2] * p[1], ax[2] * p[0] - ax[0] * p[2],
                       ax[0] * p[1] - ax[1] * p[0]};
        for (int j = 0; j < 3; j++) /* Rodrigues' rotation */
            w[i][j] = m[0] * (p[j] * c + x[j] * s + ax[j] * d * (1.0 - c)) + m[1 + j];
    }
    static const int faces[8][3] = {{1, 2, 3}, {4, 6, 5}, {1, 4, 5}, {1, 5, 2},
                                    {1, 3, 6}, {1, 6, 4}, {2, 5, 6}, {2, 6, 3}};
    /* the faces 0-3 (both ends and one side of the groove) and 4-7 (the other side) */
    int n_obj = layout == WEDGE_TWO_MESHES ? 2 : 1;
    char obj[2][300];
    for (int o = 0; o < n_obj; o++) {
        snprintf(obj[o], sizeof obj[o], "%s/wedge-%d-%d.obj", dir, k, o);
        FILE *f = fopen(obj[o], "w");
        cr_assert_not_null(f);
        int first = n_obj == 2 ? 4 * o : 0, end = n_obj == 2 ? first + 4 : 8;
        if (layout != WEDGE_SOUP)
            for (int i = 0; i < 6; i++)
                fprintf(f, "v %.9g %.9g %.9g\n", w[i][0], w[i][1], w[i][2]);
        for (int i = first; i < end; i++) {
            int v[3] = {faces[i][0], faces[i][inward ? 2 : 1], faces[i][inward ? 1 : 2]};
            if (layout == WEDGE_SOUP) { /* three vertices of its own, at the same coordinates */
                for (int c = 0; c < 3; c++)
                    fprintf(f, "v %.9g %.9g %.9g\n", w[v[c] - 1][0], w[v[c] - 1][1],
                            w[v[c] - 1][2]);
                fprintf(f, "f -3 -2 -1\n");
            } else {
                fprintf(f, "f %d %d %d\n", v[0], v[1], v[2]);
            }
        }
        fclose(f);
    }
    snprintf(scene_path, n, "%s/wedge-%d.txt", dir, k);
    FILE *f = fopen(scene_path, "w");
    cr_assert_not_null(f);
    fprintf(f,
            "camera eye=%.9g,%.9g,%.9g look-at=%.9g,%.9g,%.9g up=%.9g,%.9g,%.9g fov=70\n"
            "film width=24 height=24\nrender spp=32 sampler=independent\n"
            "material name=m type=diffuse albedo=0.9,0.9,0.9\n",
            w[6][0], w[6][1], w[6][2], w[7][0], w[7][1], w[7][2], w[4][0] - w[5][0],
            w[4][1] - w[5][1], w[4][2] - w[5][2]);
    for (int o = 0; o < n_obj; o++)
        fprintf(f, "mesh file=%s material=m\n", obj[o]);
    fprintf(f, "sky type=constant radiance=1,1,1\n");
    fclose(f);
}

/* Every wedge of three angles and four moves, written in each layout of layouts[0 .. n): the
 * winding alternates from one render to the next. */
static void wedges_see_no_sky(const char *name, const enum wedge_layout *layouts, int n)
{
    static const double degrees[] = {30.0, 10.0, 2.0};
    static const double moves[][4] = {
        /* s, t */
        {1.0, 0.0, 0.0, 0.0},
        {6.55, 695.0, 0.0, 0.0},
        {182.0, 3.31e4, -1.79e4, 3.25e3},
        {4.5e-4, 0.0, 0.676, 0.0},
    };
    char dir[64], scene_path[300];
    test_make_dir(dir, sizeof dir, name);
    int k = 0;
    for (size_t i = 0; i < sizeof degrees / sizeof degrees[0]; i++)
        for (size_t j = 0; j < sizeof moves / sizeof moves[0]; j++)
            for (int l = 0; l < n; l++, k++) {
                write_wedge(dir, k, degrees[i], moves[j], (i + j + (size_t)l) % 2 == 0, layouts[l],
                            scene_path, sizeof scene_path);
                assert_black(scene_path);
            }
    test_remove_dir(dir);
}

Test(extremes, closed_wedges_see_no_sky, .timeout = TEST_TIMEOUT_S(120))
{
    static const enum wedge_layout layouts[] = {WEDGE_SHARED, WEDGE_SHARED};
    wedges_see_no_sky("wedges", layouts, 2);
}

/* The same wedges with the groove's two sides in two meshes, or as a triangle soup (each
 * triangle its own vertices, as STL files and some exporters write them): no vertex index says
 * that the faces meet, their coordinates do (scene.c, grooves).  Every pixel is exactly 0. */
Test(extremes, wedges_of_parts_and_soups_see_no_sky, .timeout = TEST_TIMEOUT_S(120))
{
    static const enum wedge_layout layouts[] = {WEDGE_TWO_MESHES, WEDGE_SOUP};
    wedges_see_no_sky("wedge-parts", layouts, 2);
}

/* A box of six quads around (0, 0, 0) with half-size 1, turned about (1, 2, 3) by 37 degrees,
 * scaled by m[0] and moved by (m[1], m[2], m[3]), with the camera inside, written to path: with
 * as_params the quads are the axis-aligned faces and the statements' own rotate, scale and
 * translate move them; otherwise each corner and edge is written out, computed in double and
 * printed to 17 digits, as a script generating a scene would. */
static void write_quad_box(const char *path, const double m[4], bool as_params)
{
    const double deg = 37.0 * 3.14159265358979323846 / 180.0, c = cos(deg), s = sin(deg);
    const double k[3] = {1.0 / sqrt(14.0), 2.0 / sqrt(14.0), 3.0 / sqrt(14.0)};
    double R[3][3]; /* Rodrigues, as scene.c builds rotate= */
    const double K[3][3] = {{0, -k[2], k[1]}, {k[2], 0, -k[0]}, {-k[1], k[0], 0}};
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            R[i][j] = (i == j ? c : 0.0) + s * K[i][j] + (1.0 - c) * k[i] * k[j];
    FILE *f = fopen(path, "w");
    cr_assert_not_null(f);
    double eye[3] = {0.1, 0.05, 0.02}, at[3] = {0.5, 0.3, -1.0}, eye_w[3], at_w[3];
    for (int i = 0; i < 3; i++) {
        eye_w[i] = m[1 + i] + m[0] * (R[i][0] * eye[0] + R[i][1] * eye[1] + R[i][2] * eye[2]);
        at_w[i] = m[1 + i] + m[0] * (R[i][0] * at[0] + R[i][1] * at[1] + R[i][2] * at[2]);
    }
    fprintf(f,
            "camera eye=%.17g,%.17g,%.17g look-at=%.17g,%.17g,%.17g up=%.17g,%.17g,%.17g "
            "fov=100\nfilm width=32 height=32\nrender spp=64 sampler=independent\n"
            "material name=m type=diffuse albedo=0.5,0.5,0.5\n",
            eye_w[0], eye_w[1], eye_w[2], at_w[0], at_w[1], at_w[2], R[0][1], R[1][1], R[2][1]);
    for (int axis = 0; axis < 3; axis++)
        for (int sign = -1; sign <= 1; sign += 2) {
            int u = (axis + 1) % 3, w = (axis + 2) % 3;
            double q[3][3] = {{0}}; /* corner, edge1, edge2 in the box's frame */
            q[0][axis] = sign;
            q[0][u] = q[0][w] = -1.0;
            q[1][u] = 2.0;
            q[2][w] = 2.0;
            if (as_params) {
                fprintf(f,
                        "quad corner=%g,%g,%g edge1=%g,%g,%g edge2=%g,%g,%g material=m "
                        "rotate=1,2,3,37 scale=%.17g translate=%.17g,%.17g,%.17g\n",
                        q[0][0], q[0][1], q[0][2], q[1][0], q[1][1], q[1][2], q[2][0], q[2][1],
                        q[2][2], m[0], m[1], m[2], m[3]);
                continue;
            }
            double qw[3][3];
            for (int v = 0; v < 3; v++)
                for (int i = 0; i < 3; i++)
                    qw[v][i] = (v == 0 ? m[1 + i] : 0.0) +
                               m[0] * (R[i][0] * q[v][0] + R[i][1] * q[v][1] + R[i][2] * q[v][2]);
            fprintf(f,
                    "quad corner=%.17g,%.17g,%.17g edge1=%.17g,%.17g,%.17g "
                    "edge2=%.17g,%.17g,%.17g material=m\n",
                    qw[0][0], qw[0][1], qw[0][2], qw[1][0], qw[1][1], qw[1][2], qw[2][0], qw[2][1],
                    qw[2][2]);
        }
    fprintf(f, "sky type=constant radiance=1,1,1\n");
    fclose(f);
}

/* A closed box of six quads, turned, scaled and moved as moved_closed_cube_sees_no_sky moves
 * the mesh (offsets up to 10^5 times its size, 1e-12 at 1e-9): every pixel is exactly 0.  Quads
 * keep the corners and edges the file wrote in double, so neighbouring faces meet to double
 * precision (in float they had gaps of half an ulp of the corner, which let sky in from an
 * offset of 100 sizes on), and a point is pulled inside its quad by a margin of its error
 * (shape.c, edge_margin_groove), beyond what the spawned origin can move (twice its error let a box of
 * size 1e-12 at 1e-9 leak). */
Test(extremes, moved_quad_box_sees_no_sky, .timeout = TEST_TIMEOUT_S(120))
{
    static const double moves[][4] = {
        /* s, t */
        {1e-6, 0.3, 0.2, 0.1}, {1.0, 100.0, -30.0, 200.0}, {1.0, 1000.0, 2000.0, -3000.0},
        {1.0, 1e5, -3e4, 2e5}, {1e3, 1e6, 2e6, -1e6},      {1e-12, 1e-9, 0.0, 0.0},
        {1e6, 0.0, 0.0, 0.0},
    };
    char dir[64], scene_path[300];
    test_make_dir(dir, sizeof dir, "quad_box");
    for (int as_params = 0; as_params < 2; as_params++)
        for (size_t k = 0; k < sizeof moves / sizeof moves[0]; k++) {
            snprintf(scene_path, sizeof scene_path, "%s/box-%d-%zu.txt", dir, as_params, k);
            write_quad_box(scene_path, moves[k], as_params);
            assert_black(scene_path);
        }
    test_remove_dir(dir);
}

/* A parallelepiped of six quads whose faces along one edge meet at deg degrees inside (edges a,
 * b at deg degrees in their plane, c normal to it, length 2), turned about (1, 2, 3) by 37
 * degrees, scaled by m[0] and moved by (m[1], m[2], m[3]), every corner and edge written to 17
 * digits, the camera inside near the sharp edge: every pixel is exactly 0.  Quads close no
 * index-shared edges, so the load tests each pair for an edge of one lying in the other (scene.c,
 * quad_grooves); without it 22 of 70 such boxes let sky in (`python3 scripts/probe_leaks.py
 * sheared --cases 70 --seed 1`).  Face k (of the six in the order written) is a quad where bit k
 * of mesh_faces is 0 and otherwise two triangles of one mesh, written to path.obj to 17 digits;
 * n_far more quads, a tenth of the box's size, lie in a grid 3 to 23 box lengths beyond it. */
static void write_box(const char *path, double deg, const double m[4], unsigned mesh_faces,
                      unsigned n_far)
{
    const double r = 3.14159265358979323846 / 180.0, c = cos(37.0 * r), s = sin(37.0 * r);
    const double ax[3] = {1.0 / sqrt(14.0), 2.0 / sqrt(14.0), 3.0 / sqrt(14.0)};
    const double e[3][3] = {{2, 0, 0}, {2 * cos(deg * r), 2 * sin(deg * r), 0}, {0, 0, 2}};
    double w[3][3]; /* a, b, c turned and scaled */
    for (int i = 0; i < 3; i++) {
        const double *p = e[i];
        double d = ax[0] * p[0] + ax[1] * p[1] + ax[2] * p[2];
        double x[3] = {ax[1] * p[2] - ax[2] * p[1], ax[2] * p[0] - ax[0] * p[2],
                       ax[0] * p[1] - ax[1] * p[0]};
        for (int j = 0; j < 3; j++)
            w[i][j] = m[0] * (p[j] * c + x[j] * s + ax[j] * d * (1.0 - c));
    }
    double o[3] = {m[1], m[2], m[3]}, far[3], eye[3], at[3];
    for (int j = 0; j < 3; j++) {
        far[j] = o[j] + w[0][j] + w[1][j] + w[2][j];
        eye[j] = o[j] + 0.33 * w[0][j] + 0.27 * w[1][j] + 0.5 * w[2][j];
        at[j] = o[j] + 0.01 * w[0][j] + 0.01 * w[1][j] + 0.4 * w[2][j];
    }
    FILE *f = fopen(path, "w");
    cr_assert_not_null(f);
    fprintf(f,
            "camera eye=%.17g,%.17g,%.17g look-at=%.17g,%.17g,%.17g up=%.17g,%.17g,%.17g fov=70\n"
            "film width=24 height=24\nrender spp=64 sampler=independent\n"
            "material name=m type=diffuse albedo=0.9,0.9,0.9\n",
            eye[0], eye[1], eye[2], at[0], at[1], at[2], w[2][0], w[2][1], w[2][2]);
    static const int pairs[3][2] = {{0, 1}, {1, 2}, {2, 0}};
    char obj_path[320];
    snprintf(obj_path, sizeof obj_path, "%s.obj", path);
    FILE *obj = mesh_faces ? fopen(obj_path, "w") : NULL;
    cr_assert(!mesh_faces || obj);
    int n_obj = 0;
    for (int corner = 0; corner < 2; corner++)
        for (int k = 0; k < 3; k++) {
            const double *q = corner ? far : o, sign = corner ? -1.0 : 1.0;
            const double *u = w[pairs[k][0]], *v = w[pairs[k][1]];
            if (mesh_faces >> (3 * corner + k) & 1) {
                for (int c = 0; c < 4; c++) { /* corner, + u, + u + v, + v */
                    double a = c == 1 || c == 2, b = c >= 2;
                    fprintf(obj, "v %.17g %.17g %.17g\n", q[0] + sign * (a * u[0] + b * v[0]),
                            q[1] + sign * (a * u[1] + b * v[1]),
                            q[2] + sign * (a * u[2] + b * v[2]));
                }
                fprintf(obj, "f %d %d %d\nf %d %d %d\n", n_obj + 1, n_obj + 2, n_obj + 3, n_obj + 1,
                        n_obj + 3, n_obj + 4);
                n_obj += 4;
                continue;
            }
            fprintf(f,
                    "quad corner=%.17g,%.17g,%.17g edge1=%.17g,%.17g,%.17g "
                    "edge2=%.17g,%.17g,%.17g material=m\n",
                    q[0], q[1], q[2], sign * u[0], sign * u[1], sign * u[2], sign * v[0],
                    sign * v[1], sign * v[2]);
        }
    if (obj) {
        fclose(obj);
        const char *base = strrchr(obj_path, '/');
        fprintf(f, "mesh file=%s material=m\n", base ? base + 1 : obj_path);
    }
    for (unsigned k = 0; k < n_far; k++) {
        double a = 3.0 + 0.5 * (k % 40), c = 0.5 * (k / 40);
        fprintf(f,
                "quad corner=%.17g,%.17g,%.17g edge1=%.17g,%.17g,%.17g "
                "edge2=%.17g,%.17g,%.17g material=m\n",
                o[0] + a * w[0][0] + c * w[2][0], o[1] + a * w[0][1] + c * w[2][1],
                o[2] + a * w[0][2] + c * w[2][2], 0.1 * w[0][0], 0.1 * w[0][1], 0.1 * w[0][2],
                0.1 * w[2][0], 0.1 * w[2][1], 0.1 * w[2][2]);
    }
    fprintf(f, "sky type=constant radiance=1,1,1\n");
    fclose(f);
}

/* Writes write_box's box for every angle in degrees[n_deg] and every move in moves[n_moves]
 * (the mesh faces of masks[(i + j) % 4] where masks is given, n_far quads beyond it) into a
 * folder named name, and asserts that each renders black. */
static void assert_boxes_black(const char *name, const double *degrees, size_t n_deg,
                               const double (*moves)[4], size_t n_moves, const unsigned *masks,
                               unsigned n_far)
{
    char dir[64], scene_path[300];
    test_make_dir(dir, sizeof dir, name);
    for (size_t i = 0; i < n_deg; i++)
        for (size_t j = 0; j < n_moves; j++) {
            snprintf(scene_path, sizeof scene_path, "%s/box-%zu-%zu.txt", dir, i, j);
            write_box(scene_path, degrees[i], moves[j], masks ? masks[(i + j) % 4] : 0, n_far);
            assert_black(scene_path);
        }
    test_remove_dir(dir);
}

/* An open-bottomed box of 10 mesh triangles standing on a plane, a quad or two triangles of
 * another mesh, turned, scaled and moved, the camera inside: every pixel is exactly 0.  The box
 * shares no edge with the floor, so its bottom corners rounded up to half a float step above it
 * (a crack) and no margin kept the floor's points near a wall in front of it; these six let sky
 * in (`python3 scripts/probe_leaks.py standing [--mesh-floor] --cases 40 --seed 1 --save DIR`:
 * 7 and 6 of 40) until the load seated the corners on the floor and listed the lines where the
 * walls stand (scene.c, contacts; shape.c, shape_pull_from_contacts). */
Test(extremes, boxes_standing_on_a_floor_see_no_sky, .timeout = TEST_TIMEOUT_S(120))
{
    const char *paths[] = {DIR "standing-quad-tiny.txt",  DIR "standing-quad-far.txt",
                           DIR "standing-plane-tiny.txt", DIR "standing-plane-unit.txt",
                           DIR "standing-mesh-tiny.txt",  DIR "standing-mesh-far.txt"};
    for (int k = 0; k < 6; k++)
        assert_black(paths[k]);
}

Test(extremes, sheared_quad_boxes_see_no_sky, .timeout = TEST_TIMEOUT_S(120))
{
    static const double degrees[] = {20.0, 5.0};
    static const double moves[][4] = {
        /* s, t */
        {1.0, 0.0, 0.0, 0.0},
        {2.26e-6, -1.35e-3, 0.0, 0.0},
        {550.0, 3.0e4, -2.0e4, 0.0},
        {0.0266, 0.0, 0.0, 0.0},
    };
    assert_boxes_black("sheared_boxes", degrees, sizeof degrees / sizeof degrees[0], moves,
                       sizeof moves / sizeof moves[0], NULL, 0);
}

/* Boxes as in sheared_quad_boxes_see_no_sky among 1200 more quads: every pixel is exactly 0.
 * The load looked for the quads' grooves among at most 1024 quads, testing every pair, and gave
 * a scene of more none: 5 of these 9 let sky in, and 6 of 20 rows of 200 sheared boxes (`python3
 * scripts/probe_leaks.py sheared --boxes 200 --cases 20 --seed 1 --degrees 2,5,10,20`).  Now it
 * finds the pairs that meet by sweep and prune (scene.c, quad_grooves). */
Test(extremes, sheared_quad_boxes_among_many_quads_see_no_sky, .timeout = TEST_TIMEOUT_S(120))
{
    static const double degrees[] = {45.0, 20.0, 10.0};
    static const double moves[][4] = {
        /* s, t */
        {2.26e-6, -1.35e-3, 0.0, 0.0},
        {550.0, 3.0e4, -2.0e4, 0.0},
        {0.464, 3.1, -0.7, 0.0},
    };
    assert_boxes_black("many_quads", degrees, sizeof degrees / sizeof degrees[0], moves,
                       sizeof moves / sizeof moves[0], NULL, 1200);
}

/* Boxes as in sheared_quad_boxes_see_no_sky, at 90, 20 and 5 degrees, with some faces two
 * triangles of a mesh and the rest quads: every pixel is exactly 0.  A quad's corner and edges
 * are doubles and a mesh's vertices floats, so their shared edges were up to half a float ulp
 * apart until the load made the quads that meet a mesh triangles of it (scene.c,
 * quads_to_triangles); 3 of these 12 boxes let sky in before, and 11 of 30 random ones at right
 * angles (`python3 scripts/probe_leaks.py sheared --mixed --degrees 90 --cases 30`). */
Test(extremes, boxes_of_quads_and_mesh_faces_see_no_sky, .timeout = TEST_TIMEOUT_S(120))
{
    static const double degrees[] = {90.0, 20.0, 5.0};
    static const unsigned masks[] = {001, 007, 052, 036};
    static const double moves[][4] = {
        /* s, t */
        {1.0, 0.0, 0.0, 0.0},
        {0.464, 3.1, -0.7, 0.0},
        {2.26e-6, -1.35e-3, 0.0, 0.0},
        {550.0, 3.0e4, -2.0e4, 0.0},
    };
    assert_boxes_black("mixed_boxes", degrees, sizeof degrees / sizeof degrees[0], moves,
                       sizeof moves / sizeof moves[0], masks, 0);
}

/* Issue 12: parallelograms whose edges meet at 10, 3, 1, 0.3 and 0.1 degrees in a general
 * orientation, and the issue's own 1 degree quad, albedo 0.8 under a constant sky of 2: the
 * estimator has zero variance, light sample and BSDF sample each add 0.8 with MIS weight 1/2,
 * so every pixel is 1.6 up to float rounding (1e-5); a spawned ray hitting the quad again
 * takes 0.8 from a sample.  The quad's plane is decided in double (shape.c). */
static void assert_quad_exact(const char *path)
{
    struct film f;
    struct trace_result r;
    render_file(path, 1, &f, &r);
    cr_assert_eq(r.n_nonfinite, 0, "%s", path);
    for (size_t i = 0; i < (size_t)f.width * (size_t)f.height; i++)
        for (int c = 0; c < 3; c++) {
            double m = film_mean(&f.pixels[i], c);
            cr_assert(fabs(m - 1.6) <= 1e-5, "%s: pixel %zu channel %d: %.9f", path, i, c, m);
        }
    film_free(&f);
}

Test(extremes, sheared_quads_render_exactly, .timeout = TEST_TIMEOUT_S(120))
{
    const char *paths[] = {DIR "quad-shear-10deg.txt",  DIR "quad-shear-3deg.txt",
                           DIR "quad-shear-1deg.txt",   DIR "quad-shear-0.3deg.txt",
                           DIR "quad-shear-0.1deg.txt", DIR "quad-shear-issue12.txt"};
    for (int k = 0; k < 6; k++)
        assert_quad_exact(paths[k]);
}

/* The 0.1 degree parallelogram of quad-shear-0.1deg.txt scaled by s (10^-15 ... 10^15) and moved
 * by t (up to 30 times its size), its camera with it: still exactly 1.6, since every bound on
 * the quad's point and normal is relative to the numbers involved. */
Test(extremes, sheared_quad_at_any_scale_and_offset, .timeout = TEST_TIMEOUT_S(120))
{
    static const double moves[][4] = {
        /* s, t */
        {1e-15, 0.0, 0.0, 0.0}, {1e-6, 0.0, 0.0, 0.0},         {1e6, 0.0, 0.0, 0.0},
        {1e15, 0.0, 0.0, 0.0},  {1.0, 10.0, -20.0, 30.0},      {1e-3, 0.01, 0.02, -0.03},
        {1e6, 1e7, -1e7, 3e7},
    };
    static const double eye[3] = {0.410325411, 4.49570221, -0.148848386};
    static const double look_at[3] = {0.41, 4.49, -0.16};
    char dir[64], scene_path[300];
    test_make_dir(dir, sizeof dir, "moved_quad");
    for (size_t k = 0; k < sizeof moves / sizeof moves[0]; k++) {
        const double *m = moves[k];
        snprintf(scene_path, sizeof scene_path, "%s/quad-%zu.txt", dir, k);
        FILE *f = fopen(scene_path, "w");
        cr_assert_not_null(f);
        fprintf(f,
                "camera eye=%.9g,%.9g,%.9g look-at=%.9g,%.9g,%.9g"
                " up=0.922632196,0.331815474,-0.196591766 fov=0.5\n"
                "film width=16 height=16\nrender spp=16 sampler=independent\n"
                "material name=f type=diffuse albedo=0.8,0.8,0.8\n"
                "quad corner=0.0947684046,5.01757042,-0.747195106"
                " edge1=0.481626522,-0.807049848,0.898168379"
                " edge2=0.148836669,-0.248091001,0.276221833 material=f"
                " scale=%.9g translate=%.9g,%.9g,%.9g\n"
                "sky type=constant radiance=2,2,2\n",
                m[0] * eye[0] + m[1], m[0] * eye[1] + m[2], m[0] * eye[2] + m[3],
                m[0] * look_at[0] + m[1], m[0] * look_at[1] + m[2], m[0] * look_at[2] + m[3], m[0],
                m[1], m[2], m[3]);
        fclose(f);
        assert_quad_exact(scene_path);
    }
    test_remove_dir(dir);
}

/* ---- smooth shading normals ---- */

/* A UV sphere of radius 1 about the origin, n_stacks x n_slices (poles fanned), written as an
 * OBJ without normals to dir/name; a scene around it goes to scene_path, its statements
 * (camera, material, film...) from head, its mesh with normals=smooth, under a constant sky 1. */
static void write_smooth_sphere(const char *dir, const char *name, int n_stacks, int n_slices,
                                const char *head, char *scene_path, size_t bytes)
{
    char obj_path[300];
    snprintf(obj_path, sizeof obj_path, "%s/%s.obj", dir, name);
    FILE *f = fopen(obj_path, "w");
    cr_assert_not_null(f);
    fprintf(f, "v 0 1 0\nv 0 -1 0\n");
    for (int i = 1; i < n_stacks; i++)
        for (int j = 0; j < n_slices; j++) {
            double theta = M_PI * i / n_stacks, phi = 2.0 * M_PI * j / n_slices;
            fprintf(f, "v %.9g %.9g %.9g\n", sin(theta) * cos(phi), cos(theta),
                    -sin(theta) * sin(phi));
        }
    /* vertex (i, j), i = 1 .. n_stacks - 1, is 3 + (i - 1) n_slices + j; outward winding */
    for (int i = 1; i < n_stacks; i++)
        for (int j = 0; j < n_slices; j++) {
            int jn = (j + 1) % n_slices;
            int a = 3 + (i - 1) * n_slices + j, b = 3 + (i - 1) * n_slices + jn;
            if (i == 1)
                fprintf(f, "f 1 %d %d\n", a, b);
            if (i == n_stacks - 1)
                fprintf(f, "f 2 %d %d\n", b, a);
            else
                fprintf(f, "f %d %d %d\nf %d %d %d\n", a, a + n_slices, b + n_slices, a,
                        b + n_slices, b);
        }
    fclose(f);
    snprintf(scene_path, bytes, "%s/%s.txt", dir, name);
    f = fopen(scene_path, "w");
    cr_assert_not_null(f);
    fprintf(f, "%smesh file=%s material=m normals=smooth\nsky type=constant radiance=1,1,1\n", head,
            obj_path);
    fclose(f);
}

/* The largest angle between a triangle's geometric normal and the shading normal of one of its
 * corners, over the scene's triangles. */
static double max_shading_angle(const char *path)
{
    struct scene sc;
    struct mcpt_error err;
    cr_assert(scene_load(path, &sc, &err), "%s: %s", path, err.msg);
    double angle = 0.0;
    for (uint32_t i = 0; i < sc.n_tris; i++) {
        const struct scene_tri *t = &sc.tris[i];
        vec3 p0 = sc.positions[t->v[0]];
        vec3 ng = v3_normalize(
            v3_cross(v3_sub(sc.positions[t->v[1]], p0), v3_sub(sc.positions[t->v[2]], p0)));
        for (int k = 0; k < 3; k++) {
            cr_assert_geq(t->vn[k], 0, "triangle %u has no smooth normal", i);
            double c = v3_dot(ng, sc.normals[t->vn[k]]);
            angle = fmax(angle, acos(fmin(1.0, c)));
        }
    }
    scene_free(&sc);
    return angle;
}

/* Issue 12: smooth shading normals in a white furnace.  A convex sphere of 80 triangles with
 * angle-weighted normals, albedo 1, under a constant sky 1.  With the geometric normal every
 * pixel is exactly 1 (light and BSDF samples each add 1/2).  A shading normal tilted by theta
 * from the face sends the share (1 - cos theta) / 2 of its cosine lobe below the face, and the
 * geometric-side test drops those samples (the fraction of the projected unit disc outside the
 * ellipse of semi-axes cos theta and 1): so no sample exceeds 1 (no light gained or leaked,
 * exact up to float rounding), the image mean is at least 1 - (1 - cos theta_max) / 2 (4 SE),
 * and no pixel is black: a view direction on the wrong side of the shading normal (near the
 * silhouette) takes the geometric normal, so every pixel keeps at least half its samples'
 * worth (>= 0.5; the chance that most of 64 samples lose both halves is negligible). */
Test(extremes, smooth_sphere_in_white_furnace, .timeout = TEST_TIMEOUT_S(60))
{
    char dir[64], path[400];
    test_make_dir(dir, sizeof dir, "smooth");
    write_smooth_sphere(dir, "furnace", 6, 8,
                        "camera eye=0.3,0.2,3.2 look-at=0,0,0 up=0,1,0 fov=42\n"
                        "film width=32 height=32\nrender spp=64 sampler=independent\n"
                        "material name=m type=diffuse albedo=1,1,1\n",
                        path, sizeof path);
    double theta_max = max_shading_angle(path);
    cr_assert_gt(theta_max, 0.1, "the shading normals differ from the faces'");
    struct film f;
    struct trace_result r;
    render_file(path, 1, &f, &r);
    cr_assert_eq(r.n_nonfinite, 0);
    size_t n = (size_t)f.width * (size_t)f.height;
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++) {
            double m = film_mean(&f.pixels[i], c);
            cr_assert(m <= 1.0 + 1e-5, "pixel %zu channel %d: %.9f > 1", i, c, m);
            cr_assert(m >= 0.5, "pixel %zu channel %d: %.6f, black", i, c, m);
        }
    struct estimate e = region(&f, 0, 0, f.width, f.height, 1);
    double bound = 1.0 - (1.0 - cos(theta_max)) / 2.0;
    cr_log_info("smooth furnace: theta_max %.1f deg, mean %.5f (SE %.2g), bound %.5f",
                theta_max * 180.0 / M_PI, e.mean, sqrt(e.var), bound);
    cr_assert(e.mean >= bound - N_SE * sqrt(e.var), "mean %.6f below %.6f", e.mean, bound);
    film_free(&f);
    test_remove_dir(dir);
}

/* Issue 12: the camera inside the same smooth sphere (diffuse, albedo 0.5) under a white sky:
 * shading normals let no light in, every pixel is exactly 0. */
Test(extremes, smooth_sphere_lets_no_sky_in, .timeout = TEST_TIMEOUT_S(60))
{
    char dir[64], path[400];
    test_make_dir(dir, sizeof dir, "smooth");
    write_smooth_sphere(dir, "inside", 6, 8,
                        "camera eye=0.1,0.2,0.3 look-at=0.5,-0.2,-1 up=0,1,0 fov=100\n"
                        "film width=32 height=32\nrender spp=64 sampler=independent\n"
                        "material name=m type=diffuse albedo=0.5,0.5,0.5\n",
                        path, sizeof path);
    assert_black(path);
    test_remove_dir(dir);
}

/* One sphere, centre c[0..2] and radius c[3], of material m (`material`: its parameters), under
 * `sky` (a statement, or ""), with the camera inside it looking at its wall, or 4 radii out
 * looking at its centre; renders of 32 x 32 at 64 independent samples, `render` added. */
static void write_one_sphere(const char *path, const double c[4], bool inside, const char *render,
                             const char *material, const char *sky)
{
    double r = c[3], eye[3], at[3];
    const double eye_in[3] = {0.3, 0.1, -0.2}, at_in[3] = {1.0, 0.5, -1.0},
                 eye_out[3] = {0.2, 0.3, 4.0};
    for (int i = 0; i < 3; i++) {
        eye[i] = c[i] + r * (inside ? eye_in[i] : eye_out[i]);
        at[i] = inside ? c[i] + r * at_in[i] : c[i];
    }
    FILE *f = fopen(path, "w");
    cr_assert_not_null(f);
    fprintf(f,
            "camera eye=%.17g,%.17g,%.17g look-at=%.17g,%.17g,%.17g up=0,1,0 fov=%d\n"
            "film width=32 height=32\nrender spp=64 sampler=independent %s\n"
            "material name=m %s\nsphere center=%.17g,%.17g,%.17g radius=%.17g material=m\n%s\n",
            eye[0], eye[1], eye[2], at[0], at[1], at[2], inside ? 100 : 20, render, material, c[0],
            c[1], c[2], r, sky);
    fclose(f);
}

/* A closed analytic sphere far from the origin, the camera inside (diffuse, albedo 0.5, white
 * sky): every pixel exactly 0.  Its surface points are rounded to float at the centre's
 * magnitude, and a point off sideways lies outside the curved surface beyond its push along the
 * normal (the sagitta, shape.c sphere_point): before that was bounded, a sphere of radius 1 at
 * x = 1e5 let sky into its mean at 1e-3, and radius 1e5 at 1e10 at 1.3e-3.  The last case is the
 * smallest radius scene.c accepts there without a warning (2^-20 of the centre's coordinate). */
Test(extremes, sphere_far_from_the_origin_lets_no_sky_in, .timeout = TEST_TIMEOUT_S(60))
{
    const double cases[][4] = {
        {1e5, 0.0, 0.0, 1.0},
        {0.0, 0.0, 3e5, 1.0},
        {1e10, 0.0, 0.0, 1e5},
        {2.5e4, -7e3, 3e3, 0.05},
        {-3e-6, 1e-7, 0.0, 1e-11},
        {4e14, 1e14, -2e14, 1e9},
        {1e6, 2e5, -3e5, 0x1p-20 * 1e6},
    };
    char dir[64], path[400];
    test_make_dir(dir, sizeof dir, "farsphere");
    snprintf(path, sizeof path, "%s/scene.txt", dir);
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        write_one_sphere(path, cases[k], true, "", "type=diffuse albedo=0.5,0.5,0.5",
                         "sky type=constant radiance=1,1,1");
        assert_black(path);
    }
    test_remove_dir(dir);
}

/* A sphere that emits outwards only (diffuse, albedo 0.5, emission 1), the camera inside, no
 * sky: no point on or inside it receives its light, so every pixel is exactly 0, also far
 * from the origin.  Before light.c's is_within, light samples of the sphere from a point on its
 * inner surface a few rounding errors away counted as lit (image mean 1e-3 at x = 1e5 beside
 * the paths that escaped; 1e-4 once they no longer did). */
/* The lamp spheres of the two tests below: centre and radius, at the origin and far from it. */
static const double LAMP_SPHERES[][4] = {{0.0, 0.0, 0.0, 1.0},
                                         {1e5, 0.0, 0.0, 1.0},
                                         {0.0, 3e5, 0.0, 1.0},
                                         {1e10, 0.0, 0.0, 1e5}};
#define N_LAMP_SPHERES (sizeof LAMP_SPHERES / sizeof LAMP_SPHERES[0])

Test(extremes, emitting_sphere_is_dark_inside, .timeout = TEST_TIMEOUT_S(60))
{
    char dir[64], path[400];
    test_make_dir(dir, sizeof dir, "lampsphere");
    snprintf(path, sizeof path, "%s/scene.txt", dir);
    for (size_t k = 0; k < N_LAMP_SPHERES; k++) {
        write_one_sphere(path, LAMP_SPHERES[k], true, "max-depth=inf",
                         "type=diffuse albedo=0.5,0.5,0.5 emission=1,1,1", "");
        assert_black(path);
    }
    test_remove_dir(dir);
}

/* A sphere that emits on both sides (diffuse, albedo 0.5, emission 1), the camera inside, no
 * sky: every point inside sees radiance 1 / (1 - 0.5) = 2, far from the origin too, with light
 * sampling alone (`--direct light`) and with MIS.  Sampled by area from a point on its inner
 * surface, the cosine at the sampled point was rounding noise near that point (shape.c,
 * sphere_sample_inside): at x = 1e5 pixels reached 1e3 with light sampling, and MIS gave an
 * image mean of 1.9983 +- 0.0003.  Each pixel lies within 8 of its standard errors (pooled over
 * the image) of 2, the image mean within 4. */
Test(extremes, two_sided_lamp_sphere_is_even_inside, .timeout = TEST_TIMEOUT_S(60))
{
    const enum render_direct directs[] = {RENDER_DIRECT_LIGHT, RENDER_DIRECT_MIS};
    char dir[64], path[400];
    test_make_dir(dir, sizeof dir, "twosided");
    snprintf(path, sizeof path, "%s/scene.txt", dir);
    for (size_t k = 0; k < N_LAMP_SPHERES; k++) {
        const double *c = LAMP_SPHERES[k];
        write_one_sphere(path, c, true, "max-depth=inf",
                         "type=diffuse albedo=0.5,0.5,0.5 emission=1,1,1 two-sided=true", "");
        struct scene scene;
        struct mcpt_error err;
        cr_assert(scene_load(path, &scene, &err), "%s", err.msg);
        struct trace_scene *ts = trace_prepare(&scene, 2, &err);
        cr_assert_not_null(ts, "%s", err.msg);
        for (size_t j = 0; j < sizeof directs / sizeof directs[0]; j++) {
            struct film f;
            struct trace_result res;
            cr_assert(film_init(&f, scene.width, scene.height, &err));
            struct trace_options opt = {.spp = 256,
                                        .max_depth = TRACE_DEPTH_INFINITE,
                                        .seed = 5 + k,
                                        .sampler = SAMPLER_INDEPENDENT,
                                        .direct = directs[j],
                                        .n_threads = 2};
            cr_assert(trace_render(ts, &opt, &f, &res, &err), "%s", err.msg);
            size_t n = (size_t)f.width * (size_t)f.height;
            double sum = 0.0, var = 0.0;
            for (size_t i = 0; i < n; i++) {
                sum += film_mean(&f.pixels[i], 0);
                var += film_var_of_mean(&f.pixels[i], 0);
            }
            double se_pixel = sqrt(var / (double)n), mean = sum / (double)n;
            cr_assert(fabs(mean - 2.0) <= 4.0 * se_pixel / sqrt((double)n),
                      "centre %g,%g,%g, direct %d: image mean %.6f, SE %.2g", c[0], c[1], c[2],
                      (int)directs[j], mean, se_pixel / sqrt((double)n));
            for (size_t i = 0; i < n; i++) {
                double m = film_mean(&f.pixels[i], 0);
                cr_assert(fabs(m - 2.0) <= 8.0 * se_pixel,
                          "centre %g,%g,%g, direct %d: pixel %zu: %.6f (pixel SE %.2g)", c[0], c[1],
                          c[2], (int)directs[j], i, m, se_pixel);
            }
            film_free(&f);
        }
        trace_free(ts);
        scene_free(&scene);
    }
    test_remove_dir(dir);
}

/* The closed cube of 12 triangles emitting on both sides (albedo 0.5, emission 1), the camera
 * inside, at the origin and moved to x = 3e5 and 1e6 (where its size of 2 is 64 and 32 float
 * steps): every pixel is 1.5 with direct light alone (max-depth 1) and 2 with every bounce, and
 * MIS gives both within 4 of its standard errors, with lights sampled by area and (direct light)
 * by solid angle.  Light samples once measured their density from the vertex's rounded point to
 * the sampled point's rounded copy, and BSDF hits from the vertex to the rounded hit point; a
 * few percent of the distance off at 1e6, the two strategies priced the same points
 * differently, and MIS lost or gained energy (at x = 1e6, 1024 spp: 1.50296 +- 0.00016 by area;
 * by solid angle, its sample's wi pointing at the rounded point, 1.49849 +- 0.00014).  Both
 * now measure from ref->p, while BSDF rays start from the spawned origin a float step or two
 * away, so they still differ at the silhouettes of the faces: 1.50031 +- 0.00015 by area at
 * 1e6 (32 x 32, 1024 spp, seed 7; docs/theory.md, "Self-intersection"). */
Test(extremes, emitting_cube_far_from_the_origin_keeps_its_energy, .timeout = TEST_TIMEOUT_S(120))
{
    const double moves[] = {0.0, 3e5, 1e6};
    const char *sampling[] = {"area", "solid-angle"};
    char dir[64], path[300], obj[PATH_MAX];
    test_make_dir(dir, sizeof dir, "lampcube");
    snprintf(path, sizeof path, "%s/scene.txt", dir);
    cr_assert_not_null(realpath(DIR "cube-inward.obj", obj));
    for (size_t k = 0; k < sizeof moves / sizeof moves[0]; k++) {
        for (int m = 0; m < 2; m++) {
            double x = moves[k];
            FILE *f = fopen(path, "w");
            cr_assert_not_null(f);
            fprintf(f,
                    "camera eye=%.17g,0.3,0.2 look-at=%.17g,-0.5,-1 up=0,1,0 fov=100\n"
                    "film width=32 height=32\nrender light-sampling=%s\n"
                    "material name=m type=diffuse albedo=0.5,0.5,0.5 emission=1,1,1 "
                    "two-sided=true\nmesh file=%s material=m translate=%.17g,0,0\n",
                    x, x, sampling[m], obj, x);
            fclose(f);
            struct scene scene;
            struct mcpt_error err;
            cr_assert(scene_load(path, &scene, &err), "%s", err.msg);
            struct trace_scene *ts = trace_prepare(&scene, 2, &err);
            cr_assert_not_null(ts, "%s", err.msg);
            const uint32_t depths[] = {1, TRACE_DEPTH_INFINITE};
            for (int j = 0; j < (m == 0 ? 2 : 1); j++) {
                struct film film;
                struct trace_result res;
                cr_assert(film_init(&film, scene.width, scene.height, &err));
                struct trace_options opt = {.spp = 1024,
                                            .max_depth = depths[j],
                                            .seed = 11 + k,
                                            .sampler = SAMPLER_INDEPENDENT,
                                            .n_threads = 2};
                cr_assert(trace_render(ts, &opt, &film, &res, &err), "%s", err.msg);
                struct estimate e = region(&film, 0, 0, film.width, film.height, 0);
                double want = j == 0 ? 1.5 : 2.0;
                cr_assert(fabs(e.mean - want) <= 4.0 * sqrt(e.var),
                          "x = %g, %s, max-depth %u: image mean %.6f, SE %.2g, want %g", x,
                          sampling[m], depths[j], e.mean, sqrt(e.var), want);
                film_free(&film);
            }
            trace_free(ts);
            scene_free(&scene);
        }
    }
    test_remove_dir(dir);
}

/* The same class through glass: a dielectric sphere (IOR 1.5, no absorption) under a constant
 * sky of 1 renders 1 in every pixel (each path ends in the sky with weight 1; to float
 * rounding), also far from the origin.  Before the sagitta was bounded, refracted rays whose
 * origins sat outside the surface lost their way: at x = 1e5 pixels fell to 0.84, at 3e5 to
 * 0.50. */
Test(extremes, glass_sphere_far_from_the_origin_keeps_its_energy, .timeout = TEST_TIMEOUT_S(60))
{
    const double cases[][4] = {{1e5, 0.0, 0.0, 1.0}, {0.0, -3e5, 0.0, 1.0}, {1e10, 0.0, 0.0, 1e5}};
    char dir[64], path[400];
    test_make_dir(dir, sizeof dir, "farglass");
    snprintf(path, sizeof path, "%s/scene.txt", dir);
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        const double *c = cases[k];
        write_one_sphere(path, c, false, "max-depth=inf", "type=dielectric ior=1.5",
                         "sky type=constant radiance=1,1,1");
        struct film film;
        struct trace_result res;
        render_file(path, 1, &film, &res);
        cr_assert_eq(res.n_nonfinite, 0);
        for (size_t i = 0; i < (size_t)film.width * (size_t)film.height; i++)
            for (int ch = 0; ch < 3; ch++) {
                double m = film_mean(&film.pixels[i], ch);
                cr_assert(fabs(m - 1.0) <= 1e-6, "centre %g,%g,%g: pixel %zu channel %d: %.9f",
                          c[0], c[1], c[2], i, ch, m);
            }
        film_free(&film);
    }
    test_remove_dir(dir);
}

/* Rays aimed exactly at the vertices and at points along every edge of a mesh hit it: from the
 * centre of the closed icosphere (every edge shared by two faces), and from above the sliver fan
 * (its interior edges).  Woop et al. 2013's test is watertight, so no such ray slips through. */
Test(extremes, rays_through_vertices_and_edges_hit)
{
    struct obj_mesh m;
    struct mcpt_error err;
    const char *paths[] = {DIR "icosphere.obj", DIR "floor-slivers.obj"};
    const vec3 origins[] = {v3(0.0f, 0.0f, 0.0f), v3(0.1f, 1.0f, 0.2f)};
    for (int k = 0; k < 2; k++) {
        cr_assert(obj_load(paths[k], &m, &err), "%s", err.msg);
        uint32_t *idx = malloc(sizeof(uint32_t) * 3 * m.n_tris);
        for (uint32_t i = 0; i < m.n_tris; i++)
            for (int j = 0; j < 3; j++)
                idx[3 * i + j] = m.tris[i].v[j];
        struct bvh *bvh = bvh_build(m.positions, idx, m.n_tris, 1);
        cr_assert_not_null(bvh);
        int n_rays = 0;
        for (uint32_t i = 0; i < m.n_tris; i++) {
            for (int j = 0; j < 3; j++) {
                vec3 a = m.positions[m.tris[i].v[j]], b = m.positions[m.tris[i].v[(j + 1) % 3]];
                /* the fan's boundary (the square's outline) is not shared: skip it */
                bool boundary = k == 1 && (fabsf(a.x) == 1.0f || fabsf(a.z) == 1.0f) &&
                                (fabsf(b.x) == 1.0f || fabsf(b.z) == 1.0f) &&
                                (a.x == b.x || a.z == b.z);
                for (int s = boundary ? 1 : 0; s < (boundary ? 0 : 10); s++) {
                    float f = (float)s / 10.0f;
                    vec3 p = v3_add(a, v3_scale(v3_sub(b, a), f)); /* s = 0: the vertex */
                    if (k == 1 && (fabsf(p.x) == 1.0f || fabsf(p.z) == 1.0f))
                        continue; /* on the outline */
                    struct ray r = {.o = origins[k],
                                    .t_min = 0.0f,
                                    .d = v3_sub(p, origins[k]),
                                    .t_max = INFINITY};
                    struct bvh_hit hit;
                    cr_assert(bvh_intersect(bvh, &r, &hit),
                              "%s: ray through (%.9g, %.9g, %.9g) (face %u, edge %d, %d/10) "
                              "leaks",
                              paths[k], p.x, p.y, p.z, i, j, s);
                    cr_assert(fabsf(hit.t - 1.0f) < 1e-3f, "t = %g", hit.t);
                    n_rays++;
                }
            }
        }
        cr_assert_gt(n_rays, 1000);
        bvh_free(bvh);
        free(idx);
        obj_free(&m);
    }
}

/* ---- materials ---- */

/* Glass of IOR 1 is invisible: Fresnel reflectance 0, no bending, radiance scale eta^2 = 1. */
Test(extremes, ior_1_glass_is_invisible, .timeout = TEST_TIMEOUT_S(120))
{
    assert_same_scenes(DIR "ior1-without.txt", DIR "ior1-glass.txt");
}

/* Roughness 0: a GGX conductor with alpha below MAT_ALPHA_SMOOTH and F0 = 1 is a perfect
 * mirror (PBRT 4e, ch. 9, "Roughness Using Microfacet Theory": effectively smooth). */
Test(extremes, roughness_0_conductor_is_a_mirror, .timeout = TEST_TIMEOUT_S(120))
{
    assert_same_scenes(DIR "mirror-ball.txt", DIR "conductor-roughness-0.txt");
}

/* The largest roughness (1) and the smallest (0) in a white furnace: a conductor with F0 = 1
 * and plastics of albedo 1 stay finite and never exceed 1 (single-scattering microfacets lose
 * energy, they never create it: GGX at alpha = 1 keeps only about 0.3 to 0.5 of it, Kulla and
 * Conty 2017, "Revisiting Physically Based Shading at Imageworks"), but do not go black. */
Test(extremes, roughness_0_and_1_in_white_furnace, .timeout = TEST_TIMEOUT_S(120))
{
    const char *paths[] = {DIR "furnace-conductor-roughness-1.txt",
                           DIR "furnace-plastic-roughness-0.txt",
                           DIR "furnace-plastic-roughness-1.txt"};
    for (int k = 0; k < 3; k++) {
        struct film f;
        struct trace_result r;
        render_file(paths[k], 1, &f, &r);
        cr_assert_eq(r.n_nonfinite, 0, "%s", paths[k]);
        int w = f.width, h = f.height;
        for (int q = 0; q < 4; q++) { /* the quadrants of the central window: the ball */
            int x0 = w / 4 + (q % 2) * (w / 4), y0 = h / 4 + (q / 2) * (h / 4);
            for (int c = 0; c < 3; c++) {
                struct estimate e = region(&f, x0, y0, x0 + w / 4, y0 + h / 4, c);
                cr_assert(e.mean <= 1.0 + N_SE * sqrt(e.var) + 1e-6 && e.mean > 0.2,
                          "%s: quadrant %d channel %d: %.6f, SE %.2g", paths[k], q, c, e.mean,
                          sqrt(e.var));
            }
        }
        film_free(&f);
    }
}

/* Albedo 0: black surfaces reflect nothing, so every sample is exactly the sky (0.5), the
 * lamp (5) or 0.  From each pixel's sum and sum of squares the counts of 0.5 and 5 samples
 * follow; they must be whole numbers that fit in the pixel's sample count. */
Test(extremes, albedo_0_reflects_nothing)
{
    struct film f;
    struct trace_result r;
    render_file(DIR "albedo0.txt", 1, &f, &r);
    cr_assert_eq(r.n_nonfinite, 0);
    const double a = 0.5, b = 5.0;
    int n_sky = 0, n_lamp = 0;
    for (size_t i = 0; i < (size_t)f.width * (size_t)f.height; i++) {
        const struct film_pixel *p = &f.pixels[i];
        for (int c = 0; c < 3; c++) {
            /* sum = a n_a + b n_b, sum_sq = a^2 n_a + b^2 n_b */
            double n_a = (b * p->sum[c] - p->sum_sq[c]) / (a * (b - a));
            double n_b = (p->sum[c] - a * n_a) / b;
            cr_assert(fabs(n_a - round(n_a)) < 1e-6 && fabs(n_b - round(n_b)) < 1e-6 &&
                          n_a > -0.5 && n_b > -0.5 && n_a + n_b < p->n + 0.5,
                      "pixel %zu channel %d: sum %.17g, sum_sq %.17g is not made of 0, 0.5, 5", i,
                      c, p->sum[c], p->sum_sq[c]);
            n_sky += c == 0 && n_a > 0.5;
            n_lamp += c == 0 && n_b > 0.5;
        }
    }
    cr_assert(n_sky > 0 && n_lamp > 0, "the scene shows sky (%d) and lamp (%d)", n_sky, n_lamp);
    film_free(&f);
}

/* Albedo 1, white furnace: a white ball in a sky of radiance 1 renders 1 everywhere (within
 * standard errors, per quadrant and per channel). */
Test(extremes, albedo_1_white_furnace)
{
    struct film f;
    struct trace_result r;
    render_file(DIR "furnace.txt", 1, &f, &r);
    cr_assert_eq(r.n_nonfinite, 0);
    int w = f.width, h = f.height;
    for (int q = 0; q < 4; q++) {
        int x0 = q % 2 ? w / 2 : 0, y0 = q / 2 ? h / 2 : 0;
        for (int c = 0; c < 3; c++) {
            struct estimate e = region(&f, x0, y0, x0 + w / 2, y0 + h / 2, c);
            cr_assert(fabs(e.mean - 1.0) <= N_SE * sqrt(e.var) + 1e-6,
                      "quadrant %d channel %d: %.6f, SE %.2g", q, c, e.mean, sqrt(e.var));
        }
    }
    film_free(&f);
}

/* Albedo 1 inside a closed emitting ball: Le / (1 - albedo) diverges and throughput never
 * drops, so only the path-length cap (TRACE_DEPTH_CAP segments) ends a path: each of them
 * gathers about Le per segment.  The image is finite and at most Le (cap + 1), up to float
 * rounding. */
Test(extremes, albedo_1_closed_emitter_is_finite, .timeout = TEST_TIMEOUT_S(120))
{
    struct film f;
    struct trace_result r;
    render_file(DIR "enclosure.txt", 1, &f, &r);
    cr_assert_eq(r.n_nonfinite, 0);
    for (size_t i = 0; i < (size_t)f.width * (size_t)f.height; i++)
        for (int c = 0; c < 3; c++) {
            double m = film_mean(&f.pixels[i], c);
            cr_assert(isfinite(m) && m > 1.0 && m <= ((double)TRACE_DEPTH_CAP + 1.0) * 1.001,
                      "pixel %zu: %.9g", i, m);
        }
    film_free(&f);
}

/* Emission 1e-6 and 1e8: the same paths (same seed) carry Le linearly, so each pixel of the
 * 1e8 and 1e-6 renders is 1e8 and 1e-6 times the Le = 1 render up to float rounding (relative
 * 1e-5), with no overflow in the sums of squares. */
Test(extremes, emission_1e_minus_6_and_1e8_scale_linearly)
{
    struct film f1, f_lo, f_hi;
    struct trace_result r1, r_lo, r_hi;
    render_file(DIR "emission-1.txt", 7, &f1, &r1);
    render_file(DIR "emission-1e-6.txt", 7, &f_lo, &r_lo);
    render_file(DIR "emission-1e8.txt", 7, &f_hi, &r_hi);
    cr_assert(r1.n_nonfinite == 0 && r_lo.n_nonfinite == 0 && r_hi.n_nonfinite == 0);
    int n_lit = 0;
    for (size_t i = 0; i < (size_t)f1.width * (size_t)f1.height; i++)
        for (int c = 0; c < 3; c++) {
            double m = film_mean(&f1.pixels[i], c);
            double lo = film_mean(&f_lo.pixels[i], c) / 1e-6;
            double hi = film_mean(&f_hi.pixels[i], c) / 1e8;
            cr_assert(fabs(lo - m) <= 1e-5 * m && fabs(hi - m) <= 1e-5 * m,
                      "pixel %zu channel %d: %.9g, 1e-6: %.9g, 1e8: %.9g", i, c, m, lo, hi);
            cr_assert(isfinite(f_hi.pixels[i].sum_sq[c]) &&
                      isfinite(film_var_of_mean(&f_hi.pixels[i], c)));
            n_lit += m > 0.0;
        }
    cr_assert_gt(n_lit, 100);
    film_free(&f1);
    film_free(&f_lo);
    film_free(&f_hi);
}

/* ---- accumulation precision ---- */

/* One pixel accumulating 1e6 real radiance samples (trace_radiance on precision.txt) keeps its
 * sum to 1e-12 of a long-double reference sum, its variance of the mean to 1e-9 of a two-pass
 * long-double reference, and its float mean equal to the rounded reference. */
Test(extremes, million_samples_match_long_double_sum, .timeout = TEST_TIMEOUT_S(180))
{
    struct scene scene;
    struct mcpt_error err;
    cr_assert(scene_load(DIR "precision.txt", &scene, &err), "%s", err.msg);
    struct trace_scene *ts = trace_prepare(&scene, 1, &err);
    cr_assert_not_null(ts);
    struct trace_options opt = {.spp = 1,
                                .max_depth = scene.render.max_depth,
                                .seed = 3,
                                .sampler = SAMPLER_INDEPENDENT,
                                .n_threads = 1};
    const uint32_t n = 1000000;
    float *xs = malloc(sizeof(float) * n);
    cr_assert_not_null(xs);
    struct film_pixel px = {0};
    long double ref_sum = 0.0L;
    uint64_t n_rays = 0;
    uint32_t n_kept = 0;
    for (uint32_t i = 0; i < n; i++) {
        struct sampler s;
        sample_start(&s, SAMPLER_INDEPENDENT, opt.seed, 0, i);
        vec2 u_pixel = sample_2d(&s);
        vec2 u_lens = sample_2d(&s);
        struct ray ray = trace_camera_ray(ts, u_pixel.x, u_pixel.y, u_lens);
        vec3 L = trace_radiance(ts, &opt, ray, &s, &n_rays);
        cr_assert(v3_is_finite(L));
        film_add(&px, L);
        xs[n_kept++] = L.y;
        ref_sum += (long double)L.y;
    }
    cr_assert_eq(px.n, n);
    long double ref_mean = ref_sum / n;
    long double ss = 0.0L;
    for (uint32_t i = 0; i < n; i++)
        ss += ((long double)xs[i] - ref_mean) * ((long double)xs[i] - ref_mean);
    double ref_var_of_mean = (double)(ss / (n - 1) / n);
    double rel_sum = fabs((double)(((long double)px.sum[1] - ref_sum) / ref_sum));
    double rel_var = fabs(film_var_of_mean(&px, 1) - ref_var_of_mean) / ref_var_of_mean;
    cr_log_info("1e6 samples: sum relative error %.2g, variance %.2g", rel_sum, rel_var);
    cr_assert_lt(rel_sum, 1e-12);
    cr_assert_lt(rel_var, 1e-9);
    cr_assert_eq((float)film_mean(&px, 1), (float)ref_mean);
    free(xs);
    trace_free(ts);
    scene_free(&scene);
}

/* The same pixel rendered to 20000 spp in one call and in 20 calls of 1000 holds the same
 * bytes: each sample is added in sample-index order whatever the split (film.h). */
Test(extremes, split_accumulation_is_bit_identical, .timeout = TEST_TIMEOUT_S(120))
{
    struct scene scene;
    struct mcpt_error err;
    cr_assert(scene_load(DIR "precision.txt", &scene, &err));
    struct trace_scene *ts = trace_prepare(&scene, 1, &err);
    cr_assert_not_null(ts);
    struct film one, split;
    cr_assert(film_init(&one, 1, 1, &err) && film_init(&split, 1, 1, &err));
    struct trace_options opt = {.spp = 20000,
                                .max_depth = scene.render.max_depth,
                                .seed = 5,
                                .sampler = scene.render.sampler,
                                .n_threads = 1};
    struct trace_result res;
    cr_assert(trace_render(ts, &opt, &one, &res, &err));
    for (uint32_t spp = 1000; spp <= 20000; spp += 1000) {
        struct trace_options o = opt;
        o.spp = spp;
        o.sampler_spp = opt.spp; /* as progressive renders do: the final spp's strata */
        cr_assert(trace_render(ts, &o, &split, &res, &err));
    }
    cr_assert(memcmp(one.pixels, split.pixels, sizeof *one.pixels) == 0);
    film_free(&one);
    film_free(&split);
    trace_free(ts);
    scene_free(&scene);
}

/* ---- NaN and infinity ---- */

/* Runs mcpt on a scene (stderr to OUT.stderr, an alarm of 60 s); returns the exit status and
 * the stderr text. */
static int run_mcpt(const char *scene, const char *out, char *err, size_t err_bytes)
{
    char err_path[300];
    snprintf(err_path, sizeof err_path, "%s.stderr", out);
    const char *args[] = {scene, "-o", out, "--threads", "2", "--quiet", NULL};
    int rc = test_run_mcpt(args, NULL, err_path, 60);
    test_read_file(err_path, err, err_bytes);
    return rc;
}

/* The EXR mcpt wrote is finite in every channel; returns the samples dropped, spp - samples
 * summed over the pixels (each pixel takes spp samples and keeps the finite ones). */
static uint64_t exr_dropped(const char *path, float spp)
{
    struct image img;
    struct mcpt_error err;
    cr_assert(image_read_exr(path, &img, &err), "%s", err.msg);
    int s = image_find_channel(&img, "samples");
    cr_assert(s >= 0);
    uint64_t dropped = 0;
    for (size_t i = 0; i < (size_t)img.width * (size_t)img.height; i++) {
        for (int c = 0; c < img.n_channels; c++)
            cr_assert(isfinite(img.data[c][i]), "%s: channel %s pixel %zu", path, img.names[c], i);
        dropped += (uint64_t)(spp - img.data[s][i]);
    }
    image_free(&img);
    return dropped;
}

/* A glowing ball of radiance 3.3e38 that also reflects light: some samples exceed float range
 * (infinite).  They are dropped, the image is finite (variances beyond float range included),
 * and mcpt reports the count on one warning line that agrees with the EXR's sample counts. */
Test(nonfinite, overflow_dropped_counted_reported)
{
    char out[] = "/tmp/mcpt_overflow_XXXXXX.exr", err[4096];
    int fd = mkstemps(out, 4);
    cr_assert(fd >= 0);
    close(fd);
    cr_assert_eq(run_mcpt(DIR "overflow.txt", out, err, sizeof err), 0, "%s", err);
    uint64_t dropped = exr_dropped(out, 8.0f);
    unsigned long long n_reported = 0;
    unsigned x, y, s;
    cr_assert_eq(sscanf(err,
                        "mcpt: warning: %llu NaN or infinite samples dropped (first at "
                        "pixel %u,%u sample %u)",
                        &n_reported, &x, &y, &s),
                 4, "%s", err);
    cr_assert_gt(n_reported, 0);
    cr_assert_eq(n_reported, dropped);
    cr_assert(x < 16 && y < 12 && s < 8);
    char cmd[400];
    snprintf(cmd, sizeof cmd, "rm -f '%s' '%.*s.png' '%s.stderr'", out, (int)strlen(out) - 4, out,
             out);
    cr_assert_eq(system(cmd), 0);
}

/* Legal input that invites NaN (zero-length normals, degenerate and denormal faces, edge-on
 * faces and lights, a point light on a surface, emitters of radius 1e-30 and area 1e-40, a
 * grazing floor): the image is finite, and the count mcpt reports (none, if no line) is the
 * number of samples missing from the EXR's sample counts. */
Test(nonfinite, nan_invitations_finite_and_accounted)
{
    char out[] = "/tmp/mcpt_nan_XXXXXX.exr", err[4096];
    int fd = mkstemps(out, 4);
    cr_assert(fd >= 0);
    close(fd);
    cr_assert_eq(run_mcpt(DIR "nan-invitations.txt", out, err, sizeof err), 0, "%s", err);
    uint64_t dropped = exr_dropped(out, 16.0f);
    unsigned long long n_reported = 0;
    const char *warn = strstr(err, "mcpt: warning: ");
    if (warn)
        cr_assert_eq(sscanf(warn, "mcpt: warning: %llu NaN", &n_reported), 1, "%s", err);
    cr_assert_eq(n_reported, dropped, "reported %llu, EXR short by %llu", n_reported,
                 (unsigned long long)dropped);
    cr_log_info("nan-invitations.txt: %llu of %d samples not finite", n_reported, 32 * 32 * 16);
    char cmd[400];
    snprintf(cmd, sizeof cmd, "rm -f '%s' '%.*s.png' '%s.stderr'", out, (int)strlen(out) - 4, out,
             out);
    cr_assert_eq(system(cmd), 0);
}

/* A NaN albedo set on a loaded scene (the scene format cannot express one): every path that
 * reaches the floor is NaN, and trace_render drops each such sample, counts it in the pixel's
 * n_dropped and in the result with its first pixel, and keeps every mean finite. */
Test(nonfinite, nan_material_dropped_and_counted)
{
    struct scene scene;
    struct mcpt_error err;
    cr_assert(scene_load(DIR "floor-once.txt", &scene, &err), "%s", err.msg);
    for (uint32_t i = 0; i < scene.n_materials; i++)
        if (strcmp(scene.materials[i].name, "white") == 0)
            scene.materials[i].albedo.y = NAN;
    struct trace_scene *ts = trace_prepare(&scene, 2, &err);
    cr_assert_not_null(ts);
    struct film f;
    cr_assert(film_init(&f, scene.width, scene.height, &err));
    struct trace_options opt = {.spp = 8,
                                .max_depth = 3,
                                .seed = 1,
                                .sampler = scene.render.sampler,
                                .n_threads = 2};
    struct trace_result r;
    cr_assert(trace_render(ts, &opt, &f, &r, &err));
    cr_assert_gt(r.n_nonfinite, 0);
    cr_assert_eq(r.n_nonfinite, total_dropped(&f));
    const struct film_pixel *first = &f.pixels[r.first_bad_y * (uint32_t)f.width + r.first_bad_x];
    cr_assert_gt(first->n_dropped, 0);
    cr_assert_lt(r.first_bad_sample, opt.spp);
    int n_untouched = 0;
    for (size_t i = 0; i < (size_t)f.width * (size_t)f.height; i++) {
        cr_assert_eq(f.pixels[i].n + f.pixels[i].n_dropped, opt.spp);
        for (int c = 0; c < 3; c++)
            cr_assert(isfinite(film_mean(&f.pixels[i], c)) &&
                      isfinite(film_var_of_mean(&f.pixels[i], c)));
        n_untouched += f.pixels[i].n_dropped == 0;
    }
    cr_assert_gt(n_untouched, 0, "pixels that see only the sky or the lamp keep every sample");
    film_free(&f);
    trace_free(ts);
    scene_free(&scene);
}

/* ---- no scene aborts ---- */

/* Issue 12: scenes that once reached an assertion or invite one: the Cornell box at 1e-12 (a
 * normal that underflowed made a NaN ray, which passed every slab test and looped through the
 * wide nodes' empty lanes until the stack assertion), the BVH at its depth cap, zero-area faces
 * only, coordinates from 1e-30 to 1e18 in one mesh.  Each renders through the binary and exits
 * 0: no signal, no assertion; the traversal stacks are sized by the build's depth cap. */
Test(extremes, no_scene_aborts, .timeout = TEST_TIMEOUT_S(240))
{
    const char *scenes[] = {DIR "cornell-1e-12.txt", DIR "depth-cap.txt", DIR "degenerate-only.txt",
                            DIR "extreme-coordinates.txt", DIR "nan-invitations.txt"};
    char out[] = "/tmp/mcpt_abort_XXXXXX.exr", err[4096];
    int fd = mkstemps(out, 4);
    cr_assert(fd >= 0);
    close(fd);
    for (int k = 0; k < 5; k++) {
        int rc = run_mcpt(scenes[k], out, err, sizeof err);
        cr_assert_eq(rc, 0, "%s: exit status %d: %s", scenes[k], rc, err);
    }
    char cmd[400];
    snprintf(cmd, sizeof cmd, "rm -f '%s' '%.*s.png' '%s.stderr'", out, (int)strlen(out) - 4, out,
             out);
    cr_assert_eq(system(cmd), 0);
}
