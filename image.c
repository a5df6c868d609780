/* image.c - OpenEXR (through OpenEXRCore, the C API) and PNG (libpng) reading and writing.
 * EXR: one scanline part, 32-bit float channels, ZIP compression (16 scanlines a chunk), written
 * and read chunk by chunk with the encode/decode pipelines; layout per "OpenEXR File Layout"
 * (openexr.com).  Reading accepts scanline and tiled parts with half, float or uint channels.
 * PNG: 8-bit RGB; the preview encodes linear values with the sRGB transfer function of
 * IEC 61966-2-1:1999, after an exposure and a tone curve (clamp; Reinhard et al. 2002,
 * "Photographic Tone Reproduction for Digital Images", eq. 3; Narkowicz 2016, "ACES Filmic
 * Tone Mapping Curve").
 * Every write goes through file.h: a temporary beside the destination, fsync'd, then renamed
 * over it, so a reader sees the old image or the new one, never a truncated one. */
#define _POSIX_C_SOURCE 200809L

#include "image.h"

#include <assert.h>
#include <errno.h>
#include <fcntl.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

#include "file.h"

#include <openexr.h>
#include <png.h>
#include <zlib.h>

/* Writes all n_bytes (write may write less than asked). */
static bool write_all(int fd, const void *buf, size_t n_bytes)
{
    const unsigned char *p = buf;
    while (n_bytes > 0) {
        ssize_t n = write(fd, p, n_bytes);
        if (n < 0 && errno == EINTR)
            continue;
        if (n <= 0)
            return false;
        p += n;
        n_bytes -= (size_t)n;
    }
    return true;
}

/* Writes all n_bytes at offset (pwrite may write less than asked). */
static bool pwrite_all(int fd, const void *buf, size_t n_bytes, off_t offset)
{
    const unsigned char *p = buf;
    while (n_bytes > 0) {
        ssize_t n = pwrite(fd, p, n_bytes, offset);
        if (n < 0 && errno == EINTR)
            continue;
        if (n <= 0)
            return false;
        p += n;
        n_bytes -= (size_t)n;
        offset += n;
    }
    return true;
}

/* ---- OpenEXRCore streams on our own file descriptors --------------------------------------- */

/* The context's user data: our descriptor and the first error the library reported (the first
 * is the root cause; later ones wrap it, e.g. "Unable to read pixel data block"). */
struct exr_stream {
    int fd;
    int64_t size_bytes;  /* file size for reads, -1 for writes */
    int io_errno;        /* errno of a failed pread/pwrite, else 0 */
    char first_msg[200]; /* empty until the library reports an error */
};

static void exr_stream_error(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    void *user = NULL;
    (void)code;
    if (exr_get_user_data(ctxt, &user) != EXR_ERR_SUCCESS || !user)
        return;
    struct exr_stream *s = user;
    if (s->first_msg[0])
        return;
    snprintf(s->first_msg, sizeof s->first_msg, "%s", msg ? msg : "unknown error");
    /* the library quotes names read from the file: its bytes must not reach the terminal as
     * line breaks or escape sequences (the error is one line) */
    for (char *c = s->first_msg; *c; c++)
        if ((unsigned char)*c < 0x20 || (unsigned char)*c >= 0x7f)
            *c = '?';
}

/* The error handler of a write context.  It must not read the context's user data:
 * exr_get_user_data takes the context's lock, which the library holds while it reports a
 * write error, so exr_stream_error would wait for itself forever (a full disk hung mcpt).
 * exr_stream_write records its errno itself; the library's messages are dropped, and
 * exr_error_set falls back to the text of the result code. */
static void exr_write_error(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    (void)ctxt;
    (void)code;
    (void)msg;
}

static int64_t exr_stream_read(exr_const_context_t ctxt, void *user, void *buffer, uint64_t sz,
                               uint64_t offset, exr_stream_error_func_ptr_t error_cb)
{
    struct exr_stream *s = user;
    unsigned char *p = buffer;
    uint64_t done = 0;
    while (done < sz) {
        ssize_t n = pread(s->fd, p + done, (size_t)(sz - done), (off_t)(offset + done));
        if (n < 0 && errno == EINTR)
            continue;
        if (n < 0) {
            s->io_errno = errno;
            if (error_cb)
                error_cb(ctxt, EXR_ERR_READ_IO, "cannot read: %s", strerror(errno));
            return -1;
        }
        if (n == 0)
            break; /* end of file: the library reports the short read */
        done += (uint64_t)n;
    }
    return (int64_t)done;
}

static int64_t exr_stream_size(exr_const_context_t ctxt, void *user)
{
    (void)ctxt;
    return ((struct exr_stream *)user)->size_bytes;
}

static int64_t exr_stream_write(exr_const_context_t ctxt, void *user, const void *buffer,
                                uint64_t sz, uint64_t offset, exr_stream_error_func_ptr_t error_cb)
{
    struct exr_stream *s = user;
    if (!pwrite_all(s->fd, buffer, (size_t)sz, (off_t)offset)) {
        s->io_errno = errno ? errno : EIO;
        if (error_cb)
            error_cb(ctxt, EXR_ERR_WRITE_IO, "cannot write: %s", strerror(s->io_errno));
        return -1;
    }
    return (int64_t)sz;
}

/* Fills *err from a failed OpenEXRCore call: our own I/O errno first ("cannot read: ..." or
 * "cannot write: ..."), then the library's first message, then the text for its result code. */
static void exr_error_set(struct mcpt_error *err, const char *path, const char *what,
                          const struct exr_stream *s, exr_result_t rv)
{
    if (s->io_errno)
        mcpt_error_runtime(err, path, "cannot %s: %s", s->size_bytes < 0 ? "write" : "read",
                           strerror(s->io_errno));
    else if (s->first_msg[0])
        mcpt_error_set(err, path, 0, 0, "%s: %s", what, s->first_msg);
    else
        mcpt_error_set(err, path, 0, 0, "%s: %s", what, exr_get_default_error_message(rv));
    /* a file that could not be written, or memory that ran out, is no fault of the input */
    if (err && (s->size_bytes < 0 || rv == EXR_ERR_OUT_OF_MEMORY))
        err->kind = MCPT_ERROR_RUNTIME;
}

/* ---- EXR writing ----------------------------------------------------------------------------- */

/* Checks what the writer needs from img; false with a message naming the first problem. */
static bool image_is_writable(const char *path, const struct image *img, struct mcpt_error *err)
{
    if (img->width < 1 || img->height < 1) {
        mcpt_error_runtime(err, path, "expected a positive image size, got %dx%d", img->width,
                           img->height);
        return false;
    }
    if (img->n_channels < 1 || img->n_channels > IMAGE_MAX_CHANNELS) {
        mcpt_error_runtime(err, path, "expected 1 to %d channels, got %d", IMAGE_MAX_CHANNELS,
                           img->n_channels);
        return false;
    }
    for (int c = 0; c < img->n_channels; c++) {
        size_t len = strnlen(img->names[c], sizeof img->names[c]);
        if (len == 0 || len == sizeof img->names[c] || !img->data[c]) {
            mcpt_error_runtime(err, path,
                               "expected channel %d to have a name of 1 to 31 "
                               "characters and data",
                               c);
            return false;
        }
        for (int k = 0; k < c; k++) {
            if (strcmp(img->names[k], img->names[c]) == 0) {
                mcpt_error_runtime(err, path, "expected unique channel names, got '%s' twice",
                                   img->names[c]);
                return false;
            }
        }
    }
    if (img->n_attrs < 0 || img->n_attrs > IMAGE_MAX_ATTRS) {
        mcpt_error_runtime(err, path, "expected 0 to %d attributes, got %d", IMAGE_MAX_ATTRS,
                           img->n_attrs);
        return false;
    }
    for (int a = 0; a < img->n_attrs; a++) {
        size_t len = strnlen(img->attr_names[a], sizeof img->attr_names[a]);
        if (len == 0 || len == sizeof img->attr_names[a] ||
            strnlen(img->attr_values[a], IMAGE_ATTR_BYTES) == IMAGE_ATTR_BYTES) {
            mcpt_error_runtime(err, path,
                               "expected attribute %d to have a name of 1 to 31 "
                               "characters and a NUL-terminated value",
                               a);
            return false;
        }
    }
    return true;
}

/* Encodes img as a scanline EXR onto fd, a fresh file; false with *err (file = path). */
static bool exr_encode(int fd, const char *path, const struct image *img, struct mcpt_error *err)
{
    struct exr_stream s = {.fd = fd, .size_bytes = -1};
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.user_data = &s;
    init.write_fn = exr_stream_write;
    init.error_handler_fn = exr_write_error;
    init.zip_level = 1; /* deflate level: half the time of the default 6 for about 1% larger
                           files of noisy float data */

    exr_context_t ctxt = NULL;
    exr_encode_pipeline_t encode = EXR_ENCODE_PIPELINE_INITIALIZER;
    bool is_encode_ready = false;
    const size_t width = (size_t)img->width;
    int part_idx = 0;
    int32_t lines_per_chunk = 0;

    exr_result_t rv = exr_start_write(&ctxt, path, EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_add_part(ctxt, "", EXR_STORAGE_SCANLINE, &part_idx);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_initialize_required_attr_simple(ctxt, part_idx, img->width, img->height,
                                                 EXR_COMPRESSION_ZIP);
    /* exr_add_channel keeps the list sorted by name, as the format requires; the encoder's
     * channels come in that order, so each is matched to ours by name below. */
    for (int c = 0; c < img->n_channels && rv == EXR_ERR_SUCCESS; c++)
        rv = exr_add_channel(ctxt, part_idx, img->names[c], EXR_PIXEL_FLOAT,
                             EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1);
    for (int a = 0; a < img->n_attrs && rv == EXR_ERR_SUCCESS; a++)
        rv = exr_attr_set_string(ctxt, part_idx, img->attr_names[a], img->attr_values[a]);
    /* the standard attribute that says which RGB the values are in ("OpenEXR Standard
     * Attributes": chromaticities); without it a reader must assume Rec. 709 anyway */
    static const float REC709[8] = IMAGE_REC709_CHROMATICITIES;
    const exr_attr_chromaticities_t chroma = {REC709[0], REC709[1], REC709[2], REC709[3],
                                              REC709[4], REC709[5], REC709[6], REC709[7]};
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_attr_set_chromaticities(ctxt, part_idx, "chromaticities", &chroma);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_write_header(ctxt);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_get_scanlines_per_chunk(ctxt, part_idx, &lines_per_chunk);
    if (rv != EXR_ERR_SUCCESS)
        goto fail;

    for (int y = 0; y < img->height; y += lines_per_chunk) {
        exr_chunk_info_t chunk;
        rv = exr_write_scanline_chunk_info(ctxt, part_idx, y, &chunk);
        if (rv == EXR_ERR_SUCCESS)
            rv = is_encode_ready ? exr_encoding_update(ctxt, part_idx, &chunk, &encode)
                                 : exr_encoding_initialize(ctxt, part_idx, &chunk, &encode);
        if (rv != EXR_ERR_SUCCESS)
            goto fail;
        for (int k = 0; k < encode.channel_count; k++) {
            exr_coding_channel_info_t *ch = &encode.channels[k];
            int c = image_find_channel(img, ch->channel_name);
            assert(c >= 0);
            ch->encode_from_ptr = (const uint8_t *)(img->data[c] + (size_t)y * width);
            ch->user_pixel_stride = (int32_t)sizeof(float);
            ch->user_line_stride = (int32_t)(width * sizeof(float));
            ch->user_bytes_per_element = (int16_t)sizeof(float);
            ch->user_data_type = EXR_PIXEL_FLOAT;
        }
        if (!is_encode_ready) {
            rv = exr_encoding_choose_default_routines(ctxt, part_idx, &encode);
            if (rv != EXR_ERR_SUCCESS)
                goto fail;
            is_encode_ready = true;
        }
        rv = exr_encoding_run(ctxt, part_idx, &encode);
        if (rv != EXR_ERR_SUCCESS)
            goto fail;
    }
    exr_encoding_destroy(ctxt, &encode);
    rv = exr_finish(&ctxt); /* writes the chunk offset table */
    if (rv != EXR_ERR_SUCCESS)
        goto fail;
    return true;

fail:
    exr_error_set(err, path, "cannot write OpenEXR", &s, rv);
    if (ctxt) {
        exr_encoding_destroy(ctxt, &encode);
        exr_finish(&ctxt);
    }
    return false;
}

bool image_encode_exr(struct file_atomic *af, const struct image *img, struct mcpt_error *err)
{
    if (!image_is_writable(af->path, img, err) || !exr_encode(af->fd, af->path, img, err)) {
        file_atomic_abort(af);
        return false;
    }
    return file_atomic_finish(af, err);
}

bool image_write_exr(const char *path, const struct image *img, struct mcpt_error *err)
{
    struct file_atomic af;
    return image_is_writable(path, img, err) && file_atomic_open(&af, path, err) &&
           image_encode_exr(&af, img, err) && file_atomic_rename(&af, err);
}

/* ---- channel names --------------------------------------------------------------------------- */

/* A channel's name as struct image keeps it: at most 31 bytes and a NUL. */
typedef char channel_name[sizeof((struct image *)0)->names[0]];

static int find_name(const channel_name *names, int n, const char *name)
{
    for (int c = 0; c < n; c++) {
        if (strncmp(names[c], name, sizeof names[c]) == 0)
            return c;
    }
    return -1;
}

int image_find_channel(const struct image *img, const char *name)
{
    int n = img->n_channels < IMAGE_MAX_CHANNELS ? img->n_channels : IMAGE_MAX_CHANNELS;
    return find_name(img->names, n, name);
}

/* Whether channel k is LAYER.R with LAYER.G and LAYER.B beside it: their indices in idx. */
static bool layer_rgb(const channel_name *names, int n, int k, int idx[3])
{
    const char *name = names[k];
    size_t len = strnlen(name, sizeof names[k]);
    if (len < 3 || len == sizeof names[k] || strcmp(name + len - 2, ".R") != 0)
        return false;
    channel_name other;
    memcpy(other, name, len + 1);
    idx[0] = k;
    other[len - 1] = 'G';
    idx[1] = find_name(names, n, other);
    other[len - 1] = 'B';
    idx[2] = find_name(names, n, other);
    return idx[1] >= 0 && idx[2] >= 0;
}

/* Whether the layer LAYER of channel LAYER.R ends in "Combined" (after a dot, or alone). */
static bool is_combined(const char *name_r)
{
    size_t len = strlen(name_r) - 2; /* without ".R" */
    const char *want = "Combined";
    size_t n = strlen(want);
    return len >= n && memcmp(name_r + len - n, want, n) == 0 &&
           (len == n || name_r[len - n - 1] == '.');
}

/* image_find_rgb over the names of n channels. */
static bool find_rgb(const channel_name *names, int n, int idx[3], size_t *prefix_len)
{
    static const char *plain[3] = {"R", "G", "B"};
    bool all = true;
    for (int c = 0; c < 3; c++)
        all = (idx[c] = find_name(names, n, plain[c])) >= 0 && all;
    *prefix_len = 0;
    if (all)
        return true;
    int n_layers = 0, n_combined = 0, layer[3] = {-1, -1, -1}, combined[3] = {-1, -1, -1};
    for (int k = 0; k < n; k++) {
        int found[3];
        if (!layer_rgb(names, n, k, found))
            continue;
        n_layers++;
        memcpy(layer, found, sizeof layer);
        if (is_combined(names[k])) {
            n_combined++;
            memcpy(combined, found, sizeof combined);
        }
    }
    const int *pick = n_layers == 1 ? layer : n_combined == 1 ? combined : NULL;
    if (!pick)
        return false;
    memcpy(idx, pick, sizeof layer);
    *prefix_len = strlen(names[pick[0]]) - 1;
    return true;
}

bool image_find_rgb(const struct image *img, int idx[3], size_t *prefix_len)
{
    int n = img->n_channels < IMAGE_MAX_CHANNELS ? img->n_channels : IMAGE_MAX_CHANNELS;
    return find_rgb(img->names, n, idx, prefix_len);
}

/* image_find_beside over the names of n channels. */
static int find_beside(const channel_name *names, int n, int r, size_t prefix_len,
                       const char *suffix)
{
    channel_name want;
    int len = snprintf(want, sizeof want, "%.*s%s", (int)prefix_len, names[r], suffix);
    return len < (int)sizeof want ? find_name(names, n, want) : -1;
}

int image_find_beside(const struct image *img, int r, size_t prefix_len, const char *suffix)
{
    int n = img->n_channels < IMAGE_MAX_CHANNELS ? img->n_channels : IMAGE_MAX_CHANNELS;
    return find_beside(img->names, n, r, prefix_len, suffix);
}

/* ---- EXR reading ----------------------------------------------------------------------------- */

/* Decodes one chunk (a band of scanlines or a tile) whose top-left pixel is (x0, y0) relative to
 * the data window into img, converting every channel to float. */
static exr_result_t decode_chunk(exr_context_t ctxt, const exr_chunk_info_t *chunk, int x0, int y0,
                                 struct image *img, exr_decode_pipeline_t *decode,
                                 bool *is_decode_ready)
{
    /* the chunk must lie inside the data window; a damaged file could claim otherwise */
    if (x0 < 0 || y0 < 0 || chunk->width < 1 || chunk->height < 1 ||
        chunk->width > img->width - x0 || chunk->height > img->height - y0)
        return EXR_ERR_CORRUPT_CHUNK;

    exr_result_t rv = *is_decode_ready ? exr_decoding_update(ctxt, 0, chunk, decode)
                                       : exr_decoding_initialize(ctxt, 0, chunk, decode);
    if (rv != EXR_ERR_SUCCESS)
        return rv;
    const size_t width = (size_t)img->width;
    for (int k = 0; k < decode->channel_count; k++) {
        exr_coding_channel_info_t *ch = &decode->channels[k];
        int c = image_find_channel(img, ch->channel_name);
        if (c < 0 && img->n_channels < decode->channel_count) {
            ch->decode_to_ptr = NULL; /* a channel left out (image_alloc_from_header) */
            continue;
        }
        if (c < 0)
            return EXR_ERR_INVALID_ATTR;
        ch->decode_to_ptr = (uint8_t *)(img->data[c] + (size_t)y0 * width + (size_t)x0);
        ch->user_pixel_stride = (int32_t)sizeof(float);
        ch->user_line_stride = (int32_t)(width * sizeof(float));
        ch->user_bytes_per_element = (int16_t)sizeof(float);
        ch->user_data_type = EXR_PIXEL_FLOAT; /* half and uint are converted by the library */
    }
    if (!*is_decode_ready) {
        rv = exr_decoding_choose_default_routines(ctxt, 0, decode);
        if (rv != EXR_ERR_SUCCESS)
            return rv;
        *is_decode_ready = true;
    }
    return exr_decoding_run(ctxt, 0, decode);
}

/* Reads every chunk of part 0, scanline bands or the full-resolution level of a tiled part. */
static exr_result_t decode_part(exr_context_t ctxt, exr_storage_t storage,
                                const exr_attr_box2i_t *dw, struct image *img)
{
    exr_decode_pipeline_t decode = EXR_DECODE_PIPELINE_INITIALIZER;
    bool is_decode_ready = false;
    exr_chunk_info_t chunk;
    exr_result_t rv = EXR_ERR_SUCCESS;

    if (storage == EXR_STORAGE_SCANLINE) {
        int32_t lines_per_chunk = 0;
        rv = exr_get_scanlines_per_chunk(ctxt, 0, &lines_per_chunk);
        if (rv == EXR_ERR_SUCCESS && lines_per_chunk < 1)
            rv = EXR_ERR_INVALID_ATTR;
        for (int64_t y = dw->min.y; y <= dw->max.y && rv == EXR_ERR_SUCCESS; y += lines_per_chunk) {
            rv = exr_read_scanline_chunk_info(ctxt, 0, (int)y, &chunk);
            if (rv == EXR_ERR_SUCCESS)
                rv = decode_chunk(ctxt, &chunk, chunk.start_x - dw->min.x,
                                  chunk.start_y - dw->min.y, img, &decode, &is_decode_ready);
        }
    } else {
        /* level (0, 0) of a mip- or rip-mapped file is the full-resolution image */
        int32_t tile_w = 0;
        int32_t tile_h = 0;
        rv = exr_get_tile_sizes(ctxt, 0, 0, 0, &tile_w, &tile_h);
        if (rv == EXR_ERR_SUCCESS && (tile_w < 1 || tile_h < 1))
            rv = EXR_ERR_INVALID_ATTR;
        int n_tiles_x = rv == EXR_ERR_SUCCESS ? (int)(((int64_t)img->width + tile_w - 1) / tile_w)
                                              : 0;
        int n_tiles_y = rv == EXR_ERR_SUCCESS ? (int)(((int64_t)img->height + tile_h - 1) / tile_h)
                                              : 0;
        for (int ty = 0; ty < n_tiles_y && rv == EXR_ERR_SUCCESS; ty++) {
            for (int tx = 0; tx < n_tiles_x && rv == EXR_ERR_SUCCESS; tx++) {
                rv = exr_read_tile_chunk_info(ctxt, 0, tx, ty, 0, 0, &chunk);
                if (rv == EXR_ERR_SUCCESS)
                    rv = decode_chunk(ctxt, &chunk, tx * tile_w, ty * tile_h, img, &decode,
                                      &is_decode_ready);
            }
        }
    }
    exr_decoding_destroy(ctxt, &decode);
    return rv;
}

/* The channels image_read_exr keeps, as indices into chlist: all of them, up to
 * IMAGE_MAX_CHANNELS; of more (a Blender multilayer EXR with every pass has about 100), the colour
 * that image_find_rgb would take and the variance.R/G/B and samples beside it, the names
 * compared as the file spells them (a name with a control character or past 31 bytes is passed
 * over).  False with *err filled when there is no such colour. */
static bool select_channels(const char *path, const exr_attr_chlist_t *chlist,
                            int keep[IMAGE_MAX_CHANNELS], int *n_keep, struct mcpt_error *err)
{
    int n = chlist->num_channels;
    if (n < 1) {
        mcpt_error_set(err, path, 0, 0, "expected 1 or more channels, got %d", n);
        return false;
    }
    *n_keep = 0;
    if (n <= IMAGE_MAX_CHANNELS) {
        for (int c = 0; c < n; c++)
            keep[(*n_keep)++] = c;
        return true;
    }
    channel_name *names = calloc((size_t)n, sizeof *names);
    if (!names) {
        mcpt_error_runtime(err, path, "cannot read: %s", strerror(ENOMEM));
        return false;
    }
    for (int c = 0; c < n; c++) {
        const exr_attr_string_t *name = &chlist->entries[c].name;
        bool usable = name->length >= 1 && (size_t)name->length < sizeof names[c];
        for (int k = 0; usable && k < name->length; k++)
            usable = (unsigned char)name->str[k] >= 0x20 && name->str[k] != 0x7f;
        if (usable)
            memcpy(names[c], name->str, (size_t)name->length);
    }
    const channel_name *read_only = (const channel_name *)names;
    int rgb[3];
    size_t prefix_len;
    bool ok = find_rgb(read_only, n, rgb, &prefix_len);
    if (ok) {
        const char *beside[4] = {"variance.R", "variance.G", "variance.B", "samples"};
        for (int c = 0; c < 3; c++)
            keep[(*n_keep)++] = rgb[c];
        for (int k = 0; k < 4; k++) {
            int c = find_beside(read_only, n, rgb[0], prefix_len, beside[k]);
            if (c >= 0)
                keep[(*n_keep)++] = c;
        }
    } else {
        mcpt_error_set(err, path, 0, 0,
                       "expected at most %d channels, or among more: " IMAGE_RGB_EXPECTED
                       ", got %d channels without them",
                       IMAGE_MAX_CHANNELS, n);
    }
    free(names);
    return ok;
}

/* Checks the header of part 0 and allocates img's channels; false with *err filled. */
/* Decoded bytes a file may claim per byte it holds: deflate (ZIP), the compression mcpt writes,
 * packs at most 1032:1; anything beyond a margin over that is a header that lies. */
#define EXR_MAX_RATIO 2048
#define EXR_MIN_CLAIM_BYTES ((uint64_t)64 << 20) /* small files may claim this much */

static bool image_alloc_from_header(const char *path, exr_storage_t storage,
                                    const exr_attr_box2i_t *dw, const exr_attr_chlist_t *chlist,
                                    int64_t file_bytes, struct image *img, struct mcpt_error *err)
{
    if (storage != EXR_STORAGE_SCANLINE && storage != EXR_STORAGE_TILED) {
        mcpt_error_set(err, path, 0, 0, "expected a scanline or tiled image, got deep data");
        return false;
    }
    int64_t width = (int64_t)dw->max.x - dw->min.x + 1;
    int64_t height = (int64_t)dw->max.y - dw->min.y + 1;
    if (width < 1 || height < 1 || width > INT32_MAX || height > INT32_MAX ||
        (uint64_t)width > SIZE_MAX / sizeof(float) / (uint64_t)height) {
        mcpt_error_set(err, path, 0, 0, "expected a usable data window, got %lldx%lld pixels",
                       (long long)width, (long long)height);
        return false;
    }
    int keep[IMAGE_MAX_CHANNELS], n_keep = 0;
    if (!select_channels(path, chlist, keep, &n_keep, err))
        return false;
    /* checked before allocating: a header of a few bytes claimed gigabytes */
    uint64_t claim_bytes = (uint64_t)width * (uint64_t)height * sizeof(float);
    uint64_t most_bytes = (uint64_t)file_bytes * EXR_MAX_RATIO;
    if (claim_bytes >
        (EXR_MIN_CLAIM_BYTES > most_bytes ? EXR_MIN_CLAIM_BYTES : most_bytes) / (uint64_t)n_keep) {
        mcpt_error_set(err, path, 0, 0,
                       "expected pixels its %lld bytes can hold, got a header of %lldx%lld pixels "
                       "and %d channels (%.0f MiB)",
                       (long long)file_bytes, (long long)width, (long long)height, n_keep,
                       (double)claim_bytes * n_keep / 1048576.0);
        return false;
    }
    img->width = (int)width;
    img->height = (int)height;
    for (int c = 0; c < n_keep; c++) {
        const exr_attr_chlist_entry_t *e = &chlist->entries[keep[c]];
        if (e->name.length < 1 || (size_t)e->name.length >= sizeof img->names[c]) {
            mcpt_error_set(err, path, 0, 0, "expected channel names of 1 to %zu characters, got %d",
                           sizeof img->names[c] - 1, (int)e->name.length);
            return false;
        }
        memcpy(img->names[c], e->name.str, (size_t)e->name.length);
        img->names[c][e->name.length] = '\0';
        for (char *ch = img->names[c]; *ch; ch++) /* names reach messages: one line, no escapes */
            if ((unsigned char)*ch < 0x20 || *ch == 0x7f)
                *ch = '?';
        if (e->x_sampling != 1 || e->y_sampling != 1) {
            mcpt_error_set(err, path, 0, 0, "expected channel '%s' sampled 1 1, got %d %d",
                           img->names[c], (int)e->x_sampling, (int)e->y_sampling);
            return false;
        }
        /* calloc: a chunk the file lacks reads as 0, never as stale memory */
        img->data[c] = calloc((size_t)width * (size_t)height, sizeof(float));
        if (!img->data[c]) {
            mcpt_error_runtime(err, path, "cannot read: %s", strerror(ENOMEM));
            return false;
        }
        img->n_channels = c + 1;
    }
    return true;
}

/* Keeps the string attributes of part 0 that fit in img (see image.h); skips the others and
 * the structural "type" and "name" that the library writes and reads itself. */
static void read_string_attrs(exr_context_t ctxt, struct image *img)
{
    int32_t n_attrs = 0;
    if (exr_get_attribute_count(ctxt, 0, &n_attrs) != EXR_ERR_SUCCESS)
        return;
    for (int32_t i = 0; i < n_attrs && img->n_attrs < IMAGE_MAX_ATTRS; i++) {
        const exr_attribute_t *attr = NULL;
        if (exr_get_attribute_by_index(ctxt, 0, EXR_ATTR_LIST_FILE_ORDER, i, &attr) !=
                EXR_ERR_SUCCESS ||
            !attr || attr->type != EXR_ATTR_STRING || !attr->string || !attr->string->str)
            continue;
        size_t name_len = strlen(attr->name);
        int32_t value_len = attr->string->length;
        if (name_len == 0 || name_len >= sizeof img->attr_names[0] || value_len < 0 ||
            value_len >= IMAGE_ATTR_BYTES || strcmp(attr->name, "type") == 0 ||
            strcmp(attr->name, "name") == 0)
            continue;
        memcpy(img->attr_names[img->n_attrs], attr->name, name_len + 1);
        memcpy(img->attr_values[img->n_attrs], attr->string->str, (size_t)value_len);
        img->attr_values[img->n_attrs][value_len] = '\0';
        img->n_attrs++;
    }
}

bool image_read_exr(const char *path, struct image *img, struct mcpt_error *err)
{
    struct exr_stream s = {.fd = -1};
    exr_context_t ctxt = NULL;
    exr_storage_t storage = EXR_STORAGE_LAST_TYPE;
    exr_attr_box2i_t dw;
    const exr_attr_chlist_t *chlist = NULL;
    struct stat st;

    memset(img, 0, sizeof *img);
    s.fd = file_open_regular(path, err); /* never blocks on a FIFO */
    if (s.fd < 0)
        return false;
    if (fstat(s.fd, &st) != 0) {
        mcpt_error_set(err, path, 0, 0, "cannot open: %s", strerror(errno));
        goto fail;
    }
    s.size_bytes = (int64_t)st.st_size;

    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.user_data = &s;
    init.read_fn = exr_stream_read;
    init.size_fn = exr_stream_size;
    init.error_handler_fn = exr_stream_error;
    exr_result_t rv = exr_start_read(&ctxt, path, &init);
    /* part 0 only: a multi-part file's later parts are not read */
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_get_storage(ctxt, 0, &storage);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_get_data_window(ctxt, 0, &dw);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_get_channels(ctxt, 0, &chlist);
    if (rv != EXR_ERR_SUCCESS) {
        exr_error_set(err, path, "cannot read OpenEXR header", &s, rv);
        goto fail;
    }
    if (!image_alloc_from_header(path, storage, &dw, chlist, s.size_bytes, img, err))
        goto fail;
    read_string_attrs(ctxt, img);
    exr_attr_chromaticities_t chroma;
    if (exr_attr_get_chromaticities(ctxt, 0, "chromaticities", &chroma) == EXR_ERR_SUCCESS) {
        const float xy[8] = {chroma.red_x,  chroma.red_y,  chroma.green_x, chroma.green_y,
                             chroma.blue_x, chroma.blue_y, chroma.white_x, chroma.white_y};
        memcpy(img->chromaticities, xy, sizeof xy);
        img->has_chromaticities = true;
    }
    rv = decode_part(ctxt, storage, &dw, img);
    if (rv != EXR_ERR_SUCCESS) {
        exr_error_set(err, path, "cannot read OpenEXR pixels", &s, rv);
        goto fail;
    }
    exr_finish(&ctxt);
    close(s.fd);
    return true;

fail:
    if (ctxt)
        exr_finish(&ctxt);
    close(s.fd);
    image_free(img);
    return false;
}

const char *image_find_attr(const struct image *img, const char *name)
{
    for (int a = 0; a < img->n_attrs && a < IMAGE_MAX_ATTRS; a++) {
        if (strncmp(img->attr_names[a], name, sizeof img->attr_names[a]) == 0)
            return img->attr_values[a];
    }
    return NULL;
}

void image_free(struct image *img)
{
    for (int c = 0; c < IMAGE_MAX_CHANNELS; c++)
        free(img->data[c]);
    memset(img, 0, sizeof *img);
}

/* ---- PNG ------------------------------------------------------------------------------------- */

/* libpng reports errors by calling png_error_fn, which must not return: it records the message
 * and longjmps back to the setjmp in png_encode. */
struct png_sink {
    int fd;
    int io_errno;  /* errno of a failed write, else 0 */
    char msg[200]; /* libpng's error message */
};

static void png_error_fn(png_structp png, png_const_charp msg)
{
    struct png_sink *sink = png_get_error_ptr(png);
    snprintf(sink->msg, sizeof sink->msg, "%s", msg ? msg : "unknown error");
    png_longjmp(png, 1);
}

static void png_warning_fn(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg;
}

static void png_write_fn(png_structp png, png_bytep data, size_t n_bytes)
{
    struct png_sink *sink = png_get_io_ptr(png);
    if (!write_all(sink->fd, data, n_bytes)) {
        sink->io_errno = errno ? errno : EIO;
        png_error(png, "write failed");
    }
}

static void png_flush_fn(png_structp png) { (void)png; }

/* Encodes width x height interleaved RGB bytes to sink->fd; is_srgb adds an sRGB chunk. */
static bool png_encode(struct png_sink *sink, int width, int height, const uint8_t *rgb8,
                       bool is_srgb)
{
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, sink, png_error_fn,
                                              png_warning_fn);
    if (!png) {
        snprintf(sink->msg, sizeof sink->msg, "%s", strerror(ENOMEM));
        return false;
    }
    png_infop info = png_create_info_struct(png);
    if (!info) {
        png_destroy_write_struct(&png, NULL);
        snprintf(sink->msg, sizeof sink->msg, "%s", strerror(ENOMEM));
        return false;
    }
    /* png and info are not changed after setjmp, so they need not be volatile (C11 7.13.2.1) */
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        return false;
    }
    png_set_write_fn(png, sink, png_write_fn, png_flush_fn);
    /* previews are written often: the Sub filter with run-length-only deflate took a third of
     * the time of libpng's defaults (deflate level 6, adaptive filters) on 512x512 test images,
     * for files 4% (noisy image) to 40% (smooth image) larger */
    png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_SUB);
    png_set_compression_strategy(png, Z_RLE);
    png_set_IHDR(png, info, (png_uint_32)width, (png_uint_32)height, 8, PNG_COLOR_TYPE_RGB,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_BASE, PNG_FILTER_TYPE_BASE);
    if (is_srgb)
        png_set_sRGB(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
    png_write_info(png, info);
    for (int y = 0; y < height; y++)
        png_write_row(png, rgb8 + (size_t)y * (size_t)width * 3);
    png_write_end(png, info);
    png_destroy_write_struct(&png, &info);
    return true;
}

/* Encodes rgb8 into the open temporary af and finishes it (not renamed); on failure removes
 * it. */
static bool png_encode_atomic(struct file_atomic *af, int width, int height, const uint8_t *rgb8,
                              bool is_srgb, struct mcpt_error *err)
{
    struct png_sink sink = {.fd = af->fd};
    if (!png_encode(&sink, width, height, rgb8, is_srgb)) {
        if (sink.io_errno)
            mcpt_error_runtime(err, af->path, "cannot write: %s", strerror(sink.io_errno));
        else
            mcpt_error_runtime(err, af->path, "cannot write PNG: %s", sink.msg);
        file_atomic_abort(af);
        return false;
    }
    return file_atomic_finish(af, err);
}

/* Writes rgb8 atomically to path. */
static bool png_write_atomic(const char *path, int width, int height, const uint8_t *rgb8,
                             bool is_srgb, struct mcpt_error *err)
{
    struct file_atomic af;
    return file_atomic_open(&af, path, err) &&
           png_encode_atomic(&af, width, height, rgb8, is_srgb, err) &&
           file_atomic_rename(&af, err);
}

/* Checks the size and that width * height * 3 bytes fit in size_t. */
static bool png_size_is_valid(const char *path, int width, int height, struct mcpt_error *err)
{
    if (width < 1 || height < 1 || (size_t)width > SIZE_MAX / 3 / (size_t)height) {
        mcpt_error_runtime(err, path, "expected a positive image size, got %dx%d", width, height);
        return false;
    }
    return true;
}

bool image_write_png_rgb8(const char *path, int width, int height, const uint8_t *rgb8,
                          struct mcpt_error *err)
{
    if (!png_size_is_valid(path, width, height, err))
        return false;
    return png_write_atomic(path, width, height, rgb8, false, err);
}

/* sRGB encoding (IEC 61966-2-1:1999) of linear v in [0, 1]:
 *     V = 12.92 v                    for v <= 0.0031308
 *     V = 1.055 v^(1/2.4) - 0.055    otherwise,
 * then byte = floor(255 V + 0.5).  V is increasing, so byte >= k exactly when v >= t[k], where
 * t[k] is the linear value whose encoding is (k - 1/2) / 255 (the standard's inverse):
 *     t[k] = V_k / 12.92                      for V_k <= 0.04045
 *     t[k] = ((V_k + 0.055) / 1.055)^2.4      otherwise,   V_k = (k - 0.5) / 255.
 * The byte is then the number of thresholds at or below v: an 8-step binary search, exact to
 * double precision, with no pow per pixel.  NaN passes no comparison and gives 0. */
void image_srgb_init(struct image_srgb *s)
{
    s->t[0] = -INFINITY; /* every v counts byte 0 */
    for (int k = 1; k < 256; k++) {
        double V_k = (k - 0.5) / 255.0;
        s->t[k] = V_k <= 0.04045 ? V_k / 12.92 : pow((V_k + 0.055) / 1.055, 2.4);
    }
}

uint8_t image_srgb8(const struct image_srgb *s, double v)
{
    unsigned k = 0;
    for (unsigned step = 128; step > 0; step >>= 1)
        k += v >= s->t[k + step] ? step : 0;
    return (uint8_t)k;
}

/* ---- tone curves ---- */

static const char *const TONEMAP_NAMES[] = {"clamp", "reinhard", "aces"};

bool image_tonemap_parse(const char *name, enum image_tonemap *out)
{
    for (int t = 0; t < (int)(sizeof TONEMAP_NAMES / sizeof TONEMAP_NAMES[0]); t++)
        if (strcmp(name, TONEMAP_NAMES[t]) == 0) {
            *out = (enum image_tonemap)t;
            return true;
        }
    return false;
}

const char *image_tonemap_name(enum image_tonemap t)
{
    return (unsigned)t < sizeof TONEMAP_NAMES / sizeof TONEMAP_NAMES[0] ? TONEMAP_NAMES[t] : "?";
}

void image_tonemap_rgb(enum image_tonemap t, const double rgb[3], double out[3])
{
    switch (t) {
    case IMAGE_TONEMAP_REINHARD: {
        /* Reinhard et al. 2002, eq. 3: L_d = L / (1 + L), on the luminance Y of linear
         * Rec. 709 (ITU-R BT.709 weights), each channel scaled by L_d / L = 1 / (1 + Y) so the
         * colour is kept.  The key scaling of their eq. 2 is left to the exposure. */
        double Y = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
        double s = 1.0 / (1.0 + (Y > 0.0 ? Y : 0.0));
        for (int c = 0; c < 3; c++)
            out[c] = rgb[c] * s;
        return;
    }
    case IMAGE_TONEMAP_ACES:
        /* Narkowicz 2016, "ACES Filmic Tone Mapping Curve" (knarkowicz.wordpress.com,
         * 2016-01-06): a rational fit of the ACES reference rendering + Rec. 709 output
         * transforms, pre-exposed so that 1 maps to about 0.8, applied per channel and
         * clamped ("saturate") to [0, 1] */
        for (int c = 0; c < 3; c++) {
            double x = rgb[c];
            if (isnan(x) || x <= 0.0 || isinf(x)) {
                out[c] = isnan(x) ? x : x > 0.0; /* NaN stays NaN; -inf..0 -> 0; inf -> 1 */
                continue;
            }
            double y = x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14);
            out[c] = y < 1.0 ? y : 1.0;
        }
        return;
    case IMAGE_TONEMAP_CLAMP:
    default:
        for (int c = 0; c < 3; c++)
            out[c] = rgb[c];
        return;
    }
}

bool image_encode_png_srgb(struct file_atomic *af, int width, int height, const float *rgb,
                           const struct image_look *look, struct mcpt_error *err)
{
    if (!png_size_is_valid(af->path, width, height, err)) {
        file_atomic_abort(af);
        return false;
    }
    size_t n_pixels = (size_t)width * (size_t)height;
    uint8_t *rgb8 = malloc(n_pixels * 3);
    if (!rgb8) {
        mcpt_error_runtime(err, af->path, "cannot write: %s", strerror(ENOMEM));
        file_atomic_abort(af);
        return false;
    }
    struct image_srgb srgb;
    image_srgb_init(&srgb);
    const float scale = exp2f(look ? look->exposure : 0.0f); /* exposure in stops */
    const enum image_tonemap curve = look ? look->tonemap : IMAGE_TONEMAP_CLAMP;
    for (size_t i = 0; i < n_pixels; i++) {
        double v[3], d[3];
        for (int c = 0; c < 3; c++)
            v[c] = rgb[3 * i + c] * scale; /* float product, as before tone curves existed */
        image_tonemap_rgb(curve, v, d);
        for (int c = 0; c < 3; c++)
            rgb8[3 * i + c] = image_srgb8(&srgb, d[c]);
    }
    bool ok = png_encode_atomic(af, width, height, rgb8, true, err);
    free(rgb8);
    return ok;
}

bool image_write_png_srgb(const char *path, int width, int height, const float *rgb,
                          const struct image_look *look, struct mcpt_error *err)
{
    struct file_atomic af;
    return png_size_is_valid(path, width, height, err) && file_atomic_open(&af, path, err) &&
           image_encode_png_srgb(&af, width, height, rgb, look, err) &&
           file_atomic_rename(&af, err);
}
