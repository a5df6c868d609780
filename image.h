/* image.h - OpenEXR (through OpenEXR's C API, OpenEXRCore) and PNG (libpng) reading and writing.
 * The only file that includes openexr.h or png.h.  Writes are atomic: a temporary file in the
 * same folder, then rename(2), so an interrupted write never leaves a truncated image. */
#ifndef MCPT_IMAGE_H
#define MCPT_IMAGE_H

#include "vec.h"

#define IMAGE_MAX_CHANNELS 16

/* A planar float image: channel c of pixel (x, y) is data[c][y * width + x]. */
struct image {
    int width;
    int height;
    int n_channels;
    char names[IMAGE_MAX_CHANNELS][32]; /* EXR channel names, e.g. "R", "G", "B" */
    float *data[IMAGE_MAX_CHANNELS];    /* owned by the image when read by image_read_exr */
};

/* Writes img as a scanline EXR, 32-bit float channels, ZIP compression, channels in the given
 * order (the EXR file stores them sorted by name, as the format requires).  Returns false and
 * fills *err (file only, line 0) on an I/O failure. */
bool image_write_exr(const char *path, const struct image *img, struct mcpt_error *err);

/* Reads every channel of a scanline or tiled EXR (half, float or uint channels are converted
 * to float).  On success *img owns its data (free with image_free). */
bool image_read_exr(const char *path, struct image *img, struct mcpt_error *err);

/* Finds a channel by name; returns its index or -1. */
int image_find_channel(const struct image *img, const char *name);

/* Writes an 8-bit sRGB PNG of linear rgb (interleaved, 3 floats a pixel), multiplied by
 * 2^exposure, then the sRGB transfer function (IEC 61966-2-1), clamped to [0, 1], rounded. */
bool image_write_png_srgb(const char *path, int width, int height, const float *rgb,
                          float exposure, struct mcpt_error *err);

/* Writes an 8-bit PNG of rgb8 (interleaved, 3 bytes a pixel) as is. */
bool image_write_png_rgb8(const char *path, int width, int height, const uint8_t *rgb8,
                          struct mcpt_error *err);

/* Frees the channel data of an image read by image_read_exr and zeroes it. */
void image_free(struct image *img);

#endif
