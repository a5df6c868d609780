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
