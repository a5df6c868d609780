/* film.h - the accumulation buffer: per pixel, double-precision sums of the samples' RGB, of
 * their squares and of their luminance squared, and the sample count.  From these come the mean,
 * the variance of the mean (for error bars, adaptive sampling and convergence snapshots), and an
 * exact merge of renders of disjoint sample ranges.  A pixel is only ever touched by the thread
 * that owns its tile, and its samples are added in sample-index order, so sums are bit-identical
 * for any thread count.  Sample indices of a pixel run 0 .. n + n_dropped - 1. */
#ifndef MCPT_FILM_H
#define MCPT_FILM_H

#include <stddef.h>

#include "vec.h"

struct film_pixel {
    double sum[3];     /* sum of sample RGB */
    double sum_sq[3];  /* sum of squared sample RGB, per channel */
    double sum_lum_sq; /* sum of squared sample luminance (Rec. 709) */
    uint32_t n;        /* samples accumulated */
    uint32_t n_dropped; /* samples taken but not added: NaN or infinite (counted, reported) */
}; /* 64 bytes */

struct film {
    int width;
    int height;
    struct film_pixel *pixels; /* row-major, y = 0 at the top */
};

/* Largest film the program will allocate, in bytes, given this machine's physical memory
 * (half of it).  film_init refuses anything larger with a clear message. */
size_t film_max_bytes(void);

/* Allocates a zeroed film.  Fails (err: file/line unset, msg says how much memory it needs
 * against how much is allowed) when width * height * 64 bytes overflows or exceeds
 * film_max_bytes(), or when allocation fails. */
bool film_init(struct film *film, int width, int height, struct mcpt_error *err);
void film_free(struct film *film);

/* Adds one finite sample L to pixel p. */
static inline void film_add(struct film_pixel *p, vec3 L)
{
    double r = L.x, g = L.y, b = L.z;
    double lum = 0.2126 * r + 0.7152 * g + 0.0722 * b;
    p->sum[0] += r;
    p->sum[1] += g;
    p->sum[2] += b;
    p->sum_sq[0] += r * r;
    p->sum_sq[1] += g * g;
    p->sum_sq[2] += b * b;
    p->sum_lum_sq += lum * lum;
    p->n++;
}

/* Sum of the luminances of pixel p's samples (luminance is linear in RGB, so it is the
 * luminance of the RGB sums; Rec. 709 weights, as in film_add). */
static inline double film_sum_lum(const struct film_pixel *p)
{
    return 0.2126 * p->sum[0] + 0.7152 * p->sum[1] + 0.0722 * p->sum[2];
}

/* Mean of pixel p, channel c; 0 for an empty pixel. */
double film_mean(const struct film_pixel *p, int c);
/* Unbiased estimate of the variance of the mean of pixel p, channel c:
 * s^2 / n with s^2 = (sum_sq - sum^2 / n) / (n - 1); 0 when n < 2. */
double film_var_of_mean(const struct film_pixel *p, int c);

/* Fills planar float arrays (width * height each; any may be NULL) with the mean RGB, the
 * variance of the mean RGB and the sample count.  Values beyond float range are stored as
 * +-FLT_MAX, so no image holds an infinity. */
void film_resolve(const struct film *film, float *mean[3], float *var_of_mean[3], float *count);

/* ---- checkpoints: an interrupted render's film, to be resumed bit-identically ---- */

#define FILM_CHECKPOINT_VERSION 1u
#define FILM_CHECKPOINT_PATH_BYTES 1024 /* scene path stored for messages, incl. NUL */
#define FILM_CHECKPOINT_ARGS_BYTES 4096 /* the run's options, NUL-separated words */

/* The render parameters a resumed run must reproduce exactly: with them, each pixel continues
 * from its own count with the same sample indices, so the result is bit-identical to an
 * uninterrupted run. */
struct film_checkpoint_info {
    uint64_t scene_hash;    /* FNV-1a 64 of the scene file's bytes */
    uint64_t seed;          /* render seed */
    uint32_t spp;           /* target samples per pixel */
    uint32_t max_depth;     /* bounces (0: emission seen directly), TRACE_DEPTH_INFINITE allowed */
    uint32_t sampler;       /* enum sampler_kind */
    uint32_t sample_offset; /* sample index of a pixel's first film sample */
    char scene_path[FILM_CHECKPOINT_PATH_BYTES]; /* as given on the command line */
    uint32_t args_bytes;                          /* bytes of args in use */
    char args[FILM_CHECKPOINT_ARGS_BYTES];        /* options of the run, each word NUL-ended */
};

/* Writes film and info to path atomically (a temporary file in the same folder, fsync, rename),
 * so a reader sees the old file or the new one, never a mix.  Format (docs/reliability.md):
 * magic "MCPTCKPT", version, byte-order mark, pixel record size, film size, info, the raw
 * pixel records, then an FNV-1a 64 checksum of everything before it.  Returns false with *err
 * (file = path, no line) on an I/O failure; nothing is left behind then. */
bool film_save_checkpoint(const char *path, const struct film *film,
                          const struct film_checkpoint_info *info, struct mcpt_error *err);

/* Reads a checkpoint written by film_save_checkpoint into a new film (free with film_free) and
 * *info.  Every field is checked (magic, version, byte order, record size, film size against
 * memory, string lengths, per-pixel counts at most spp, exact file length, checksum); on any
 * mismatch returns false with *film zeroed and *err naming path and what was expected. */
bool film_load_checkpoint(const char *path, struct film *film, struct film_checkpoint_info *info,
                          struct mcpt_error *err);

#endif
