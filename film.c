/* film.c - the accumulation buffer: allocation with a memory check, per-pixel mean and variance
 * of the mean.  Sums are double so that 1e6 or more samples lose no precision that matters
 * (PBRT 4e, ch. 5, "Film and Imaging", accumulates in double for the same reason). */
#include "film.h"

#include <errno.h>
#include <fcntl.h>
#include <float.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

size_t film_max_bytes(void)
{
    long pages = sysconf(_SC_PHYS_PAGES);
    long page_bytes = sysconf(_SC_PAGESIZE);
    if (pages <= 0 || page_bytes <= 0)
        return (size_t)1 << 32; /* unknown: allow 4 GiB */
    return (size_t)pages / 2 * (size_t)page_bytes;
}

bool film_init(struct film *film, int width, int height, struct mcpt_error *err)
{
    memset(film, 0, sizeof *film);
    if (width <= 0 || height <= 0) {
        mcpt_error_set(err, "", 0, 0, "expected a film of at least 1x1 pixels, got %dx%d", width,
                       height);
        return false;
    }
    size_t n_pixels = (size_t)width * (size_t)height;
    size_t max_bytes = film_max_bytes();
    if (n_pixels > max_bytes / sizeof(struct film_pixel)) {
        mcpt_error_set(err, "", 0, 0,
                       "expected a film that fits in memory (at most %zu MiB), got %dx%d "
                       "needing %.0f MiB",
                       max_bytes >> 20, width, height,
                       (double)n_pixels * (double)sizeof(struct film_pixel) / 1048576.0);
        return false;
    }
    film->pixels = calloc(n_pixels, sizeof(struct film_pixel));
    if (!film->pixels) {
        mcpt_error_set(err, "", 0, 0, "out of memory allocating a %dx%d film", width, height);
        return false;
    }
    film->width = width;
    film->height = height;
    return true;
}

void film_free(struct film *film)
{
    free(film->pixels);
    memset(film, 0, sizeof *film);
}

double film_mean(const struct film_pixel *p, int c)
{
    return p->n ? p->sum[c] / (double)p->n : 0.0;
}

double film_var_of_mean(const struct film_pixel *p, int c)
{
    if (p->n < 2)
        return 0.0;
    double n = (double)p->n;
    double s2 = (p->sum_sq[c] - p->sum[c] * p->sum[c] / n) / (n - 1.0);
    return s2 > 0.0 ? s2 / n : 0.0; /* rounding can make a zero variance slightly negative */
}

/* A double as float, saturated at +-FLT_MAX: a mean or variance beyond float range (samples
 * near 3e38, whose squares only double can hold) must not reach an image as infinity. */
static float to_float_saturated(double v)
{
    return v > FLT_MAX ? FLT_MAX : v < -FLT_MAX ? -FLT_MAX : (float)v;
}

void film_resolve(const struct film *film, float *mean[3], float *var_of_mean[3], float *count)
{
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    for (size_t i = 0; i < n_pixels; i++) {
        const struct film_pixel *p = &film->pixels[i];
        for (int c = 0; c < 3; c++) {
            if (mean && mean[c])
                mean[c][i] = to_float_saturated(film_mean(p, c));
            if (var_of_mean && var_of_mean[c])
                var_of_mean[c][i] = to_float_saturated(film_var_of_mean(p, c));
        }
        if (count)
            count[i] = (float)p->n;
    }
}

/* ---- checkpoints ----
 * Layout, in this machine's byte order (the byte-order mark tells a reader on the other order):
 *   "MCPTCKPT" | u32 version | u32 0x01020304 | u32 pixel record bytes | u32 width | u32 height
 *   | u64 scene_hash | u64 seed | u32 spp | u32 max_depth | u32 sampler | u32 sample_offset
 *   | u32 n, scene path (n bytes) | u32 n, args (n bytes) | width * height raw film_pixel
 *   | u64 FNV-1a 64 of every byte before it. */

static const char CKPT_MAGIC[8] = {'M', 'C', 'P', 'T', 'C', 'K', 'P', 'T'};
#define CKPT_BYTE_ORDER 0x01020304u /* reads back as 0x04030201 on the other byte order */
#define FNV_OFFSET 0xcbf29ce484222325ull /* FNV-1a 64 (Fowler, Noll, Vo): offset basis */
#define FNV_PRIME 0x100000001b3ull       /* FNV-1a 64 prime */

static uint64_t fnv1a(uint64_t h, const void *data, size_t n_bytes)
{
    const unsigned char *p = data;
    for (size_t i = 0; i < n_bytes; i++) {
        h ^= p[i];
        h *= FNV_PRIME;
    }
    return h;
}

/* A checkpoint being written or read: the running checksum of the bytes so far. */
struct ckpt_file {
    FILE *f;
    uint64_t hash;
    uint64_t n_bytes; /* bytes written or read so far */
    bool ok;          /* false after a short write or read */
};

static void put(struct ckpt_file *cf, const void *data, size_t n_bytes)
{
    if (cf->ok && fwrite(data, 1, n_bytes, cf->f) != n_bytes)
        cf->ok = false;
    cf->hash = fnv1a(cf->hash, data, n_bytes);
    cf->n_bytes += n_bytes;
}

static void put_u32(struct ckpt_file *cf, uint32_t v) { put(cf, &v, sizeof v); }
static void put_u64(struct ckpt_file *cf, uint64_t v) { put(cf, &v, sizeof v); }

static bool get(struct ckpt_file *cf, void *data, size_t n_bytes)
{
    if (cf->ok && fread(data, 1, n_bytes, cf->f) != n_bytes)
        cf->ok = false;
    if (cf->ok) {
        cf->hash = fnv1a(cf->hash, data, n_bytes);
        cf->n_bytes += n_bytes;
    }
    return cf->ok;
}

static uint32_t get_u32(struct ckpt_file *cf)
{
    uint32_t v = 0;
    get(cf, &v, sizeof v);
    return v;
}

static uint64_t get_u64(struct ckpt_file *cf)
{
    uint64_t v = 0;
    get(cf, &v, sizeof v);
    return v;
}

bool film_save_checkpoint(const char *path, const struct film *film,
                          const struct film_checkpoint_info *info, struct mcpt_error *err)
{
    size_t tmp_bytes = strlen(path) + 48;
    char *tmp = malloc(tmp_bytes);
    struct ckpt_file cf = {.hash = FNV_OFFSET, .ok = true};
    int fd = -1;
    if (!tmp) {
        mcpt_error_set(err, path, 0, 0, "out of memory writing the checkpoint");
        return false;
    }
    /* a fresh "<path>.tmp.<pid>.<n>" beside path (O_EXCL: two writers never share one) */
    for (int i = 0; i < 100 && fd < 0; i++) {
        snprintf(tmp, tmp_bytes, "%s.tmp.%ld.%d", path, (long)getpid(), i);
        fd = open(tmp, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
        if (fd < 0 && errno != EEXIST)
            break;
    }
    if (fd < 0) {
        mcpt_error_set(err, path, 0, 0, "cannot write: %s", strerror(errno));
        free(tmp);
        return false;
    }
    if (!(cf.f = fdopen(fd, "wb")))
        goto fail;
    fd = -1; /* owned by cf.f now */

    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    uint32_t n_path = (uint32_t)strnlen(info->scene_path, FILM_CHECKPOINT_PATH_BYTES - 1);
    uint32_t n_args = info->args_bytes < FILM_CHECKPOINT_ARGS_BYTES ? info->args_bytes
                                                                    : FILM_CHECKPOINT_ARGS_BYTES;
    put(&cf, CKPT_MAGIC, sizeof CKPT_MAGIC);
    put_u32(&cf, FILM_CHECKPOINT_VERSION);
    put_u32(&cf, CKPT_BYTE_ORDER);
    put_u32(&cf, (uint32_t)sizeof(struct film_pixel));
    put_u32(&cf, (uint32_t)film->width);
    put_u32(&cf, (uint32_t)film->height);
    put_u64(&cf, info->scene_hash);
    put_u64(&cf, info->seed);
    put_u32(&cf, info->spp);
    put_u32(&cf, info->max_depth);
    put_u32(&cf, info->sampler);
    put_u32(&cf, info->sample_offset);
    put_u32(&cf, n_path);
    put(&cf, info->scene_path, n_path);
    put_u32(&cf, n_args);
    put(&cf, info->args, n_args);
    put(&cf, film->pixels, n_pixels * sizeof(struct film_pixel));
    put_u64(&cf, cf.hash);
    if (!cf.ok || fflush(cf.f) != 0 || fsync(fileno(cf.f)) != 0)
        goto fail;
    FILE *f = cf.f;
    cf.f = NULL;
    if (fclose(f) != 0 || rename(tmp, path) != 0)
        goto fail;
    free(tmp);
    return true;
fail:
    mcpt_error_set(err, path, 0, 0, "cannot write: %s", strerror(errno ? errno : EIO));
    if (cf.f)
        fclose(cf.f);
    if (fd >= 0)
        close(fd);
    unlink(tmp);
    free(tmp);
    return false;
}

bool film_load_checkpoint(const char *path, struct film *film, struct film_checkpoint_info *info,
                          struct mcpt_error *err)
{
    memset(film, 0, sizeof *film);
    memset(info, 0, sizeof *info);
    struct ckpt_file cf = {.hash = FNV_OFFSET, .ok = true};
    struct stat st;
    cf.f = fopen(path, "rb");
    if (!cf.f || fstat(fileno(cf.f), &st) != 0) {
        mcpt_error_set(err, path, 0, 0, "expected a readable checkpoint, got '%s'",
                       strerror(errno));
        goto fail;
    }
    if (!S_ISREG(st.st_mode)) {
        mcpt_error_set(err, path, 0, 0, "expected a checkpoint file, got a directory or device");
        goto fail;
    }
    char magic[sizeof CKPT_MAGIC];
    if (!get(&cf, magic, sizeof magic) || memcmp(magic, CKPT_MAGIC, sizeof magic) != 0) {
        mcpt_error_set(err, path, 0, 0, "expected an mcpt checkpoint (starting 'MCPTCKPT'), got "
                                        "other data");
        goto fail;
    }
    uint32_t version = get_u32(&cf);
    uint32_t byte_order = get_u32(&cf);
    uint32_t pixel_bytes = get_u32(&cf);
    uint32_t width = get_u32(&cf);
    uint32_t height = get_u32(&cf);
    info->scene_hash = get_u64(&cf);
    info->seed = get_u64(&cf);
    info->spp = get_u32(&cf);
    info->max_depth = get_u32(&cf);
    info->sampler = get_u32(&cf);
    info->sample_offset = get_u32(&cf);
    uint32_t n_path = get_u32(&cf);
    if (!cf.ok) {
        mcpt_error_set(err, path, 0, 0, "expected a complete checkpoint header, got %llu bytes",
                       (unsigned long long)st.st_size);
        goto fail;
    }
    if (version != FILM_CHECKPOINT_VERSION) {
        mcpt_error_set(err, path, 0, 0, "expected checkpoint version %u, got %u",
                       FILM_CHECKPOINT_VERSION, version);
        goto fail;
    }
    if (byte_order != CKPT_BYTE_ORDER) {
        mcpt_error_set(err, path, 0, 0, "expected a checkpoint in this machine's byte order, got "
                                        "the other");
        goto fail;
    }
    if (pixel_bytes != sizeof(struct film_pixel)) {
        mcpt_error_set(err, path, 0, 0, "expected pixel records of %zu bytes, got %u",
                       sizeof(struct film_pixel), pixel_bytes);
        goto fail;
    }
    if (width < 1 || width > 65535 || height < 1 || height > 65535) {
        mcpt_error_set(err, path, 0, 0, "expected a film of 1..65535 pixels a side, got %ux%u",
                       width, height);
        goto fail;
    }
    if (n_path >= FILM_CHECKPOINT_PATH_BYTES) {
        mcpt_error_set(err, path, 0, 0, "expected a scene path of at most %d bytes, got %u",
                       FILM_CHECKPOINT_PATH_BYTES - 1, n_path);
        goto fail;
    }
    get(&cf, info->scene_path, n_path);
    info->args_bytes = get_u32(&cf);
    if (cf.ok && info->args_bytes > FILM_CHECKPOINT_ARGS_BYTES) {
        mcpt_error_set(err, path, 0, 0, "expected options of at most %d bytes, got %u",
                       FILM_CHECKPOINT_ARGS_BYTES, info->args_bytes);
        goto fail;
    }
    get(&cf, info->args, info->args_bytes);
    if (cf.ok && info->args_bytes > 0 && info->args[info->args_bytes - 1] != '\0') {
        mcpt_error_set(err, path, 0, 0, "expected options ending in a NUL byte, got other data");
        goto fail;
    }
    /* the exact length, checked before the film is allocated */
    uint64_t n_pixels = (uint64_t)width * height;
    uint64_t expect_bytes = cf.n_bytes + n_pixels * sizeof(struct film_pixel) + sizeof(uint64_t);
    if (!cf.ok || (uint64_t)st.st_size != expect_bytes) {
        mcpt_error_set(err, path, 0, 0, "expected %llu bytes for a %ux%u film, got %llu",
                       (unsigned long long)expect_bytes, width, height,
                       (unsigned long long)st.st_size);
        goto fail;
    }
    if (!film_init(film, (int)width, (int)height, err)) {
        snprintf(err->file, sizeof err->file, "%s", path);
        goto fail;
    }
    get(&cf, film->pixels, (size_t)n_pixels * sizeof(struct film_pixel));
    uint64_t expect_hash = cf.hash;
    uint64_t hash = get_u64(&cf);
    if (!cf.ok || hash != expect_hash) {
        mcpt_error_set(err, path, 0, 0, "expected checksum %016llx, got %016llx (the file is "
                                        "corrupt)", (unsigned long long)expect_hash,
                       (unsigned long long)hash);
        goto fail;
    }
    for (uint64_t i = 0; i < n_pixels; i++) {
        const struct film_pixel *p = &film->pixels[i];
        if ((uint64_t)p->n + p->n_dropped > info->spp) {
            mcpt_error_set(err, path, 0, 0, "expected at most %u samples in a pixel (the spp), "
                                            "got %llu at pixel %llu,%llu", info->spp,
                           (unsigned long long)p->n + p->n_dropped,
                           (unsigned long long)(i % width), (unsigned long long)(i / width));
            goto fail;
        }
    }
    fclose(cf.f);
    return true;
fail:
    if (cf.f)
        fclose(cf.f);
    film_free(film);
    memset(info, 0, sizeof *info);
    return false;
}

/* ---- the sample-count map ---- */

/* Viridis (van der Walt & Smith 2015, matplotlib's default colour map: perceptually uniform,
 * readable in grey and by colour-blind viewers) at t = 0, 1/8, ..., 1; linear in between. */
static const float VIRIDIS[9][3] = {
    {0.267004f, 0.004874f, 0.329415f}, {0.282623f, 0.140926f, 0.457517f},
    {0.229739f, 0.322361f, 0.545706f}, {0.172719f, 0.448791f, 0.557885f},
    {0.127568f, 0.566949f, 0.550556f}, {0.134692f, 0.658636f, 0.517649f},
    {0.266941f, 0.748751f, 0.440573f}, {0.477504f, 0.821444f, 0.318195f},
    {0.993248f, 0.906157f, 0.143936f},
};

static void viridis_rgb8(double t, uint8_t out[3])
{
    t = t < 0.0 ? 0.0 : t > 1.0 ? 1.0 : t;
    double x = t * 8.0;
    int i = x >= 8.0 ? 7 : (int)x;
    double f = x - i;
    for (int c = 0; c < 3; c++)
        out[c] = (uint8_t)(255.0 * ((1.0 - f) * VIRIDIS[i][c] + f * VIRIDIS[i + 1][c]) + 0.5);
}

/* A 5 x 7 bitmap font for the legend: digits and the letters of its title.  Row r of glyph g
 * is GLYPHS[g].rows[r], bit 4 = leftmost column. */
static const struct {
    char ch;
    uint8_t rows[7];
} GLYPHS[] = {
    {'0', {0x0e, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0e}},
    {'1', {0x04, 0x0c, 0x04, 0x04, 0x04, 0x04, 0x0e}},
    {'2', {0x0e, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1f}},
    {'3', {0x1f, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0e}},
    {'4', {0x02, 0x06, 0x0a, 0x12, 0x1f, 0x02, 0x02}},
    {'5', {0x1f, 0x10, 0x1e, 0x01, 0x01, 0x11, 0x0e}},
    {'6', {0x06, 0x08, 0x10, 0x1e, 0x11, 0x11, 0x0e}},
    {'7', {0x1f, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08}},
    {'8', {0x0e, 0x11, 0x11, 0x0e, 0x11, 0x11, 0x0e}},
    {'9', {0x0e, 0x11, 0x11, 0x0f, 0x01, 0x02, 0x0c}},
    {'s', {0x00, 0x00, 0x0e, 0x10, 0x0e, 0x01, 0x1e}},
    {'a', {0x00, 0x00, 0x0e, 0x01, 0x0f, 0x11, 0x0f}},
    {'m', {0x00, 0x00, 0x1a, 0x15, 0x15, 0x11, 0x11}},
    {'p', {0x00, 0x00, 0x1e, 0x11, 0x1e, 0x10, 0x10}},
    {'l', {0x0c, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0e}},
    {'e', {0x00, 0x00, 0x0e, 0x11, 0x1f, 0x10, 0x0e}},
    {'r', {0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10}},
    {'i', {0x04, 0x00, 0x0c, 0x04, 0x04, 0x04, 0x0e}},
    {'x', {0x00, 0x00, 0x11, 0x0a, 0x04, 0x0a, 0x11}},
};

/* An RGB8 canvas being drawn on. */
struct canvas {
    uint8_t *rgb;
    int width;
    int height;
};

static void fill_rect(struct canvas *cv, int x0, int y0, int w, int h, const uint8_t col[3])
{
    for (int y = y0 > 0 ? y0 : 0; y < y0 + h && y < cv->height; y++)
        for (int x = x0 > 0 ? x0 : 0; x < x0 + w && x < cv->width; x++)
            memcpy(cv->rgb + 3 * ((size_t)y * (size_t)cv->width + (size_t)x), col, 3);
}

/* Draws text with its top-left corner at (x, y), each font pixel a scale x scale square;
 * characters without a glyph (space) advance only.  Returns the width drawn. */
static int draw_text(struct canvas *cv, int x, int y, int scale, const char *text,
                     const uint8_t col[3])
{
    int x_start = x;
    for (const char *c = text; *c; c++, x += 6 * scale)
        for (size_t g = 0; g < sizeof GLYPHS / sizeof GLYPHS[0]; g++)
            if (GLYPHS[g].ch == *c)
                for (int r = 0; r < 7; r++)
                    for (int k = 0; k < 5; k++)
                        if (GLYPHS[g].rows[r] & (0x10 >> k))
                            fill_rect(cv, x + k * scale, y + r * scale, scale, scale, col);
    return x - x_start - scale;
}

uint8_t *film_count_heatmap(const struct film *film, int *width, int *height)
{
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    uint32_t lo = UINT32_MAX, hi = 0;
    for (size_t i = 0; i < n_pixels; i++) {
        uint32_t n = film->pixels[i].n + film->pixels[i].n_dropped;
        lo = n < lo ? n : lo;
        hi = n > hi ? n : hi;
    }
    int k = (FILM_HEATMAP_MIN_WIDTH + film->width - 1) / film->width; /* whole scale factor */
    k = k < 1 ? 1 : k;
    int s = film->width * k >= 2 * FILM_HEATMAP_MIN_WIDTH ? 2 : 1; /* a font pixel, in pixels */
    /* legend rows, in font pixels s: margin 4, title 7, gap 4, bar 12, tick 3, gap 2, labels
     * 7, margin 4 */
    int legend_h = 43 * s;
    if ((int64_t)film->height * k + legend_h > 65535 || (int64_t)film->width * k > 65535)
        return NULL;
    struct canvas cv = {NULL, film->width * k, film->height * k + legend_h};
    cv.rgb = calloc((size_t)cv.width * (size_t)cv.height, 3); /* black background */
    if (!cv.rgb)
        return NULL;

    /* the film: t = (n - lo) / (hi - lo) */
    double span = hi > lo ? (double)(hi - lo) : 1.0;
    for (int y = 0; y < film->height; y++)
        for (int x = 0; x < film->width; x++) {
            const struct film_pixel *p = &film->pixels[(size_t)y * (size_t)film->width + x];
            uint8_t col[3];
            viridis_rgb8((double)(p->n + p->n_dropped - lo) / span, col);
            fill_rect(&cv, x * k, y * k, k, k, col);
        }

    /* the legend: title, colour bar, ticks and their counts */
    static const uint8_t WHITE[3] = {255, 255, 255};
    int margin = 6 * s, y_title = film->height * k + 4 * s;
    draw_text(&cv, margin, y_title, s, "samples per pixel", WHITE);
    int bar_x0 = margin, bar_x1 = cv.width - margin, y_bar = y_title + 11 * s;
    for (int x = bar_x0; x < bar_x1; x++) {
        uint8_t col[3];
        viridis_rgb8((double)(x - bar_x0) / (double)(bar_x1 - 1 - bar_x0), col);
        fill_rect(&cv, x, y_bar, 1, 12 * s, col);
    }
    int n_ticks = hi > lo ? 5 : 1;
    for (int t = 0; t < n_ticks; t++) {
        double f = n_ticks > 1 ? t / (double)(n_ticks - 1) : 0.0;
        int x = bar_x0 + (int)(f * (bar_x1 - 1 - bar_x0) + 0.5);
        fill_rect(&cv, x - (s - 1) / 2, y_bar + 12 * s, s, 3 * s, WHITE);
        char label[16];
        snprintf(label, sizeof label, "%u", (unsigned)(lo + f * (double)(hi - lo) + 0.5));
        int text_w = (int)strlen(label) * 6 * s - s;
        int x_text = x - text_w / 2;
        x_text = x_text < 0 ? 0 : x_text + text_w > cv.width ? cv.width - text_w : x_text;
        draw_text(&cv, x_text, y_bar + 17 * s, s, label, WHITE);
    }
    *width = cv.width;
    *height = cv.height;
    return cv.rgb;
}
