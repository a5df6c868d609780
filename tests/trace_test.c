/* tests/trace_test.c - trace.c: the path tracer against analytic answers and a high-spp
 * reference, and the render loop's determinism.
 * - Inside a closed diffuse sphere of albedo rho emitting Le, L = Le / (1 - rho) (the Neumann
 *   series of Kajiya 1986, eq. 1, with a constant solution).
 * - The Cornell box image mean agrees with a 4096-spp mcpt value within 4 combined standard
 *   errors.
 * - Images are bit-identical for 1 and 2 threads and for any split of the samples into calls. */
#include <criterion/criterion.h>

#include <stdlib.h>

#include "film.h"
#include "scene.h"
#include "trace.h"

/* Image mean per channel and its standard error: the pixels are independent, so
 * Var(mean) = sum_i Var(mean_i) / N^2. */
static void image_mean_se(const struct film *film, double mean[3], double se[3])
{
    size_t n = (size_t)film->width * (size_t)film->height;
    for (int c = 0; c < 3; c++) {
        double s = 0, v = 0;
        for (size_t i = 0; i < n; i++) {
            s += film_mean(&film->pixels[i], c);
            v += film_var_of_mean(&film->pixels[i], c);
        }
        mean[c] = s / (double)n;
        se[c] = sqrt(v) / (double)n;
    }
}

static void render(const struct trace_scene *ts, struct film *film, uint32_t spp, int threads,
                   uint64_t seed)
{
    struct trace_options opt = {.spp = spp, .max_depth = TRACE_DEPTH_INFINITE, .seed = seed,
                                .sampler = SAMPLER_INDEPENDENT, .n_threads = threads};
    struct trace_result res;
    struct mcpt_error err;
    cr_assert(trace_render(ts, &opt, film, &res, &err));
    cr_assert_eq(res.n_nonfinite, 0u);
}

/* A scene built in code: the camera at the centre of a closed sphere. */
static struct material furnace_mat[1];
static struct sphere furnace_sphere[1];
static struct light furnace_light[1];

static struct scene furnace_scene(float rho, float Le)
{
    furnace_mat[0] = (struct material){.kind = MAT_DIFFUSE, .albedo = v3_splat(rho),
                                       .Le = v3_splat(Le), .two_sided_emission = true};
    furnace_sphere[0] = (struct sphere){.center = v3(0, 0, 0), .radius = 1.0f, .mat_idx = 0};
    furnace_light[0] = (struct light){.kind = LIGHT_SPHERE, .prim_idx = 0};
    struct scene s = {
        .camera = {.eye = v3(0.1f, -0.2f, 0.3f), .look_at = v3(0, 0, -1), .up = v3(0, 1, 0),
                   .fov_deg = 60.0f},
        .width = 16, .height = 16,
        .render = {.spp = 16, .max_depth = TRACE_DEPTH_INFINITE},
        .materials = furnace_mat, .n_materials = 1,
        .spheres = furnace_sphere, .n_spheres = 1,
        .lights = furnace_light, .n_lights = 1,
    };
    return s;
}

/* L = Le / (1 - rho) inside a closed emissive diffuse sphere, for rho = 0.5 and 0.9. */
Test(trace, closed_sphere_analytic)
{
    float rhos[2] = {0.5f, 0.9f};
    for (int k = 0; k < 2; k++) {
        struct scene s = furnace_scene(rhos[k], 1.0f);
        struct mcpt_error err;
        struct trace_scene *ts = trace_prepare(&s, 1, &err);
        cr_assert(ts);
        struct film film;
        cr_assert(film_init(&film, s.width, s.height, &err));
        render(ts, &film, 64, 2, 1);
        double mean[3], se[3];
        image_mean_se(&film, mean, se);
        double expect = 1.0 / (1.0 - rhos[k]);
        cr_assert(se[0] > 0.0);
        cr_assert(fabs(mean[0] - expect) < 4.0 * se[0], "rho %.1f: mean %.5f +- %.5f, expected %.5f",
                  rhos[k], mean[0], se[0], expect);
        film_free(&film);
        trace_free(ts);
    }
}

/* Same seed: identical sums for 1 and 2 threads, and for spp 3 then 8 versus 8 at once. */
Test(trace, deterministic_across_threads_and_splits)
{
    struct scene s;
    struct mcpt_error err;
    cr_assert(scene_load("scenes/cornell-box.txt", &s, &err), "%s", err.msg);
    s.width = 24;
    s.height = 20;
    struct trace_scene *ts = trace_prepare(&s, 1, &err);
    cr_assert(ts);
    struct film a, b, c;
    cr_assert(film_init(&a, s.width, s.height, &err));
    cr_assert(film_init(&b, s.width, s.height, &err));
    cr_assert(film_init(&c, s.width, s.height, &err));
    render(ts, &a, 8, 1, 42);
    render(ts, &b, 8, 2, 42);
    render(ts, &c, 3, 2, 42);
    render(ts, &c, 8, 1, 42);
    size_t bytes = sizeof(struct film_pixel) * (size_t)s.width * (size_t)s.height;
    cr_assert(memcmp(a.pixels, b.pixels, bytes) == 0, "1 vs 2 threads");
    cr_assert(memcmp(a.pixels, c.pixels, bytes) == 0, "one call vs two");
    struct film d;
    cr_assert(film_init(&d, s.width, s.height, &err));
    render(ts, &d, 8, 2, 43);
    cr_assert(memcmp(a.pixels, d.pixels, bytes) != 0, "another seed, another image");
    film_free(&a);
    film_free(&b);
    film_free(&c);
    film_free(&d);
    trace_free(ts);
    scene_free(&s);
}

/* The Cornell box (scenes/cornell-box.txt) image mean at 32x32, 16 spp, against the mean of a
 * 64x64, 4096 spp render by mcpt (seed 7; RGB and standard errors below), within 4 combined
 * standard errors per channel.  The image mean does not depend on resolution: it is the
 * film-plane average of the radiance. */
Test(trace, cornell_box_mean_matches_reference, .timeout = 120)
{
    static const double ref[3] = {0.185736, 0.120391, 0.034360};
    static const double ref_se[3] = {0.000094, 0.000066, 0.000022};
    struct scene s;
    struct mcpt_error err;
    cr_assert(scene_load("scenes/cornell-box.txt", &s, &err), "%s", err.msg);
    s.width = 32;
    s.height = 32;
    struct trace_scene *ts = trace_prepare(&s, 1, &err);
    cr_assert(ts);
    struct film film;
    cr_assert(film_init(&film, s.width, s.height, &err));
    render(ts, &film, 16, 2, 1);
    double mean[3], se[3];
    image_mean_se(&film, mean, se);
    for (int c = 0; c < 3; c++) {
        double tol = 4.0 * sqrt(se[c] * se[c] + ref_se[c] * ref_se[c]);
        cr_assert(fabs(mean[c] - ref[c]) < tol, "channel %d: %.5f vs %.5f (tolerance %.5f)", c,
                  mean[c], ref[c], tol);
    }
    film_free(&film);
    trace_free(ts);
    scene_free(&s);
}
