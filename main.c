/* main.c - the mcpt command line: parse the arguments, load the scene, build the BVH, render,
 * write the EXR and the PNG preview, report.  Exit status: 0 success, 2 bad usage or bad input
 * (anything the user can fix), 1 runtime or I/O failure. */
#include <errno.h>
#include <stdarg.h>
#include <getopt.h>
#include <signal.h>
#include <stdlib.h>
#include <time.h>
#include <unistd.h>

#include "checkpoint.h"
#include "film.h"
#include "image.h"
#include "partial.h"
#include "plot.h"
#include "scene.h"
#include "stats.h"
#include "trace.h"

static const char USAGE[] =
    "usage: mcpt SCENE [options]\n"
    "       mcpt compare A.exr REF.exr [--heatmap ERR.png] [--json]   (mcpt compare --help)\n"
    "       mcpt integrate FUNCTION [--sampler S] [--spp N] [--seeds K]  (mcpt integrate --help)\n"
    "       mcpt merge PART.exr... -o OUT.exr   (mcpt merge --help)\n"
    "Render SCENE (see docs/scene-format.md) to OUT.exr (linear float RGB, with per-pixel\n"
    "variance of the mean and sample count) and OUT.png (sRGB preview).\n"
    "\n"
    "  -o, --output OUT.exr   output image (default: the scene's name with .exr, here)\n"
    "      --spp N            samples per pixel (default: the scene's render spp, else 64)\n"
    "      --max-depth D      most bounces per path; 0 = emission only, 1 = direct light,\n"
    "                         inf = until Russian roulette ends it (default: scene, else inf)\n"
    "      --direct E         direct-light estimator: mis (default), light, bsdf, cosine or\n"
    "                         hemisphere; every one converges to the same image\n"
    "      --light-samples N  shadow rays per path vertex, each to a light picked by power\n"
    "                         (1..1024, default 1)\n"
    "      --split S          full (default), direct (bounces 0-1) or indirect (bounces > 1)\n"
    "      --rr P             Russian roulette: throughput (default: continue with probability\n"
    "                         max beta) or a fixed continuation probability P in (0, 1]\n"
    "      --rr-depth D       bounces before roulette may end a path (1..1024, default 2)\n"
    "      --threads N        render threads (default: all cores)\n"
    "      --seed S           random seed, 0..2^64-1 (default 0)\n"
    "      --sampler K        independent, stratified or sobol (default: scene, else sobol);\n"
    "                         see docs/sampling.md\n"
    "      --adaptive         adaptive sampling: a pixel stops when the 95% interval of its\n"
    "                         mean luminance, 1.96 sigma/sqrt(n), is <= T max(mean, floor)\n"
    "      --tolerance T      adaptive: relative tolerance (default 0.05)\n"
    "      --adaptive-floor F adaptive: luminance below which T applies absolutely\n"
    "                         (default 0.01)\n"
    "      --batch B          adaptive: samples between tests (default 32)\n"
    "      --min-spp N        adaptive: samples before the first test (default 64, >= 2)\n"
    "      --max-spp N        adaptive: most samples per pixel (default: the spp)\n"
    "      --heatmap PNG      write a false-colour map of the samples per pixel with a legend\n"
    "                         (adaptive default: OUT.samples.png)\n"
    "      --width W          film width in pixels (default: the scene's film)\n"
    "      --height H         film height in pixels (default: the scene's film)\n"
    "      --exposure E       PNG preview exposure in stops (default 0)\n"
    "      --quiet            print errors only\n"
    ; /* the help is two strings: C11 compilers need only accept 4095 bytes in one */
static const char USAGE_MORE[] =
    "      --checkpoint CKPT  where an interrupted render saves its state (default OUT.exr.ckpt)\n"
    "      --resume CKPT      continue the interrupted render saved in CKPT to its target spp,\n"
    "                         with its options (later options override; render settings must\n"
    "                         match); the result is bit-identical to an uninterrupted run;\n"
    "                         SCENE may be left out (the checkpoint names it)\n"
    "      --sample-range A:B render only sample indices A..B-1 of every pixel of the --spp\n"
    "                         render (0 <= A < B <= spp); the EXR carries the sums that\n"
    "                         mcpt merge adds up (docs/distributed.md)\n"
    "convergence (docs/convergence.md):\n"
    "      --snapshots pow2   write OUT-sppN.exr/.png at 1, 2, 4, ... spp and OUT-contact.png\n"
    "      --reference REF    measure the error against REF.exr (noise-corrected when REF has\n"
    "                         variance channels); without: the image's own variance estimate\n"
    "      --curve CSV        write the curve at 1, 2, 4, ... spp as CSV, its fits as .json and\n"
    "                         the plot as .svg beside it\n"
    "      --seeds K          repeat the measured run with seeds S .. S+K-1 (default 1)\n"
    "      --target-rmse E    extrapolate the spp and time for RMSE E (default: half the last)\n"
    "      --preview-every T  rewrite OUT.png every T seconds while rendering\n"
    "  -h, --help             show this help\n"
    "      --version          show the version\n"
    "\n"
    "SIGINT or SIGTERM (Ctrl-C) stops the render between samples, writes the partial OUT.exr\n"
    "and the checkpoint, and exits with 130 (SIGINT) or 143 (SIGTERM); a second signal exits at\n"
    "once (every file is written to a temporary name and renamed, so none is left half-written).\n"
    "Exit status: 0 done, 1 runtime or I/O failure, 2 bad usage or bad input.\n";

enum exit_status { EXIT_OK = 0, EXIT_RUNTIME = 1, EXIT_USAGE = 2 };

struct options {
    const char *scene_path;
    const char *output; /* NULL: derived from the scene path */
    uint32_t spp;       /* 0: from the scene */
    bool has_max_depth;
    uint32_t max_depth;
    int n_threads;
    uint64_t seed;
    bool has_sampler;
    enum sampler_kind sampler;
    bool adaptive;
    float tolerance;      /* 0: from the scene, else the default */
    float adaptive_floor; /* < 0: from the scene, else the default */
    uint32_t batch;       /* 0: from the scene, else the default (likewise the next two) */
    uint32_t min_spp;
    uint32_t max_spp;
    const char *heatmap_path; /* NULL: OUT.samples.png when adaptive, else none */
    int width;  /* 0: from the scene */
    int height; /* 0: from the scene */
    float exposure;
    bool quiet;
    const char *checkpoint_path; /* NULL: OUT.exr.ckpt */
    bool snapshots;              /* --snapshots pow2 */
    const char *reference_path;  /* --reference REF.exr, or NULL */
    const char *curve_path;      /* --curve CSV, or NULL */
    uint32_t n_seeds;            /* --seeds K, >= 1 */
    double target_rmse;          /* --target-rmse E; 0: half the last RMSE */
    double preview_every;        /* --preview-every T seconds; 0: none */
    bool has_direct;             /* light transport: the --direct, --split and --rr given */
    enum render_direct direct;
    bool has_split;
    enum render_split split;
    bool has_rr;
    float rr_prob;               /* 0: throughput-based */
    uint32_t light_samples;      /* --light-samples N; 0: from the scene, else 1 */
    uint32_t rr_depth;           /* --rr-depth D; 0: from the scene, else the default */
    const char *resume_path;     /* --resume CKPT, or NULL */
    bool has_range;              /* --sample-range A:B given */
    struct partial_range range;  /* its sample indices */
    uint32_t args_bytes;         /* bytes used in args */
    char args[CHECKPOINT_ARGS_BYTES]; /* every option but --resume as "--name[=value]",
                                              NUL-ended: what a checkpoint stores */
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

/* Appends option c as "--name" or "--name=value" to o->args, the words a checkpoint stores so
 * that --resume repeats them.  False when o->args is full. */
static bool record_option(struct options *o, const struct option *long_opts, int c,
                          const char *value)
{
    const char *name = NULL;
    for (int i = 0; long_opts[i].name; i++)
        if (long_opts[i].val == c)
            name = long_opts[i].name;
    if (!name)
        return true; /* ':' or '?': parse_args reports the error */
    size_t room = sizeof o->args - o->args_bytes;
    int n = value ? snprintf(o->args + o->args_bytes, room, "--%s=%s", name, value)
                  : snprintf(o->args + o->args_bytes, room, "--%s", name);
    if (n < 0 || (size_t)n >= room)
        return false;
    o->args_bytes += (uint32_t)n + 1;
    return true;
}

/* Returns -1 when the run should go on, else the exit status (help, version, errors). */
static int parse_args(int argc, char **argv, struct options *o)
{
    enum { OPT_SPP = 256, OPT_MAX_DEPTH, OPT_THREADS, OPT_SEED, OPT_WIDTH, OPT_HEIGHT,
           OPT_EXPOSURE, OPT_QUIET, OPT_VERSION, OPT_CHECKPOINT, OPT_RESUME };
    enum { OPT_SAMPLER = 512, OPT_ADAPTIVE, OPT_TOLERANCE, OPT_ADAPTIVE_FLOOR, OPT_BATCH,
           OPT_MIN_SPP, OPT_MAX_SPP, OPT_HEATMAP };
    enum { OPT_SNAPSHOTS = 768, OPT_REFERENCE, OPT_CURVE, OPT_SEEDS, OPT_TARGET_RMSE,
           OPT_PREVIEW_EVERY };
    enum { OPT_DIRECT = 1024, OPT_LIGHT_SAMPLES, OPT_SPLIT, OPT_RR, OPT_RR_DEPTH };
    enum { OPT_SAMPLE_RANGE = 1280 };
    static const struct option long_opts[] = {
        {"output", required_argument, NULL, 'o'},
        {"spp", required_argument, NULL, OPT_SPP},
        {"max-depth", required_argument, NULL, OPT_MAX_DEPTH},
        {"direct", required_argument, NULL, OPT_DIRECT},
        {"light-samples", required_argument, NULL, OPT_LIGHT_SAMPLES},
        {"split", required_argument, NULL, OPT_SPLIT},
        {"rr", required_argument, NULL, OPT_RR},
        {"rr-depth", required_argument, NULL, OPT_RR_DEPTH},
        {"threads", required_argument, NULL, OPT_THREADS},
        {"seed", required_argument, NULL, OPT_SEED},
        {"sampler", required_argument, NULL, OPT_SAMPLER},
        {"adaptive", no_argument, NULL, OPT_ADAPTIVE},
        {"tolerance", required_argument, NULL, OPT_TOLERANCE},
        {"adaptive-floor", required_argument, NULL, OPT_ADAPTIVE_FLOOR},
        {"batch", required_argument, NULL, OPT_BATCH},
        {"min-spp", required_argument, NULL, OPT_MIN_SPP},
        {"max-spp", required_argument, NULL, OPT_MAX_SPP},
        {"heatmap", required_argument, NULL, OPT_HEATMAP},
        {"width", required_argument, NULL, OPT_WIDTH},
        {"height", required_argument, NULL, OPT_HEIGHT},
        {"exposure", required_argument, NULL, OPT_EXPOSURE},
        {"quiet", no_argument, NULL, OPT_QUIET},
        {"help", no_argument, NULL, 'h'},
        {"version", no_argument, NULL, OPT_VERSION},
        {"checkpoint", required_argument, NULL, OPT_CHECKPOINT},
        {"resume", required_argument, NULL, OPT_RESUME},
        {"snapshots", required_argument, NULL, OPT_SNAPSHOTS},
        {"reference", required_argument, NULL, OPT_REFERENCE},
        {"curve", required_argument, NULL, OPT_CURVE},
        {"seeds", required_argument, NULL, OPT_SEEDS},
        {"target-rmse", required_argument, NULL, OPT_TARGET_RMSE},
        {"preview-every", required_argument, NULL, OPT_PREVIEW_EVERY},
        {"sample-range", required_argument, NULL, OPT_SAMPLE_RANGE},
        {NULL, 0, NULL, 0},
    };
    memset(o, 0, sizeof *o);
    o->adaptive_floor = -1.0f;
    o->n_seeds = 1;
    long n_cpus = sysconf(_SC_NPROCESSORS_ONLN);
    o->n_threads = n_cpus > 0 ? (int)n_cpus : 1;
    opterr = 0;
    int c;
    uint64_t v;
    while ((c = getopt_long(argc, argv, ":o:h", long_opts, NULL)) != -1) {
        const char *name = argv[optind - 1];
        if (c != OPT_RESUME && !record_option(o, long_opts, c, optarg))
            return usage_error("expected options of at most %d bytes in all, got more",
                               CHECKPOINT_ARGS_BYTES);
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
        case OPT_DIRECT:
            if (!scene_direct_parse(optarg, &o->direct))
                return usage_error("expected --direct to be mis, light, bsdf, cosine or "
                                   "hemisphere, got '%s'", optarg);
            o->has_direct = true;
            break;
        case OPT_SPLIT:
            if (!scene_split_parse(optarg, &o->split))
                return usage_error("expected --split to be full, direct or indirect, got '%s'",
                                   optarg);
            o->has_split = true;
            break;
        case OPT_RR:
            o->has_rr = true;
            o->rr_prob = 0.0f;
            if (strcmp(optarg, "throughput") != 0 &&
                !(parse_float(optarg, 0.0f, 1.0f, &o->rr_prob) && o->rr_prob > 0.0f))
                return usage_error("expected --rr to be 'throughput' or a probability in (0, 1], "
                                   "got '%s'", optarg);
            break;
        case OPT_LIGHT_SAMPLES:
        case OPT_RR_DEPTH:
            if (!parse_u64(optarg, 1, 1024, &v))
                return usage_error("expected %s to be an integer in 1..1024, got '%s'",
                                   c == OPT_RR_DEPTH ? "--rr-depth" : "--light-samples", optarg);
            *(c == OPT_RR_DEPTH ? &o->rr_depth : &o->light_samples) = (uint32_t)v;
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
        case OPT_SAMPLER:
            if (!sample_sampler_parse(optarg, &o->sampler))
                return usage_error("expected --sampler to be independent, stratified or sobol, "
                                   "got '%s'", optarg);
            o->has_sampler = true;
            break;
        case OPT_ADAPTIVE:
            o->adaptive = true;
            break;
        case OPT_TOLERANCE:
            if (!parse_float(optarg, 0.0f, 1e6f, &o->tolerance) || !(o->tolerance > 0.0f))
                return usage_error("expected --tolerance to be a number > 0, got '%s'", optarg);
            break;
        case OPT_ADAPTIVE_FLOOR:
            if (!parse_float(optarg, 0.0f, 1e30f, &o->adaptive_floor))
                return usage_error("expected --adaptive-floor to be a number >= 0, got '%s'",
                                   optarg);
            break;
        case OPT_BATCH:
        case OPT_MIN_SPP:
        case OPT_MAX_SPP: {
            const char *what = c == OPT_BATCH ? "--batch" : c == OPT_MIN_SPP ? "--min-spp"
                                                                             : "--max-spp";
            uint64_t lo = c == OPT_MIN_SPP ? 2 : 1; /* one sample has no spread */
            if (!parse_u64(optarg, lo, UINT32_MAX, &v))
                return usage_error("expected %s to be an integer in %llu..4294967295, got '%s'",
                                   what, (unsigned long long)lo, optarg);
            *(c == OPT_BATCH ? &o->batch : c == OPT_MIN_SPP ? &o->min_spp : &o->max_spp) =
                (uint32_t)v;
            break;
        }
        case OPT_HEATMAP:
            if (!*optarg)
                return usage_error("expected a file name after --heatmap, got ''");
            o->heatmap_path = optarg;
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
        case OPT_CHECKPOINT:
        case OPT_RESUME:
            if (!*optarg)
                return usage_error("expected a file name after %s, got ''",
                                   c == OPT_RESUME ? "--resume" : "--checkpoint");
            *(c == OPT_RESUME ? &o->resume_path : &o->checkpoint_path) = optarg;
            break;
        case OPT_SNAPSHOTS:
            if (strcmp(optarg, "pow2") != 0)
                return usage_error("expected --snapshots pow2, got '%s'", optarg);
            o->snapshots = true;
            break;
        case OPT_REFERENCE:
        case OPT_CURVE:
            if (!*optarg)
                return usage_error("expected a file name after %s, got ''",
                                   c == OPT_REFERENCE ? "--reference" : "--curve");
            *(c == OPT_REFERENCE ? &o->reference_path : &o->curve_path) = optarg;
            break;
        case OPT_SEEDS:
            if (!parse_u64(optarg, 1, 1000000, &v))
                return usage_error("expected --seeds to be an integer in 1..1000000, got '%s'",
                                   optarg);
            o->n_seeds = (uint32_t)v;
            break;
        case OPT_TARGET_RMSE:
        case OPT_PREVIEW_EVERY: {
            float f;
            if (!parse_float(optarg, 0.0f, 1e30f, &f) || !(f > 0.0f))
                return usage_error("expected %s to be a number > 0, got '%s'",
                                   c == OPT_TARGET_RMSE ? "--target-rmse" : "--preview-every",
                                   optarg);
            *(c == OPT_TARGET_RMSE ? &o->target_rmse : &o->preview_every) = f;
            break;
        }
        case OPT_SAMPLE_RANGE:
            if (!partial_parse_range(optarg, &o->range))
                return usage_error("expected --sample-range A:B with integers 0 <= A < B <= "
                                   "4294967295, got '%s'", optarg);
            o->has_range = true;
            break;
        case 'h':
            fputs(USAGE, stdout);
            fputs(USAGE_MORE, stdout);
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
    if (optind >= argc && !o->resume_path) /* a checkpoint names its scene */
        return usage_error("expected a scene file, got nothing");
    if (optind + 1 < argc)
        return usage_error("expected one scene file, got '%s' too", argv[optind + 1]);
    o->scene_path = optind < argc ? argv[optind] : NULL;
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
    uint64_t base;      /* render passes: samples of the passes before this one */
    uint64_t total_all; /* render passes: samples of all of them; 0: one trace_render call */
};

static void report_progress(void *user, uint64_t done, uint64_t total)
{
    struct progress *p = user;
    if (p->total_all) { /* one of several passes: report the whole */
        done += p->base;
        total = p->total_all > done ? p->total_all : done;
    }
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

/* Fills topt's adaptive-sampling fields from the command line, else the scene's render
 * statement, else the defaults; with adaptive sampling topt->spp becomes the maximum.  Returns
 * -1 to go on, else EXIT_USAGE after printing why. */
static int sampling_options(const struct options *o, const struct render_settings *r,
                            struct trace_options *topt)
{
    topt->adaptive = o->adaptive || r->adaptive;
    if (!topt->adaptive) {
        if (o->tolerance || o->adaptive_floor >= 0.0f || o->batch || o->min_spp || o->max_spp)
            return usage_error("expected --adaptive (or the scene's render adaptive=true) with "
                               "--tolerance, --adaptive-floor, --batch, --min-spp or --max-spp, "
                               "got none");
        return -1;
    }
    topt->spp = o->max_spp ? o->max_spp : r->max_spp ? r->max_spp : topt->spp;
    topt->tolerance = o->tolerance ? o->tolerance : r->tolerance ? r->tolerance
                                                                 : TRACE_ADAPTIVE_TOLERANCE;
    topt->adaptive_floor = o->adaptive_floor >= 0.0f ? o->adaptive_floor
                           : r->adaptive_floor >= 0.0f ? r->adaptive_floor
                                                       : TRACE_ADAPTIVE_FLOOR;
    topt->batch = o->batch ? o->batch : r->batch ? r->batch : TRACE_ADAPTIVE_BATCH;
    uint32_t min_default = TRACE_ADAPTIVE_MIN_SPP < topt->spp ? TRACE_ADAPTIVE_MIN_SPP
                                                              : topt->spp;
    topt->min_spp = o->min_spp ? o->min_spp : r->min_spp ? r->min_spp : min_default;
    if (topt->min_spp > topt->spp)
        return usage_error("expected --min-spp <= the most samples per pixel (%u), got %u",
                           topt->spp, topt->min_spp);
    return -1;
}

/* --sample-range A:B: renders sample indices A..B-1 of the topt->spp-sample render, i.e.
 * B - A samples a pixel from sample offset A, in the stratified sets of the whole render (so
 * disjoint ranges hold exactly the whole render's samples), and fills *info with the range and
 * every setting the parts of one render must share.  Returns -1 to go on, else EXIT_USAGE. */
static int sample_range_options(const struct options *o, bool measuring, uint64_t scene_hash,
                                const struct film *film, struct trace_options *topt,
                                struct partial_info *info)
{
    if (topt->adaptive)
        return usage_error("expected no adaptive sampling with --sample-range (where a pixel "
                           "stops depends on all its samples), got it");
    if (measuring)
        return usage_error("expected no --snapshots, --curve, --reference or --seeds with "
                           "--sample-range, got one");
    if (o->range.end > topt->spp)
        return usage_error("expected --sample-range within the render's %u samples per pixel "
                           "(--spp sets them), got %u:%u", topt->spp, o->range.begin,
                           o->range.end);
    memset(info, 0, sizeof *info);
    info->n_ranges = 1;
    info->ranges[0] = o->range;
    snprintf(info->render, sizeof info->render,
             "scene=%016llx film=%dx%d spp=%u seed=%llu sampler=%s max-depth=%u direct=%s "
             "light-samples=%u split=%s rr=%.9g rr-depth=%u", (unsigned long long)scene_hash,
             film->width, film->height, topt->spp, (unsigned long long)topt->seed,
             sample_sampler_name(topt->sampler), topt->max_depth, scene_direct_name(topt->direct),
             topt->light_samples ? topt->light_samples : 1u, scene_split_name(topt->split),
             (double)topt->rr_prob, topt->rr_depth ? topt->rr_depth : TRACE_RR_DEPTH_DEFAULT);
    topt->sampler_spp = topt->spp; /* the whole render's stratified sets */
    topt->sample_offset = o->range.begin;
    topt->spp = o->range.end - o->range.begin;
    return -1;
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

/* ---- interrupt and resume ---- */

/* Set by the first SIGINT or SIGTERM; trace_render's workers stop between samples when it is
 * nonzero.  Globals only because a signal handler can reach nothing else. */
static atomic_int g_cancel;
static volatile sig_atomic_t g_signal; /* the signal that set g_cancel */
_Static_assert(ATOMIC_INT_LOCK_FREE == 2, "the signal handler needs a lock-free atomic_int");

static void on_signal(int sig)
{
    if (atomic_exchange(&g_cancel, 1) != 0)
        _exit(128 + sig); /* the second signal: leave at once (files are renamed into place) */
    g_signal = sig;
}

static void catch_signals(void)
{
    struct sigaction sa = {.sa_handler = on_signal};
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
}

/* --resume: loads the checkpoint's film and settings, then parses its stored options followed
 * by this command line (later words win), so the run goes on as the interrupted one did unless
 * told otherwise.  ck must outlive *o.  Returns -1 to go on, else the exit status. */
static int resume_options(int argc, char **argv, struct options *o, struct film *film,
                          struct checkpoint_info *ck)
{
    struct mcpt_error err = {0};
    if (!checkpoint_load(o->resume_path, film, ck, &err)) {
        print_error(&err);
        return EXIT_USAGE;
    }
    char **words = malloc(sizeof(char *) * ((size_t)ck->args_bytes + (size_t)argc + 1));
    if (!words) {
        fprintf(stderr, "mcpt: error: out of memory\n");
        film_free(film);
        return EXIT_RUNTIME;
    }
    int n = 0;
    words[n++] = argv[0];
    for (uint32_t i = 0; i < ck->args_bytes; i += (uint32_t)strlen(ck->args + i) + 1)
        words[n++] = ck->args + i;
    for (int i = 1; i < argc; i++)
        words[n++] = argv[i];
    words[n] = NULL;
    optind = 0; /* glibc: start a fresh scan */
    int status = parse_args(n, words, o);
    free(words); /* o points into ck and argv, not into words */
    if (status < 0 && !o->scene_path)
        o->scene_path = ck->scene_path;
    if (status >= 0)
        film_free(film);
    return status;
}

/* The resumed run must render exactly what the interrupted one would have: same scene bytes,
 * film, spp target, seed, sampler, depth and sample offset. */
static bool resume_matches(const struct checkpoint_info *ck, uint64_t scene_hash,
                           const struct trace_options *topt, const struct film *film,
                           const struct scene *scene, const char *ckpt_path,
                           struct mcpt_error *err)
{
    const char *what = NULL;
    unsigned long long want = 0, got = 0;
    if (ck->scene_hash != scene_hash) {
        mcpt_error_set(err, ckpt_path, 0, 0, "expected the scene the checkpoint was made from "
                       "('%.200s', FNV-1a %016llx), got a file with hash %016llx", ck->scene_path,
                       (unsigned long long)ck->scene_hash, (unsigned long long)scene_hash);
        return false;
    }
    if (film->width != scene->width || film->height != scene->height) {
        mcpt_error_set(err, ckpt_path, 0, 0, "expected a %dx%d film as in the checkpoint, got "
                       "%dx%d", film->width, film->height, scene->width, scene->height);
        return false;
    }
    if (ck->spp != topt->spp)
        what = "--spp", want = ck->spp, got = topt->spp;
    else if (ck->seed != topt->seed)
        what = "--seed", want = ck->seed, got = topt->seed;
    else if (ck->max_depth != topt->max_depth)
        what = "--max-depth", want = ck->max_depth, got = topt->max_depth;
    else if (ck->sampler != (uint32_t)topt->sampler) {
        mcpt_error_set(err, ckpt_path, 0, 0, "expected --sampler %s as in the checkpoint, got %s",
                       sample_sampler_name((enum sampler_kind)ck->sampler),
                       sample_sampler_name(topt->sampler));
        return false;
    } else if (ck->sample_offset != topt->sample_offset)
        what = "the sample offset", want = ck->sample_offset, got = topt->sample_offset;
    if (what)
        mcpt_error_set(err, ckpt_path, 0, 0, "expected %s %llu as in the checkpoint, got %llu",
                       what, want, got);
    return !what;
}

/* Writes the checkpoint of an interrupted render (atomically, see checkpoint_save). */
static bool write_checkpoint(const struct options *o, const char *ckpt_path, uint64_t scene_hash,
                             const struct trace_options *topt, const struct film *film,
                             struct mcpt_error *err)
{
    struct checkpoint_info *ck = calloc(1, sizeof *ck);
    if (!ck) {
        mcpt_error_set(err, ckpt_path, 0, 0, "out of memory writing the checkpoint");
        return false;
    }
    ck->scene_hash = scene_hash;
    ck->seed = topt->seed;
    ck->spp = topt->spp;
    ck->max_depth = topt->max_depth;
    ck->sampler = (uint32_t)topt->sampler;
    ck->sample_offset = topt->sample_offset;
    snprintf(ck->scene_path, sizeof ck->scene_path, "%s", o->scene_path);
    memcpy(ck->args, o->args, o->args_bytes);
    ck->args_bytes = o->args_bytes;
    bool ok = checkpoint_save(ckpt_path, film, ck, err);
    free(ck);
    return ok;
}

/* ---- convergence measurements (docs/convergence.md): snapshots, curves, previews ---- */

/* The measuring state of a render: the reference, the curve and the options that shape it. */
struct convergence {
    bool measuring;            /* measure at 1, 2, 4, ... spp (and the final spp) */
    struct image ref_img;      /* --reference as read */
    struct stats_image ref;    /* its R, G, B and variance channels */
    bool has_ref;
    struct stats_curve curve;  /* one point per (seed, measured spp) */
    struct stats_summary summary;
    struct plot_sheet sheet;   /* --snapshots: the contact sheet's thumbnails */
};

static bool is_pow2(uint32_t v) { return v && !(v & (v - 1)); }

/* "x/out.exr" -> "x/out" + suffix (the extension replaced by suffix). */
static void path_with_suffix(const char *path, const char *suffix, char *out, size_t out_bytes)
{
    const char *slash = strrchr(path, '/');
    const char *dot = strrchr(path, '.');
    int len = dot && (!slash || dot > slash + 1) ? (int)(dot - path) : (int)strlen(path);
    snprintf(out, out_bytes, "%.*s%s", len, path, suffix);
}

/* Rewrites OUT.png from the film as it stands (atomically, so a viewer never sees half). */
static bool write_preview(const struct film *film, const char *exr_path, float exposure,
                          struct mcpt_error *err)
{
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    float *rgb = malloc(sizeof(float) * 3 * n_pixels);
    if (!rgb) {
        mcpt_error_set(err, exr_path, 0, 0, "out of memory writing the preview");
        return false;
    }
    for (size_t i = 0; i < n_pixels; i++)
        for (int c = 0; c < 3; c++)
            rgb[3 * i + c] = (float)film_mean(&film->pixels[i], c);
    char png_path[4096];
    png_path_for(exr_path, png_path, sizeof png_path);
    bool ok = image_write_png_srgb(png_path, film->width, film->height, rgb, exposure, err);
    free(rgb);
    return ok;
}

/* Renders the film to topt->spp.  Without measurements or previews: one trace_render call.
 * Otherwise in passes: each call continues every pixel from its count, so the final film is
 * bit-identical to one call; between passes the film is measured at 1, 2, 4, ... spp (a CSV
 * point, a snapshot EXR + PNG for the first seed) and the preview PNG is rewritten every
 * --preview-every seconds (passes sized from the last one's speed).  With --seeds K the run is
 * repeated for seeds S .. S+K-1 in a scratch film; the film keeps seed S's image. */
static bool render_passes(const struct options *o, const struct trace_scene *ts,
                          const struct trace_options *topt, struct film *film,
                          const char *exr_path, struct convergence *cv, struct progress *prog,
                          struct trace_result *res, struct mcpt_error *err)
{
    memset(res, 0, sizeof *res);
    if (!cv->measuring && !(o->preview_every > 0.0))
        return trace_render(ts, topt, film, res, err);
    uint32_t n_seeds = cv->measuring ? o->n_seeds : 1;
    uint32_t spp_final = topt->spp;
    int digits = snprintf(NULL, 0, "%u", spp_final);
    prog->total_all = (uint64_t)n_seeds * spp_final * (uint64_t)film->width * film->height;
    struct film scratch = {0};
    bool ok = false;
    for (uint32_t k = 0; k < n_seeds; k++) {
        struct film *f = film;
        if (k > 0) {
            if (!scratch.pixels && !film_init(&scratch, film->width, film->height, err))
                goto done;
            memset(scratch.pixels, 0,
                   sizeof *scratch.pixels * (size_t)scratch.width * (size_t)scratch.height);
            f = &scratch;
        }
        struct trace_options pass = *topt;
        pass.seed = topt->seed + k;
        if (!pass.adaptive && !pass.sampler_spp)
            pass.sampler_spp = spp_final; /* the strata of the final spp in every pass */
        double seconds = 0.0, seconds_per_spp = 0.0, t_preview = now_seconds();
        for (uint32_t done_spp = 0; done_spp < spp_final;) {
            uint32_t next = cv->measuring ? stats_next_pow2(done_spp, spp_final) : spp_final;
            if (o->preview_every > 0.0 && k == 0) {
                double step = seconds_per_spp > 0.0 ? o->preview_every / seconds_per_spp : 1.0;
                if (step < (double)(next - done_spp))
                    next = done_spp + (step >= 1.0 ? (uint32_t)step : 1u);
            }
            pass.spp = next;
            struct trace_result r;
            double t0 = now_seconds();
            if (!trace_render(ts, &pass, f, &r, err))
                goto done;
            double dt = now_seconds() - t0;
            seconds += dt;
            seconds_per_spp = dt / (double)(next - done_spp);
            prog->base += r.n_samples;
            if (r.n_nonfinite && !res->n_nonfinite) {
                res->first_bad_x = r.first_bad_x;
                res->first_bad_y = r.first_bad_y;
                res->first_bad_sample = r.first_bad_sample;
            }
            res->n_samples += r.n_samples;
            res->n_rays += r.n_rays;
            res->n_nonfinite += r.n_nonfinite;
            if (r.cancelled) {
                res->cancelled = true;
                ok = true;
                goto done;
            }
            done_spp = next;
            bool snapshot = o->snapshots && k == 0;
            if (cv->measuring && (is_pow2(done_spp) || done_spp == spp_final)) {
                struct stats_image img;
                if (!stats_curve_add(&cv->curve, f, cv->has_ref ? &cv->ref : NULL, pass.seed,
                                     done_spp, seconds, &img, err))
                    goto done;
                const struct stats_point *p = &cv->curve.points[cv->curve.n_points - 1];
                if (snapshot && !plot_sheet_add(&cv->sheet, &img, done_spp, p->psnr_db,
                                                p->source, o->exposure, err))
                    goto done;
                char suffix[64], snap_path[4200];
                snprintf(suffix, sizeof suffix, "-spp%0*u.exr", digits, done_spp);
                path_with_suffix(exr_path, suffix, snap_path, sizeof snap_path);
                if (snapshot && !write_images(f, snap_path, o->exposure, err))
                    goto done;
            }
            if (o->preview_every > 0.0 && k == 0 && done_spp < spp_final &&
                now_seconds() - t_preview >= o->preview_every) {
                if (!write_preview(f, exr_path, o->exposure, err))
                    goto done;
                t_preview = now_seconds();
            }
        }
    }
    if (prog->base != prog->total_all) { /* adaptive: fewer samples than the maximum */
        prog->total_all = prog->base;
        report_progress(prog, 0, 0);
    }
    ok = true;
done:
    film_free(&scratch);
    return ok;
}

/* The estimator as the convergence CSV names it: "path-" and the direct-lighting mode, then the
 * split ("-direct", "-indirect") and the light samples ("-ls4") when not the defaults. */
static void integrator_name(const struct trace_options *topt, char *out, size_t out_bytes)
{
    int n = snprintf(out, out_bytes, "path-%s", scene_direct_name(topt->direct));
    if (topt->split != RENDER_SPLIT_FULL && n > 0 && (size_t)n < out_bytes)
        n += snprintf(out + n, out_bytes - (size_t)n, "-%s", scene_split_name(topt->split));
    if (topt->light_samples > 1 && n > 0 && (size_t)n < out_bytes)
        snprintf(out + n, out_bytes - (size_t)n, "-ls%u", topt->light_samples);
}

/* Reads --reference REF.exr, which must have the film's size. */
static bool load_reference(const char *path, const struct film *film, struct convergence *cv,
                           struct mcpt_error *err)
{
    if (!image_read_exr(path, &cv->ref_img, err) ||
        !stats_image_from_exr(&cv->ref_img, path, &cv->ref, err))
        return false;
    if (cv->ref.width != film->width || cv->ref.height != film->height) {
        mcpt_error_set(err, path, 0, 0, "expected a reference of the film's size %dx%d, got %dx%d",
                       film->width, film->height, cv->ref.width, cv->ref.height);
        return false;
    }
    cv->has_ref = true;
    return true;
}

/* The curve's CSV, JSON (beside it, .json) and SVG plot (.svg), and the contact sheet
 * OUT-contact.png of the snapshots. */
static bool write_convergence(const struct options *o, const char *exr_path,
                              struct convergence *cv, struct mcpt_error *err)
{
    if (!stats_summarize(&cv->curve, o->target_rmse, &cv->summary)) {
        mcpt_error_set(err, "", 0, 0, "out of memory summarising the convergence curve");
        return false;
    }
    char path[4200];
    if (o->curve_path) {
        if (!stats_write_csv(o->curve_path, &cv->curve, err))
            return false;
        path_with_suffix(o->curve_path, ".json", path, sizeof path);
        if (!stats_write_json(path, &cv->curve, &cv->summary, err))
            return false;
        path_with_suffix(o->curve_path, ".svg", path, sizeof path);
        if (!plot_write_svg(path, &cv->curve, &cv->summary, err))
            return false;
    }
    path_with_suffix(exr_path, "-contact.png", path, sizeof path);
    return !o->snapshots || !cv->sheet.n_thumbs ||
           plot_write_contact_sheet(path, &cv->sheet, err);
}

/* ---- mcpt compare A.exr REF.exr [--heatmap ERR.png] [--json] ---- */

static const char COMPARE_USAGE[] =
    "usage: mcpt compare A.exr REF.exr [--heatmap ERR.png] [--json]\n"
    "Prints MSE, RMSE, relMSE, pbrt's MRSE, MAE, PSNR and the bias of A against REF; when REF\n"
    "has variance.R/G/B channels, also its noise floor and the MSE with REF's noise removed.\n"
    "See docs/convergence.md.\n"
    "  --heatmap ERR.png   false-colour map of the per-pixel relative squared error\n"
    "  --json              print one JSON object instead of text\n";

static int cmd_compare(int argc, char **argv)
{
    enum { OPT_HEATMAP = 256, OPT_JSON };
    static const struct option long_opts[] = {
        {"heatmap", required_argument, NULL, OPT_HEATMAP},
        {"json", no_argument, NULL, OPT_JSON},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    const char *heatmap = NULL;
    bool json = false;
    opterr = 0;
    optind = 0;
    int c;
    while ((c = getopt_long(argc, argv, ":h", long_opts, NULL)) != -1) {
        switch (c) {
        case OPT_HEATMAP:
            if (!*optarg)
                return usage_error("expected a file name after --heatmap, got ''");
            heatmap = optarg;
            break;
        case OPT_JSON:
            json = true;
            break;
        case 'h':
            fputs(COMPARE_USAGE, stdout);
            return EXIT_OK;
        case ':':
            return usage_error("expected a value after %s, got nothing", argv[optind - 1]);
        default:
            return usage_error("expected an option of mcpt compare, got '%s'", argv[optind - 1]);
        }
    }
    if (argc - optind != 2)
        return usage_error("expected two images, A.exr and REF.exr, got %d", argc - optind);
    const char *a_path = argv[optind], *ref_path = argv[optind + 1];
    struct image a_img = {0}, ref_img = {0};
    struct stats_image a, ref;
    struct stats_metrics m;
    struct mcpt_error err = {0};
    int status = EXIT_USAGE;
    if (!image_read_exr(a_path, &a_img, &err) || !image_read_exr(ref_path, &ref_img, &err) ||
        !stats_image_from_exr(&a_img, a_path, &a, &err) ||
        !stats_image_from_exr(&ref_img, ref_path, &ref, &err))
        goto fail;
    if (!stats_compare(&a, &ref, &m, &err)) {
        snprintf(err.file, sizeof err.file, "%s", ref_path);
        goto fail;
    }
    if (json)
        stats_write_metrics_json(stdout, &m, a_path, ref_path);
    else
        stats_print_metrics(stdout, &m, a_path, ref_path);
    status = EXIT_RUNTIME;
    if (heatmap && !plot_write_error_heatmap(heatmap, &a, &ref, &err))
        goto fail;
    status = EXIT_OK;
    goto done;
fail:
    print_error(&err);
done:
    image_free(&a_img);
    image_free(&ref_img);
    return status;
}

/* ---- mcpt integrate FUNCTION --sampler S --spp N --seeds K ---- */

static const char INTEGRATE_USAGE[] =
    "usage: mcpt integrate FUNCTION [--sampler S] [--spp N] [--seeds K] [--seed S]\n"
    "Estimates the integral over [0,1]^2 of FUNCTION (step, disk, checkerboard, gaussian,\n"
    "polynomial, or all), whose value is known, with spp = 1, 2, 4, ..., N points of each\n"
    "sampler, K times with seeds S .. S+K-1, and prints the MSE as CSV on stdout\n"
    "(function,sampler,spp,seeds,mse,mse_se,rmse) and the fitted MSE ~ spp^slope on stderr.\n"
    "  --sampler S   independent, stratified, sobol, a comma-separated list, or all (default)\n"
    "  --spp N       largest spp, a power of two (default 4096)\n"
    "  --seeds K     independent estimates per spp (default 64)\n"
    "  --seed S      first seed (default 0)\n";

static int cmd_integrate(int argc, char **argv)
{
    enum { OPT_SAMPLER = 256, OPT_SPP, OPT_SEEDS, OPT_SEED };
    static const struct option long_opts[] = {
        {"sampler", required_argument, NULL, OPT_SAMPLER},
        {"spp", required_argument, NULL, OPT_SPP},
        {"seeds", required_argument, NULL, OPT_SEEDS},
        {"seed", required_argument, NULL, OPT_SEED},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    bool use[SAMPLER_COUNT];
    for (int k = 0; k < SAMPLER_COUNT; k++)
        use[k] = true;
    uint64_t spp_max = 4096, n_seeds = 64, seed = 0;
    opterr = 0;
    optind = 0;
    int c;
    while ((c = getopt_long(argc, argv, ":h", long_opts, NULL)) != -1) {
        switch (c) {
        case OPT_SAMPLER:
            if (strcmp(optarg, "all") != 0) {
                for (int k = 0; k < SAMPLER_COUNT; k++)
                    use[k] = false;
                char list[256];
                snprintf(list, sizeof list, "%s", optarg);
                for (char *save, *name = strtok_r(list, ",", &save); name;
                     name = strtok_r(NULL, ",", &save)) {
                    enum sampler_kind kind;
                    if (!sample_sampler_parse(name, &kind))
                        return usage_error("expected --sampler independent, stratified, sobol "
                                           "or all, got '%s'", name);
                    use[kind] = true;
                }
            }
            break;
        case OPT_SPP:
            if (!parse_u64(optarg, 1, 1u << 24, &spp_max) || !is_pow2((uint32_t)spp_max))
                return usage_error("expected --spp to be a power of two in 1..16777216, got "
                                   "'%s'", optarg);
            break;
        case OPT_SEEDS:
            if (!parse_u64(optarg, 1, 1000000, &n_seeds))
                return usage_error("expected --seeds to be an integer in 1..1000000, got '%s'",
                                   optarg);
            break;
        case OPT_SEED:
            if (!parse_u64(optarg, 0, UINT64_MAX, &seed))
                return usage_error("expected --seed to be an integer in 0..2^64-1, got '%s'",
                                   optarg);
            break;
        case 'h':
            fputs(INTEGRATE_USAGE, stdout);
            return EXIT_OK;
        case ':':
            return usage_error("expected a value after %s, got nothing", argv[optind - 1]);
        default:
            return usage_error("expected an option of mcpt integrate, got '%s'",
                               argv[optind - 1]);
        }
    }
    if (argc - optind != 1)
        return usage_error("expected one FUNCTION (step, disk, checkerboard, gaussian, "
                           "polynomial or all), got %d", argc - optind);
    enum stats_integrand only = STATS_FN_COUNT;
    if (strcmp(argv[optind], "all") != 0 && !stats_integrand_parse(argv[optind], &only))
        return usage_error("expected FUNCTION step, disk, checkerboard, gaussian, polynomial or "
                           "all, got '%s'", argv[optind]);
    struct stats_integrate_row rows[25];
    printf("function,sampler,spp,seeds,mse,mse_se,rmse\n");
    for (int fn = 0; fn < STATS_FN_COUNT; fn++) {
        if (only != STATS_FN_COUNT && fn != (int)only)
            continue;
        for (int k = 0; k < SAMPLER_COUNT; k++) {
            if (!use[k])
                continue;
            size_t n = stats_integrate((enum stats_integrand)fn, (enum sampler_kind)k,
                                       (uint32_t)spp_max, (uint32_t)n_seeds, seed, rows);
            double x[25], y[25];
            for (size_t i = 0; i < n; i++) {
                printf("%s,%s,%u,%llu,%.9g,%.9g,%.9g\n",
                       stats_integrand_name((enum stats_integrand)fn),
                       sample_sampler_name((enum sampler_kind)k), rows[i].spp,
                       (unsigned long long)n_seeds, rows[i].mse, rows[i].mse_se,
                       sqrt(rows[i].mse));
                x[i] = log((double)rows[i].spp);
                y[i] = rows[i].mse > 0.0 ? log(rows[i].mse) : NAN;
            }
            struct stats_fit fit;
            if (stats_fit_line(x, y, n, &fit) && fit.n >= 3)
                fprintf(stderr, "mcpt integrate: %-12s %-11s MSE ~ spp^%+.3f  95%% CI [%+.3f, "
                        "%+.3f]  R^2 %.4f\n", stats_integrand_name((enum stats_integrand)fn),
                        sample_sampler_name((enum sampler_kind)k), fit.slope, fit.ci_lo,
                        fit.ci_hi, fit.r2);
        }
    }
    return fflush(stdout) == 0 ? EXIT_OK : EXIT_RUNTIME;
}

/* ---- mcpt merge PART.exr... -o OUT.exr ---- */

static const char MERGE_USAGE[] =
    "usage: mcpt merge PART.exr... -o OUT.exr [--exposure E] [--quiet]\n"
    "Merges partial renders (mcpt SCENE --sample-range A:B) of one scene and one set of render\n"
    "settings over disjoint sample ranges into OUT.exr and OUT.png: per pixel the sums, sums\n"
    "of squares and counts add, so parts covering 0:N give the N-spp render to within float\n"
    "rounding (docs/distributed.md).  OUT.exr is itself a partial render and can be merged.\n"
    "  -o, --output OUT.exr  the merged image (required)\n"
    "      --exposure E      PNG preview exposure in stops (default 0)\n"
    "      --quiet           print errors only\n";

static int cmd_merge(int argc, char **argv)
{
    enum { OPT_EXPOSURE = 256, OPT_QUIET };
    static const struct option long_opts[] = {
        {"output", required_argument, NULL, 'o'},
        {"exposure", required_argument, NULL, OPT_EXPOSURE},
        {"quiet", no_argument, NULL, OPT_QUIET},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    const char *out = NULL;
    float exposure = 0.0f;
    bool quiet = false;
    opterr = 0;
    optind = 0;
    int c;
    while ((c = getopt_long(argc, argv, ":o:h", long_opts, NULL)) != -1) {
        switch (c) {
        case 'o':
            if (!*optarg)
                return usage_error("expected a file name after -o, got ''");
            out = optarg;
            break;
        case OPT_EXPOSURE:
            if (!parse_float(optarg, -64.0f, 64.0f, &exposure))
                return usage_error("expected --exposure to be a number in -64..64, got '%s'",
                                   optarg);
            break;
        case OPT_QUIET:
            quiet = true;
            break;
        case 'h':
            fputs(MERGE_USAGE, stdout);
            return EXIT_OK;
        case ':':
            return usage_error("expected a value after %s, got nothing", argv[optind - 1]);
        default:
            return usage_error("expected an option of mcpt merge, got '%s'", argv[optind - 1]);
        }
    }
    if (!out)
        return usage_error("expected -o OUT.exr for mcpt merge, got none");
    if (optind >= argc)
        return usage_error("expected partial renders to merge, got none");
    struct film film;
    struct partial_info info;
    struct mcpt_error err = {0};
    if (!partial_merge_files((const char *const *)argv + optind, argc - optind, &film, &info,
                             &err)) {
        print_error(&err);
        return EXIT_USAGE;
    }
    int status = EXIT_OK;
    if (!partial_write_exr(out, &film, &info, &err) ||
        !write_preview(&film, out, exposure, &err)) {
        print_error(&err);
        status = EXIT_RUNTIME;
    } else if (!quiet) {
        char ranges[PARTIAL_RENDER_BYTES];
        partial_format_ranges(&info, ranges, sizeof ranges);
        const char *spp_word = strstr(info.render, " spp=");
        unsigned spp_total = 0;
        bool is_complete = spp_word && sscanf(spp_word, " spp=%u", &spp_total) == 1 &&
                           info.n_ranges == 1 && info.ranges[0].begin == 0 &&
                           info.ranges[0].end == spp_total;
        printf("mcpt merge: %d part%s, %dx%d, sample ranges %s (%llu spp%s); wrote %s\n",
               argc - optind, argc - optind == 1 ? "" : "s", film.width, film.height, ranges,
               (unsigned long long)partial_n_samples(&info),
               is_complete ? ", the whole render" : ", not yet the whole render", out);
    }
    film_free(&film);
    return status;
}

int main(int argc, char **argv)
{
    if (argc > 1 && strcmp(argv[1], "compare") == 0)
        return cmd_compare(argc - 1, argv + 1);
    if (argc > 1 && strcmp(argv[1], "merge") == 0)
        return cmd_merge(argc - 1, argv + 1);
    if (argc > 1 && strcmp(argv[1], "integrate") == 0)
        return cmd_integrate(argc - 1, argv + 1);
    struct options o;
    int status = parse_args(argc, argv, &o);
    if (status >= 0)
        return status;
    struct film film = {0};
    struct checkpoint_info ck; /* --resume: the film and settings of the interrupted run */
    if (o.resume_path && (status = resume_options(argc, argv, &o, &film, &ck)) >= 0)
        return status;

    struct mcpt_error err = {0};
    struct scene scene;
    struct trace_scene *ts = NULL;
    struct convergence cv = {0};
    status = EXIT_USAGE;

    /* load */
    if (!scene_load(o.scene_path, &scene, &err)) {
        print_error(&err);
        film_free(&film);
        return EXIT_USAGE;
    }
    uint64_t scene_hash = 0; /* recorded in a checkpoint, checked on --resume */
    if (!checkpoint_hash_file(o.scene_path, &scene_hash, &err)) {
        print_error(&err);
        goto done;
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
    if (!o.resume_path && !film_init(&film, scene.width, scene.height, &err)) {
        snprintf(err.file, sizeof err.file, "%s", o.scene_path); /* its film statement */
        print_error(&err);
        goto done;
    }
    cv.measuring = o.snapshots || o.curve_path || o.reference_path || o.n_seeds > 1;
    if (cv.measuring && o.resume_path) {
        fprintf(stderr, "mcpt: note: a resumed render is not measured (--snapshots, --curve, "
                "--reference, --seeds ignored)\n");
        cv.measuring = false;
    }
    if (cv.measuring && o.reference_path && !load_reference(o.reference_path, &film, &cv, &err)) {
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
        .sampler = o.has_sampler ? o.sampler : scene.render.sampler,
        .n_threads = o.n_threads,
        .progress = report_progress,
        .direct = o.has_direct ? o.direct : scene.render.direct,
        .light_samples = o.light_samples ? o.light_samples : scene.render.light_samples,
        .split = o.has_split ? o.split : scene.render.split,
        .rr_prob = o.has_rr ? o.rr_prob : scene.render.rr_prob,
        .rr_depth = o.rr_depth ? o.rr_depth : scene.render.rr_depth,
    };
    if ((status = sampling_options(&o, &scene.render, &topt)) >= 0)
        goto done;
    struct partial_info part_info; /* --sample-range: what the EXR records */
    if (o.has_range && (status = sample_range_options(&o, cv.measuring, scene_hash, &film,
                                                      &topt, &part_info)) >= 0)
        goto done;
    status = EXIT_USAGE;
    struct progress prog = {.is_tty = isatty(STDERR_FILENO), .quiet = o.quiet,
                            .t_start = now_seconds()};
    topt.progress_user = &prog;
    if (o.resume_path &&
        !resume_matches(&ck, scene_hash, &topt, &film, &scene, o.resume_path, &err)) {
        print_error(&err);
        goto done;
    }
    topt.cancel = &g_cancel;
    catch_signals();
    struct trace_result res;
    status = EXIT_RUNTIME;
    char integrator[64]; /* the CSV's name of the estimator: path-DIRECT[-SPLIT][-lsN] */
    integrator_name(&topt, integrator, sizeof integrator);
    struct stats_run_info run_info = {
        .scene = o.scene_path, .reference = o.reference_path,
        .sampler = sample_sampler_name(topt.sampler), .integrator = integrator,
        .max_depth = topt.max_depth, .width = film.width, .height = film.height};
    stats_curve_init(&cv.curve, &run_info);
    if (!render_passes(&o, ts, &topt, &film, exr_path, &cv, &prog, &res, &err)) {
        print_error(&err);
        goto done;
    }
    double t_render = now_seconds() - prog.t_start;
    int sig = g_signal ? g_signal : SIGINT; /* what interrupted the render, if res.cancelled */
    if (res.cancelled && prog.is_tty && !o.quiet)
        fputc('\n', stderr); /* end the progress bar's line */
    if (res.cancelled && res.n_samples == 0) {
        fprintf(stderr, "mcpt: interrupted by %s before any new sample; nothing written\n",
                sig == SIGTERM ? "SIGTERM" : "SIGINT");
        status = 128 + sig;
        goto done;
    }

    /* write: an interrupted render saves its checkpoint first, then the partial image */
    char ckpt_path[4200];
    snprintf(ckpt_path, sizeof ckpt_path, o.checkpoint_path ? "%s" : "%s.ckpt",
             o.checkpoint_path ? o.checkpoint_path : exr_path);
    if (res.cancelled && !write_checkpoint(&o, ckpt_path, scene_hash, &topt, &film, &err)) {
        print_error(&err);
        goto done;
    }
    if (o.has_range ? !partial_write_exr(exr_path, &film, &part_info, &err) ||
                          !write_preview(&film, exr_path, o.exposure, &err)
                    : !write_images(&film, exr_path, o.exposure, &err)) {
        print_error(&err);
        goto done;
    }
    if (o.resume_path && !res.cancelled)
        unlink(o.resume_path); /* done: the checkpoint has served */
    char heatmap_path[4200];
    snprintf(heatmap_path, sizeof heatmap_path, "%s", o.heatmap_path ? o.heatmap_path : "");
    if (!o.heatmap_path && topt.adaptive) { /* OUT.exr -> OUT.samples.png */
        char png_path[4096];
        png_path_for(exr_path, png_path, sizeof png_path);
        snprintf(heatmap_path, sizeof heatmap_path, "%.*s.samples.png",
                 (int)strlen(png_path) - 4, png_path);
    }
    if (heatmap_path[0] && !plot_write_count_heatmap(heatmap_path, &film, &err)) {
        print_error(&err);
        goto done;
    }
    if (cv.measuring && !res.cancelled && !write_convergence(&o, exr_path, &cv, &err)) {
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
    if (res.cancelled) {
        fprintf(stderr, "mcpt: interrupted by %s: wrote the partial %s (its 'samples' channel "
                "counts each pixel's samples) and the checkpoint %s; continue with: mcpt %s "
                "--resume %s\n", sig == SIGTERM ? "SIGTERM" : "SIGINT", exr_path, ckpt_path,
                o.scene_path, ckpt_path);
        status = 128 + sig;
        goto done;
    }
    if (!o.quiet) {
        struct bvh_stats bs = trace_bvh_stats(ts);
        printf("mcpt: %dx%d, %u spp, %d threads: render %.2f s, %.3f Msamples/s, %.2f Mrays/s; "
               "BVH %u tris in %.1f ms; wrote %s\n",
               film.width, film.height, topt.spp, o.n_threads, t_render,
               (double)res.n_samples / t_render * 1e-6, (double)res.n_rays / t_render * 1e-6,
               bs.n_tris, t_build * 1e3, exr_path);
        if (cv.measuring)
            stats_print_summary(stdout, &cv.curve, &cv.summary);
        if (topt.adaptive) {
            /* where the samples went: mean, least and most per pixel, share at the maximum */
            size_t n_pixels = (size_t)film.width * (size_t)film.height, n_at_max = 0;
            uint64_t total = 0;
            uint32_t lo = UINT32_MAX, hi = 0;
            for (size_t i = 0; i < n_pixels; i++) {
                uint32_t n = film.pixels[i].n + film.pixels[i].n_dropped;
                total += n;
                lo = n < lo ? n : lo;
                hi = n > hi ? n : hi;
                n_at_max += n >= topt.spp;
            }
            printf("mcpt: adaptive (T %g, floor %g, batch %u, %u..%u spp): mean %.1f spp, "
                   "least %u, most %u, %.1f%% of pixels at the maximum; sample map %s\n",
                   topt.tolerance, topt.adaptive_floor, topt.batch, topt.min_spp, topt.spp,
                   (double)total / (double)n_pixels, lo, hi,
                   100.0 * (double)n_at_max / (double)n_pixels, heatmap_path);
        }
    }
    status = EXIT_OK;
done:
    stats_summary_free(&cv.summary);
    stats_curve_free(&cv.curve);
    plot_sheet_free(&cv.sheet);
    image_free(&cv.ref_img);
    trace_free(ts);
    film_free(&film);
    scene_free(&scene);
    return status;
}
