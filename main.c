/* main.c - the mcpt command line: parse the arguments, load the scene, build the BVH, render,
 * write the EXR and the PNG preview, report.  Exit status: 0 success, 2 bad usage or bad input
 * (anything the user can fix), 1 runtime or I/O failure. */
#include <errno.h>
#include <stdarg.h>
#include <getopt.h>
#include <stdlib.h>
#include <time.h>
#include <unistd.h>

#include "film.h"
#include "image.h"
#include "scene.h"
#include "trace.h"

static const char USAGE[] =
    "usage: mcpt SCENE [options]\n"
    "Render SCENE (see docs/scene-format.md) to OUT.exr (linear float RGB, with per-pixel\n"
    "variance of the mean and sample count) and OUT.png (sRGB preview).\n"
    "\n"
    "  -o, --output OUT.exr   output image (default: the scene's name with .exr, here)\n"
    "      --spp N            samples per pixel (default: the scene's render spp, else 64)\n"
    "      --max-depth D      longest path in segments; 0 = emission only, 1 = direct light,\n"
    "                         inf = until Russian roulette ends it (default: scene, else inf)\n"
    "      --threads N        render threads (default: all cores)\n"
    "      --seed S           random seed, 0..2^64-1 (default 0)\n"
    "      --width W          film width in pixels (default: the scene's film)\n"
    "      --height H         film height in pixels (default: the scene's film)\n"
    "      --exposure E       PNG preview exposure in stops (default 0)\n"
    "      --quiet            print errors only\n"
    "  -h, --help             show this help\n"
    "      --version          show the version\n";

enum exit_status { EXIT_OK = 0, EXIT_RUNTIME = 1, EXIT_USAGE = 2 };

struct options {
    const char *scene_path;
    const char *output; /* NULL: derived from the scene path */
    uint32_t spp;       /* 0: from the scene */
    bool has_max_depth;
    uint32_t max_depth;
    int n_threads;
    uint64_t seed;
    int width;  /* 0: from the scene */
    int height; /* 0: from the scene */
    float exposure;
    bool quiet;
};

/* Prints one line "mcpt: error: <what was expected, what was got>" and returns EXIT_USAGE. */
static int usage_error(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "mcpt: error: ");
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, " (see mcpt --help)\n");
    va_end(ap);
    return EXIT_USAGE;
}

/* Strict unsigned parse of the whole string into [lo, hi]. */
static bool parse_u64(const char *s, uint64_t lo, uint64_t hi, uint64_t *out)
{
    if (!s || !*s || *s == '-' || *s == '+' || *s == ' ')
        return false;
    errno = 0;
    char *end;
    unsigned long long v = strtoull(s, &end, 10);
    if (errno || *end || v < lo || v > hi)
        return false;
    *out = v;
    return true;
}

static bool parse_float(const char *s, float lo, float hi, float *out)
{
    if (!s || !*s)
        return false;
    errno = 0;
    char *end;
    float v = strtof(s, &end);
    if (errno || *end || !isfinite(v) || v < lo || v > hi)
        return false;
    *out = v;
    return true;
}

/* Returns -1 when the run should go on, else the exit status (help, version, errors). */
static int parse_args(int argc, char **argv, struct options *o)
{
    enum { OPT_SPP = 256, OPT_MAX_DEPTH, OPT_THREADS, OPT_SEED, OPT_WIDTH, OPT_HEIGHT,
           OPT_EXPOSURE, OPT_QUIET, OPT_VERSION };
    static const struct option long_opts[] = {
        {"output", required_argument, NULL, 'o'},
        {"spp", required_argument, NULL, OPT_SPP},
        {"max-depth", required_argument, NULL, OPT_MAX_DEPTH},
        {"threads", required_argument, NULL, OPT_THREADS},
        {"seed", required_argument, NULL, OPT_SEED},
        {"width", required_argument, NULL, OPT_WIDTH},
        {"height", required_argument, NULL, OPT_HEIGHT},
        {"exposure", required_argument, NULL, OPT_EXPOSURE},
        {"quiet", no_argument, NULL, OPT_QUIET},
        {"help", no_argument, NULL, 'h'},
        {"version", no_argument, NULL, OPT_VERSION},
        {NULL, 0, NULL, 0},
    };
    memset(o, 0, sizeof *o);
    long n_cpus = sysconf(_SC_NPROCESSORS_ONLN);
    o->n_threads = n_cpus > 0 ? (int)n_cpus : 1;
    opterr = 0;
    int c;
    uint64_t v;
    while ((c = getopt_long(argc, argv, ":o:h", long_opts, NULL)) != -1) {
        const char *name = argv[optind - 1];
        switch (c) {
        case 'o':
            if (!*optarg)
                return usage_error("expected a file name after %s, got '%s'", "-o", optarg);
            o->output = optarg;
            break;
        case OPT_SPP:
            if (!parse_u64(optarg, 1, UINT32_MAX, &v))
                return usage_error("expected --spp to be an integer in 1..4294967295, got '%s'",
                                   optarg);
            o->spp = (uint32_t)v;
            break;
        case OPT_MAX_DEPTH:
            o->has_max_depth = true;
            if (strcmp(optarg, "inf") == 0)
                o->max_depth = TRACE_DEPTH_INFINITE;
            else if (parse_u64(optarg, 0, TRACE_DEPTH_CAP, &v))
                o->max_depth = (uint32_t)v;
            else
                return usage_error("expected --max-depth to be an integer in 0..1024 or 'inf', "
                                   "got '%s'", optarg);
            break;
        case OPT_THREADS:
            if (!parse_u64(optarg, 1, 1024, &v))
                return usage_error("expected --threads to be an integer in 1..1024, got '%s'",
                                   optarg);
            o->n_threads = (int)v;
            break;
        case OPT_SEED:
            if (!parse_u64(optarg, 0, UINT64_MAX, &v))
                return usage_error("expected --seed to be an integer in 0..2^64-1, got '%s'",
                                   optarg);
            o->seed = v;
            break;
        case OPT_WIDTH:
        case OPT_HEIGHT:
            if (!parse_u64(optarg, 1, 65535, &v))
                return usage_error("expected %s to be an integer in 1..65535, got '%s'",
                                   c == OPT_WIDTH ? "--width" : "--height", optarg);
            *(c == OPT_WIDTH ? &o->width : &o->height) = (int)v;
            break;
        case OPT_EXPOSURE:
            if (!parse_float(optarg, -64.0f, 64.0f, &o->exposure))
                return usage_error("expected --exposure to be a number in -64..64, got '%s'",
                                   optarg);
            break;
        case OPT_QUIET:
            o->quiet = true;
            break;
        case 'h':
            fputs(USAGE, stdout);
            return EXIT_OK;
        case OPT_VERSION:
            printf("mcpt %s\n", MCPT_VERSION);
            return EXIT_OK;
        case ':':
            return usage_error("expected a value after %s, got nothing", name);
        default:
            return usage_error("expected an option from mcpt --help, got '%s'", name);
        }
    }
    if (optind >= argc)
        return usage_error("expected a scene file, got nothing");
    if (optind + 1 < argc)
        return usage_error("expected one scene file, got '%s' too", argv[optind + 1]);
    o->scene_path = argv[optind];
    return -1;
}

/* "dir/name.txt" -> "name.exr" in the current folder. */
static void default_output(const char *scene_path, char *out, size_t out_bytes)
{
    const char *base = strrchr(scene_path, '/');
    base = base ? base + 1 : scene_path;
    const char *dot = strrchr(base, '.');
    int len = dot && dot != base ? (int)(dot - base) : (int)strlen(base);
    snprintf(out, out_bytes, "%.*s.exr", len, base);
}

/* "x/y.exr" -> "x/y.png" (any extension replaced; none: ".png" appended). */
static void png_path_for(const char *exr_path, char *out, size_t out_bytes)
{
    const char *slash = strrchr(exr_path, '/');
    const char *dot = strrchr(exr_path, '.');
    int len = dot && (!slash || dot > slash + 1) ? (int)(dot - exr_path) : (int)strlen(exr_path);
    snprintf(out, out_bytes, "%.*s.png", len, exr_path);
}

static double now_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Progress: a bar redrawn in place on a terminal, else a line at each quarter. */
struct progress {
    bool is_tty;
    bool quiet;
    double t_start;
    int quarters_printed;
};

static void report_progress(void *user, uint64_t done, uint64_t total)
{
    struct progress *p = user;
    if (p->quiet || total == 0)
        return;
    double frac = (double)done / (double)total;
    double elapsed = now_seconds() - p->t_start;
    double rate = elapsed > 0.0 ? (double)done / elapsed : 0.0;
    double eta = rate > 0.0 ? (double)(total - done) / rate : 0.0;
    if (p->is_tty) {
        char bar[31];
        int filled = (int)(frac * 30.0);
        for (int i = 0; i < 30; i++)
            bar[i] = i < filled ? '#' : '.';
        bar[30] = '\0';
        fprintf(stderr, "\r[%s] %5.1f%%  %.3g/%.3g Msamples  %.2f Msamples/s  ETA %4.0f s ", bar,
                100.0 * frac, (double)done * 1e-6, (double)total * 1e-6, rate * 1e-6, eta);
        if (done == total)
            fputc('\n', stderr);
    } else {
        int quarter = (int)(frac * 4.0);
        if (quarter > p->quarters_printed) {
            p->quarters_printed = quarter;
            fprintf(stderr, "progress: %3.0f%%  %.2f Msamples/s  ETA %.0f s\n", 100.0 * frac,
                    rate * 1e-6, eta);
        }
    }
}

static void print_error(const struct mcpt_error *err)
{
    char line[1024];
    mcpt_error_format(err, line, sizeof line);
    fprintf(stderr, "%s\n", line);
}

/* Writes the film as EXR (R, G, B, variance of the mean per channel, sample count) and PNG. */
static bool write_images(const struct film *film, const char *exr_path, float exposure,
                         struct mcpt_error *err)
{
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    struct image img = {.width = film->width, .height = film->height, .n_channels = 7};
    static const char *names[7] = {"R", "G", "B", "variance.R", "variance.G", "variance.B",
                                   "samples"};
    float *planes = malloc(sizeof(float) * n_pixels * 7);
    float *rgb = malloc(sizeof(float) * n_pixels * 3);
    bool ok = false;
    if (!planes || !rgb) {
        mcpt_error_set(err, exr_path, 0, 0, "out of memory writing the image");
        goto done;
    }
    for (int c = 0; c < 7; c++) {
        snprintf(img.names[c], sizeof img.names[c], "%s", names[c]);
        img.data[c] = planes + (size_t)c * n_pixels;
    }
    film_resolve(film, img.data, img.data + 3, img.data[6]);
    if (!image_write_exr(exr_path, &img, err))
        goto done;
    for (size_t i = 0; i < n_pixels; i++)
        for (int c = 0; c < 3; c++)
            rgb[3 * i + c] = img.data[c][i];
    char png_path[4096];
    png_path_for(exr_path, png_path, sizeof png_path);
    ok = image_write_png_srgb(png_path, film->width, film->height, rgb, exposure, err);
done:
    free(planes);
    free(rgb);
    return ok;
}

int main(int argc, char **argv)
{
    struct options o;
    int status = parse_args(argc, argv, &o);
    if (status >= 0)
        return status;

    struct mcpt_error err = {0};
    struct scene scene;
    struct trace_scene *ts = NULL;
    struct film film = {0};
    status = EXIT_USAGE;

    /* load */
    if (!scene_load(o.scene_path, &scene, &err)) {
        print_error(&err);
        return EXIT_USAGE;
    }
    if (o.width)
        scene.width = o.width;
    if (o.height)
        scene.height = o.height;
    char exr_path[4096];
    if (o.output)
        snprintf(exr_path, sizeof exr_path, "%s", o.output);
    else
        default_output(o.scene_path, exr_path, sizeof exr_path);
    if (!film_init(&film, scene.width, scene.height, &err)) {
        print_error(&err);
        goto done;
    }

    /* build */
    double t0 = now_seconds();
    ts = trace_prepare(&scene, o.n_threads, &err);
    if (!ts) {
        print_error(&err);
        goto done;
    }
    double t_build = now_seconds() - t0;

    /* render */
    struct trace_options topt = {
        .spp = o.spp ? o.spp : scene.render.spp,
        .max_depth = o.has_max_depth ? o.max_depth : scene.render.max_depth,
        .seed = o.seed,
        .sampler = SAMPLER_INDEPENDENT,
        .n_threads = o.n_threads,
        .progress = report_progress,
    };
    struct progress prog = {.is_tty = isatty(STDERR_FILENO), .quiet = o.quiet,
                            .t_start = now_seconds()};
    topt.progress_user = &prog;
    struct trace_result res;
    status = EXIT_RUNTIME;
    if (!trace_render(ts, &topt, &film, &res, &err)) {
        print_error(&err);
        goto done;
    }
    double t_render = now_seconds() - prog.t_start;

    /* write */
    if (!write_images(&film, exr_path, o.exposure, &err)) {
        print_error(&err);
        goto done;
    }

    /* report */
    if (res.n_nonfinite)
        fprintf(stderr,
                "mcpt: warning: %llu NaN or infinite samples dropped (first at pixel %u,%u "
                "sample %u)\n",
                (unsigned long long)res.n_nonfinite, res.first_bad_x, res.first_bad_y,
                res.first_bad_sample);
    if (!o.quiet) {
        struct bvh_stats bs = trace_bvh_stats(ts);
        printf("mcpt: %dx%d, %u spp, %d threads: render %.2f s, %.3f Msamples/s, %.2f Mrays/s; "
               "BVH %u tris in %.1f ms; wrote %s\n",
               film.width, film.height, topt.spp, o.n_threads, t_render,
               (double)res.n_samples / t_render * 1e-6, (double)res.n_rays / t_render * 1e-6,
               bs.n_tris, t_build * 1e3, exr_path);
    }
    status = EXIT_OK;
done:
    trace_free(ts);
    film_free(&film);
    scene_free(&scene);
    return status;
}
