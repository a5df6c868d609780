/* checkpoint.c - an interrupted render on disk, to be resumed bit-identically: its film's raw
 * pixel records and the settings of the run, written atomically (file.h), checksummed with
 * FNV-1a 64 (Fowler, Noll, Vo), and checked field by field before a resumed run trusts it.
 * Also the comparison of a resumed run's settings with the saved ones (the scene by the hash
 * of its bytes, scene.file_hash).  Format: docs/reliability.md. */
#include "checkpoint.h"

#include <errno.h>
#include <sys/stat.h>
#include <unistd.h>

#include "file.h"
#include "sample.h"

/* Layout, in this machine's byte order (the byte-order mark tells a reader on the other order):
 *   "MCPTCKPT" | u32 version | u32 0x01020304 | u32 pixel record bytes | u32 width | u32 height
 *   | u64 scene_hash | u64 seed | u32 spp | u32 max_depth | u32 sampler | u32 sample_offset
 *   | u32 n, scene path (n bytes) | u32 n, args (n bytes) | width * height raw film_pixel
 *   | u64 FNV-1a 64 of every byte before it. */

static const char CKPT_MAGIC[8] = {'M', 'C', 'P', 'T', 'C', 'K', 'P', 'T'};
#define CKPT_BYTE_ORDER 0x01020304u /* reads back as 0x04030201 on the other byte order */

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
    cf->hash = file_fnv1a64(cf->hash, data, n_bytes);
    cf->n_bytes += n_bytes;
}

static void put_u32(struct ckpt_file *cf, uint32_t v) { put(cf, &v, sizeof v); }
static void put_u64(struct ckpt_file *cf, uint64_t v) { put(cf, &v, sizeof v); }

static bool get(struct ckpt_file *cf, void *data, size_t n_bytes)
{
    if (cf->ok && fread(data, 1, n_bytes, cf->f) != n_bytes)
        cf->ok = false;
    if (cf->ok) {
        cf->hash = file_fnv1a64(cf->hash, data, n_bytes);
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

bool checkpoint_save(const char *path, const struct film *film, const struct checkpoint_info *info,
                     struct mcpt_error *err)
{
    struct file_atomic af;
    struct ckpt_file cf = {.hash = FILE_FNV_OFFSET, .ok = true};
    if (!file_atomic_open(&af, path, err) || !(cf.f = file_atomic_stream(&af, err)))
        return false;
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    uint32_t n_path = (uint32_t)strnlen(info->scene_path, CHECKPOINT_PATH_BYTES - 1);
    uint32_t n_args = info->args_bytes < CHECKPOINT_ARGS_BYTES ? info->args_bytes
                                                               : CHECKPOINT_ARGS_BYTES;
    put(&cf, CKPT_MAGIC, sizeof CKPT_MAGIC);
    put_u32(&cf, CHECKPOINT_VERSION);
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
    return file_atomic_commit(&af, err); /* a short write above left the stream's error set */
}

/* Reads and checks everything before the pixel records: magic, version, byte order, record
 * size, film size, the settings and the two strings.  size_bytes is the file's length, for the
 * message about a short header.  False with *err (bad input, file = path). */
static bool read_header(struct ckpt_file *cf, const char *path, uint64_t size_bytes,
                        struct checkpoint_info *info, uint32_t *width, uint32_t *height,
                        struct mcpt_error *err)
{
    char magic[sizeof CKPT_MAGIC];
    if (!get(cf, magic, sizeof magic) || memcmp(magic, CKPT_MAGIC, sizeof magic) != 0) {
        mcpt_error_set(err, path, 0, 0,
                       "expected an mcpt checkpoint (starting 'MCPTCKPT'), got "
                       "other data");
        return false;
    }
    uint32_t version = get_u32(cf);
    uint32_t byte_order = get_u32(cf);
    uint32_t pixel_bytes = get_u32(cf);
    *width = get_u32(cf);
    *height = get_u32(cf);
    info->scene_hash = get_u64(cf);
    info->seed = get_u64(cf);
    info->spp = get_u32(cf);
    info->max_depth = get_u32(cf);
    info->sampler = get_u32(cf);
    info->sample_offset = get_u32(cf);
    uint32_t n_path = get_u32(cf);
    if (!cf->ok) {
        mcpt_error_set(err, path, 0, 0, "expected a complete checkpoint header, got %llu bytes",
                       (unsigned long long)size_bytes);
        return false;
    }
    if (version != CHECKPOINT_VERSION) {
        mcpt_error_set(err, path, 0, 0, "expected checkpoint version %u, got %u",
                       CHECKPOINT_VERSION, version);
        return false;
    }
    if (byte_order != CKPT_BYTE_ORDER) {
        mcpt_error_set(err, path, 0, 0,
                       "expected a checkpoint in this machine's byte order, got "
                       "the other");
        return false;
    }
    if (pixel_bytes != sizeof(struct film_pixel)) {
        mcpt_error_set(err, path, 0, 0, "expected pixel records of %zu bytes, got %u",
                       sizeof(struct film_pixel), pixel_bytes);
        return false;
    }
    if (*width < 1 || *width > 65535 || *height < 1 || *height > 65535) {
        mcpt_error_set(err, path, 0, 0, "expected a film of 1..65535 pixels a side, got %ux%u",
                       *width, *height);
        return false;
    }
    if (info->spp < 1 || (uint64_t)info->sample_offset + info->spp > UINT32_MAX) {
        mcpt_error_set(err, path, 0, 0,
                       "expected a target of 1 or more samples per pixel whose indices (from "
                       "the offset %u) stay below 2^32, got %u",
                       info->sample_offset, info->spp);
        return false;
    }
    if (info->sampler >= SAMPLER_COUNT) {
        mcpt_error_set(err, path, 0, 0, "expected a sampler number below %d, got %u", SAMPLER_COUNT,
                       info->sampler);
        return false;
    }
    if (n_path >= CHECKPOINT_PATH_BYTES) {
        mcpt_error_set(err, path, 0, 0, "expected a scene path of at most %d bytes, got %u",
                       CHECKPOINT_PATH_BYTES - 1, n_path);
        return false;
    }
    get(cf, info->scene_path, n_path);
    info->args_bytes = get_u32(cf);
    if (cf->ok && info->args_bytes > CHECKPOINT_ARGS_BYTES) {
        mcpt_error_set(err, path, 0, 0, "expected options of at most %d bytes, got %u",
                       CHECKPOINT_ARGS_BYTES, info->args_bytes);
        return false;
    }
    get(cf, info->args, info->args_bytes);
    if (cf->ok && info->args_bytes > 0 && info->args[info->args_bytes - 1] != '\0') {
        mcpt_error_set(err, path, 0, 0, "expected options ending in a NUL byte, got other data");
        return false;
    }
    return true; /* a short read here shows as the wrong length, next */
}

bool checkpoint_is_one(const char *path)
{
    const char *not_regular;
    int fd = file_open_input(path, false, &not_regular); /* a FIFO must not block */
    struct ckpt_file cf = {.hash = FILE_FNV_OFFSET, .ok = true};
    cf.f = fd >= 0 ? fdopen(fd, "rb") : NULL;
    if (!cf.f) {
        if (fd >= 0)
            close(fd);
        return false;
    }
    char magic[sizeof CKPT_MAGIC];
    bool is_one = get(&cf, magic, sizeof magic) && memcmp(magic, CKPT_MAGIC, sizeof magic) == 0;
    fclose(cf.f);
    return is_one;
}

bool checkpoint_load(const char *path, struct film *film, struct checkpoint_info *info,
                     struct mcpt_error *err)
{
    memset(film, 0, sizeof *film);
    memset(info, 0, sizeof *info);
    struct ckpt_file cf = {.hash = FILE_FNV_OFFSET, .ok = true};
    struct stat st;
    uint32_t width, height;
    const char *not_regular;
    int fd = file_open_input(path, false, &not_regular); /* a FIFO must not block */
    if (fd < 0 && not_regular) {
        mcpt_error_set(err, path, 0, 0, "expected a checkpoint file, got %s", not_regular);
        goto fail;
    }
    cf.f = fd >= 0 ? fdopen(fd, "rb") : NULL;
    if (!cf.f || fstat(fileno(cf.f), &st) != 0) {
        mcpt_error_set(err, path, 0, 0, "expected a readable checkpoint, got '%s'",
                       strerror(errno));
        if (fd >= 0 && !cf.f)
            close(fd);
        goto fail;
    }
    if (!read_header(&cf, path, (uint64_t)st.st_size, info, &width, &height, err))
        goto fail;
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
        snprintf(err->file, sizeof err->file, "%s", path); /* the kind stays film_init's */
        goto fail;
    }
    get(&cf, film->pixels, (size_t)n_pixels * sizeof(struct film_pixel));
    uint64_t expect_hash = cf.hash;
    uint64_t hash = get_u64(&cf);
    if (!cf.ok || hash != expect_hash) {
        mcpt_error_set(err, path, 0, 0,
                       "expected checksum %016llx, got %016llx (the file is "
                       "corrupt)",
                       (unsigned long long)expect_hash, (unsigned long long)hash);
        goto fail;
    }
    /* a valid checksum says the bytes are as written, not that a writer made them: every
     * value is checked as the renderer would have left it */
    for (uint64_t i = 0; i < n_pixels; i++) {
        const struct film_pixel *p = &film->pixels[i];
        const char *problem = film_pixel_problem(p, info->spp);
        unsigned long long x = i % width, y = i / width;
        if (problem && (uint64_t)p->n + p->n_dropped > info->spp) {
            mcpt_error_set(err, path, 0, 0,
                           "expected at most %u samples in a pixel (the spp), "
                           "got %llu at pixel %llu,%llu",
                           info->spp, (unsigned long long)p->n + p->n_dropped, x, y);
            goto fail;
        }
        if (problem) {
            mcpt_error_set(err, path, 0, 0,
                           "expected pixel sums that %u samples can give, got %s at pixel "
                           "%llu,%llu",
                           p->n, problem, x, y);
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

bool checkpoint_matches(const char *path, const struct checkpoint_info *saved,
                        const struct checkpoint_info *run, struct mcpt_error *err)
{
    const char *what = NULL;
    unsigned long long want = 0, got = 0;
    if (saved->scene_hash != run->scene_hash) {
        mcpt_error_set(err, path, 0, 0,
                       "expected the scene the checkpoint was made from "
                       "('%s', FNV-1a %016llx), got files with hash %016llx (the scene, or "
                       "a mesh or MTL file it loads, changed)",
                       saved->scene_path, (unsigned long long)saved->scene_hash,
                       (unsigned long long)run->scene_hash);
        return false;
    }
    if (saved->spp != run->spp)
        what = "--spp", want = saved->spp, got = run->spp;
    else if (saved->seed != run->seed)
        what = "--seed", want = saved->seed, got = run->seed;
    else if (saved->max_depth != run->max_depth)
        what = "--max-depth", want = saved->max_depth, got = run->max_depth;
    else if (saved->sampler != run->sampler) {
        mcpt_error_set(err, path, 0, 0, "expected --sampler %s as in the checkpoint, got %s",
                       sample_sampler_name((enum sampler_kind)saved->sampler),
                       sample_sampler_name((enum sampler_kind)run->sampler));
        return false;
    } else if (saved->sample_offset != run->sample_offset)
        what = "the sample offset", want = saved->sample_offset, got = run->sample_offset;
    if (what)
        mcpt_error_set(err, path, 0, 0, "expected %s %llu as in the checkpoint, got %llu", what,
                       want, got);
    return !what;
}
