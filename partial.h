/* partial.h - renders split by sample index, for many processes or machines: a partial render
 * holds sample indices A..B-1 of every pixel (mcpt --sample-range A:B), written to an EXR that
 * carries the film's double-precision sums to 48 bits, and partial renders of disjoint ranges
 * merge into the film of their union (mcpt merge).  Format and error bound: docs/distributed.md. */
#ifndef MCPT_PARTIAL_H
#define MCPT_PARTIAL_H

#include "film.h"

#define PARTIAL_MAX_RANGES 8     /* separate runs of sample indices one image may hold */
#define PARTIAL_RENDER_BYTES 256 /* the render-settings string, including the NUL */
#define PARTIAL_ATTR_RANGES "mcpt.sample-ranges" /* EXR string attribute: "A:B[,A:B...]" */
#define PARTIAL_ATTR_RENDER "mcpt.render"        /* EXR string attribute: the settings */

/* Sample indices begin .. end - 1 of every pixel. */
struct partial_range {
    uint32_t begin; /* first sample index */
    uint32_t end;   /* one past the last; begin < end */
};                  /* 8 bytes */

/* What a partial render holds: its runs of sample indices, sorted, disjoint and never adjacent
 * (adjacent runs are joined), and the settings that made it.  Only renders with the same
 * settings (scene bytes, film, total spp, seed, sampler, estimator) can be merged. */
struct partial_info {
    uint32_t n_ranges;
    struct partial_range ranges[PARTIAL_MAX_RANGES];
    char render[PARTIAL_RENDER_BYTES]; /* e.g. "scene=... spp=256 seed=0 sampler=sobol ..." */
};

/* Parses "A:B" (decimal, 0 <= A < B <= 4294967295) into *r; false on anything else. */
bool partial_parse_range(const char *s, struct partial_range *r);

/* Samples per pixel the info's ranges hold together. */
uint64_t partial_n_samples(const struct partial_info *info);

/* Whether the info's ranges are the whole render: one range 0:N, N the spp of its settings. */
bool partial_is_whole(const struct partial_info *info);

/* Writes film as an EXR: the channels of every mcpt render (R, G, B, variance.R/G/B, samples)
 * plus each double of every pixel's film_pixel split into two float channels, hi = (float)x
 * and lo = (float)(x - hi) (sum.R/G/B and sum_lo.R/G/B, sum_sq.*, sum_sq_lo.*, sum_lum_sq.Y,
 * sum_lum_sq_lo.Y, samples_lo, dropped, dropped_lo), and info as the string attributes
 * PARTIAL_ATTR_RANGES and PARTIAL_ATTR_RENDER.  False with *err (runtime; file = path) when a
 * sum lies beyond float range (it cannot be stored), when out of memory, or on an I/O failure. */
bool partial_write_exr(const char *path, const struct film *film, const struct partial_info *info,
                       struct mcpt_error *err);

struct file_atomic; /* file.h */

/* partial_write_exr into af, a temporary open for writing, finished but not renamed
 * (image_encode_exr); on failure the temporary is removed. */
bool partial_encode_exr(struct file_atomic *af, const struct film *film,
                        const struct partial_info *info, struct mcpt_error *err);

/* Reads an EXR written by partial_write_exr into a new film (free with film_free) and *info.
 * Every value is checked: channels and attributes present, ranges well formed, sums finite,
 * counts whole numbers, and every pixel's n + n_dropped equal to the ranges' sample count (an
 * interrupted render's image fails here).  On failure *film is zeroed and *err names path (bad
 * input; a runtime error when out of memory). */
bool partial_read_exr(const char *path, struct film *film, struct partial_info *info,
                      struct mcpt_error *err);

/* Adds src (with src_info, read from src_path) into dst (dst_info): per pixel every sum, n and
 * n_dropped.  Checks first that the films have the same size, the infos the same render
 * string, and that their ranges are disjoint; on a mismatch returns false with *err naming
 * src_path and changes nothing.  dst_info's ranges become the union. */
bool partial_merge(struct film *dst, struct partial_info *dst_info, const struct film *src,
                   const struct partial_info *src_info, const char *src_path,
                   struct mcpt_error *err);

/* Merges the partial renders at paths[0 .. n_paths-1] into a new film (free with film_free)
 * and *info.  The parts are added in the order of their first sample index, whatever the order
 * of paths, so the result's bits do not depend on it.  Each file is read twice (first its
 * ranges, then its pixels) so that only two films are in memory at a time.  On failure *film
 * is zeroed and *err names the offending file. */
bool partial_merge_files(const char *const *paths, int n_paths, struct film *film,
                         struct partial_info *info, struct mcpt_error *err);

/* Writes info's ranges as "A:B[,A:B...]" into out (at least PARTIAL_RENDER_BYTES bytes). */
void partial_format_ranges(const struct partial_info *info, char *out, size_t out_bytes);

#endif
