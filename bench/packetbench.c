/* packetbench.c - what the camera packets of render_pixel (trace.c) buy end to end: renders
 * SCENE on one thread with camera rays in packets and with trace_options.single_rays, the two
 * interleaved over R rounds after a warm-up, and prints each one's render time (process CPU
 * time of trace_render alone: loading and the BVH build are left out), the median of the
 * per-round time ratios single/packets (> 1: packets win), and whether the two films are the
 * same to the bit (they must be; exit 1 otherwise).  `make bench-render` runs it per scene. */
#include <getopt.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bench.h"
#include "bench_scene.h"
#include "film.h"
#include "scene.h"
#include "trace.h"

static const char usage[] =
    "usage: packetbench SCENE [options]\n"
    "times a one-thread render with camera packets and with single camera rays\n"
    "options:\n"
    "  --width W, --height H   film size (default: the scene's)\n"
    "  --spp N                 samples per pixel (default 16)\n"
    "  --runs R                rounds, each timing both (default 5)\n"
    "  --seed S                random seed (default 0)\n";

static double cpu_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return 1e3 * (double)t.tv_sec + 1e-6 * (double)t.tv_nsec;
}

/* Renders into film (zeroed first); the CPU ms it took, or -1 with *err filled. */
static double timed_render(const struct trace_scene *ts, const struct trace_options *opt,
                           struct film *film, struct mcpt_error *err)
{
    memset(film->pixels, 0, sizeof(struct film_pixel) * (size_t)film->width * film->height);
    struct trace_result result;
    double t0 = cpu_ms();
    if (!trace_render(ts, opt, film, &result, err))
        return -1.0;
    return cpu_ms() - t0;
}

int main(int argc, char **argv)
{
    static const struct option long_opts[] = {{"width", required_argument, NULL, 'W'},
                                              {"height", required_argument, NULL, 'H'},
                                              {"spp", required_argument, NULL, 'n'},
                                              {"runs", required_argument, NULL, 'r'},
                                              {"seed", required_argument, NULL, 's'},
                                              {"help", no_argument, NULL, 'h'},
                                              {NULL, 0, NULL, 0}};
    uint32_t width = 0, height = 0, spp = 16, runs = 5, seed = 0;
    int c;
    while ((c = getopt_long(argc, argv, "h", long_opts, NULL)) != -1) {
        bool ok = true;
        switch (c) {
        case 'W':
            ok = bench_parse_u32("packetbench", optarg, "--width", 1, &width);
            break;
        case 'H':
            ok = bench_parse_u32("packetbench", optarg, "--height", 1, &height);
            break;
        case 'n':
            ok = bench_parse_u32("packetbench", optarg, "--spp", 1, &spp);
            break;
        case 'r':
            ok = bench_parse_u32("packetbench", optarg, "--runs", 1, &runs);
            break;
        case 's':
            ok = bench_parse_u32("packetbench", optarg, "--seed", 0, &seed);
            break;
        case 'h':
            fputs(usage, stdout);
            return 0;
        default:
            ok = false;
            break;
        }
        if (!ok || runs > 1000) {
            fputs(usage, stderr);
            return 2;
        }
    }
    if (optind != argc - 1) {
        fputs(usage, stderr);
        return 2;
    }
    struct scene scene;
    struct trace_options opt;
    if (!bench_scene_load(argv[optind], width, height, spp, seed, &scene, &opt))
        return 2;
    struct mcpt_error err;
    char line[600];
    int status = 1;
    struct film packets = {0}, single = {0};
    double *ms[2] = {calloc(runs, sizeof(double)), calloc(runs, sizeof(double))};
    double *ratio = calloc(runs, sizeof(double));
    struct trace_scene *ts = NULL;
    if (!ms[0] || !ms[1] || !ratio) {
        fprintf(stderr, "packetbench: out of memory\n");
        goto done;
    }
    ts = trace_prepare(&scene, 1, &err);
    if (!ts || !film_init(&packets, scene.width, scene.height, &err) ||
        !film_init(&single, scene.width, scene.height, &err))
        goto fail;
    struct film *films[2] = {&packets, &single};
    for (uint32_t r = 0; r <= runs; r++) /* round 0: warm-up, not counted */
        for (int mode = 0; mode < 2; mode++) {
            opt.single_rays = mode == 1;
            double t = timed_render(ts, &opt, films[mode], &err);
            if (t < 0.0)
                goto fail;
            if (r > 0)
                ms[mode][r - 1] = t;
        }
    for (uint32_t r = 0; r < runs; r++)
        ratio[r] = ms[1][r] / ms[0][r];
    bool same = memcmp(packets.pixels, single.pixels,
                       sizeof(struct film_pixel) * (size_t)scene.width * scene.height) == 0;
    double n_samples = (double)scene.width * scene.height * spp;
    double med_p = bench_median(ms[0], (int)runs), med_s = bench_median(ms[1], (int)runs);
    printf("packetbench: %s, %dx%d, %u spp, %u triangles, %u rounds, load %.2f: packets %.1f ms "
           "(%.3f Msamples/s), single rays %.1f ms (%.3f Msamples/s), single/packets x%.3f; "
           "films %s\n",
           argv[optind], scene.width, scene.height, spp, scene.n_tris, runs, bench_loadavg(), med_p,
           n_samples / med_p * 1e-3, med_s, n_samples / med_s * 1e-3,
           bench_median(ratio, (int)runs), same ? "identical" : "DIFFER");
    status = same ? 0 : 1;
    goto done;
fail:
    mcpt_error_format(&err, line, sizeof line);
    fprintf(stderr, "%s\n", line);
done:
    free(ms[0]);
    free(ms[1]);
    free(ratio);
    film_free(&packets);
    film_free(&single);
    trace_free(ts);
    scene_free(&scene);
    return status;
}
