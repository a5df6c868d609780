/* image.h - OpenEXR (through OpenEXR's C API, OpenEXRCore) and PNG (libpng) reading and writing,
 * and the sRGB encoding of the previews.  The only file that includes openexr.h or png.h.
 * Writes are atomic (file.h), so an interrupted write never leaves a truncated image.  Errors:
 * a file that cannot be read or is malformed is bad input; a failed write or an allocation
 * failure is a runtime error (vec.h). */
#ifndef MCPT_IMAGE_H
#define MCPT_IMAGE_H

#include "vec.h"

#define IMAGE_MAX_CHANNELS 32 /* mcpt's partial renders (partial.h) write 24 */
#define IMAGE_MAX_ATTRS 16    /* string attributes kept per image */
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
    /* the standard "chromaticities" attribute as read (CIE xy of red, green, blue, white);
     * every image mcpt writes carries IMAGE_REC709_CHROMATICITIES */
    bool has_chromaticities;
    float chromaticities[8];
};

/* Linear Rec. ITU-R BT.709 (sRGB) primaries and the D65 white point, CIE 1931 xy: red, green,
 * blue, white (ITU-R BT.709-6, table "Derivation of luminance signal"; pbrt-v4 writes the same
 * for its sRGB films). */
#define IMAGE_REC709_CHROMATICITIES                                                                \
    {                                                                                              \
        0.64f, 0.33f, 0.30f, 0.60f, 0.15f, 0.06f, 0.3127f, 0.3290f                                 \
    }

/* Writes img as a scanline EXR, 32-bit float channels, ZIP compression, channels in the given
 * order (the EXR file stores them sorted by name, as the format requires), img's string
 * attributes and the chromaticities of linear Rec. 709 (IMAGE_REC709_CHROMATICITIES: mcpt
 * renders in those primaries) in the header.  Returns false and fills *err (file only, line
 * 0) on an I/O failure. */
bool image_write_exr(const char *path, const struct image *img, struct mcpt_error *err);

struct file_atomic; /* file.h */

/* image_write_exr into af, a temporary open for writing (file_atomic_open), which is then
 * finished (flushed and synced) but not renamed: the caller renames it together with the
 * other files of a set, so a reader never sees one new file beside an old other.  On failure
 * the temporary is removed and *err filled (file = af->path). */
bool image_encode_exr(struct file_atomic *af, const struct image *img, struct mcpt_error *err);

/* Reads every channel of a scanline or tiled EXR (half, float or uint channels are converted
 * to float); of a file with more than IMAGE_MAX_CHANNELS (a Blender multilayer EXR with its
 * render passes), only the colour image_find_rgb takes and the variance.R/G/B and samples
 * beside it, or none (an error) where there is no such colour; the first IMAGE_MAX_ATTRS
 * string attributes of its header that fit (name of at most 31 bytes, value of at most
 * IMAGE_ATTR_BYTES - 1; others are skipped, and so are the structural "type" and "name") and
 * the chromaticities when present.  On success *img owns its data (free with image_free). */
bool image_read_exr(const char *path, struct image *img, struct mcpt_error *err);

/* Finds a channel by name; returns its index or -1. */
int image_find_channel(const struct image *img, const char *name);

/* The colour channels of an image: R, G and B, or else those of one layer, LAYER.R, LAYER.G and
 * LAYER.B, as Blender's multilayer EXRs name them ("ViewLayer.Combined.R"): the only layer
 * that has all three, or among several the one whose last part is "Combined" (Blender's
 * beauty pass).  Fills idx with the three indices and *prefix_len with the length of
 * "LAYER." (0 for R, G, B); false when there is no such set or no way to choose one. */
bool image_find_rgb(const struct image *img, int idx[3], size_t *prefix_len);
/* What image_find_rgb looks for, as error messages say it. */
#define IMAGE_RGB_EXPECTED                                                                         \
    "channels R, G and B, or one layer's (LAYER.R, LAYER.G, LAYER.B; of several, the one named "   \
    "Combined)"
/* The channel named suffix ("variance.R", "samples") in the layer of the colour image_find_rgb
 * found, whose R is channel r and whose "LAYER." is prefix_len bytes; -1 when there is none. */
int image_find_beside(const struct image *img, int r, size_t prefix_len, const char *suffix);

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

/* How linear radiance becomes a displayed value: times 2^exposure, then a tone curve, then the
 * sRGB encoding.  The curves (image_tonemap), each mapping [0, inf) into [0, 1]:
 *   clamp     v                                      (values above 1 clip: the default)
 *   reinhard  rgb / (1 + Y), Y = 0.2126 R + 0.7152 G + 0.0722 B, the luminance of linear
 *             Rec. 709: Reinhard et al. 2002, eq. 3 applied to Y with the colour kept
 *   aces      x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14) per channel, clamped to [0, 1]:
 *             Narkowicz 2016's fit of the ACES RRT + ODT (1 maps to 0.80) */
enum image_tonemap {
    IMAGE_TONEMAP_CLAMP,
    IMAGE_TONEMAP_REINHARD,
    IMAGE_TONEMAP_ACES,
};

struct image_look {
    float exposure;             /* stops: values are multiplied by 2^exposure first */
    enum image_tonemap tonemap; /* then this curve */
};                              /* 8 bytes */

/* "clamp", "reinhard" or "aces" to the curve; false for any other name. */
bool image_tonemap_parse(const char *name, enum image_tonemap *out);
const char *image_tonemap_name(enum image_tonemap t);

/* The curve t on one pixel of linear rgb (already exposed): display-linear out, each in [0, 1]
 * for finite non-negative input (clamp: as given; the sRGB encoding clips).  NaN stays NaN. */
void image_tonemap_rgb(enum image_tonemap t, const double rgb[3], double out[3]);

/* Writes an 8-bit sRGB PNG of linear rgb (interleaved, 3 floats a pixel) as look says: times
 * 2^exposure, through the tone curve, then encoded by image_srgb8.  look NULL: exposure 0,
 * clamp. */
bool image_write_png_srgb(const char *path, int width, int height, const float *rgb,
                          const struct image_look *look, struct mcpt_error *err);

/* image_write_png_srgb into the temporary af, finished but not renamed (image_encode_exr). */
bool image_encode_png_srgb(struct file_atomic *af, int width, int height, const float *rgb,
                           const struct image_look *look, struct mcpt_error *err);

/* Writes an 8-bit PNG of rgb8 (interleaved, 3 bytes a pixel) as is. */
bool image_write_png_rgb8(const char *path, int width, int height, const uint8_t *rgb8,
                          struct mcpt_error *err);

/* Frees the channel data of an image read by image_read_exr and zeroes it. */
void image_free(struct image *img);

#endif
