/* cmd.c - the subcommands beside rendering, each a parse of its options followed by one job:
 *   mcpt compare A.exr REF.exr   error metrics of A against REF (stats.c), a heat map (plot.c)
 *   mcpt integrate FUNCTION      the sampler laboratory: MSE of known integrals (stats.c)
 *   mcpt merge PART.exr... -o    partial renders into one image (partial.c)
 *   mcpt convert IN.exr OUT.png  an EXR to an sRGB PNG with an exposure and a tone curve
 *                                (image.c), as pbrt-v4's "imgtool convert"
 * and the helpers main.c shares with them: usage errors, strict numbers, and cmd_fail, where an
 * error becomes one printed line and the exit status its kind names (2 bad input, 1 runtime).
 * See docs/convergence.md (compare, integrate) and docs/distributed.md (merge). */
#include "cmd.h"

#include <errno.h>
#include <float.h>
#include <getopt.h>
#include <stdlib.h>
#include <string.h>

#include "image.h"
#include "output.h"
#include "partial.h"
#include "stats.h"

/* ---- the helpers shared with main.c ---- */

int cmd_fail(const struct mcpt_error *err)
{
    char line[MCPT_ERROR_LINE_BYTES];
    mcpt_error_format(err, line, sizeof line);
    fprintf(stderr, "%s\n", line);
    return err->kind == MCPT_ERROR_RUNTIME ? CMD_EXIT_RUNTIME : CMD_EXIT_INPUT;
}

bool cmd_usage_error(struct mcpt_error *err, const char *fmt, ...)
{
    static const char HINT[] = " (see mcpt --help)";
    char msg[sizeof err->msg - sizeof HINT + 1]; /* room for the hint, whatever the message */
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    mcpt_error_set(err, "mcpt", 0, 0, "%s%s", msg, HINT);
    return false;
}

bool cmd_parse_u64(const char *s, uint64_t lo, uint64_t hi, uint64_t *out)
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

bool cmd_parse_float(const char *s, float lo, float hi, float *out)
{
    if (!s || !*s)
        return false;
    /* decimal numbers only, as in the scene format: no blanks, hexadecimal, inf or nan */
    if (s[strspn(s, "0123456789+-.eE")] != '\0')
        return false;
    errno = 0;
    char *end;
    float v = strtof(s, &end);
    /* an underflow is a tiny number or 0 (the scene format's 1e-50 is 0 too) */
    if ((errno && errno != ERANGE) || *end || !isfinite(v) || v < lo || v > hi)
        return false;
    *out = v;
    return true;
}

/* The getopt_long answers every subcommand treats alike: a missing value, an unknown option. */
static bool option_error(const char *subcommand, int c, const char *name, struct mcpt_error *err)
{
    if (c == ':')
        return cmd_usage_error(err, "expected a value after %s, got nothing", name);
    return cmd_usage_error(err, "expected an option of mcpt %s, got '%s'", subcommand, name);
}

/* ---- mcpt compare A.exr REF.exr [--heatmap ERR.png] [--json] ---- */

static const char COMPARE_USAGE[] =
    "usage: mcpt compare A.exr REF.exr [--heatmap ERR.png] [--json] [--max-ref-luminance L]\n"
    "Prints MSE, RMSE, relMSE, pbrt's MRSE, MAE, PSNR and the bias of A against REF; when REF\n"
    "has variance.R/G/B channels, also its noise floor and the MSE with REF's noise removed.\n"
    "See docs/convergence.md.\n"
    "  --heatmap ERR.png        false-colour map of the per-pixel relative squared error\n"
    "  --json                   print one JSON object instead of text\n"
    "  --max-ref-luminance L    compare only the pixels whose luminance in REF is <= L\n"
    "                           (e.g. 1 leaves out a lamp seen directly)\n";

/* Reads path and points img at its R, G, B (and variance) channels. */
static bool read_image(const char *path, struct image *exr, struct stats_image *img,
                       struct mcpt_error *err)
{
    return image_read_exr(path, exr, err) && stats_image_from_exr(exr, path, img, err);
}

static int run_compare(int argc, char **argv)
{
    enum { OPT_HEATMAP = 256, OPT_JSON, OPT_MAX_LUM };
    static const struct option long_opts[] = {
        {"heatmap", required_argument, NULL, OPT_HEATMAP},
        {"json", no_argument, NULL, OPT_JSON},
        {"max-ref-luminance", required_argument, NULL, OPT_MAX_LUM},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    const char *heatmap = NULL;
    bool json = false;
    float max_lum = INFINITY;
    struct mcpt_error err = {0};
    opterr = 0;
    optind = 0;
    for (int c; (c = getopt_long(argc, argv, ":h", long_opts, NULL)) != -1;) {
        bool ok = true;
        switch (c) {
        case OPT_HEATMAP:
            heatmap = optarg;
            ok = output_has_extension(optarg, "png") ||
                 cmd_usage_error(&err, "expected --heatmap to name a .png file, got '%s'", optarg);
            break;
        case OPT_JSON:
            json = true;
            break;
        case OPT_MAX_LUM:
            ok = cmd_parse_float(optarg, 0.0f, FLT_MAX, &max_lum) ||
                 cmd_usage_error(&err,
                                 "expected a luminance >= 0 after --max-ref-luminance, "
                                 "got '%s'",
                                 optarg);
            break;
        case 'h':
            fputs(COMPARE_USAGE, stdout);
            return CMD_EXIT_OK;
        default:
            ok = option_error("compare", c, argv[optind - 1], &err);
        }
        if (!ok)
            return cmd_fail(&err);
    }
    if (argc - optind != 2) {
        cmd_usage_error(&err, "expected two images, A.exr and REF.exr, got %d", argc - optind);
        return cmd_fail(&err);
    }
    const char *a_path = argv[optind], *ref_path = argv[optind + 1];
    struct image a_exr = {0}, ref_exr = {0};
    struct stats_image a, ref;
    struct stats_metrics m;
    struct output_file files[3] = {{.role = "the heat map (--heatmap)"},
                                   {.role = "the image A"},
                                   {.role = "the reference"}};
    const char *paths[3] = {heatmap, a_path, ref_path};
    for (int k = 0; k < 3; k++)
        snprintf(files[k].path, sizeof files[k].path, "%s", paths[k] ? paths[k] : "");
    /* the inputs first: bad input touches no output, not even by the creatability probe */
    bool ok = read_image(a_path, &a_exr, &a, &err) && read_image(ref_path, &ref_exr, &ref, &err);
    if (ok && !stats_compare_where(&a, &ref, max_lum, &m, &err)) {
        snprintf(err.file, sizeof err.file, "%s", ref_path);
        ok = false;
    }
    if (ok && m.n_values == 0) { /* each image has usable pixels (read_image), none in common */
        mcpt_error_set(&err, ref_path, 0, 0,
                       "expected pixels to compare, got none (%zu channel values NaN or infinite "
                       "in either image, %zu of %dx%d pixels above --max-ref-luminance)",
                       m.n_skipped, m.n_pixels_masked, m.width, m.height);
        ok = false;
    }
    ok = ok && (!heatmap || output_check(files, 1, files + 1, 2, &err));
    if (ok) {
        if (json)
            stats_write_metrics_json(stdout, &m, a_path, ref_path);
        else
            stats_print_metrics(stdout, &m, a_path, ref_path);
        ok = !heatmap || plot_write_error_heatmap(heatmap, &a, &ref, &err);
    }
    image_free(&a_exr);
    image_free(&ref_exr);
    return ok ? CMD_EXIT_OK : cmd_fail(&err);
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

/* What mcpt integrate was asked for. */
struct integrate_options {
    bool use[SAMPLER_COUNT];   /* the samplers to run */
    enum stats_integrand only; /* one function, or STATS_FN_COUNT for all */
    uint64_t spp_max;          /* a power of two */
    uint64_t n_seeds;
    uint64_t seed; /* the first */
    bool is_help;  /* --help: printed, nothing to run */
};

/* --sampler: "all", or a comma-separated list of sampler names, none of them empty (an
 * empty list once ran nothing and exited 0). */
static bool parse_samplers(const char *arg, bool use[SAMPLER_COUNT], struct mcpt_error *err)
{
    bool is_all = strcmp(arg, "all") == 0;
    for (int k = 0; k < SAMPLER_COUNT; k++)
        use[k] = is_all;
    if (is_all)
        return true;
    for (const char *name = arg;; name++) {
        size_t n_name = strcspn(name, ",");
        char word[32];
        enum sampler_kind kind;
        snprintf(word, sizeof word, "%.*s", (int)(n_name < sizeof word ? n_name : sizeof word - 1),
                 name);
        if (n_name >= sizeof word || !sample_sampler_parse(word, &kind))
            return cmd_usage_error(err,
                                   "expected --sampler independent, stratified, sobol, all or a "
                                   "comma-separated list of the three, got '%.*s' in '%s'",
                                   (int)n_name, name, arg);
        use[kind] = true;
        name += n_name;
        if (*name == '\0')
            return true;
    }
}

/* Parses argv into *o (printing the help for --help); false with *err on bad usage. */
static bool parse_integrate(int argc, char **argv, struct integrate_options *o,
                            struct mcpt_error *err)
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
    *o = (struct integrate_options){.only = STATS_FN_COUNT, .spp_max = 4096, .n_seeds = 64};
    for (int k = 0; k < SAMPLER_COUNT; k++)
        o->use[k] = true;
    opterr = 0;
    optind = 0;
    for (int c; (c = getopt_long(argc, argv, ":h", long_opts, NULL)) != -1;) {
        switch (c) {
        case OPT_SAMPLER:
            if (!parse_samplers(optarg, o->use, err))
                return false;
            break;
        case OPT_SPP:
            if (!cmd_parse_u64(optarg, 1, 1u << 24, &o->spp_max) || (o->spp_max & (o->spp_max - 1)))
                return cmd_usage_error(err,
                                       "expected --spp to be a power of two in 1..16777216, "
                                       "got '%s'",
                                       optarg);
            break;
        case OPT_SEEDS:
            if (!cmd_parse_u64(optarg, 1, 1000000, &o->n_seeds))
                return cmd_usage_error(err,
                                       "expected --seeds to be an integer in 1..1000000, got "
                                       "'%s'",
                                       optarg);
            break;
        case OPT_SEED:
            if (!cmd_parse_u64(optarg, 0, UINT64_MAX, &o->seed))
                return cmd_usage_error(err,
                                       "expected --seed to be an integer in 0..2^64-1, got "
                                       "'%s'",
                                       optarg);
            break;
        case 'h':
            fputs(INTEGRATE_USAGE, stdout);
            o->is_help = true;
            return true;
        default:
            return option_error("integrate", c, argv[optind - 1], err);
        }
    }
    if (argc - optind != 1)
        return cmd_usage_error(err,
                               "expected one FUNCTION (step, disk, checkerboard, gaussian, "
                               "polynomial or all), got %d",
                               argc - optind);
    if (strcmp(argv[optind], "all") != 0 && !stats_integrand_parse(argv[optind], &o->only))
        return cmd_usage_error(err,
                               "expected FUNCTION step, disk, checkerboard, gaussian, "
                               "polynomial or all, got '%s'",
                               argv[optind]);
    return true;
}

/* One function and one sampler: the CSV rows on stdout, the fitted slope on stderr. */
static void integrate_one(enum stats_integrand fn, enum sampler_kind kind,
                          const struct integrate_options *o)
{
    struct stats_integrate_row rows[25];
    size_t n = stats_integrate(fn, kind, (uint32_t)o->spp_max, (uint32_t)o->n_seeds, o->seed, rows);
    double x[25], y[25];
    for (size_t i = 0; i < n; i++) {
        printf("%s,%s,%u,%llu,%.9g,%.9g,%.9g\n", stats_integrand_name(fn),
               sample_sampler_name(kind), rows[i].spp, (unsigned long long)o->n_seeds, rows[i].mse,
               rows[i].mse_se, sqrt(rows[i].mse));
        x[i] = log((double)rows[i].spp);
        y[i] = rows[i].mse > 0.0 ? log(rows[i].mse) : NAN;
    }
    struct stats_fit fit;
    if (stats_fit_line(x, y, n, &fit) && fit.n >= 3)
        fprintf(stderr,
                "mcpt integrate: %-12s %-11s MSE ~ spp^%+.3f  95%% CI [%+.3f, %+.3f]  "
                "R^2 %.4f\n",
                stats_integrand_name(fn), sample_sampler_name(kind), fit.slope, fit.ci_lo,
                fit.ci_hi, fit.r2);
}

static int run_integrate(int argc, char **argv)
{
    struct integrate_options o;
    struct mcpt_error err = {0};
    if (!parse_integrate(argc, argv, &o, &err))
        return cmd_fail(&err);
    if (o.is_help)
        return CMD_EXIT_OK;
    printf("function,sampler,spp,seeds,mse,mse_se,rmse\n");
    for (int fn = 0; fn < STATS_FN_COUNT; fn++)
        for (int k = 0; k < SAMPLER_COUNT; k++)
            if ((o.only == STATS_FN_COUNT || fn == (int)o.only) && o.use[k])
                integrate_one((enum stats_integrand)fn, (enum sampler_kind)k, &o);
    if (fflush(stdout) != 0) {
        mcpt_error_runtime(&err, "mcpt", "cannot write to standard output: %s", strerror(errno));
        return cmd_fail(&err);
    }
    return CMD_EXIT_OK;
}

/* ---- mcpt merge PART.exr... -o OUT.exr ---- */

static const char MERGE_USAGE[] =
    "usage: mcpt merge PART.exr... -o OUT.exr [--partial] [--no-preview] [--exposure E]\n"
    "                  [--tonemap T] [--quiet]\n"
    "Merges partial renders (mcpt SCENE --sample-range A:B) of one scene and one set of render\n"
    "settings over disjoint sample ranges into OUT.exr and OUT.png: per pixel the sums, sums\n"
    "of squares and counts add, so parts covering 0:N give the N-spp render to within float\n"
    "rounding (docs/distributed.md).  When the parts make the whole render, OUT.exr is a plain\n"
    "image (R, G, B, variance.R/G/B, samples); otherwise it is itself a partial render, to be\n"
    "merged with the missing ranges later.\n"
    "  -o, --output OUT      the merged image: OUT.exr (and its preview OUT.png), or OUT.png\n"
    "                        alone (required)\n"
    "      --partial         keep the partial-render channels (sums as hi/lo float pairs) even\n"
    "                        when the parts make the whole render, to merge again later\n"
    "      --no-preview      write no OUT.png beside OUT.exr\n"
    "      --exposure E      PNG exposure in stops (default 0)\n"
    "      --tonemap T       PNG tone curve: clamp (default), reinhard or aces\n"
    "      --quiet           print errors only\n";

/* The options the PNG-writing subcommands share: --exposure E and --tonemap T. */
static bool parse_look(int c, const char *arg, struct image_look *look, struct mcpt_error *err)
{
    if (c == 'e')
        return cmd_parse_float(arg, -64.0f, 64.0f, &look->exposure) ||
               cmd_usage_error(err, "expected --exposure to be a number in -64..64, got '%s'", arg);
    return image_tonemap_parse(arg, &look->tonemap) ||
           cmd_usage_error(err, "expected --tonemap to be clamp, reinhard or aces, got '%s'", arg);
}

/* The summary line of a merge: parts, size, ranges, whether they make the whole render, and
 * what was written. */
static void print_merge(int n_parts, const struct film *film, const struct partial_info *info,
                        const struct output_paths *paths, bool is_plain)
{
    char ranges[PARTIAL_RENDER_BYTES];
    partial_format_ranges(info, ranges, sizeof ranges);
    bool is_whole = partial_is_whole(info);
    printf("mcpt merge: %d part%s, %dx%d, sample ranges %s (%llu spp%s); wrote ", n_parts,
           n_parts == 1 ? "" : "s", film->width, film->height, ranges,
           (unsigned long long)partial_n_samples(info),
           is_whole ? ", the whole render" : ", not yet the whole render");
    if (paths->exr[0])
        printf("%s (%s)%s", paths->exr,
               is_plain ? "R, G, B, variance, samples" : "a partial render, mergeable",
               paths->png[0] ? " and " : "");
    printf("%s\n", paths->png);
}

/* The merged image and its preview may overwrite no part and must be creatable. */
static bool check_merge_outputs(const struct output_paths *paths, char **parts, int n_parts,
                                struct mcpt_error *err)
{
    struct output_file *files = malloc(sizeof *files * ((size_t)n_parts + 2));
    if (!files) {
        mcpt_error_runtime(err, NULL, "out of memory checking the output files");
        return false;
    }
    int n_out = 0; /* the EXR and its preview, or the PNG alone */
    if (paths->exr[0]) {
        snprintf(files[n_out].path, sizeof files[0].path, "%s", paths->exr);
        files[n_out++].role = "the merged image (-o)";
    }
    if (paths->png[0]) {
        snprintf(files[n_out].path, sizeof files[0].path, "%s", paths->png);
        files[n_out++].role = paths->exr[0] ? "its PNG preview" : "the merged image (-o)";
    }
    for (int k = 0; k < n_parts; k++) {
        snprintf(files[n_out + k].path, sizeof files[0].path, "%s", parts[k]);
        files[n_out + k].role = "a part";
    }
    bool ok = output_check(files, n_out, files + n_out, n_parts, err);
    free(files);
    return ok;
}

static int run_merge(int argc, char **argv)
{
    enum { OPT_PARTIAL = 256, OPT_NO_PREVIEW, OPT_QUIET };
    static const struct option long_opts[] = {
        {"output", required_argument, NULL, 'o'},
        {"partial", no_argument, NULL, OPT_PARTIAL},
        {"no-preview", no_argument, NULL, OPT_NO_PREVIEW},
        {"exposure", required_argument, NULL, 'e'},
        {"tonemap", required_argument, NULL, 't'},
        {"quiet", no_argument, NULL, OPT_QUIET},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    const char *out = NULL;
    struct image_look look = {0};
    bool quiet = false, keep_partial = false, has_preview = true;
    struct mcpt_error err = {0};
    opterr = 0;
    optind = 0;
    for (int c; (c = getopt_long(argc, argv, ":o:h", long_opts, NULL)) != -1;) {
        bool ok = true;
        switch (c) {
        case 'o':
            out = optarg;
            ok = *optarg || cmd_usage_error(&err, "expected a file name after -o, got ''");
            break;
        case 'e':
        case 't':
            ok = parse_look(c, optarg, &look, &err);
            break;
        case OPT_PARTIAL:
            keep_partial = true;
            break;
        case OPT_NO_PREVIEW:
            has_preview = false;
            break;
        case OPT_QUIET:
            quiet = true;
            break;
        case 'h':
            fputs(MERGE_USAGE, stdout);
            return CMD_EXIT_OK;
        default:
            ok = option_error("merge", c, argv[optind - 1], &err);
        }
        if (!ok)
            return cmd_fail(&err);
    }
    struct output_paths paths;
    bool ok = true;
    if (!out)
        ok = cmd_usage_error(&err, "expected -o OUT.exr for mcpt merge, got none");
    else if (optind >= argc)
        ok = cmd_usage_error(&err, "expected partial renders to merge, got none");
    else if (!output_paths_init(&paths, NULL, out, NULL, NULL, false, has_preview, &err))
        ok = false;
    else if (!paths.exr[0] && (keep_partial || !has_preview))
        ok = cmd_usage_error(&err, "expected -o OUT.exr with %s, got '%s'",
                             keep_partial ? "--partial" : "--no-preview", out);
    struct film film = {0};
    struct partial_info info;
    /* the parts first: bad input touches no output, not even by the creatability probe */
    ok = ok &&
         partial_merge_files((const char *const *)argv + optind, argc - optind, &film, &info,
                             &err) &&
         check_merge_outputs(&paths, argv + optind, argc - optind, &err);
    /* the whole render is an ordinary image, unless asked to stay mergeable */
    bool is_plain = ok && partial_is_whole(&info) && !keep_partial;
    char ranges[PARTIAL_RENDER_BYTES];
    if (ok) {
        partial_format_ranges(&info, ranges, sizeof ranges);
        struct output_meta meta = {.render_s = -1.0, .render = info.render, .ranges = ranges};
        ok = output_write_image(&paths, &film, is_plain ? NULL : &info, &meta, &look, &err);
    }
    if (ok && !quiet)
        print_merge(argc - optind, &film, &info, &paths, is_plain);
    film_free(&film);
    return ok ? CMD_EXIT_OK : cmd_fail(&err);
}

/* ---- mcpt convert IN.exr OUT.png [--exposure E] [--tonemap T] ---- */

static const char CONVERT_USAGE[] =
    "usage: mcpt convert IN.exr OUT.png [--exposure E] [--tonemap T] [--quiet]\n"
    "Writes the R, G, B channels of IN.exr (linear Rec. 709, as mcpt writes them; or one\n"
    "layer's, LAYER.R/G/B, as Blender's multilayer EXRs name them: the one named Combined\n"
    "among several) to OUT.png, 8-bit sRGB: times 2^E, then the tone curve T, then the sRGB\n"
    "encoding.  Changes the look of a render without rendering it again (pbrt-v4: imgtool\n"
    "convert).\n"
    "      --exposure E   exposure in stops (default 0)\n"
    "      --tonemap T    clamp (default: values above 1 clip), reinhard (Reinhard et al.\n"
    "                     2002, eq. 3, on luminance) or aces (Narkowicz 2016's ACES fit)\n"
    "      --quiet        print errors only\n";

/* Parses mcpt convert's argv; false with *err on bad usage, *is_help after --help. */
static bool parse_convert(int argc, char **argv, const char **in, const char **out,
                          struct image_look *look, bool *quiet, bool *is_help,
                          struct mcpt_error *err)
{
    static const struct option long_opts[] = {
        {"exposure", required_argument, NULL, 'e'},
        {"tonemap", required_argument, NULL, 't'},
        {"quiet", no_argument, NULL, 'q'},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    opterr = 0;
    optind = 0;
    for (int c; (c = getopt_long(argc, argv, ":h", long_opts, NULL)) != -1;) {
        if (c == 'h') {
            fputs(CONVERT_USAGE, stdout);
            *is_help = true;
            return true;
        }
        if (c == 'q')
            *quiet = true;
        else if (c == 'e' || c == 't') {
            if (!parse_look(c, optarg, look, err))
                return false;
        } else
            return option_error("convert", c, argv[optind - 1], err);
    }
    if (argc - optind != 2)
        return cmd_usage_error(err, "expected two files, IN.exr and OUT.png, got %d",
                               argc - optind);
    *in = argv[optind];
    *out = argv[optind + 1];
    if (!output_has_extension(*out, "png"))
        return cmd_usage_error(err, "expected OUT to end in .png, got '%s'", *out);
    return true;
}

static int run_convert(int argc, char **argv)
{
    const char *in = NULL, *out = NULL;
    struct image_look look = {0};
    bool quiet = false, is_help = false;
    struct mcpt_error err = {0};
    if (!parse_convert(argc, argv, &in, &out, &look, &quiet, &is_help, &err))
        return cmd_fail(&err);
    if (is_help)
        return CMD_EXIT_OK;
    /* the PNG may not overwrite the image it is made from, and must be creatable */
    struct output_file files[2] = {{.role = "the PNG (OUT)"}, {.role = "the image IN"}};
    snprintf(files[0].path, sizeof files[0].path, "%s", out);
    snprintf(files[1].path, sizeof files[1].path, "%s", in);
    struct image img;
    if (!image_read_exr(in, &img, &err))
        return cmd_fail(&err);
    int rgb_idx[3];
    size_t prefix_len;
    size_t n_pixels = (size_t)img.width * (size_t)img.height;
    float *rgb = NULL;
    bool ok = image_find_rgb(&img, rgb_idx, &prefix_len);
    if (!ok)
        mcpt_error_set(&err, in, 0, 0,
                       "expected " IMAGE_RGB_EXPECTED ", got an image without them");
    else if (!(rgb = malloc(sizeof(float) * 3 * n_pixels))) {
        mcpt_error_runtime(&err, in, "out of memory");
        ok = false;
    }
    for (size_t i = 0; ok && i < n_pixels; i++)
        for (int c = 0; c < 3; c++)
            rgb[3 * i + c] = img.data[rgb_idx[c]][i];
    /* checked once the input is known good: bad input touches no output */
    ok = ok && output_check(files, 1, files + 1, 1, &err) &&
         image_write_png_srgb(out, img.width, img.height, rgb, &look, &err);
    if (ok && !quiet)
        printf("mcpt convert: %dx%d, exposure %g, tonemap %s; wrote %s\n", img.width, img.height,
               (double)look.exposure, image_tonemap_name(look.tonemap), out);
    free(rgb);
    image_free(&img);
    return ok ? CMD_EXIT_OK : cmd_fail(&err);
}

/* ---- dispatch ---- */

bool cmd_is_subcommand(const char *name)
{
    return strcmp(name, "compare") == 0 || strcmp(name, "integrate") == 0 ||
           strcmp(name, "merge") == 0 || strcmp(name, "convert") == 0;
}

int cmd_run(int argc, char **argv)
{
    if (strcmp(argv[0], "compare") == 0)
        return run_compare(argc, argv);
    if (strcmp(argv[0], "integrate") == 0)
        return run_integrate(argc, argv);
    if (strcmp(argv[0], "convert") == 0)
        return run_convert(argc, argv);
    return run_merge(argc, argv);
}
