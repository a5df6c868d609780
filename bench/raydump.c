/* raydump.c - the rays of a render as ray files (../shared/BENCHMARKS.md, "Ray files"), so that
 * bench/raybench (or bench/embree_bench) can time the BVH on exactly the work a render gives it.
 * It renders SCENE on one thread with trace_options.ray_hook set, and writes
 *   PREFIX.obj          the scene's triangles in world space (its meshes after their transforms)
 *   PREFIX-closest.bin  the camera and bounce rays (closest hit), in the order traced
 *   PREFIX-shadow.bin   the shadow rays (any hit), directions normalised as the format asks
 * Analytic shapes (spheres, quads, planes) are not in the OBJ: raybench's rate on a scene that
 * has them leaves out their tests, which the render makes for every ray. */
#include <errno.h>
#include <getopt.h>
#include <stdlib.h>
#include <string.h>

#include "bench.h"
#include "bench_scene.h"
#include "film.h"
#include "scene.h"
#include "trace.h"

static const char usage[] =
    "usage: raydump SCENE -o PREFIX [options]\n"
    "writes PREFIX.obj, PREFIX-closest.bin and PREFIX-shadow.bin: the scene's triangles and the\n"
    "rays of a one-thread render of it (camera and bounce rays; shadow rays)\n"
    "options:\n"
    "  --width W, --height H   film size (default: the scene's)\n"
    "  --spp N                 samples per pixel (default 4: every sample traces the same\n"
    "                          kinds of rays, so a few give the render's mix)\n"
    "  --seed S                random seed (default 0)\n"
    "  --sampler K             independent, stratified or sobol (default: the scene's)\n";

/* The rays of one kind, growing as the render traces them. */
struct ray_list {
    struct ray *rays;
    uint64_t n;
    uint64_t cap;
    bool failed; /* out of memory */
};

struct dump {
    struct ray_list closest;
    struct ray_list shadow;
};

static void ray_list_push(struct ray_list *l, const struct ray *r)
{
    if (l->failed)
        return;
    if (l->n == l->cap) {
        uint64_t cap = l->cap ? 2 * l->cap : 4096;
        struct ray *rays = realloc(l->rays, cap * sizeof *rays);
        if (!rays) {
            l->failed = true;
            return;
        }
        l->rays = rays;
        l->cap = cap;
    }
    l->rays[l->n++] = *r;
}

/* trace_options.ray_hook: one thread only, so no locking.  Shadow rays end at t_max of a
 * direction that is not unit length (PBRT's SpawnRayTo); the format wants unit directions, so
 * d and t_max are rescaled (the same segment, up to rounding). */
static void record_ray(void *user, const struct ray *ray, bool is_shadow)
{
    struct dump *dump = user;
    if (!is_shadow) {
        ray_list_push(&dump->closest, ray);
        return;
    }
    struct ray r = *ray;
    float len = v3_length(r.d);
    if (len > 0.0f && isfinite(len)) {
        r.d = v3_scale(r.d, 1.0f / len);
        r.t_max = isfinite(r.t_max) ? r.t_max * len : r.t_max;
    }
    ray_list_push(&dump->shadow, &r);
}

static bool write_obj(const char *path, const struct scene *scene)
{
    FILE *f = fopen(path, "w");
    if (!f) {
        fprintf(stderr, "raydump: cannot open %s: %s\n", path, strerror(errno));
        return false;
    }
    fprintf(f, "# raydump: the triangles of a scene in world space\n");
    for (uint32_t i = 0; i < scene->n_positions; i++) {
        vec3 p = scene->positions[i];
        fprintf(f, "v %.9g %.9g %.9g\n", (double)p.x, (double)p.y, (double)p.z);
    }
    for (uint32_t i = 0; i < scene->n_tris; i++)
        fprintf(f, "f %u %u %u\n", scene->tris[i].v[0] + 1, scene->tris[i].v[1] + 1,
                scene->tris[i].v[2] + 1);
    if (fclose(f) != 0) {
        fprintf(stderr, "raydump: cannot write %s: %s\n", path, strerror(errno));
        return false;
    }
    return true;
}

static bool write_rays(const char *prefix, const char *suffix, uint32_t kind,
                       const struct ray_list *l)
{
    char path[4096];
    snprintf(path, sizeof path, "%s-%s.bin", prefix, suffix);
    struct bench_rays rays = {kind, l->n, l->rays};
    struct mcpt_error err;
    if (!bench_rays_write(path, &rays, &err)) {
        char line[600];
        mcpt_error_format(&err, line, sizeof line);
        fprintf(stderr, "%s\n", line);
        return false;
    }
    printf("wrote %s: %llu rays\n", path, (unsigned long long)l->n);
    return true;
}

int main(int argc, char **argv)
{
    static const struct option long_opts[] = {{"width", required_argument, NULL, 'W'},
                                              {"height", required_argument, NULL, 'H'},
                                              {"spp", required_argument, NULL, 'n'},
                                              {"seed", required_argument, NULL, 's'},
                                              {"sampler", required_argument, NULL, 'k'},
                                              {"help", no_argument, NULL, 'h'},
                                              {NULL, 0, NULL, 0}};
    const char *prefix = NULL;
    uint32_t width = 0, height = 0, spp = 4, seed = 0;
    const char *sampler = NULL;
    int c;
    while ((c = getopt_long(argc, argv, "o:h", long_opts, NULL)) != -1) {
        bool ok = true;
        switch (c) {
        case 'o':
            prefix = optarg;
            break;
        case 'W':
            ok = bench_parse_u32("raydump", optarg, "--width", 1, &width);
            break;
        case 'H':
            ok = bench_parse_u32("raydump", optarg, "--height", 1, &height);
            break;
        case 'n':
            ok = bench_parse_u32("raydump", optarg, "--spp", 1, &spp);
            break;
        case 's':
            ok = bench_parse_u32("raydump", optarg, "--seed", 0, &seed);
            break;
        case 'k':
            sampler = optarg;
            break;
        case 'h':
            fputs(usage, stdout);
            return 0;
        default:
            ok = false;
            break;
        }
        if (!ok) {
            fputs(usage, stderr);
            return 2;
        }
    }
    if (optind != argc - 1 || !prefix) {
        fputs(usage, stderr);
        return 2;
    }
    struct scene scene;
    struct trace_options opt;
    if (!bench_scene_load(argv[optind], width, height, spp, seed, &scene, &opt))
        return 2;
    opt.ray_hook = record_ray;
    struct mcpt_error err;
    char line[600];
    if (sampler && !sample_sampler_parse(sampler, &opt.sampler)) {
        fprintf(stderr, "raydump: expected --sampler independent, stratified or sobol, got '%s'\n",
                sampler);
        scene_free(&scene);
        return 2;
    }
    struct dump dump = {{0}, {0}};
    opt.ray_hook_user = &dump;
    int status = 1;
    struct film film = {0};
    struct trace_scene *ts = trace_prepare(&scene, 1, &err);
    struct trace_result result;
    if (!ts || !film_init(&film, scene.width, scene.height, &err) ||
        !trace_render(ts, &opt, &film, &result, &err)) {
        mcpt_error_format(&err, line, sizeof line);
        fprintf(stderr, "%s\n", line);
        goto done;
    }
    if (dump.closest.failed || dump.shadow.failed) {
        fprintf(stderr, "raydump: out of memory for the rays\n");
        goto done;
    }
    printf("raydump: %s: %dx%d, %u spp: %llu samples, %llu rays (%llu closest, %llu shadow); "
           "%u triangles, %u analytic shapes (not in the OBJ)\n",
           argv[optind], scene.width, scene.height, spp, (unsigned long long)result.n_samples,
           (unsigned long long)result.n_rays, (unsigned long long)dump.closest.n,
           (unsigned long long)dump.shadow.n, scene.n_tris,
           scene.n_spheres + scene.n_quads + scene.n_planes);
    char path[4096];
    snprintf(path, sizeof path, "%s.obj", prefix);
    if (write_obj(path, &scene) &&
        write_rays(prefix, "closest", BENCH_KIND_CLOSEST, &dump.closest) &&
        write_rays(prefix, "shadow", BENCH_KIND_OCCLUSION, &dump.shadow))
        status = 0;
done:
    free(dump.closest.rays);
    free(dump.shadow.rays);
    film_free(&film);
    trace_free(ts);
    scene_free(&scene);
    return status;
}
