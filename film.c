/* film.c - the accumulation buffer: allocation with a memory check, per-pixel mean and variance
 * of the mean, and their conversion to the float planes of an image.  Sums are double so that
 * 1e6 or more samples lose no precision that matters (PBRT 4e, ch. 5, "Film and Imaging",
 * accumulates in double for the same reason).  A film's checkpoint is in checkpoint.c, its
 * images in output.c and partial.c. */
#include "film.h"

#include <float.h>
#include <stdlib.h>
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
        mcpt_error_runtime(err, NULL, "out of memory allocating a %dx%d film", width, height);
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
