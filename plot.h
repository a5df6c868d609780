/* plot.h - pictures of results: the convergence plot (SVG), the contact sheet of snapshots, the
 * false-colour heat maps of per-pixel error and of samples per pixel, the colour map they share
 * (viridis) and the bitmap font that labels them.  Every number drawn is computed elsewhere
 * (stats.c, film.c): this module only places and colours it.  Formats: docs/convergence.md. */
#ifndef MCPT_PLOT_H
#define MCPT_PLOT_H

#include "film.h"
#include "image.h"
#include "stats.h"

/* ---- the convergence plot ---- */

/* Two log-log panels: RMSE vs spp (with the fit, the ideal N^-1/2 line, the uncorrected curve
 * and the reference's noise floor when known, error bars over seeds) and RMSE vs seconds.
 * Written atomically; false with *err (runtime; file = path) on failure. */
bool plot_write_svg(const char *path, const struct stats_curve *c, const struct stats_summary *s,
                    struct mcpt_error *err);

/* ---- the contact sheet: snapshots side by side, each labelled with its spp and PSNR ---- */

/* A thumbnail of one snapshot (sRGB, 8 bits a channel). */
struct plot_thumb {
    uint32_t spp;
    double psnr_db;                 /* as the curve measured it (NAN: none, inf: exact) */
    enum stats_error_source source; /* what the PSNR was measured against */
    int width;                      /* pixels */
    int height;                     /* pixels */
    uint8_t *rgb8;                  /* interleaved RGB, width * height * 3 bytes */
};

struct plot_sheet {
    struct plot_thumb *thumbs;
    size_t n_thumbs;
    size_t cap_thumbs;
    uint64_t seed;    /* the one seed whose snapshots these are (each tile says "seed S") */
    uint32_t n_seeds; /* seeds of the run: > 1 labels the PSNR "seed S only", since the
                         summary table gives the mean over all of them */
};

/* Adds a thumbnail of img (its rgb planes box-filtered down or repeated up by a whole factor to
 * about 160 pixels on its longer side, shown as look says: exposure, tone curve, sRGB)
 * labelled with spp, psnr_db and source.  False with *err (runtime) when out of memory. */
bool plot_sheet_add(struct plot_sheet *sheet, const struct stats_image *img, uint32_t spp,
                    double psnr_db, enum stats_error_source source, const struct image_look *look,
                    struct mcpt_error *err);
void plot_sheet_free(struct plot_sheet *sheet);

/* Writes the thumbnails in a grid of at most 5 columns as a PNG.  False with *err (runtime;
 * file = path) when there are none or the write fails. */
bool plot_write_contact_sheet(const char *path, const struct plot_sheet *sheet,
                              struct mcpt_error *err);

/* ---- heat maps: one value per pixel in viridis, scaled up, above a legend ---- */

/* Writes a false-colour PNG of each pixel's relative squared error against r
 * (stats_relative_error_map) on a log scale, whole decades chosen from the data, above a legend
 * with tick labels; films narrower than 256 pixels are scaled up by a whole factor.  a and r
 * must have the same size.  False with *err (runtime; file = path) on failure. */
bool plot_write_error_heatmap(const char *path, const struct stats_image *a,
                              const struct stats_image *r, struct mcpt_error *err);

/* Writes a false-colour PNG of each pixel's sample count n + n_dropped (where the renderer spent
 * its samples: adaptive sampling's map), linear from the least to the most samples in the film,
 * with the same scaling and legend as plot_write_error_heatmap.  False with *err (runtime;
 * file = path) when out of memory, when the map would exceed 65535 pixels a side, or when the
 * write fails. */
bool plot_write_count_heatmap(const char *path, const struct film *film, struct mcpt_error *err);

/* ---- text in 8-bit images ---- */

#define PLOT_FONT_W 5 /* glyph cell in font pixels, plus one column of spacing */
#define PLOT_FONT_H 7

/* Draws printable ASCII text into an interleaved RGB8 image with its top-left corner at (x, y),
 * each font pixel a scale x scale square, clipped to the image; other characters draw a box.
 * Returns the width of the text in pixels. */
int plot_draw_text(uint8_t *rgb8, int width, int height, int x, int y, int scale, const char *text,
                   const uint8_t color[3]);

#endif
