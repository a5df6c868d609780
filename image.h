/* image.h - OpenEXR (through OpenEXR's C API, OpenEXRCore) and PNG (libpng) reading and writing,
 * and the sRGB encoding of the previews.  The only file that includes openexr.h or png.h.
 * Writes are atomic (file.h), so an interrupted write never leaves a truncated image.  Errors:
 * a file that cannot be read or is malformed is bad input; a failed write or an allocation
 * failure is a runtime error (vec.h). */
#ifndef MCPT_IMAGE_H
#define MCPT_IMAGE_H

#include "vec.h"

#define IMAGE_MAX_CHANNELS 32 /* mcpt's partial renders (partial.h) write 24 */
#define IMAGE_MAX_ATTRS 8     /* string attributes kept per image */
#define IMAGE_ATTR_BYTES 256  /* longest attribute value kept, including the NUL */

/* A planar float image: channel c of pixel (x, y) is data[c][y * width + x]. */
struct image {
    int width;
    int height;
    int n_channels;
    char names[IMAGE_MAX_CHANNELS][32]; /* EXR channel names, e.g. "R", "G", "B" */
    float *data[IMAGE_MAX_CHANNELS];    /* owned by the image when read by image_read_exr */
    /* header attributes of type string, e.g. "mcpt.sample-ranges" = "0:64" (partial.h) */
    int n_attrs;
    char attr_names[IMAGE_MAX_ATTRS][32];
    char attr_values[IMAGE_MAX_ATTRS][IMAGE_ATTR_BYTES];
};

/* Writes img as a scanline EXR, 32-bit float channels, ZIP compression, channels in the given
 * order (the EXR file stores them sorted by name, as the format requires), and img's string
 * attributes in the header.  Returns false and fills *err (file only, line 0) on an I/O
 * failure. */
bool image_write_exr(const char *path, const struct image *img, struct mcpt_error *err);

struct file_atomic; /* file.h */

/* image_write_exr into af, a temporary open for writing (file_atomic_open), which is then
 * finished (flushed and synced) but not renamed: the caller renames it together with the
 * other files of a set, so a reader never sees one new file beside an old other.  On failure
 * the temporary is removed and *err filled (file = af->path). */
bool image_encode_exr(struct file_atomic *af, const struct image *img, struct mcpt_error *err);

/* Reads every channel of a scanline or tiled EXR (half, float or uint channels are converted
 * to float) and the first IMAGE_MAX_ATTRS string attributes of its header that fit (name of
 * at most 31 bytes, value of at most IMAGE_ATTR_BYTES - 1; others are skipped, and so are the
 * structural "type" and "name").  On success
 * *img owns its data (free with image_free). */
bool image_read_exr(const char *path, struct image *img, struct mcpt_error *err);

/* Finds a channel by name; returns its index or -1. */
int image_find_channel(const struct image *img, const char *name);

/* Finds a string attribute by name; returns its value (owned by img) or NULL. */
const char *image_find_attr(const struct image *img, const char *name);

/* The 8-bit sRGB encoding (IEC 61966-2-1) of a linear value, clamped to [0, 1] and rounded:
 * image_srgb_init fills the table of the 256 thresholds once, then image_srgb8 encodes each
 * value exactly with 8 comparisons (no pow per value).  NaN encodes as 0. */
struct image_srgb {
    double t[256]; /* t[k]: the least linear value whose byte is k; t[0] = -inf */
};
void image_srgb_init(struct image_srgb *s);
uint8_t image_srgb8(const struct image_srgb *s, double v);

/* Writes an 8-bit sRGB PNG of linear rgb (interleaved, 3 floats a pixel), multiplied by
 * 2^exposure, then encoded by image_srgb8. */
bool image_write_png_srgb(const char *path, int width, int height, const float *rgb, float exposure,
                          struct mcpt_error *err);

/* image_write_png_srgb into the temporary af, finished but not renamed (image_encode_exr). */
bool image_encode_png_srgb(struct file_atomic *af, int width, int height, const float *rgb,
                           float exposure, struct mcpt_error *err);

/* Writes an 8-bit PNG of rgb8 (interleaved, 3 bytes a pixel) as is. */
bool image_write_png_rgb8(const char *path, int width, int height, const uint8_t *rgb8,
                          struct mcpt_error *err);

/* Frees the channel data of an image read by image_read_exr and zeroes it. */
void image_free(struct image *img);

#endif
