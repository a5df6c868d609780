/* partial.c - partial renders (sample indices A..B-1 of every pixel) and their exact merge.
 * A pixel's estimate depends only on (seed, pixel, sample index) (sample.h), so renders of
 * disjoint sample ranges hold disjoint sets of the full render's samples, and the film of their
 * union is the sum of their films: sum, sum of squares and counts add (Chan, Golub & LeVeque
 * 1979, "Updating formulae and a pairwise algorithm for computing sample variances": merging
 * raw moments is exact, merging means and variances by counts is the same in exact arithmetic).
 * EXR has no 64-bit float channel, so each double x is stored as two floats, hi = (float)x and
 * lo = (float)(x - hi): hi + lo equals x to within 2^-48 |x| (Dekker 1971, "A floating-point
 * technique for extending the available precision", the double-float pair).  Format, error
 * bound and recipes: docs/distributed.md. */
#include "partial.h"

#include <float.h>
#include <stdlib.h>

#include "file.h"
#include "image.h"

/* The doubles of struct film_pixel, in the order of their channels. */
enum {
    PART_SUM = 0,     /* sum[0..2] */
    PART_SUM_SQ = 3,  /* sum_sq[0..2] */
    PART_LUM_SQ = 6,  /* sum_lum_sq */
    PART_N = 7,       /* n */
    PART_DROPPED = 8, /* n_dropped */
    PART_N_VALUES = 9
};

/* hi channels (hi = (float)x); "samples" is also the count channel of every mcpt render */
static const char *const HI_NAMES[PART_N_VALUES] = {"sum.R",        "sum.G",    "sum.B",
                                                    "sum_sq.R",     "sum_sq.G", "sum_sq.B",
                                                    "sum_lum_sq.Y", "samples",  "dropped"};
/* lo channels (lo = (float)(x - hi)) */
static const char *const LO_NAMES[PART_N_VALUES] = {"sum_lo.R",        "sum_lo.G",    "sum_lo.B",
                                                    "sum_sq_lo.R",     "sum_sq_lo.G", "sum_sq_lo.B",
                                                    "sum_lum_sq_lo.Y", "samples_lo",  "dropped_lo"};

/* The channels every mcpt render has besides "samples" (main.c writes the same). */
static const char *const STD_NAMES[6] = {"R", "G", "B", "variance.R", "variance.G", "variance.B"};
#define PART_N_CHANNELS (6 + 2 * PART_N_VALUES) /* 24 */
_Static_assert(PART_N_CHANNELS <= IMAGE_MAX_CHANNELS, "a partial render's channels must fit");

static double pixel_value(const struct film_pixel *p, int k)
{
    switch (k) {
    case PART_LUM_SQ:
        return p->sum_lum_sq;
    case PART_N:
        return (double)p->n;
    case PART_DROPPED:
        return (double)p->n_dropped;
    default:
        return k < PART_SUM_SQ ? p->sum[k - PART_SUM] : p->sum_sq[k - PART_SUM_SQ];
    }
}

static void pixel_set(struct film_pixel *p, int k, double v)
{
    switch (k) {
    case PART_LUM_SQ:
        p->sum_lum_sq = v;
        break;
    case PART_N:
        p->n = (uint32_t)v;
        break;
    case PART_DROPPED:
        p->n_dropped = (uint32_t)v;
        break;
    default:
        if (k < PART_SUM_SQ)
            p->sum[k - PART_SUM] = v;
        else
            p->sum_sq[k - PART_SUM_SQ] = v;
    }
}

/* ---- ranges ---- */

bool partial_parse_range(const char *s, struct partial_range *r)
{
    uint64_t v[2] = {0, 0};
    for (int i = 0; i < 2; i++) {
        if (*s < '0' || *s > '9')
            return false;
        for (; *s >= '0' && *s <= '9'; s++) {
            v[i] = v[i] * 10 + (uint64_t)(*s - '0');
            if (v[i] > UINT32_MAX)
                return false;
        }
        if (*s++ != (i == 0 ? ':' : '\0'))
            return false;
    }
    if (v[0] >= v[1])
        return false;
    r->begin = (uint32_t)v[0];
    r->end = (uint32_t)v[1];
    return true;
}

uint64_t partial_n_samples(const struct partial_info *info)
{
    uint64_t n = 0;
    for (uint32_t i = 0; i < info->n_ranges; i++)
        n += (uint64_t)info->ranges[i].end - info->ranges[i].begin;
    return n;
}

bool partial_is_whole(const struct partial_info *info)
{
    const char *spp_word = strstr(info->render, " spp=");
    unsigned spp_total = 0;
    return spp_word && sscanf(spp_word, " spp=%u", &spp_total) == 1 && info->n_ranges == 1 &&
           info->ranges[0].begin == 0 && info->ranges[0].end == spp_total;
}

void partial_format_ranges(const struct partial_info *info, char *out, size_t out_bytes)
{
    size_t used = 0;
    out[0] = '\0';
    for (uint32_t i = 0; i < info->n_ranges && used < out_bytes; i++) {
        int n = snprintf(out + used, out_bytes - used, "%s%u:%u", i ? "," : "",
                         info->ranges[i].begin, info->ranges[i].end);
        if (n < 0)
            break;
        used += (size_t)n;
    }
}

/* Parses "A:B[,A:B...]": sorted, disjoint and not adjacent, as partial_format_ranges writes. */
static bool parse_ranges(const char *s, struct partial_info *info)
{
    info->n_ranges = 0;
    char word[32];
    while (*s) {
        size_t len = strcspn(s, ",");
        if (len == 0 || len >= sizeof word || info->n_ranges == PARTIAL_MAX_RANGES)
            return false;
        memcpy(word, s, len);
        word[len] = '\0';
        struct partial_range *r = &info->ranges[info->n_ranges];
        if (!partial_parse_range(word, r))
            return false;
        if (info->n_ranges > 0 && r->begin <= info->ranges[info->n_ranges - 1].end)
            return false;
        info->n_ranges++;
        s += len;
        if (*s == ',' && !*++s)
            return false; /* a trailing comma */
    }
    return info->n_ranges > 0;
}

static int compare_ranges(const void *a, const void *b)
{
    const struct partial_range *ra = a, *rb = b;
    return ra->begin < rb->begin ? -1 : ra->begin > rb->begin;
}

/* ---- writing ---- */

bool partial_encode_exr(struct file_atomic *af, const struct film *film,
                        const struct partial_info *info, struct mcpt_error *err)
{
    const char *path = af->path;
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    struct image *img = calloc(1, sizeof *img);
    float *planes = NULL;
    bool ok = false;
    if (!img || n_pixels > SIZE_MAX / sizeof(float) / PART_N_CHANNELS ||
        !(planes = malloc(sizeof(float) * n_pixels * PART_N_CHANNELS))) {
        mcpt_error_runtime(err, path, "out of memory writing the image");
        goto done;
    }
    img->width = film->width;
    img->height = film->height;
    img->n_channels = PART_N_CHANNELS;
    for (int c = 0; c < PART_N_CHANNELS; c++) {
        const char *name = c < 6                   ? STD_NAMES[c]
                           : c < 6 + PART_N_VALUES ? HI_NAMES[c - 6]
                                                   : LO_NAMES[c - 15];
        snprintf(img->names[c], sizeof img->names[c], "%s", name);
        img->data[c] = planes + (size_t)c * n_pixels;
    }
    float **hi = img->data + 6, **lo = img->data + 6 + PART_N_VALUES;
    film_resolve(film, img->data, img->data + 3, NULL);
    for (size_t i = 0; i < n_pixels; i++) {
        for (int k = 0; k < PART_N_VALUES; k++) {
            double x = pixel_value(&film->pixels[i], k);
            if (!(fabs(x) <= FLT_MAX)) {
                mcpt_error_runtime(err, path,
                                   "expected per-pixel sums within float range "
                                   "(3.4e38) to store them, got %g in '%s' at pixel %zu,%zu",
                                   x, HI_NAMES[k], i % (size_t)film->width,
                                   i / (size_t)film->width);
                goto done;
            }
            /* the double-float pair: hi carries 24 bits, lo the next 24 (Dekker 1971) */
            hi[k][i] = (float)x;
            lo[k][i] = (float)(x - (double)hi[k][i]);
        }
    }
    char ranges[PARTIAL_RENDER_BYTES];
    partial_format_ranges(info, ranges, sizeof ranges);
    img->n_attrs = 2;
    snprintf(img->attr_names[0], sizeof img->attr_names[0], "%s", PARTIAL_ATTR_RANGES);
    snprintf(img->attr_values[0], sizeof img->attr_values[0], "%s", ranges);
    snprintf(img->attr_names[1], sizeof img->attr_names[1], "%s", PARTIAL_ATTR_RENDER);
    snprintf(img->attr_values[1], sizeof img->attr_values[1], "%s", info->render);
    ok = image_encode_exr(af, img, err);
done:
    if (!ok)
        file_atomic_abort(af); /* again, after image_encode_exr: harmless */
    free(planes);
    free(img);
    return ok;
}

bool partial_write_exr(const char *path, const struct film *film, const struct partial_info *info,
                       struct mcpt_error *err)
{
    struct file_atomic af;
    return file_atomic_open(&af, path, err) && partial_encode_exr(&af, film, info, err) &&
           file_atomic_rename(&af, err);
}

/* ---- reading ---- */

/* Whether s holds printable ASCII only (no control bytes, no bytes above 0x7e). */
static bool is_printable(const char *s)
{
    for (; *s; s++)
        if ((unsigned char)*s < 0x20 || (unsigned char)*s > 0x7e)
            return false;
    return true;
}

bool partial_read_exr(const char *path, struct film *film, struct partial_info *info,
                      struct mcpt_error *err)
{
    memset(film, 0, sizeof *film);
    memset(info, 0, sizeof *info);
    struct image *img = calloc(1, sizeof *img);
    if (!img) {
        mcpt_error_runtime(err, path, "out of memory reading the image");
        return false;
    }
    if (!image_read_exr(path, img, err)) {
        free(img);
        return false;
    }
    bool ok = false;
    int hi[PART_N_VALUES], lo[PART_N_VALUES];
    for (int k = 0; k < PART_N_VALUES; k++) {
        hi[k] = image_find_channel(img, HI_NAMES[k]);
        lo[k] = image_find_channel(img, LO_NAMES[k]);
        if (hi[k] < 0 || lo[k] < 0) {
            mcpt_error_set(err, path, 0, 0,
                           "expected a partial render (mcpt --sample-range) "
                           "with channel '%s', got an image without it",
                           hi[k] < 0 ? HI_NAMES[k] : LO_NAMES[k]);
            goto done;
        }
    }
    const char *ranges = image_find_attr(img, PARTIAL_ATTR_RANGES);
    const char *render = image_find_attr(img, PARTIAL_ATTR_RENDER);
    if (!ranges || !render) {
        mcpt_error_set(err, path, 0, 0,
                       "expected a partial render (mcpt --sample-range) with "
                       "attribute '%s', got an image without it",
                       !ranges ? PARTIAL_ATTR_RANGES : PARTIAL_ATTR_RENDER);
        goto done;
    }
    const char *unprintable = !is_printable(ranges)   ? PARTIAL_ATTR_RANGES
                              : !is_printable(render) ? PARTIAL_ATTR_RENDER
                                                      : NULL;
    if (unprintable) { /* it would be quoted in messages: no line breaks or escapes there */
        mcpt_error_set(err, path, 0, 0,
                       "expected attribute '%s' of printable ASCII characters, got other bytes",
                       unprintable);
        goto done;
    }
    if (!parse_ranges(ranges, info)) {
        mcpt_error_set(err, path, 0, 0,
                       "expected attribute '%s' to hold at most %d sorted, "
                       "disjoint ranges A:B[,A:B...], got '%.100s'",
                       PARTIAL_ATTR_RANGES, PARTIAL_MAX_RANGES, ranges);
        goto done;
    }
    snprintf(info->render, sizeof info->render, "%s", render);
    if (!film_init(film, img->width, img->height, err)) {
        snprintf(err->file, sizeof err->file, "%s", path);
        goto done;
    }
    uint64_t n_expected = partial_n_samples(info);
    size_t n_pixels = (size_t)img->width * (size_t)img->height;
    for (size_t i = 0; i < n_pixels; i++) {
        struct film_pixel *p = &film->pixels[i];
        size_t x = i % (size_t)img->width, y = i / (size_t)img->width;
        for (int k = 0; k < PART_N_VALUES; k++) {
            float h = img->data[hi[k]][i], l = img->data[lo[k]][i];
            double v = (double)h + (double)l; /* exact: 48 bits fit in a double's 53 */
            if (!isfinite(h) || !isfinite(l) ||
                (k >= PART_N && !(v >= 0.0 && v <= UINT32_MAX && v == floor(v)))) {
                mcpt_error_set(err, path, 0, 0,
                               "expected %s in '%s' and '%s', got %g and %g at "
                               "pixel %zu,%zu",
                               k >= PART_N ? "a count in 0..4294967295" : "a finite sum",
                               HI_NAMES[k], LO_NAMES[k], (double)h, (double)l, x, y);
                goto done;
            }
            pixel_set(p, k, v);
        }
        if ((uint64_t)p->n + p->n_dropped != n_expected) {
            mcpt_error_set(err, path, 0, 0,
                           "expected the %llu samples of ranges %.100s at every "
                           "pixel, got %llu at pixel %zu,%zu (an interrupted render? finish it "
                           "with --resume first)",
                           (unsigned long long)n_expected, ranges,
                           (unsigned long long)p->n + p->n_dropped, x, y);
            goto done;
        }
        const char *problem = film_pixel_problem(p, n_expected); /* values no render writes */
        if (problem) {
            mcpt_error_set(err, path, 0, 0,
                           "expected pixel sums that %u samples can give, got %s at pixel "
                           "%zu,%zu",
                           p->n, problem, x, y);
            goto done;
        }
    }
    ok = true;
done:
    if (!ok)
        film_free(film);
    image_free(img);
    free(img);
    return ok;
}

/* ---- merging ---- */

bool partial_merge(struct film *dst, struct partial_info *dst_info, const struct film *src,
                   const struct partial_info *src_info, const char *src_path,
                   struct mcpt_error *err)
{
    if (src->width != dst->width || src->height != dst->height) {
        mcpt_error_set(err, src_path, 0, 0,
                       "expected a %dx%d image like the parts before it, "
                       "got %dx%d",
                       dst->width, dst->height, src->width, src->height);
        return false;
    }
    if (strcmp(src_info->render, dst_info->render) != 0) {
        mcpt_error_set(err, src_path, 0, 0,
                       "expected the render settings of the parts before "
                       "it ('%.100s'), got '%.100s'",
                       dst_info->render, src_info->render);
        return false;
    }
    struct partial_range all[2 * PARTIAL_MAX_RANGES];
    uint32_t n_all = 0;
    for (uint32_t i = 0; i < dst_info->n_ranges; i++)
        all[n_all++] = dst_info->ranges[i];
    for (uint32_t j = 0; j < src_info->n_ranges; j++) {
        const struct partial_range *b = &src_info->ranges[j];
        for (uint32_t i = 0; i < dst_info->n_ranges; i++) {
            const struct partial_range *a = &dst_info->ranges[i];
            if (a->begin < b->end && b->begin < a->end) {
                char merged[PARTIAL_RENDER_BYTES];
                partial_format_ranges(dst_info, merged, sizeof merged);
                mcpt_error_set(err, src_path, 0, 0,
                               "expected sample ranges disjoint from those "
                               "of the parts before it (%.100s), got %u:%u",
                               merged, b->begin, b->end);
                return false;
            }
        }
        all[n_all++] = *b;
    }
    /* the union: sorted, adjacent runs joined */
    qsort(all, n_all, sizeof all[0], compare_ranges);
    uint32_t n_union = 0;
    for (uint32_t i = 0; i < n_all; i++) {
        if (n_union > 0 && all[n_union - 1].end == all[i].begin)
            all[n_union - 1].end = all[i].end;
        else
            all[n_union++] = all[i];
    }
    if (n_union > PARTIAL_MAX_RANGES) {
        mcpt_error_set(err, src_path, 0, 0,
                       "expected the merged sample ranges to form at most "
                       "%d separate runs, got %u (merge neighbouring ranges first)",
                       PARTIAL_MAX_RANGES, n_union);
        return false;
    }
    /* Chan et al. 1979: the raw moments of a union are the sums of the parts' moments */
    size_t n_pixels = (size_t)dst->width * (size_t)dst->height;
    for (size_t i = 0; i < n_pixels; i++) {
        struct film_pixel *d = &dst->pixels[i];
        const struct film_pixel *s = &src->pixels[i];
        for (int c = 0; c < 3; c++) {
            d->sum[c] += s->sum[c];
            d->sum_sq[c] += s->sum_sq[c];
        }
        d->sum_lum_sq += s->sum_lum_sq;
        d->n += s->n; /* disjoint ranges below 2^32: no overflow */
        d->n_dropped += s->n_dropped;
    }
    dst_info->n_ranges = n_union;
    memcpy(dst_info->ranges, all, sizeof all[0] * n_union);
    return true;
}

/* A part to merge: its index in the command line and its first sample index. */
struct part_order {
    int path_idx;
    uint32_t begin;
};

static int compare_parts(const void *a, const void *b)
{
    const struct part_order *pa = a, *pb = b;
    return pa->begin < pb->begin ? -1 : pa->begin > pb->begin ? 1 : pa->path_idx - pb->path_idx;
}

bool partial_merge_files(const char *const *paths, int n_paths, struct film *film,
                         struct partial_info *info, struct mcpt_error *err)
{
    memset(film, 0, sizeof *film);
    memset(info, 0, sizeof *info);
    struct film part = {0};
    struct partial_info part_info;
    struct part_order *order = n_paths > 0 ? malloc(sizeof *order * (size_t)n_paths) : NULL;
    if (!order) {
        if (n_paths > 0)
            mcpt_error_runtime(err, NULL, "out of memory");
        else
            mcpt_error_set(err, "", 0, 0, "expected images to merge, got none");
        return false;
    }
    /* first pass: each part's first sample index (and every check on its own) */
    for (int i = 0; i < n_paths; i++) {
        if (!partial_read_exr(paths[i], &part, &part_info, err))
            goto fail;
        order[i].path_idx = i;
        order[i].begin = part_info.ranges[0].begin;
        film_free(&part);
    }
    qsort(order, (size_t)n_paths, sizeof *order, compare_parts);
    /* second pass: add them in sample order */
    if (!partial_read_exr(paths[order[0].path_idx], film, info, err))
        goto fail;
    for (int i = 1; i < n_paths; i++) {
        const char *path = paths[order[i].path_idx];
        if (!partial_read_exr(path, &part, &part_info, err) ||
            !partial_merge(film, info, &part, &part_info, path, err))
            goto fail;
        film_free(&part);
    }
    free(order);
    return true;
fail:
    film_free(&part);
    film_free(film);
    free(order);
    return false;
}
