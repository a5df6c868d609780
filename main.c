/* main.c - the mcpt command line.  main() reads as the six steps of a render: parse the
 * arguments, load the scene, build the BVH and light table, render, write the EXR and its PNG
 * preview, report.  Each step returns false with a struct mcpt_error whose kind names the exit
 * status (cmd_fail): 2 for bad usage or bad input (anything the user can fix), 1 for a runtime
 * or I/O failure; 0 on success, and 128 + the signal when SIGINT or SIGTERM stops the render.
 * The subcommands compare, integrate and merge are in cmd.c; the output files are named and
 * written by output.c; an interrupted render's checkpoint is checkpoint.c's.  This file holds
 * the run's options and state, the render passes (snapshots, curves, previews), the progress
 * line and the signal handler, and is the only one that may exit. */
#include <ctype.h>
#include <errno.h>
#include <float.h>
#include <getopt.h>
#include <stdarg.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/ioctl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "checkpoint.h"
#include "cmd.h"
#include "image.h"
#include "output.h"
#include "partial.h"
#include "plot.h"
#include "scene.h"
#include "stats.h"
#include "trace.h"

#define STDIN_NAME "<stdin>" /* the scene "-" in messages and in the EXR header */

static const char USAGE[] =
    "usage: mcpt SCENE [options]         (SCENE -: read it from standard input)\n"
    "       mcpt compare A.exr REF.exr [--heatmap ERR.png] [--json]   (mcpt compare --help)\n"
    "       mcpt integrate FUNCTION [--sampler S] [--spp N] [--seeds K]  (mcpt integrate --help)\n"
    "       mcpt merge PART.exr... -o OUT.exr   (mcpt merge --help)\n"
    "       mcpt convert IN.exr OUT.png [--exposure E] [--tonemap T]  (mcpt convert --help)\n"
    "Render SCENE (see docs/scene-format.md) to OUT.exr (linear float RGB, with per-pixel\n"
    "variance of the mean and sample count) and OUT.png (sRGB preview).\n"
    "\n"
    "  -o, --output OUT       OUT.exr: the float image and its preview OUT.png; OUT.png: an\n"
    "                         8-bit sRGB image only (default: the scene's name with .exr)\n"
    "      --spp N            samples per pixel (default: the scene's render spp, else 64)\n"
    "      --max-depth D      most bounces per path; 0 = emission only, 1 = direct light,\n"
    "                         inf = until Russian roulette ends it; no path goes beyond 1024\n"
    "                         (default: scene, else inf)\n"
    "      --direct E         direct-light estimator: mis (default), light, bsdf, cosine or\n"
    "                         hemisphere; every one converges to the same image\n"
    "      --light-samples N  shadow rays per path vertex, each to a light picked by power\n"
    "                         (1..1024, default 1)\n"
    "      --split S          full (default), direct (bounces 0-1) or indirect (bounces > 1)\n"
    "      --light-sampling M area (default) or solid-angle: how triangle and quad lights\n"
    "                         are sampled (Arvo 1995; Urena et al. 2013)\n"
    "      --rr P             Russian roulette: throughput (default: continue with probability\n"
    "                         max beta / threshold) or a fixed continuation probability P in\n"
    "                         (0, 1]\n"
    "      --rr-threshold B   throughput below which roulette plays (default 0.25; PBRT's 1)\n"
    "      --rr-depth D       bounces before roulette may end a path (1..1024, default 2)\n"
    "      --threads N        render threads (default: all cores)\n"
    "      --seed S           random seed, 0..2^64-1 (default 0)\n"
    "      --sampler K        independent, stratified or sobol (default: scene, else sobol);\n"
    "                         see docs/sampling.md\n"
    "      --adaptive         adaptive sampling: each pixel gets the samples that bring the\n"
    "                         95% interval of its mean luminance, 1.96 sigma/sqrt(n), to\n"
    "                         T max(mean, floor) (docs/sampling.md)\n"
    "      --adaptive-rule R  pilot (default: sigma from a discarded pilot; unbiased), stop\n"
    "                         (stop when the pixel's own interval is narrow; biased low) or\n"
    "                         budget (--spp is a budget, the rays of that many uniform spp:\n"
    "                         every pixel's discarded pilot sets its count, a power of two,\n"
    "                         where it lowers the MSE most; unbiased)\n"
    "      --tolerance T      adaptive: relative tolerance (default 0.1)\n"
    "      --adaptive-floor F adaptive: luminance below which T applies absolutely\n"
    "                         (default 0.01)\n"
    "      --pilot-spp P      adaptive pilot: samples of the pilot (default 16, >= 2; budget 8)\n"
    "      --batch B          adaptive: samples between tests, or pilot counts rounded up to\n"
    "                         whole batches (default 32)\n"
    "      --min-spp N        adaptive: samples before the first test, or the least a pixel\n"
    "                         gets by the pilot (default 64, >= 2; budget: the largest\n"
    "                         power of two <= spp / 4)\n"
    "      --max-spp N        adaptive: most samples per pixel (default: the spp; budget:\n"
    "                         8 spp)\n";
/* the help is two strings: C11 compilers need only accept 4095 bytes in one */
static const char USAGE_MORE[] =
    "      --heatmap PNG      write a false-colour map of the samples per pixel with a legend\n"
    "                         (adaptive default: OUT.samples.png)\n"
    "      --width W          film width in pixels (default: the scene's film); alone, the\n"
    "                         height keeps the film's aspect ratio\n"
    "      --height H         film height in pixels (likewise)\n"
    "      --scale F          both sides times F, in (0, 64]: the same framing\n"
    "      --exposure E       PNG exposure in stops (default 0)\n"
    "      --tonemap T        PNG tone curve: clamp (default), reinhard or aces\n"
    "      --no-preview       no PNG beside OUT.exr\n"
    "      --quiet            print errors only\n"
    "      --checkpoint CKPT  where an interrupted render saves its state (default OUT.exr.ckpt)\n"
    "      --checkpoint-every S  save the checkpoint every S seconds while rendering too, so\n"
    "                         that kill -9 or a power cut loses at most S s (default 60; 0: only\n"
    "                         on SIGINT/SIGTERM)\n"
    "      --resume CKPT      continue the interrupted render saved in CKPT to its target spp,\n"
    "                         with its options (later options override; render settings must\n"
    "                         match); the result is bit-identical to an uninterrupted run;\n"
    "                         SCENE may be left out (the checkpoint names it)\n"
    "      --restart          discard the checkpoint of an interrupted render of the same\n"
    "                         output (without it, a render refuses to start over one)\n"
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

/* What the command line asks for: every option, parsed and range-checked (parse_args). */
struct options {
    const char *scene_path;
    const char *output; /* NULL: derived from the scene path */
    uint32_t spp;       /* 0: from the scene */
    bool has_max_depth;
    uint32_t max_depth; /* bounces */
    int n_threads;
    uint64_t seed;
    bool has_sampler;
    enum sampler_kind sampler;
    bool adaptive;
    bool has_adaptive_rule;
    enum render_adaptive_rule adaptive_rule;
    uint32_t pilot_spp;   /* 0: from the scene, else the default */
    float tolerance;      /* 0: from the scene, else the default */
    float adaptive_floor; /* < 0: from the scene, else the default */
    uint32_t batch;       /* 0: from the scene, else the default (likewise the next two) */
    uint32_t min_spp;
    uint32_t max_spp;
    const char *heatmap_path; /* NULL: OUT.samples.png when adaptive, else none */
    int width;                /* 0: from the scene */
    int height;               /* 0: from the scene */
    float exposure;
    enum image_tonemap tonemap; /* --tonemap: the PNG's tone curve */
    float scale;                /* --scale F: film size times F; 0: none */
    bool no_preview;            /* --no-preview: no PNG beside the EXR */
    bool quiet;
    const char *checkpoint_path; /* NULL: OUT.exr.ckpt */
    double checkpoint_every;     /* --checkpoint-every S, seconds of wall time; 0: never */
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
    bool has_light_sampling;
    enum render_light_sampling light_sampling;
    bool has_rr;
    float rr_prob;                    /* 0: throughput-based */
    uint32_t light_samples;           /* --light-samples N; 0: from the scene, else 1 */
    uint32_t rr_depth;                /* --rr-depth D; 0: from the scene, else the default */
    float rr_threshold;               /* --rr-threshold B; 0: from the scene, else the default */
    const char *resume_path;          /* --resume CKPT, or NULL */
    bool restart;                     /* --restart: discard an existing checkpoint */
    bool has_range;                   /* --sample-range A:B given */
    struct partial_range range;       /* its sample indices */
    bool is_done;                     /* --help or --version answered: nothing to render */
    uint32_t args_bytes;              /* bytes used in args */
    char args[CHECKPOINT_ARGS_BYTES]; /* every option but --resume as "--name[=value]",
                                         NUL-ended: what a checkpoint stores */
};

/* Progress: a bar redrawn in place on a terminal, else a line at each quarter. */
struct progress {
    bool is_tty;
    bool quiet;
    double t_start;
    int quarters_printed;
    bool is_finished;   /* the 100% line is out: later reports of it print nothing */
    uint64_t base;      /* render passes: samples of the passes before this one */
    uint64_t total_all; /* render passes: samples of all of them; 0: one trace_render call */
};

/* The measuring state of a render (docs/convergence.md): the reference, the curve, its
 * summary and the snapshots' thumbnails. */
struct convergence {
    bool measuring;         /* measure at 1, 2, 4, ... spp (and the final spp) */
    struct image ref_img;   /* --reference as read */
    struct stats_image ref; /* its R, G, B and variance channels */
    bool has_ref;
    struct stats_curve curve; /* one point per (seed, measured spp) */
    struct stats_summary summary;
    struct plot_sheet sheet; /* --snapshots: the contact sheet's thumbnails */
};

/* Everything one render holds, from parse to report; run_free releases it. */
struct run {
    struct options o;
    const char *argv0;            /* the program as invoked, for the commands we suggest */
    struct checkpoint_info saved; /* --resume: the interrupted run's settings and options */
    struct options saved_o;       /* --resume: its stored options alone, parsed */
    enum render_light_sampling scene_light_sampling; /* the scene's, before --light-sampling */
    struct scene scene;
    bool has_scene;          /* scene loaded (run_free frees it) */
    uint64_t scene_hash;     /* FNV-1a 64 of the scene file: a checkpoint records it */
    struct output_paths out; /* the files it writes */
    struct film film;
    struct trace_scene *ts;
    struct trace_options topt; /* the render's settings: options, else the scene's */
    uint32_t *pilot_target;    /* adaptive pilot: each pixel's sample count (topt.pilot_target) */
    struct partial_info part;  /* --sample-range: what the EXR records */
    struct convergence cv;
    struct progress prog;
    struct trace_result res;
    double t_build_s; /* trace_prepare: BVH, camera, light table */
    double t_render_s;
    double t_cpu_s;               /* CPU time of the render, all threads (SIGSTOP stops it) */
    double t_checkpoint;          /* now_seconds() of the last periodic checkpoint, or 0 */
    double checkpoint_write_s;    /* how long it took to write (output_save_interval) */
    double preview_write_s;       /* likewise the last --preview-every preview */
    bool is_checkpoint_failed;    /* a periodic checkpoint could not be written: warned once */
    bool has_periodic_checkpoint; /* one was written: the checkpoint file is this run's */
    bool is_preview_failed;       /* a --preview-every preview could not be written: warned */
    int signal;                   /* SIGINT or SIGTERM, when it stopped the render */
};

/* The parsers' warnings (file:line:col: warning: ...), one line each, unless --quiet. */
static void print_scene_warnings(const struct scene *scene, bool quiet)
{
    if (quiet)
        return;
    uint32_t n_kept = scene->n_warnings < SCENE_MAX_WARNINGS ? scene->n_warnings
                                                             : SCENE_MAX_WARNINGS;
    for (uint32_t i = 0; i < n_kept; i++)
        fprintf(stderr, "%s\n", scene->warnings[i]);
    if (scene->n_warnings > n_kept)
        fprintf(stderr, "mcpt: warning: %u more warnings not shown\n", scene->n_warnings - n_kept);
}

static bool parse(int argc, char **argv, struct run *run, struct mcpt_error *err);
static bool load(struct run *run, struct mcpt_error *err);
static bool build(struct run *run, struct mcpt_error *err);
static bool render(struct run *run, struct mcpt_error *err);
static bool write_outputs(struct run *run, struct mcpt_error *err);
static int report(const struct run *run);
static void run_free(struct run *run);

int main(int argc, char **argv)
{
    if (argc > 1 && cmd_is_subcommand(argv[1]))
        return cmd_run(argc - 1, argv + 1);
    struct run run = {0};
    struct mcpt_error err = {0};
    bool ok = parse(argc, argv, &run, &err);
    if (ok && !run.o.is_done)
        ok = load(&run, &err) && build(&run, &err) && render(&run, &err) &&
             write_outputs(&run, &err);
    int status = !ok ? cmd_fail(&err) : run.o.is_done ? CMD_EXIT_OK : report(&run);
    run_free(&run);
    return status;
}

/* ---- parse ---- */

enum {
    OPT_SPP = 256,
    OPT_MAX_DEPTH,
    OPT_THREADS,
    OPT_SEED,
    OPT_WIDTH,
    OPT_HEIGHT,
    OPT_EXPOSURE,
    OPT_QUIET,
    OPT_VERSION,
    OPT_CHECKPOINT,
    OPT_RESUME,
    OPT_RESTART,
    OPT_CHECKPOINT_EVERY,
    OPT_SAMPLER = 512,
    OPT_ADAPTIVE,
    OPT_TOLERANCE,
    OPT_ADAPTIVE_FLOOR,
    OPT_BATCH,
    OPT_MIN_SPP,
    OPT_MAX_SPP,
    OPT_HEATMAP,
    OPT_ADAPTIVE_RULE,
    OPT_PILOT_SPP,
    OPT_SNAPSHOTS = 768,
    OPT_REFERENCE,
    OPT_CURVE,
    OPT_SEEDS,
    OPT_TARGET_RMSE,
    OPT_PREVIEW_EVERY,
    OPT_DIRECT = 1024,
    OPT_LIGHT_SAMPLES,
    OPT_SPLIT,
    OPT_RR,
    OPT_RR_DEPTH,
    OPT_LIGHT_SAMPLING,
    OPT_RR_THRESHOLD,
    OPT_SAMPLE_RANGE = 1280,
    OPT_TONEMAP = 1536,
    OPT_SCALE,
    OPT_NO_PREVIEW,
};

static const struct option LONG_OPTS[] = {
    {"output", required_argument, NULL, 'o'},
    {"spp", required_argument, NULL, OPT_SPP},
    {"max-depth", required_argument, NULL, OPT_MAX_DEPTH},
    {"direct", required_argument, NULL, OPT_DIRECT},
    {"light-samples", required_argument, NULL, OPT_LIGHT_SAMPLES},
    {"split", required_argument, NULL, OPT_SPLIT},
    {"light-sampling", required_argument, NULL, OPT_LIGHT_SAMPLING},
    {"rr", required_argument, NULL, OPT_RR},
    {"rr-depth", required_argument, NULL, OPT_RR_DEPTH},
    {"rr-threshold", required_argument, NULL, OPT_RR_THRESHOLD},
    {"threads", required_argument, NULL, OPT_THREADS},
    {"seed", required_argument, NULL, OPT_SEED},
    {"sampler", required_argument, NULL, OPT_SAMPLER},
    {"adaptive", no_argument, NULL, OPT_ADAPTIVE},
    {"adaptive-rule", required_argument, NULL, OPT_ADAPTIVE_RULE},
    {"pilot-spp", required_argument, NULL, OPT_PILOT_SPP},
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
    {"restart", no_argument, NULL, OPT_RESTART},
    {"checkpoint-every", required_argument, NULL, OPT_CHECKPOINT_EVERY},
    {"snapshots", required_argument, NULL, OPT_SNAPSHOTS},
    {"reference", required_argument, NULL, OPT_REFERENCE},
    {"curve", required_argument, NULL, OPT_CURVE},
    {"seeds", required_argument, NULL, OPT_SEEDS},
    {"target-rmse", required_argument, NULL, OPT_TARGET_RMSE},
    {"preview-every", required_argument, NULL, OPT_PREVIEW_EVERY},
    {"sample-range", required_argument, NULL, OPT_SAMPLE_RANGE},
    {"tonemap", required_argument, NULL, OPT_TONEMAP},
    {"scale", required_argument, NULL, OPT_SCALE},
    {"no-preview", no_argument, NULL, OPT_NO_PREVIEW},
    {NULL, 0, NULL, 0},
};

/* Appends option c as "--name" or "--name=value" to o->args, the words a checkpoint stores so
 * that --resume repeats them.  False when o->args is full. */
static bool record_option(struct options *o, int c, const char *value)
{
    const char *name = NULL;
    for (int i = 0; LONG_OPTS[i].name; i++)
        if (LONG_OPTS[i].val == c)
            name = LONG_OPTS[i].name;
    if (!name)
        return true; /* ':' or '?': apply_option reports the error */
    size_t room = sizeof o->args - o->args_bytes;
    int n = value ? snprintf(o->args + o->args_bytes, room, "--%s=%s", name, value)
                  : snprintf(o->args + o->args_bytes, room, "--%s", name);
    if (n < 0 || (size_t)n >= room)
        return false;
    o->args_bytes += (uint32_t)n + 1;
    return true;
}

/* Sets the option c (value optarg, written `name` on the command line) in *o.  False with
 * *err (bad usage) when the value is out of range; --help and --version print and set
 * o->is_done. */
static bool apply_option(struct options *o, int c, const char *name, struct mcpt_error *err)
{
    uint64_t v;
    switch (c) {
    case 'o':
        o->output = optarg;
        return *optarg || cmd_usage_error(err, "expected a file name after -o, got ''");
    case OPT_SPP:
        if (!cmd_parse_u64(optarg, 1, UINT32_MAX, &v))
            return cmd_usage_error(err,
                                   "expected --spp to be an integer in 1..4294967295, got "
                                   "'%s'",
                                   optarg);
        o->spp = (uint32_t)v;
        return true;
    case OPT_MAX_DEPTH:
        o->has_max_depth = true;
        if (strcmp(optarg, "inf") == 0)
            o->max_depth = TRACE_DEPTH_INFINITE;
        else if (cmd_parse_u64(optarg, 0, UINT32_MAX, &v)) /* as the scene's; 1024 at most run */
            o->max_depth = (uint32_t)v;
        else
            return cmd_usage_error(err,
                                   "expected --max-depth to be an integer in 0..4294967295 or "
                                   "'inf', got '%s'",
                                   optarg);
        return true;
    case OPT_DIRECT:
        o->has_direct = true;
        return scene_direct_parse(optarg, &o->direct) ||
               cmd_usage_error(err,
                               "expected --direct to be mis, light, bsdf, cosine or "
                               "hemisphere, got '%s'",
                               optarg);
    case OPT_SPLIT:
        o->has_split = true;
        return scene_split_parse(optarg, &o->split) ||
               cmd_usage_error(err, "expected --split to be full, direct or indirect, got '%s'",
                               optarg);
    case OPT_RR_THRESHOLD:
        return (cmd_parse_float(optarg, 0.0f, FLT_MAX, &o->rr_threshold) &&
                o->rr_threshold > 0.0f) ||
               cmd_usage_error(err, "expected --rr-threshold to be a number > 0, got '%s'", optarg);
    case OPT_LIGHT_SAMPLING:
        o->has_light_sampling = true;
        return scene_light_sampling_parse(optarg, &o->light_sampling) ||
               cmd_usage_error(err, "expected --light-sampling to be area or solid-angle, got '%s'",
                               optarg);
    case OPT_RR:
        o->has_rr = true;
        o->rr_prob = 0.0f;
        if (strcmp(optarg, "throughput") != 0 &&
            !(cmd_parse_float(optarg, 0.0f, 1.0f, &o->rr_prob) && o->rr_prob > 0.0f))
            return cmd_usage_error(err,
                                   "expected --rr to be 'throughput' or a probability in "
                                   "(0, 1], got '%s'",
                                   optarg);
        return true;
    case OPT_LIGHT_SAMPLES:
    case OPT_RR_DEPTH:
        if (!cmd_parse_u64(optarg, 1, 1024, &v))
            return cmd_usage_error(err, "expected %s to be an integer in 1..1024, got '%s'",
                                   c == OPT_RR_DEPTH ? "--rr-depth" : "--light-samples", optarg);
        *(c == OPT_RR_DEPTH ? &o->rr_depth : &o->light_samples) = (uint32_t)v;
        return true;
    case OPT_THREADS:
        if (!cmd_parse_u64(optarg, 1, 1024, &v))
            return cmd_usage_error(err,
                                   "expected --threads to be an integer in 1..1024, got "
                                   "'%s'",
                                   optarg);
        o->n_threads = (int)v;
        return true;
    case OPT_SEED:
        if (!cmd_parse_u64(optarg, 0, UINT64_MAX, &v))
            return cmd_usage_error(err,
                                   "expected --seed to be an integer in 0..2^64-1, got "
                                   "'%s'",
                                   optarg);
        o->seed = v;
        return true;
    case OPT_SAMPLER:
        o->has_sampler = true;
        return sample_sampler_parse(optarg, &o->sampler) ||
               cmd_usage_error(err,
                               "expected --sampler to be independent, stratified or "
                               "sobol, got '%s'",
                               optarg);
    case OPT_ADAPTIVE:
        o->adaptive = true;
        return true;
    case OPT_ADAPTIVE_RULE:
        o->has_adaptive_rule = true;
        return scene_adaptive_rule_parse(optarg, &o->adaptive_rule) ||
               cmd_usage_error(err,
                               "expected --adaptive-rule to be pilot, stop or budget, got '%s'",
                               optarg);
    case OPT_TOLERANCE:
        return (cmd_parse_float(optarg, 0.0f, SCENE_MAX_TOLERANCE, &o->tolerance) &&
                o->tolerance > 0.0f) ||
               cmd_usage_error(err, "expected --tolerance to be a number in (0, 1e6], got '%s'",
                               optarg);
    case OPT_ADAPTIVE_FLOOR:
        return cmd_parse_float(optarg, 0.0f, SCENE_MAX_ADAPTIVE_FLOOR, &o->adaptive_floor) ||
               cmd_usage_error(err, "expected --adaptive-floor to be a number in [0, 1e30], got "
                                    "'%s'",
                               optarg);
    case OPT_BATCH:
    case OPT_MIN_SPP:
    case OPT_MAX_SPP:
    case OPT_PILOT_SPP: {
        const char *what = c == OPT_BATCH     ? "--batch"
                           : c == OPT_MIN_SPP ? "--min-spp"
                           : c == OPT_MAX_SPP ? "--max-spp"
                                              : "--pilot-spp";
        uint64_t lo = c == OPT_MIN_SPP || c == OPT_PILOT_SPP ? 2 : 1; /* one sample: no spread */
        if (!cmd_parse_u64(optarg, lo, UINT32_MAX, &v))
            return cmd_usage_error(err,
                                   "expected %s to be an integer in %llu..4294967295, got "
                                   "'%s'",
                                   what, (unsigned long long)lo, optarg);
        *(c == OPT_BATCH     ? &o->batch
          : c == OPT_MIN_SPP ? &o->min_spp
          : c == OPT_MAX_SPP ? &o->max_spp
                             : &o->pilot_spp) = (uint32_t)v;
        return true;
    }
    case OPT_HEATMAP:
        o->heatmap_path = optarg;
        return output_has_extension(optarg, "png") ||
               cmd_usage_error(err, "expected --heatmap to name a .png file, got '%s'", optarg);
    case OPT_WIDTH:
    case OPT_HEIGHT:
        if (!cmd_parse_u64(optarg, 1, 65535, &v))
            return cmd_usage_error(err, "expected %s to be an integer in 1..65535, got '%s'",
                                   c == OPT_WIDTH ? "--width" : "--height", optarg);
        *(c == OPT_WIDTH ? &o->width : &o->height) = (int)v;
        return true;
    case OPT_EXPOSURE:
        return cmd_parse_float(optarg, -64.0f, 64.0f, &o->exposure) ||
               cmd_usage_error(err, "expected --exposure to be a number in -64..64, got '%s'",
                               optarg);
    case OPT_QUIET:
        o->quiet = true;
        return true;
    case OPT_RESTART:
        o->restart = true;
        return true;
    case OPT_CHECKPOINT_EVERY: {
        float s;
        if (!cmd_parse_float(optarg, 0.0f, 1e9f, &s))
            return cmd_usage_error(err,
                                   "expected --checkpoint-every to be seconds in 0..1e9 (0: "
                                   "never), got '%s'",
                                   optarg);
        o->checkpoint_every = s;
        return true;
    }
    case OPT_TONEMAP:
        return image_tonemap_parse(optarg, &o->tonemap) ||
               cmd_usage_error(err, "expected --tonemap to be clamp, reinhard or aces, got '%s'",
                               optarg);
    case OPT_SCALE:
        return (cmd_parse_float(optarg, 0.0f, 64.0f, &o->scale) && o->scale > 0.0f) ||
               cmd_usage_error(err, "expected --scale to be a number in (0, 64], got '%s'", optarg);
    case OPT_NO_PREVIEW:
        o->no_preview = true;
        return true;
    case OPT_CHECKPOINT:
    case OPT_RESUME:
        *(c == OPT_RESUME ? &o->resume_path : &o->checkpoint_path) = optarg;
        return *optarg || cmd_usage_error(err, "expected a file name after %s, got ''",
                                          c == OPT_RESUME ? "--resume" : "--checkpoint");
    case OPT_SNAPSHOTS:
        o->snapshots = true;
        return strcmp(optarg, "pow2") == 0 ||
               cmd_usage_error(err, "expected --snapshots pow2, got '%s'", optarg);
    case OPT_REFERENCE:
    case OPT_CURVE:
        *(c == OPT_REFERENCE ? &o->reference_path : &o->curve_path) = optarg;
        return *optarg || cmd_usage_error(err, "expected a file name after %s, got ''",
                                          c == OPT_REFERENCE ? "--reference" : "--curve");
    case OPT_SEEDS:
        if (!cmd_parse_u64(optarg, 1, 1000000, &v))
            return cmd_usage_error(err,
                                   "expected --seeds to be an integer in 1..1000000, got "
                                   "'%s'",
                                   optarg);
        o->n_seeds = (uint32_t)v;
        return true;
    case OPT_TARGET_RMSE:
    case OPT_PREVIEW_EVERY: {
        float f;
        if (!cmd_parse_float(optarg, 0.0f, 1e30f, &f) || !(f > 0.0f))
            return cmd_usage_error(err, "expected %s to be a number > 0, got '%s'",
                                   c == OPT_TARGET_RMSE ? "--target-rmse" : "--preview-every",
                                   optarg);
        *(c == OPT_TARGET_RMSE ? &o->target_rmse : &o->preview_every) = f;
        return true;
    }
    case OPT_SAMPLE_RANGE:
        o->has_range = true;
        return partial_parse_range(optarg, &o->range) ||
               cmd_usage_error(err,
                               "expected --sample-range A:B with integers 0 <= A < B <= "
                               "4294967295, got '%s'",
                               optarg);
    case 'h':
        fputs(USAGE, stdout);
        fputs(USAGE_MORE, stdout);
        o->is_done = true;
        return true;
    case OPT_VERSION:
        printf("mcpt %s\n", MCPT_VERSION);
        o->is_done = true;
        return true;
    case ':':
        return cmd_usage_error(err, "expected a value after %s, got nothing", name);
    default:
        return cmd_usage_error(err, "expected an option from mcpt --help, got '%s'", name);
    }
}

/* Parses argv (options and one scene file, which --resume may leave out) into *o.  False with
 * *err (bad usage) on the first bad word. */
static bool parse_args(int argc, char **argv, struct options *o, struct mcpt_error *err)
{
    memset(o, 0, sizeof *o);
    o->adaptive_floor = -1.0f;
    o->n_seeds = 1;
    o->checkpoint_every = 60.0; /* issue 15: kill -9 loses at most a minute */
    long n_cpus = sysconf(_SC_NPROCESSORS_ONLN);
    o->n_threads = n_cpus > 0 ? (int)n_cpus : 1;
    opterr = 0;
    optind = 0; /* glibc: a fresh scan (parse_args runs twice with --resume) */
    for (int c; (c = getopt_long(argc, argv, ":o:h", LONG_OPTS, NULL)) != -1;) {
        /* --resume and --restart are this run's, not the render's: a checkpoint omits them */
        if (c != OPT_RESUME && c != OPT_RESTART && !record_option(o, c, optarg))
            return cmd_usage_error(err, "expected options of at most %d bytes in all, got more",
                                   CHECKPOINT_ARGS_BYTES);
        if (!apply_option(o, c, argv[optind - 1], err))
            return false;
        if (o->is_done)
            return true;
    }
    if (optind >= argc && !o->resume_path) /* a checkpoint names its scene */
        return cmd_usage_error(err, "expected a scene file, got nothing");
    if (optind + 1 < argc)
        return cmd_usage_error(err, "expected one scene file, got '%s' too", argv[optind + 1]);
    if (optind < argc && argv[optind][0] == '\0')
        return cmd_usage_error(err, "expected a scene file, got an empty name");
    o->scene_path = optind < argc ? argv[optind] : NULL;
    return true;
}

/* --resume: loads the checkpoint's film and settings, then parses its stored options followed
 * by this command line (later words win), so the run goes on as the interrupted one did unless
 * told otherwise; the scene is the checkpoint's unless one is named. */
/* Whether every stored word of the checkpoint at path is an option as record_option writes
 * it: "--name" for an option without a value, "--name=value" for one with, and a name that a
 * render records (not --help, --version, --resume or --restart).  False with *err (bad input,
 * file = path) naming the first other word, which parse_args would otherwise blame on the
 * command line. */
static bool check_stored_options(const char *path, const struct checkpoint_info *ck,
                                 struct mcpt_error *err)
{
    for (uint32_t i = 0; i < ck->args_bytes; i += (uint32_t)strlen(ck->args + i) + 1) {
        const char *word = ck->args + i;
        const char *eq = strchr(word, '=');
        size_t n_name = eq ? (size_t)(eq - word) - 2 : strlen(word) - 2;
        bool ok = false;
        for (int k = 0; LONG_OPTS[k].name && strncmp(word, "--", 2) == 0; k++) {
            const struct option *opt = &LONG_OPTS[k];
            if (strlen(opt->name) == n_name && strncmp(word + 2, opt->name, n_name) == 0)
                ok = (opt->has_arg == required_argument) == (eq != NULL) && opt->val != 'h' &&
                     opt->val != OPT_VERSION && opt->val != OPT_RESUME && opt->val != OPT_RESTART;
        }
        if (!ok) {
            mcpt_error_set(err, path, 0, 0,
                           "expected stored options '--name' or '--name=value' of a render, got "
                           "'%.100s'",
                           word);
            return false;
        }
    }
    return true;
}

static bool resume_options(int argc, char **argv, struct run *run, struct mcpt_error *err)
{
    struct checkpoint_info *ck = &run->saved;
    if (!checkpoint_load(run->o.resume_path, &run->film, ck, err) ||
        !check_stored_options(run->o.resume_path, ck, err))
        return false;
    char **words = malloc(sizeof(char *) * ((size_t)ck->args_bytes + (size_t)argc + 1));
    if (!words) {
        mcpt_error_runtime(err, "mcpt", "out of memory");
        return false;
    }
    int n = 0;
    words[n++] = argv[0];
    for (uint32_t i = 0; i < ck->args_bytes; i += (uint32_t)strlen(ck->args + i) + 1)
        words[n++] = ck->args + i;
    for (int i = 1; i < argc; i++)
        words[n++] = argv[i];
    words[n] = NULL;
    int n_stored = n - argc;                    /* words 1 .. n_stored are the checkpoint's */
    const char *ckpt_path = run->o.resume_path; /* parse_args clears run->o first */
    /* the stored options alone (and the scene, which parse_args wants), for resume_matches to
     * compare the settings they give with this run's */
    char *stored[CHECKPOINT_ARGS_BYTES / 2 + 3];
    int n_saved = 0;
    for (int i = 0; i <= n_stored && n_saved < (int)(sizeof stored / sizeof *stored) - 2; i++)
        stored[n_saved++] = words[i];
    stored[n_saved++] = ck->scene_path;
    stored[n_saved] = NULL;
    struct mcpt_error ignored;
    if (!parse_args(n_saved, stored, &run->saved_o, &ignored))
        memset(&run->saved_o, 0, sizeof run->saved_o); /* reported by the parse below */
    bool ok = parse_args(n, words, &run->o, err);
    if (!ok && optind - 1 <= n_stored) { /* a stored value (--spp=0): the checkpoint's fault */
        char *hint = strstr(err->msg, " (see mcpt --help)");
        if (hint)
            *hint = '\0';
        snprintf(err->file, sizeof err->file, "%s", ckpt_path);
        size_t len = strlen(err->msg);
        snprintf(err->msg + len, sizeof err->msg - len, " (a stored option)");
    }
    free(words); /* run->o points into ck and argv, not into words */
    if (ok && !run->o.scene_path)
        run->o.scene_path = ck->scene_path;
    return ok;
}

/* parse: the command line, after the interrupted run's options when it says --resume. */
static bool parse(int argc, char **argv, struct run *run, struct mcpt_error *err)
{
    run->argv0 = argv[0];
    if (!parse_args(argc, argv, &run->o, err))
        return false;
    return run->o.is_done || !run->o.resume_path || resume_options(argc, argv, run, err);
}

/* ---- load ---- */

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

/* The scene; "-" is standard input, read once as it comes (the loader hashes the bytes it
 * reads), named <stdin> in messages, its meshes found relative to the working directory. */
static bool load_scene(struct run *run, struct mcpt_error *err)
{
    const char *path = run->o.scene_path;
    if (strcmp(path, "-") == 0)
        run->has_scene = scene_load_stream(stdin, STDIN_NAME, &run->scene, err);
    else
        run->has_scene = scene_load(path, &run->scene, err);
    return run->has_scene;
}

/* The film size: --width and --height as given; one of them alone keeps the scene film's
 * aspect ratio (the other side rounded), as renderers do when given one side; then --scale F
 * multiplies both sides (rounded), keeping the framing.  Each side at least 1; bad usage
 * when one passes 65535. */
static bool film_size(const struct options *o, struct scene *sc, struct mcpt_error *err)
{
    double w = sc->width, h = sc->height; /* the scene's film, >= 1 each */
    if (o->width && o->height) {
        w = o->width;
        h = o->height;
    } else if (o->width) {
        h = round(o->width * h / w);
        w = o->width;
    } else if (o->height) {
        w = round(o->height * w / h);
        h = o->height;
    }
    if (o->scale > 0.0f) {
        w = round(w * o->scale);
        h = round(h * o->scale);
    }
    w = w < 1.0 ? 1.0 : w;
    h = h < 1.0 ? 1.0 : h;
    if (w > 65535.0 || h > 65535.0)
        return cmd_usage_error(err, "expected a film of at most 65535x65535 pixels, got %.0fx%.0f",
                               w, h);
    sc->width = (int)w;
    sc->height = (int)h;
    return true;
}

/* load: the scene (with the film size the command line asks for) and its hash, the names of
 * the outputs, the film (a resumed run has the checkpoint's), and the reference of a measured
 * run. */
static bool load(struct run *run, struct mcpt_error *err)
{
    const struct options *o = &run->o;
    struct convergence *cv = &run->cv;
    if (!load_scene(run, err))
        return false;
    print_scene_warnings(&run->scene, o->quiet);
    /* a checkpoint names its scene by the bytes of the scene file (as read: a pipe or standard
     * input cannot be read again) and of every mesh and MTL file it loaded, so an edited OBJ is
     * noticed */
    run->scene_hash = run->scene.file_hash;
    for (uint32_t i = 0; i < run->scene.n_loaded; i++)
        if (!file_hash_file(run->scene.loaded_paths[i], &run->scene_hash, err))
            return false;
    bool is_stdin = strcmp(o->scene_path, "-") == 0; /* outputs named stdin.exr, ... */
    if (!film_size(o, &run->scene, err) ||
        !output_paths_init(&run->out, is_stdin ? "stdin" : o->scene_path, o->output,
                           o->checkpoint_path, o->heatmap_path,
                           o->adaptive || run->scene.render.adaptive, !o->no_preview, err))
        return false;
    if (!run->out.exr[0] && (o->has_range || o->no_preview)) /* they are about the EXR */
        return cmd_usage_error(err, "expected -o OUT.exr with %s, got '%s'",
                               o->has_range ? "--sample-range" : "--no-preview", o->output);
    /* options that would do nothing */
    if (o->preview_every > 0.0 && o->no_preview)
        return cmd_usage_error(err, "expected --preview-every without --no-preview (it rewrites "
                                    "the PNG preview), got both");
    if (o->target_rmse > 0.0 &&
        !(o->snapshots || o->curve_path || o->reference_path || o->n_seeds > 1))
        return cmd_usage_error(err, "expected --curve, --reference, --snapshots or --seeds with "
                                    "--target-rmse (it extrapolates their error curve), got none");
    if (!o->resume_path && !film_init(&run->film, run->scene.width, run->scene.height, err)) {
        snprintf(err->file, sizeof err->file, "%s", o->scene_path); /* its film statement */
        return false;
    }
    cv->measuring = o->snapshots || o->curve_path || o->reference_path || o->n_seeds > 1;
    if (cv->measuring && o->resume_path) {
        fprintf(stderr, "mcpt: note: a resumed render is not measured (--snapshots, --curve, "
                        "--reference, --seeds ignored)\n");
        cv->measuring = false;
    }
    return !cv->measuring || !o->reference_path ||
           load_reference(o->reference_path, &run->film, cv, err);
}

/* ---- build ---- */

static double now_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* CPU time of the process, all threads, in seconds: time stopped (SIGSTOP, a suspended job)
 * or waiting does not count, as it does in wall time. */
static double cpu_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* build: the BVH, the camera and the light table (trace_prepare), timed for the report.  The
 * light table samples as --light-sampling says, else as the scene's render statement. */
static bool build(struct run *run, struct mcpt_error *err)
{
    run->scene_light_sampling = run->scene.render.light_sampling;
    if (run->o.has_light_sampling)
        run->scene.render.light_sampling = run->o.light_sampling;
    double t0 = now_seconds();
    run->ts = trace_prepare(&run->scene, run->o.n_threads, err);
    run->t_build_s = now_seconds() - t0;
    return run->ts != NULL;
}

/* ---- render: the settings ---- */

/* The budget rule's fields of topt (sampling_options): topt->spp, the budget, becomes
 * budget_spp, and the maximum max-spp, else TRACE_BUDGET_MAX_FACTOR times the budget; min-spp
 * defaults to the largest power of two at most a quarter of the budget; batch is set for the
 * stratified sampler's sets.  The pilot and the least count must leave room in the budget. */
static bool budget_options(const struct options *o, const struct render_settings *r,
                           struct trace_options *topt, struct mcpt_error *err)
{
    if (o->tolerance || o->adaptive_floor >= 0.0f || o->batch)
        return cmd_usage_error(err,
                               "expected no --tolerance, --adaptive-floor or --batch with "
                               "--adaptive-rule budget (it spends --spp as a budget), got one");
    uint32_t budget = topt->spp;
    topt->budget_spp = budget;
    topt->pilot_spp = o->pilot_spp   ? o->pilot_spp
                      : r->pilot_spp ? r->pilot_spp
                                     : TRACE_BUDGET_PILOT_SPP;
    uint64_t max_default = (uint64_t)TRACE_BUDGET_MAX_FACTOR * budget;
    topt->spp = o->max_spp   ? o->max_spp
                : r->max_spp ? r->max_spp
                             : (uint32_t)(max_default < UINT32_MAX ? max_default : UINT32_MAX);
    uint32_t min_default = 1;
    while (min_default <= budget / 8)
        min_default *= 2;
    topt->min_spp = o->min_spp ? o->min_spp : r->min_spp ? r->min_spp : min_default;
    topt->max_spp = topt->spp;
    /* the stratified sampler's sets (trace_render): the largest power of two <= min-spp, so
     * that the counts, powers of two from min-spp on, hold whole sets */
    topt->batch = 1;
    while (topt->batch <= topt->min_spp / 2)
        topt->batch *= 2;
    const char *problem = NULL;
    char text[200];
    if (topt->spp < budget || topt->min_spp > budget) {
        snprintf(text, sizeof text, "min-spp (%u) <= spp (%u, the budget) <= max-spp (%u)",
                 topt->min_spp, budget, topt->spp);
        problem = text;
    } else if ((uint64_t)topt->pilot_spp + topt->min_spp > budget) {
        snprintf(text, sizeof text, "spp (%u, the budget) >= the pilot (%u) plus min-spp (%u)",
                 budget, topt->pilot_spp, topt->min_spp);
        problem = text;
    }
    if (!problem)
        return true;
    /* settings from the scene alone: its adaptive-rule=budget is where the error is */
    if (!o->has_adaptive_rule && !o->spp && !o->min_spp && !o->max_spp && !o->pilot_spp) {
        mcpt_error_set(err, o->scene_path, r->adaptive_rule_line, r->adaptive_rule_col,
                       "expected %s with 'adaptive-rule' budget", problem);
        return false;
    }
    return cmd_usage_error(err, "expected %s with --adaptive-rule budget", problem);
}

/* Fills topt's adaptive-sampling fields from the command line, else the scene's render
 * statement, else the defaults; with adaptive sampling topt->spp becomes the maximum. */
static bool sampling_options(const struct options *o, const struct render_settings *r,
                             struct trace_options *topt, struct mcpt_error *err)
{
    topt->adaptive = o->adaptive || r->adaptive;
    if (!topt->adaptive) {
        if (o->tolerance || o->adaptive_floor >= 0.0f || o->batch || o->min_spp || o->max_spp ||
            o->has_adaptive_rule || o->pilot_spp)
            return cmd_usage_error(err, "expected --adaptive (or the scene's render "
                                        "adaptive=true) with --adaptive-rule, --tolerance, "
                                        "--adaptive-floor, --pilot-spp, --batch, --min-spp or "
                                        "--max-spp, got none");
        return true;
    }
    topt->adaptive_rule = o->has_adaptive_rule   ? o->adaptive_rule
                          : r->has_adaptive_rule ? r->adaptive_rule
                                                 : RENDER_ADAPTIVE_PILOT;
    if (topt->adaptive_rule == RENDER_ADAPTIVE_STOP && o->pilot_spp)
        return cmd_usage_error(err, "expected --adaptive-rule pilot or budget with --pilot-spp, "
                                    "got stop");
    if (topt->adaptive_rule == RENDER_ADAPTIVE_BUDGET)
        return budget_options(o, r, topt, err);
    topt->pilot_spp = o->pilot_spp   ? o->pilot_spp
                      : r->pilot_spp ? r->pilot_spp
                                     : TRACE_ADAPTIVE_PILOT_SPP;
    topt->spp = o->max_spp ? o->max_spp : r->max_spp ? r->max_spp : topt->spp;
    topt->tolerance = o->tolerance   ? o->tolerance
                      : r->tolerance ? r->tolerance
                                     : TRACE_ADAPTIVE_TOLERANCE;
    topt->adaptive_floor = o->adaptive_floor >= 0.0f   ? o->adaptive_floor
                           : r->adaptive_floor >= 0.0f ? r->adaptive_floor
                                                       : TRACE_ADAPTIVE_FLOOR;
    topt->batch = o->batch ? o->batch : r->batch ? r->batch : TRACE_ADAPTIVE_BATCH;
    uint32_t min_default = TRACE_ADAPTIVE_MIN_SPP < topt->spp ? TRACE_ADAPTIVE_MIN_SPP : topt->spp;
    topt->min_spp = o->min_spp ? o->min_spp : r->min_spp ? r->min_spp : min_default;
    if (topt->min_spp > topt->spp && !o->min_spp && r->min_spp) { /* the scene's min-spp */
        mcpt_error_set(err, o->scene_path, r->min_spp_line, r->min_spp_col,
                       "expected 'min-spp' <= the run's most samples per pixel (%u: max-spp, "
                       "else spp), got %u",
                       topt->spp, topt->min_spp);
        return false;
    }
    if (topt->min_spp > topt->spp)
        return cmd_usage_error(err,
                               "expected --min-spp <= the most samples per pixel (%u), got "
                               "%u",
                               topt->spp, topt->min_spp);
    topt->max_spp = topt->spp;
    return true;
}

/* --sample-range A:B: renders sample indices A..B-1 of the topt->spp-sample render, i.e.
 * B - A samples a pixel from sample offset A, in the stratified sets of the whole render (so
 * disjoint ranges hold exactly the whole render's samples), and fills *info with the range and
 * every setting the parts of one render must share. */
static bool sample_range_options(const struct options *o, bool measuring, uint64_t scene_hash,
                                 const struct film *film,
                                 enum render_light_sampling scene_light_sampling,
                                 struct trace_options *topt, struct partial_info *info,
                                 struct mcpt_error *err)
{
    if (topt->adaptive)
        return cmd_usage_error(err, "expected no adaptive sampling with --sample-range (where a "
                                    "pixel stops depends on all its samples), got it");
    if (measuring)
        return cmd_usage_error(err, "expected no --snapshots, --curve, --reference or --seeds "
                                    "with --sample-range, got one");
    if (o->range.end > topt->spp)
        return cmd_usage_error(err,
                               "expected --sample-range within the render's %u samples per "
                               "pixel (--spp sets them), got %u:%u",
                               topt->spp, o->range.begin, o->range.end);
    memset(info, 0, sizeof *info);
    info->n_ranges = 1;
    info->ranges[0] = o->range;
    snprintf(info->render, sizeof info->render,
             "scene=%016llx film=%dx%d spp=%u seed=%llu sampler=%s max-depth=%u direct=%s "
             "light-samples=%u split=%s rr=%.9g rr-depth=%u rr-threshold=%.9g "
             "light-sampling=%s",
             (unsigned long long)scene_hash, film->width, film->height, topt->spp,
             (unsigned long long)topt->seed, sample_sampler_name(topt->sampler), topt->max_depth,
             scene_direct_name(topt->direct), topt->light_samples ? topt->light_samples : 1u,
             scene_split_name(topt->split), (double)topt->rr_prob,
             topt->rr_depth ? topt->rr_depth : TRACE_RR_DEPTH_DEFAULT,
             (double)(topt->rr_threshold > 0.0f ? topt->rr_threshold : TRACE_RR_THRESHOLD_DEFAULT),
             scene_light_sampling_name(scene_light_sampling));
    topt->sampler_spp = topt->spp; /* the whole render's stratified sets */
    topt->sample_offset = o->range.begin;
    topt->spp = o->range.end - o->range.begin;
    return true;
}

/* What a checkpoint of this run records: the settings a resumed run must repeat. */
static void checkpoint_info_of(const struct run *run, struct checkpoint_info *info)
{
    memset(info, 0, sizeof *info);
    info->scene_hash = run->scene_hash;
    info->seed = run->topt.seed;
    info->spp = run->topt.spp;
    info->max_depth = run->topt.max_depth;
    info->sampler = (uint32_t)run->topt.sampler;
    info->sample_offset = run->topt.sample_offset;
    snprintf(info->scene_path, sizeof info->scene_path, "%s", run->o.scene_path);
    memcpy(info->args, run->o.args, run->o.args_bytes);
    info->args_bytes = run->o.args_bytes;
}

static bool estimator_settings(const struct options *o, const struct render_settings *r,
                               struct trace_options *t, struct mcpt_error *err);

/* Two different floats as short as they can be told apart: %g, else all 9 digits. */
static void float_pair_text(float a, float b, char *ta, char *tb, size_t bytes)
{
    snprintf(ta, bytes, "%g", (double)a);
    snprintf(tb, bytes, "%g", (double)b);
    if (strcmp(ta, tb) == 0) {
        snprintf(ta, bytes, "%.9g", (double)a);
        snprintf(tb, bytes, "%.9g", (double)b);
    }
}

/* Text of a roulette setting (--rr): "throughput" or the fixed probability. */
static void rr_text(float rr_prob, char *out, size_t out_bytes)
{
    if (rr_prob > 0.0f)
        snprintf(out, out_bytes, "%.9g", (double)rr_prob);
    else
        snprintf(out, out_bytes, "throughput");
}

static const char *on_off(bool on) { return on ? "on" : "off"; }

/* The estimator settings of the resumed run against those its checkpoint's options give with
 * the same scene: a resumed render adds samples of the same estimator, or its image would be
 * a mix of two (--split indirect on a full render's samples, say).  False with *err naming the
 * first that differs. */
static bool resume_estimator_matches(const struct run *run, struct mcpt_error *err)
{
    struct trace_options was;
    struct mcpt_error ignored;
    if (!estimator_settings(&run->saved_o, &run->scene.render, &was, &ignored))
        return true; /* the stored options do not apply to this scene: checked elsewhere */
    const struct trace_options *now = &run->topt;
    const char *opt = NULL;
    char want[64], got[64];
    /* the whole render's samples per pixel: a range's samples are stratified for them */
    uint32_t now_spp = run->o.has_range ? now->sampler_spp : now->spp;
#define DIFFER(name, a, b)                                                                         \
    do {                                                                                           \
        if (!opt && (a) != (b)) {                                                                  \
            opt = name;                                                                            \
            snprintf(want, sizeof want, "%u", (unsigned)(a));                                      \
            snprintf(got, sizeof got, "%u", (unsigned)(b));                                        \
        }                                                                                          \
    } while (0)
#define DIFFER_F(name, a, b)                                                                       \
    do {                                                                                           \
        if (!opt && (a) != (b)) {                                                                  \
            opt = name;                                                                            \
            float_pair_text(a, b, want, got, sizeof want);                                         \
        }                                                                                          \
    } while (0)
#define DIFFER_NAMED(name, a, b, text)                                                             \
    do {                                                                                           \
        if (!opt && (a) != (b)) {                                                                  \
            opt = name;                                                                            \
            snprintf(want, sizeof want, "%s", text(a));                                            \
            snprintf(got, sizeof got, "%s", text(b));                                              \
        }                                                                                          \
    } while (0)
    DIFFER("--spp", was.spp, now_spp);
    enum render_light_sampling ls_was = run->saved_o.has_light_sampling
                                            ? run->saved_o.light_sampling
                                            : run->scene_light_sampling;
    DIFFER_NAMED("--light-sampling", ls_was, run->scene.render.light_sampling,
                 scene_light_sampling_name);
    DIFFER_NAMED("--direct", was.direct, now->direct, scene_direct_name);
    DIFFER_NAMED("--split", was.split, now->split, scene_split_name);
    DIFFER("--light-samples", was.light_samples ? was.light_samples : 1u,
           now->light_samples ? now->light_samples : 1u);
    if (!opt && was.rr_prob != now->rr_prob) {
        opt = "--rr";
        rr_text(was.rr_prob, want, sizeof want);
        rr_text(now->rr_prob, got, sizeof got);
    }
    DIFFER("--rr-depth", was.rr_depth ? was.rr_depth : TRACE_RR_DEPTH_DEFAULT,
           now->rr_depth ? now->rr_depth : TRACE_RR_DEPTH_DEFAULT);
    DIFFER_F("--rr-threshold",
             was.rr_threshold > 0.0f ? was.rr_threshold : TRACE_RR_THRESHOLD_DEFAULT,
             now->rr_threshold > 0.0f ? now->rr_threshold : TRACE_RR_THRESHOLD_DEFAULT);
    DIFFER_NAMED("adaptive sampling", was.adaptive, now->adaptive, on_off);
    if (was.adaptive) {
        DIFFER_NAMED("--adaptive-rule", was.adaptive_rule, now->adaptive_rule,
                     scene_adaptive_rule_name);
        DIFFER("--pilot-spp", was.pilot_spp, now->pilot_spp);
        DIFFER("--spp (the budget)", was.budget_spp, now->budget_spp);
        DIFFER_F("--tolerance", was.tolerance, now->tolerance);
        DIFFER_F("--adaptive-floor", was.adaptive_floor, now->adaptive_floor);
        DIFFER("--batch", was.batch, now->batch);
        DIFFER("--min-spp", was.min_spp, now->min_spp);
    }
#undef DIFFER
#undef DIFFER_F
#undef DIFFER_NAMED
    if (opt)
        mcpt_error_set(err, run->o.resume_path, 0, 0,
                       "expected %s %s as in the checkpoint, got %s (a resumed render adds "
                       "samples of the same estimator)",
                       opt, want, got);
    return !opt;
}

/* The resumed run's --sample-range against the checkpoint's: the same range, or none in both
 * (a range changes which samples the checkpoint's counts stand for). */
static bool resume_range_matches(const struct run *run, struct mcpt_error *err)
{
    const struct options *was = &run->saved_o, *now = &run->o;
    if (was->has_range == now->has_range &&
        (!was->has_range ||
         (was->range.begin == now->range.begin && was->range.end == now->range.end)))
        return true;
    char want[48] = "no --sample-range", got[48] = "none";
    if (was->has_range)
        snprintf(want, sizeof want, "--sample-range %u:%u", was->range.begin, was->range.end);
    if (now->has_range)
        snprintf(got, sizeof got, "--sample-range %u:%u", now->range.begin, now->range.end);
    mcpt_error_set(err, run->o.resume_path, 0, 0,
                   "expected %s as in the checkpoint, got %s (a resumed render adds the "
                   "samples the interrupted one would have)",
                   want, got);
    return false;
}

/* The resumed run must render exactly what the interrupted one would have: the same scene
 * bytes, settings and film. */
static bool resume_matches(const struct run *run, struct mcpt_error *err)
{
    struct checkpoint_info now;
    checkpoint_info_of(run, &now);
    if (!resume_range_matches(run, err) ||
        !checkpoint_matches(run->o.resume_path, &run->saved, &now, err) ||
        !resume_estimator_matches(run, err))
        return false;
    if (run->film.width != run->scene.width || run->film.height != run->scene.height) {
        mcpt_error_set(err, run->o.resume_path, 0, 0,
                       "expected a %dx%d film as in the "
                       "checkpoint, got %dx%d",
                       run->film.width, run->film.height, run->scene.width, run->scene.height);
        return false;
    }
    return true;
}

/* The settings that decide what a render estimates, from the options o and the scene's render
 * statement r: each option given, else the scene's, else the default. */
static bool estimator_settings(const struct options *o, const struct render_settings *r,
                               struct trace_options *t, struct mcpt_error *err)
{
    *t = (struct trace_options){
        .spp = o->spp ? o->spp : r->spp,
        .max_depth = o->has_max_depth ? o->max_depth : r->max_depth,
        .seed = o->seed,
        .sampler = o->has_sampler ? o->sampler : r->sampler,
        .n_threads = o->n_threads,
        .direct = o->has_direct ? o->direct : r->direct,
        .light_samples = o->light_samples ? o->light_samples : r->light_samples,
        .split = o->has_split ? o->split : r->split,
        .rr_prob = o->has_rr ? o->rr_prob : r->rr_prob,
        .rr_depth = o->rr_depth ? o->rr_depth : r->rr_depth,
        .rr_threshold = o->rr_threshold > 0.0f ? o->rr_threshold : r->rr_threshold,
    };
    return sampling_options(o, r, t, err);
}

/* The render's settings (estimator_settings), checked against each other and, with --resume,
 * against the checkpoint. */
static bool render_options(struct run *run, struct mcpt_error *err)
{
    const struct options *o = &run->o;
    if (!estimator_settings(o, &run->scene.render, &run->topt, err))
        return false;
    if (run->topt.adaptive && run->topt.adaptive_rule != RENDER_ADAPTIVE_STOP) {
        /* the pilot's counts, kept between passes (render_seed clears them for each seed) */
        run->pilot_target = calloc((size_t)run->film.width * (size_t)run->film.height,
                                   sizeof *run->pilot_target);
        if (!run->pilot_target) {
            mcpt_error_runtime(err, NULL, "out of memory for the adaptive pilot's counts");
            return false;
        }
        run->topt.pilot_target = run->pilot_target;
    }
    if (o->has_range &&
        !sample_range_options(o, run->cv.measuring, run->scene_hash, &run->film,
                              run->scene.render.light_sampling, &run->topt, &run->part, err))
        return false;
    return !o->resume_path || resume_matches(run, err);
}

/* ---- render: the checks before it ---- */

/* word as a shell reads it back: as it is when it holds only characters no shell treats
 * specially, else in single quotes (a quote inside as '\''). */
static void shell_word(const char *word, char *out, size_t out_bytes)
{
    bool is_plain = *word != '\0';
    for (const char *c = word; *c; c++)
        is_plain = is_plain && (isalnum((unsigned char)*c) || strchr("_./:=+,@%-", *c));
    if (is_plain) {
        snprintf(out, out_bytes, "%s", word);
        return;
    }
    size_t n = 0;
    if (n + 1 < out_bytes)
        out[n++] = '\'';
    for (const char *c = word; *c && n + 5 < out_bytes; c++) {
        if (*c == '\'') {
            memcpy(out + n, "'\\''", 4);
            n += 4;
        } else {
            out[n++] = *c;
        }
    }
    if (n + 1 < out_bytes)
        out[n++] = '\'';
    out[n < out_bytes ? n : out_bytes - 1] = '\0';
}

/* The command that continues the render saved at ckpt: the program as it was invoked
 * (./mcpt, mcpt, a full path), the scene and --resume.  A scene read from standard input must
 * come that way again: from the file it was given (/proc/self/fd/0 names it), else as said. */
static void resume_command(const struct run *run, const char *ckpt, char *out, size_t out_bytes)
{
    char prog[FILE_PATH_BYTES], scene[FILE_PATH_BYTES], path[FILE_PATH_BYTES];
    shell_word(run->argv0, prog, sizeof prog);
    shell_word(run->o.scene_path, scene, sizeof scene);
    shell_word(ckpt, path, sizeof path);
    int n = snprintf(out, out_bytes, "%s %s --resume %s", prog, scene, path);
    if (strcmp(run->o.scene_path, "-") != 0 || n < 0 || (size_t)n >= out_bytes)
        return;
    char target[FILE_PATH_BYTES];
    ssize_t len = readlink("/proc/self/fd/0", target, sizeof target - 1);
    struct stat st;
    if (len > 0 && target[0] == '/' && fstat(STDIN_FILENO, &st) == 0 && S_ISREG(st.st_mode)) {
        target[len] = '\0';
        shell_word(target, scene, sizeof scene);
        snprintf(out + n, out_bytes - (size_t)n, " < %s", scene);
    } else {
        snprintf(out + n, out_bytes - (size_t)n, " (the scene on standard input again)");
    }
}

/* Bytes a thread's stack takes: pthread's default, RLIMIT_STACK (glibc), else 8 MiB. */
static size_t thread_stack_bytes(void)
{
    struct rlimit lim;
    if (getrlimit(RLIMIT_STACK, &lim) == 0 && lim.rlim_cur != RLIM_INFINITY && lim.rlim_cur > 0 &&
        lim.rlim_cur < ((rlim_t)1 << 30))
        return (size_t)lim.rlim_cur;
    return (size_t)8 << 20;
}

/* Before the render, the memory all of it will need beyond what is allocated now (the film,
 * the scene, the BVH): the render threads' stacks, a measured run's curve planes (7 floats a
 * pixel) and second film (--seeds), and the writes' peak (output_peak_bytes), against what the
 * process may still allocate (film_memory_free_bytes: ulimit -v, RLIMIT_DATA).  A render that
 * would run out when writing its image is refused now (bad input: a smaller film, fewer
 * threads or a larger limit fixes it). */
static bool check_memory(const struct run *run, struct mcpt_error *err)
{
    const struct film *film = &run->film;
    double n_pixels = (double)film->width * (double)film->height;
    double threads = (double)run->o.n_threads * (double)thread_stack_bytes();
    double measuring = !run->cv.measuring
                           ? 0.0
                           : n_pixels * (7.0 * sizeof(float) + (run->o.n_seeds > 1 ? 64.0 : 0.0));
    double writes = (double)output_peak_bytes(film->width, film->height, run->o.has_range);
    double need = threads + measuring + writes;
    size_t free_bytes = film_memory_free_bytes();
    if (need <= (double)free_bytes)
        return true;
    mcpt_error_set(err, run->o.scene_path, 0, 0,
                   "expected a render that fits in this process's memory limit (%.0f MiB left "
                   "beside the %.0f MiB film), got a %dx%d film needing %.0f MiB more (writing "
                   "the image %.0f, %d threads %.0f, measuring %.0f)",
                   (double)free_bytes / 1048576.0, n_pixels * 64.0 / 1048576.0, film->width,
                   film->height, need / 1048576.0, writes / 1048576.0, run->o.n_threads,
                   threads / 1048576.0, measuring / 1048576.0);
    return false;
}

/* Before the render, what would make it fail late or do harm: no output may be an input (the
 * scene, the meshes and MTL files it loaded, the reference, the checkpoint resumed from unless
 * it is the one to rewrite) or another output, every output must be creatable (output_check), and a checkpoint left by an
 * interrupted render of this output is not overwritten unless --restart says so (it is then
 * removed here); a file there that is not a checkpoint is refused, never removed. */
static bool check_outputs(struct run *run, struct mcpt_error *err)
{
    const struct options *o = &run->o;
    size_t n_files = OUTPUT_MAX_FILES + 3 + (size_t)run->scene.n_loaded;
    struct output_file *files = malloc(sizeof *files * n_files);
    if (!files) {
        mcpt_error_runtime(err, NULL, "out of memory checking the output files");
        return false;
    }
    bool measuring = run->cv.measuring;
    int n_out = output_list(&run->out, measuring ? o->curve_path : NULL, measuring && o->snapshots,
                            run->topt.spp, files, err);
    struct output_file *in = files + (n_out > 0 ? n_out : 0);
    int n_in = 0;
    struct file_id ckpt_id, resume_id;
    bool is_resumed_here = o->resume_path && file_id_of(run->out.checkpoint, &ckpt_id) &&
                           file_id_of(o->resume_path, &resume_id) &&
                           file_id_same(&ckpt_id, &resume_id);
    bool is_stdin = strcmp(o->scene_path, "-") == 0; /* /dev/stdin: the file it was given */
    const char *in_paths[3] = {is_stdin ? "/dev/stdin" : o->scene_path,
                               measuring ? o->reference_path : NULL,
                               is_resumed_here ? NULL : o->resume_path};
    static const char *in_roles[3] = {"the scene file", "the reference (--reference)",
                                      "the checkpoint of --resume"};
    for (int k = 0; k < 3; k++)
        if (in_paths[k]) {
            snprintf(in[n_in].path, sizeof in[n_in].path, "%s", in_paths[k]);
            in[n_in++].role = in_roles[k];
        }
    for (uint32_t i = 0; i < run->scene.n_loaded; i++) {
        snprintf(in[n_in].path, sizeof in[n_in].path, "%s", run->scene.loaded_paths[i]);
        in[n_in++].role = "a file the scene loads";
    }
    /* a checkpoint in the way is refused before any output is probed */
    struct stat st;
    bool has_checkpoint = !is_resumed_here && stat(run->out.checkpoint, &st) == 0;
    if (n_out > 0 && !output_check_names(files, n_out, in, n_in, err)) {
        free(files);
        return false;
    }
    if (n_out > 0 && has_checkpoint && !checkpoint_is_one(run->out.checkpoint)) {
        free(files); /* not a checkpoint: neither --restart nor a finished render removes it */
        mcpt_error_set(err, run->out.checkpoint, 0, 0,
                       "expected an mcpt checkpoint or a new name for the checkpoint, got a file "
                       "that is not one (it is kept; --checkpoint names another)");
        return false;
    }
    if (n_out > 0 && has_checkpoint && !o->restart) {
        free(files);
        char cmd[3 * FILE_PATH_BYTES + 16];
        resume_command(run, run->out.checkpoint, cmd, sizeof cmd);
        mcpt_error_set(err, run->out.checkpoint, 0, 0,
                       "expected no checkpoint of an interrupted render here, got one: continue "
                       "it with '%s', or discard it with --restart",
                       cmd);
        return false;
    }
    bool ok = n_out > 0 && output_check_creatable(files, n_out, err);
    free(files);
    if (ok && has_checkpoint)
        unlink(run->out.checkpoint); /* --restart: the user discards the interrupted render */
    return ok;
}

/* ---- render: progress, signals, passes ---- */

/* A duration as m:ss, or h:mm:ss from an hour on; "--:--" when unknown. */
static void format_duration(double seconds, char *out, size_t out_bytes)
{
    if (!(seconds >= 0.0) || seconds > 3.6e7) { /* NaN, negative, or past 10000 hours */
        snprintf(out, out_bytes, "--:--");
        return;
    }
    unsigned long s = (unsigned long)(seconds + 0.5);
    if (s < 3600)
        snprintf(out, out_bytes, "%lu:%02lu", s / 60, s % 60);
    else
        snprintf(out, out_bytes, "%lu:%02lu:%02lu", s / 3600, s / 60 % 60, s % 60);
}

/* The terminal's width in columns: TIOCGWINSZ on stderr, else $COLUMNS, else 80. */
static int terminal_columns(void)
{
    struct winsize ws;
    if (ioctl(STDERR_FILENO, TIOCGWINSZ, &ws) == 0 && ws.ws_col > 0)
        return ws.ws_col;
    uint64_t v;
    const char *env = getenv("COLUMNS");
    return env && cmd_parse_u64(env, 1, 10000, &v) ? (int)v : 80;
}

#define PROGRESS_BAR_MAX 30 /* characters of the bar between its brackets, at most */
#define PROGRESS_BAR_MIN 10 /* and at least, or no bar */

/* The progress bar's line for a terminal `columns` wide, padded with spaces to columns - 1
 * characters: the last column is never written, so no terminal wraps it.  Its fields, most
 * important first: percent, ETA, elapsed time, the bar, speed, sample counts; the least
 * important are dropped until the rest fits, then the bar takes the room left. */
static void format_progress(char *out, size_t out_bytes, int columns, double frac, uint64_t done,
                            uint64_t total, double rate, double elapsed, double eta)
{
    enum { F_ETA, F_ELAPSED, F_BAR, F_RATE, F_COUNT, N_FIELDS };
    char eta_s[24], elapsed_s[24], field[N_FIELDS][64];
    format_duration(eta, eta_s, sizeof eta_s);
    format_duration(elapsed, elapsed_s, sizeof elapsed_s);
    snprintf(field[F_ETA], sizeof field[0], "ETA %s", eta_s);
    snprintf(field[F_ELAPSED], sizeof field[0], "elapsed %s", elapsed_s);
    field[F_BAR][0] = '\0';
    snprintf(field[F_RATE], sizeof field[0], "%.2f Msamples/s", rate * 1e-6);
    snprintf(field[F_COUNT], sizeof field[0], "%.3g/%.3g Msamples", (double)done * 1e-6,
             (double)total * 1e-6);
    int room = columns - 1 < (int)out_bytes - 1 ? columns - 1 : (int)out_bytes - 1;
    if (room < 1) {
        out[0] = '\0';
        return;
    }
    char pct[16];
    int len = snprintf(pct, sizeof pct, "%5.1f%%", 100.0 * frac);
    int n_fields = N_FIELDS; /* keep fields 0 .. n_fields-1, the bar as PROGRESS_BAR_MIN */
    for (; n_fields > 0; n_fields--) {
        int need = len;
        for (int k = 0; k < n_fields; k++)
            need += 2 + (k == F_BAR ? PROGRESS_BAR_MIN + 2 : (int)strlen(field[k]));
        if (need <= room)
            break;
    }
    int bar_w = 0;
    if (n_fields > F_BAR) { /* the bar grows into what is left, up to its most */
        int used = len;
        for (int k = 0; k < n_fields; k++)
            used += 2 + (k == F_BAR ? 2 : (int)strlen(field[k]));
        bar_w = room - used < PROGRESS_BAR_MAX ? room - used : PROGRESS_BAR_MAX;
    }
    /* shown: the bar, percent, elapsed time, ETA, speed, sample counts */
    int n = 0;
    if (bar_w > 0) {
        int filled = (int)(frac * bar_w);
        out[n++] = '[';
        for (int i = 0; i < bar_w; i++)
            out[n++] = i < filled ? '#' : '.';
        out[n++] = ']';
        out[n++] = ' ';
    }
    n += snprintf(out + n, out_bytes - (size_t)n, "%.*s", room - n, pct);
    static const int SHOWN[N_FIELDS] = {F_ELAPSED, F_ETA, F_RATE, F_COUNT}; /* reading order */
    for (int i = 0; i < N_FIELDS - 1; i++)
        if (SHOWN[i] < n_fields)
            n += snprintf(out + n, out_bytes - (size_t)n, "  %s", field[SHOWN[i]]);
    while (n < room)
        out[n++] = ' ';
    out[n] = '\0';
}

static void report_progress(void *user, uint64_t done, uint64_t total)
{
    struct progress *p = user;
    if (p->total_all) { /* one of several passes: report the whole */
        done += p->base;
        total = p->total_all > done ? p->total_all : done;
    }
    if (p->quiet || total == 0 || p->is_finished)
        return;
    p->is_finished = done == total;
    double frac = (double)done / (double)total;
    double elapsed = now_seconds() - p->t_start;
    double rate = elapsed > 0.0 ? (double)done / elapsed : 0.0;
    double eta = rate > 0.0 ? (double)(total - done) / rate : NAN;
    if (p->is_tty) {
        char line[512];
        format_progress(line, sizeof line, terminal_columns(), frac, done, total, rate, elapsed,
                        eta);
        fprintf(stderr, "\r%s", line);
        if (done == total)
            fputc('\n', stderr);
    } else {
        int quarter = (int)(frac * 4.0);
        if (quarter > p->quarters_printed) {
            char eta_s[24], elapsed_s[24];
            format_duration(eta, eta_s, sizeof eta_s);
            format_duration(elapsed, elapsed_s, sizeof elapsed_s);
            p->quarters_printed = quarter;
            fprintf(stderr, "progress: %3.0f%%  elapsed %s  ETA %s  %.2f Msamples/s\n",
                    100.0 * frac, elapsed_s, eta_s, rate * 1e-6);
        }
    }
}

/* Set by the first SIGINT or SIGTERM; trace_render's workers stop between samples when it is
 * nonzero.  Globals only because a signal handler can reach nothing else. */
static atomic_int g_cancel;
static volatile sig_atomic_t g_signal; /* the signal that set g_cancel */
_Static_assert(ATOMIC_INT_LOCK_FREE == 2, "the signal handler needs a lock-free atomic_int");

static void on_signal(int sig)
{
    if (atomic_exchange(&g_cancel, 1) != 0) {
        /* the second signal: leave at once, removing the temporaries being written (a
         * checkpoint's is the film's size); finished files were renamed into place whole */
        file_remove_temporaries_now();
        _exit(128 + sig);
    }
    g_signal = sig;
}

static void catch_signals(void)
{
    struct sigaction sa = {.sa_handler = on_signal};
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
}

static bool is_pow2(uint32_t v) { return v && !(v & (v - 1)); }

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

/* What the PNGs show: --exposure, --tonemap. */
static struct image_look look_of(const struct options *o)
{
    return (struct image_look){.exposure = o->exposure, .tonemap = o->tonemap};
}

/* What an EXR's header records of this run (output.h), seconds into the render; the render
 * time is left out where SOURCE_DATE_EPOCH is set, the reproducible-builds convention, so that
 * two runs write the same bytes. */
static struct output_meta meta_of(const struct run *run, double seconds)
{
    const char *path = run->o.scene_path;
    return (struct output_meta){.scene = strcmp(path, "-") == 0 ? STDIN_NAME : path,
                                .sampler = sample_sampler_name(run->topt.sampler),
                                .seed = run->topt.seed,
                                .max_depth = run->topt.max_depth,
                                .render_s = getenv("SOURCE_DATE_EPOCH") ? -1.0 : seconds};
}

/* A point of the convergence curve for film f at spp; for the first seed of a run with
 * --snapshots also a thumbnail for the contact sheet and the snapshot OUT-sppN.exr/.png. */
static bool measure(struct run *run, const struct film *f, uint64_t seed, uint32_t spp,
                    double seconds, bool is_first_seed, struct mcpt_error *err)
{
    struct convergence *cv = &run->cv;
    struct stats_image img;
    if (!stats_curve_add(&cv->curve, f, cv->has_ref ? &cv->ref : NULL, seed, spp, seconds, &img,
                         err))
        return false;
    if (!run->o.snapshots || !is_first_seed)
        return true;
    const struct stats_point *p = &cv->curve.points[cv->curve.n_points - 1];
    struct image_look look = look_of(&run->o);
    struct output_meta meta = meta_of(run, seconds);
    return plot_sheet_add(&cv->sheet, &img, spp, p->psnr_db, p->source, &look, err) &&
           output_write_snapshot(&run->out, f, spp, run->topt.spp, &meta, &look, err);
}

/* The fewest samples any pixel of f has taken (kept or dropped). */
static uint32_t least_count(const struct film *f)
{
    size_t n_pixels = (size_t)f->width * (size_t)f->height;
    uint32_t least = UINT32_MAX;
    for (size_t i = 0; i < n_pixels; i++) {
        uint32_t n = f->pixels[i].n + f->pixels[i].n_dropped;
        least = n < least ? n : least;
    }
    return n_pixels ? least : 0;
}

/* A checkpoint between passes (--checkpoint-every), so that kill -9 loses at most that long:
 * written atomically like the one of an interrupt.  One that cannot be written is a warning,
 * printed once; the render goes on. */
static void save_periodic_checkpoint(struct run *run, const struct film *f)
{
    struct checkpoint_info info;
    struct mcpt_error err = {0};
    checkpoint_info_of(run, &info);
    double t0 = now_seconds();
    bool saved = checkpoint_save(run->out.checkpoint, f, &info, &err);
    run->t_checkpoint = now_seconds();
    run->checkpoint_write_s = run->t_checkpoint - t0;
    if (saved) {
        run->has_periodic_checkpoint = true;
        return;
    }
    if (!run->is_checkpoint_failed)
        fprintf(stderr, "%s: warning: %s (the render goes on; it is tried again every %g s)\n",
                err.file, err.msg, run->o.checkpoint_every);
    run->is_checkpoint_failed = true;
}

/* Renders seed number k of the run (seed topt.seed + k) into f, in passes: each trace_render
 * call continues every pixel from its count, so the final film is bit-identical to one call.
 * Between passes the film is measured at 1, 2, 4, ... spp and, for the first seed, the preview
 * is rewritten every --preview-every seconds (passes sized from the last one's speed). */
static bool render_seed(struct run *run, struct film *f, uint32_t k, struct mcpt_error *err)
{
    const struct options *o = &run->o;
    uint32_t spp_final = run->topt.spp;
    bool is_previewed = o->preview_every > 0.0 && k == 0;
    bool is_checkpointed = o->checkpoint_every > 0.0 && k == 0;
    struct trace_options pass = run->topt;
    pass.seed = run->topt.seed + k;
    if (pass.pilot_target) /* another seed, another pilot */
        memset(pass.pilot_target, 0,
               sizeof *pass.pilot_target * (size_t)f->width * (size_t)f->height);
    if (!pass.adaptive && !pass.sampler_spp)
        pass.sampler_spp = spp_final; /* the strata of the final spp in every pass */
    double seconds = 0.0, seconds_per_spp = 0.0, t_preview = now_seconds();
    run->t_checkpoint = now_seconds();
    /* a resumed film starts where its least advanced pixel is */
    for (uint32_t done_spp = k == 0 ? least_count(f) : 0; done_spp < spp_final;) {
        uint32_t next = run->cv.measuring ? stats_next_pow2(done_spp, spp_final) : spp_final;
        /* the pass ends when the next preview or checkpoint is due */
        double preview_every = output_save_interval(o->preview_every, run->preview_write_s);
        double checkpoint_every = output_save_interval(o->checkpoint_every,
                                                       run->checkpoint_write_s);
        double due_s = INFINITY, now = now_seconds();
        if (is_previewed)
            due_s = fmin(due_s, t_preview + preview_every - now);
        if (is_checkpointed)
            due_s = fmin(due_s, run->t_checkpoint + checkpoint_every - now);
        if (due_s < INFINITY) {
            double step = seconds_per_spp > 0.0 ? due_s / seconds_per_spp : 1.0;
            if (step < (double)(next - done_spp))
                next = done_spp + (step >= 1.0 ? (uint32_t)step : 1u);
        }
        pass.spp = next;
        struct trace_result r;
        double t0 = now_seconds();
        if (!trace_render(run->ts, &pass, f, &r, err))
            return false;
        double dt = now_seconds() - t0;
        seconds += dt;
        if (r.n_samples > 0)
            seconds_per_spp = dt / (double)(next - done_spp);
        run->prog.base += r.n_samples;
        trace_result_add(&run->res, &r);
        if (r.cancelled)
            return true;
        done_spp = next;
        if (run->cv.measuring && (is_pow2(done_spp) || done_spp == spp_final) &&
            !measure(run, f, pass.seed, done_spp, seconds, k == 0, err))
            return false;
        if (is_previewed && done_spp < spp_final && now_seconds() - t_preview >= preview_every) {
            /* a preview that cannot be written (a full disk) must not cost the render */
            struct image_look look = look_of(o);
            struct mcpt_error preview_err = {0};
            double t0_preview = now_seconds();
            if (!output_write_preview(&run->out, f, &look, &preview_err) &&
                !run->is_preview_failed) {
                fprintf(stderr, "%s: warning: %s (the render goes on)\n", preview_err.file,
                        preview_err.msg);
                run->is_preview_failed = true;
            }
            t_preview = now_seconds();
            run->preview_write_s = t_preview - t0_preview;
        }
        if (is_checkpointed && done_spp < spp_final &&
            now_seconds() - run->t_checkpoint >= checkpoint_every)
            save_periodic_checkpoint(run, f);
    }
    return true;
}

/* Renders the film to topt.spp: one trace_render call, or without measurements and previews,
 * render_seed for each seed; with --seeds K the seeds after the first render into a scratch
 * film, so the film keeps the first seed's image. */
static bool render_passes(struct run *run, struct mcpt_error *err)
{
    const struct options *o = &run->o;
    memset(&run->res, 0, sizeof run->res);
    if (!run->cv.measuring && !(o->preview_every > 0.0) && !(o->checkpoint_every > 0.0))
        return trace_render(run->ts, &run->topt, &run->film, &run->res, err);
    uint32_t n_seeds = run->cv.measuring ? o->n_seeds : 1;
    struct progress *prog = &run->prog;
    prog->total_all = (uint64_t)n_seeds * run->topt.spp * (uint64_t)run->film.width *
                      run->film.height;
    struct film scratch = {0};
    bool ok = true;
    for (uint32_t k = 0; ok && k < n_seeds && !run->res.cancelled; k++) {
        struct film *f = &run->film;
        if (k > 0) {
            if (!scratch.pixels && !film_init(&scratch, run->film.width, run->film.height, err))
                ok = false;
            else
                memset(scratch.pixels, 0,
                       sizeof *scratch.pixels * (size_t)scratch.width * (size_t)scratch.height);
            f = &scratch;
        }
        ok = ok && render_seed(run, f, k, err);
    }
    film_free(&scratch);
    if (ok && !run->res.cancelled && prog->base != prog->total_all) {
        prog->total_all = prog->base; /* adaptive: fewer samples than the maximum */
        report_progress(prog, 0, 0);
    }
    return ok;
}

/* render: the settings, then the passes, stopped between samples by SIGINT or SIGTERM. */
static bool render(struct run *run, struct mcpt_error *err)
{
    const struct options *o = &run->o;
    if (!render_options(run, err) || !check_memory(run, err) || !check_outputs(run, err))
        return false;
    run->cv.sheet.seed = run->topt.seed; /* the contact sheet shows the first seed's images */
    run->cv.sheet.n_seeds = o->n_seeds;
    run->prog = (struct progress){.is_tty = isatty(STDERR_FILENO),
                                  .quiet = o->quiet,
                                  .t_start = now_seconds()};
    run->topt.progress = report_progress;
    run->topt.progress_user = &run->prog;
    run->topt.cancel = &g_cancel;
    catch_signals();
    char integrator[64]; /* the CSV's name of the estimator: path-DIRECT[-SPLIT][-lsN] */
    integrator_name(&run->topt, integrator, sizeof integrator);
    struct stats_run_info info = {.scene = o->scene_path,
                                  .reference = o->reference_path,
                                  .sampler = sample_sampler_name(run->topt.sampler),
                                  .integrator = integrator,
                                  .max_depth = run->topt.max_depth,
                                  .width = run->film.width,
                                  .height = run->film.height};
    stats_curve_init(&run->cv.curve, &info);
    double t_cpu0 = cpu_seconds();
    if (!render_passes(run, err))
        return false;
    run->t_render_s = now_seconds() - run->prog.t_start;
    run->t_cpu_s = cpu_seconds() - t_cpu0;
    if (run->res.cancelled) {
        run->signal = g_signal ? g_signal : SIGINT;
        if (run->prog.is_tty && !o->quiet)
            fputc('\n', stderr); /* end the progress bar's line */
    }
    return true;
}

/* ---- write ---- */

/* Appends fmt's text to err's message, as far as it fits. */
static void append_msg(struct mcpt_error *err, const char *fmt, ...)
{
    size_t len = strnlen(err->msg, sizeof err->msg);
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err->msg + len, sizeof err->msg - len, fmt, ap);
    va_end(ap);
}

/* An interrupted render: the checkpoint, then the partial image, each written whatever became
 * of the other (a checkpoint's folder removed meanwhile still leaves the partial image).
 * False with *err (the first failure, saying what was written) when either failed. */
static bool write_interrupted(struct run *run, struct mcpt_error *err)
{
    const struct options *o = &run->o;
    struct checkpoint_info info;
    checkpoint_info_of(run, &info);
    struct mcpt_error image_err = {0};
    bool is_checkpoint_saved = checkpoint_save(run->out.checkpoint, &run->film, &info, err);
    struct image_look look = look_of(o);
    struct output_meta meta = meta_of(run, run->t_render_s);
    bool is_image_written = output_write_image(&run->out, &run->film,
                                               o->has_range ? &run->part : NULL, &meta, &look,
                                               is_checkpoint_saved ? err : &image_err);
    if (is_checkpoint_saved)
        return is_image_written;
    append_msg(err,
               is_image_written ? "; the partial image %s was written, but the render "
                                  "cannot be resumed"
                                : "; nor could the partial image %s be written",
               output_image_path(&run->out));
    return false;
}

/* write: an interrupted render saves its checkpoint first, then the partial image; a finished
 * one its image, the sample-count map and the convergence files, and removes the checkpoint it
 * was resumed from.  An interrupted render with no new sample writes nothing. */
static bool write_outputs(struct run *run, struct mcpt_error *err)
{
    const struct options *o = &run->o;
    bool is_cancelled = run->res.cancelled;
    if (is_cancelled && run->res.n_samples == 0)
        return true;
    if (is_cancelled)
        return write_interrupted(run, err);
    struct image_look look = look_of(o);
    struct output_meta meta = meta_of(run, run->t_render_s);
    if (!output_write_image(&run->out, &run->film, o->has_range ? &run->part : NULL, &meta, &look,
                            err)) {
        if (run->has_periodic_checkpoint)
            append_msg(err, "; the checkpoint %s has the render as of %.0f s before its end",
                       run->out.checkpoint, now_seconds() - run->t_checkpoint);
        return false;
    }
    /* done: the checkpoints have served */
    if (run->has_periodic_checkpoint)
        unlink(run->out.checkpoint);
    if (o->resume_path)
        unlink(o->resume_path);
    if (!output_write_heatmap(&run->out, &run->film, err))
        return false;
    if (!run->cv.measuring || is_cancelled)
        return true;
    if (!stats_summarize(&run->cv.curve, o->target_rmse, &run->cv.summary)) {
        mcpt_error_runtime(err, NULL, "out of memory summarising the convergence curve");
        return false;
    }
    return output_write_convergence(&run->out, o->curve_path, &run->cv.curve, &run->cv.summary,
                                    &run->cv.sheet, err);
}

/* ---- report ---- */

/* Where a render's samples went: mean, least and most per pixel, the share of pixels at the
 * maximum. */
struct spp_spread {
    double mean;
    uint32_t lo;
    uint32_t hi;
    double share_at_max; /* fraction of pixels with spp samples */
};

static struct spp_spread spp_spread_of(const struct film *film, uint32_t spp)
{
    size_t n_pixels = (size_t)film->width * (size_t)film->height, n_at_max = 0;
    uint64_t total = 0;
    struct spp_spread sp = {.lo = UINT32_MAX};
    for (size_t i = 0; i < n_pixels; i++) {
        uint32_t n = film->pixels[i].n + film->pixels[i].n_dropped;
        total += n;
        sp.lo = n < sp.lo ? n : sp.lo;
        sp.hi = n > sp.hi ? n : sp.hi;
        n_at_max += n >= spp;
    }
    sp.mean = (double)total / (double)n_pixels;
    sp.share_at_max = (double)n_at_max / (double)n_pixels;
    return sp;
}

/* An adaptive render's rule and settings, the share of pixels at the maximum and the map. */
static void report_adaptive(const struct run *run)
{
    const struct trace_options *topt = &run->topt;
    struct spp_spread sp = spp_spread_of(&run->film, topt->spp);
    if (topt->adaptive_rule == RENDER_ADAPTIVE_BUDGET)
        printf("mcpt: adaptive, budget rule (the rays of %u uniform spp, a pilot of %u spp "
               "included; %u..%u spp): %.1f spp a pixel in the image, %.1f%% of pixels at the "
               "maximum; "
               "sample map %s\n",
               topt->budget_spp, topt->pilot_spp, topt->min_spp, topt->spp, sp.mean,
               100.0 * sp.share_at_max, run->out.heatmap);
    else if (topt->adaptive_rule == RENDER_ADAPTIVE_PILOT)
        printf("mcpt: adaptive, pilot rule (T %g, floor %g, pilot %u spp, batch %u, %u..%u "
               "spp): %.1f%% of pixels at the maximum; %.1f pilot samples a pixel, not in the "
               "image; sample map %s\n",
               topt->tolerance, topt->adaptive_floor, topt->pilot_spp, topt->batch, topt->min_spp,
               topt->spp, 100.0 * sp.share_at_max,
               (double)run->res.n_pilot / ((double)run->film.width * run->film.height),
               run->out.heatmap);
    else
        printf("mcpt: adaptive, stop rule (T %g, floor %g, batch %u, %u..%u spp): %.1f%% of "
               "pixels at the maximum; sample map %s\n",
               topt->tolerance, topt->adaptive_floor, topt->batch, topt->min_spp, topt->spp,
               100.0 * sp.share_at_max, run->out.heatmap);
}

/* report: the dropped samples on stderr, then the summary on stdout, or on stderr where an
 * interrupted render goes on from.  Returns the exit status: 0, or 128 + the signal. */
static int report(const struct run *run)
{
    const struct options *o = &run->o;
    const struct trace_result *res = &run->res;
    const char *signal_name = run->signal == SIGTERM ? "SIGTERM" : "SIGINT";
    if (res->cancelled && res->n_samples == 0) {
        fprintf(stderr, "mcpt: interrupted by %s before any new sample; nothing written\n",
                signal_name);
        return 128 + run->signal;
    }
    if (res->n_nonfinite)
        fprintf(stderr,
                "mcpt: warning: %llu NaN or infinite samples dropped (first at pixel "
                "%u,%u sample %u)\n",
                (unsigned long long)res->n_nonfinite, res->first_bad_x, res->first_bad_y,
                res->first_bad_sample);
    if (res->cancelled) {
        char cmd[3 * FILE_PATH_BYTES + 16];
        resume_command(run, run->out.checkpoint, cmd, sizeof cmd);
        fprintf(stderr,
                "mcpt: interrupted by %s: wrote the partial %s (its 'samples' channel "
                "counts each pixel's samples) and the checkpoint %s; continue with: %s\n",
                signal_name, output_image_path(&run->out), run->out.checkpoint, cmd);
        return 128 + run->signal;
    }
    if (o->quiet)
        return CMD_EXIT_OK;
    struct bvh_stats bs = trace_bvh_stats(run->ts);
    double t = run->t_render_s;
    const struct output_paths *out = &run->out;
    char spp[96]; /* "256 spp", or an adaptive render's spread */
    if (run->topt.adaptive) {
        struct spp_spread sp = spp_spread_of(&run->film, run->topt.spp);
        snprintf(spp, sizeof spp, "adaptive %.1f spp (least %u, most %u)", sp.mean, sp.lo, sp.hi);
    } else {
        snprintf(spp, sizeof spp, "%u spp", run->topt.spp);
    }
    /* samples/s counts every camera sample traced, the adaptive pilot's too */
    printf("mcpt: %dx%d, %s, %d threads: render %.2f s wall, %.2f s CPU, %.3f Msamples/s, "
           "%.2f Mrays/s; BVH %u tris in %.1f ms; wrote %s%s%s\n",
           run->film.width, run->film.height, spp, o->n_threads, t, run->t_cpu_s,
           (double)(res->n_samples + res->n_pilot) / t * 1e-6, (double)res->n_rays / t * 1e-6,
           bs.n_tris, run->t_build_s * 1e3, out->exr[0] ? out->exr : out->png,
           out->exr[0] && out->png[0] ? " and " : "",
           !out->exr[0] ? " (8-bit sRGB only: -o OUT.exr keeps the float image)" : out->png);
    if (run->cv.measuring)
        stats_print_summary(stdout, &run->cv.curve, &run->cv.summary);
    if (run->topt.adaptive)
        report_adaptive(run);
    return CMD_EXIT_OK;
}

static void run_free(struct run *run)
{
    stats_summary_free(&run->cv.summary);
    stats_curve_free(&run->cv.curve);
    plot_sheet_free(&run->cv.sheet);
    image_free(&run->cv.ref_img);
    trace_free(run->ts);
    free(run->pilot_target);
    film_free(&run->film);
    if (run->has_scene)
        scene_free(&run->scene);
}
