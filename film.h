/* film.h - the accumulation buffer: per pixel, double-precision sums of the samples' RGB, of
 * their squares and of their luminance squared, and the sample count.  From these come the mean,
 * the variance of the mean (for error bars, adaptive sampling and convergence snapshots), and an
 * exact merge of renders of disjoint sample ranges.  A pixel is only ever touched by the thread
 * that owns its tile, and its samples are added in sample-index order, so sums are bit-identical
 * for any thread count.  Sample indices of a pixel run 0 .. n + n_dropped - 1.  The film is
 * written as images by output.c and partial.c, and saved for --resume by checkpoint.c. */
#ifndef MCPT_FILM_H
#define MCPT_FILM_H

#include <stddef.h>

#include "vec.h"

struct film_pixel {
    double sum[3];      /* sum of sample RGB */
    double sum_sq[3];   /* sum of squared sample RGB, per channel */
    double sum_lum_sq;  /* sum of squared sample luminance (Rec. 709) */
    uint32_t n;         /* samples accumulated */
    uint32_t n_dropped; /* samples taken but not added: NaN or infinite (counted, reported) */
};                      /* 64 bytes */

struct film {
    int width;
    int height;
    struct film_pixel *pixels; /* row-major, y = 0 at the top */
};

/* Bytes this process may still allocate under its resource limits: RLIMIT_AS less the address
 * space in use, RLIMIT_DATA less the data in use (Linux's /proc/self/statm; where it cannot be
 * read, the whole limit), SIZE_MAX when neither limit is set.  A limit set by `ulimit -v` or a
 * batch system is met as a failed malloc, so a long job checks it before it starts. */
size_t film_memory_free_bytes(void);

/* Largest film the program will allocate, in bytes: half this machine's physical memory, and
 * no more than film_memory_free_bytes.  film_init refuses anything larger with a clear
 * message. */
size_t film_max_bytes(void);

/* Allocates a zeroed film.  Fails (err: file/line unset) with a bad-input error saying how
 * much memory it needs against how much is allowed when width * height * 64 bytes overflows or
 * exceeds film_max_bytes(), and with a runtime error when the allocation fails. */
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

/* Whether pixel p holds what finite samples could have summed to, for readers of saved films
 * (checkpoint.c, partial.c).  With n = p->n: n + n_dropped <= max_samples; an empty pixel is
 * all zeros; each sum in [0, n FLT_MAX] (radiance is never negative) and sum of squares in
 * [0, n FLT_MAX^2] (so finite, as a sample above FLT_MAX is dropped); and per channel and for
 * the luminance the Cauchy-Schwarz bound sum^2 <= n sum_sq, up to rounding.  Returns NULL when
 * it does, else what is wrong, for a message ("a sum of squares below 0", ...). */
const char *film_pixel_problem(const struct film_pixel *p, uint64_t max_samples);

/* Mean of pixel p, channel c; 0 for an empty pixel. */
double film_mean(const struct film_pixel *p, int c);
/* Unbiased estimate of the variance of the mean of pixel p, channel c:
 * s^2 / n with s^2 = (sum_sq - sum^2 / n) / (n - 1); 0 when n < 2. */
double film_var_of_mean(const struct film_pixel *p, int c);

/* Fills planar float arrays (width * height each; any may be NULL) with the mean RGB, the
 * variance of the mean RGB and the sample count.  Values beyond float range are stored as
 * +-FLT_MAX, so no image holds an infinity. */
void film_resolve(const struct film *film, float *mean[3], float *var_of_mean[3], float *count);

#endif
