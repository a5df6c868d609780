/* film.c - the accumulation buffer: allocation with a memory check, per-pixel mean and variance
 * of the mean, and their conversion to the float planes of an image.  Sums are double so that
 * 1e6 or more samples lose no precision that matters (PBRT 4e, ch. 5, "Film and Imaging",
 * accumulates in double for the same reason).  A film's checkpoint is in checkpoint.c, its
 * images in output.c and partial.c. */
#include "film.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <unistd.h>

/* What is left of limit (bytes, or RLIM_INFINITY) once used bytes are taken. */
static size_t left_of(rlim_t limit, unsigned long long used)
{
    if (limit == RLIM_INFINITY)
        return SIZE_MAX;
    return (unsigned long long)limit > used ? (size_t)((unsigned long long)limit - used) : 0;
}

size_t film_memory_free_bytes(void)
{
    long page_bytes = sysconf(_SC_PAGESIZE);
    unsigned long long vm_pages = 0, data_pages = 0; /* statm: size ... data (pages) */
    FILE *f = fopen("/proc/self/statm", "r");
    if (!f || fscanf(f, "%llu %*u %*u %*u %*u %llu", &vm_pages, &data_pages) != 2)
        vm_pages = data_pages = 0;
    if (f)
        fclose(f);
    unsigned long long page = page_bytes > 0 ? (unsigned long long)page_bytes : 4096;
    size_t free_bytes = SIZE_MAX;
    struct rlimit lim;
    if (getrlimit(RLIMIT_AS, &lim) == 0 && left_of(lim.rlim_cur, vm_pages * page) < free_bytes)
        free_bytes = left_of(lim.rlim_cur, vm_pages * page);
    if (getrlimit(RLIMIT_DATA, &lim) == 0 && left_of(lim.rlim_cur, data_pages * page) < free_bytes)
        free_bytes = left_of(lim.rlim_cur, data_pages * page);
    return free_bytes;
}

size_t film_max_bytes(void)
{
    long pages = sysconf(_SC_PHYS_PAGES);
    long page_bytes = sysconf(_SC_PAGESIZE);
    size_t half_ram = pages <= 0 || page_bytes <= 0 ? (size_t)1 << 32 /* unknown: allow 4 GiB */
                                                    : (size_t)pages / 2 * (size_t)page_bytes;
    size_t free_bytes = film_memory_free_bytes();
    return half_ram < free_bytes ? half_ram : free_bytes;
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

/* Whether sum and sum_sq can be the sum and sum of squares of n finite float samples. */
static const char *sums_problem(double sum, double sum_sq, double n)
{
    /* rounding: each of the n additions errs by at most half an ulp, so both sums are within a
     * relative n * 2^-53 of the exact ones; 1e-6 covers n up to 2^32 with room */
    const double slack = 1.0 + 1e-6;
    const double max_sample = FLT_MAX;
    if (!(fabs(sum) <= n * max_sample))
        return "a sum that is not finite or exceeds the count times the largest float";
    if (sum < 0.0) /* radiance is never negative, so neither is a sum of its samples */
        return "a negative sum";
    if (!(sum_sq >= 0.0 && sum_sq <= n * max_sample * max_sample))
        return "a sum of squares below 0, not finite or beyond the count's reach";
    if (sum * sum > n * sum_sq * slack)
        return "a sum whose square exceeds the count times the sum of squares";
    return NULL;
}

const char *film_pixel_problem(const struct film_pixel *p, uint64_t max_samples)
{
    if ((uint64_t)p->n + p->n_dropped > max_samples)
        return "more samples than the render takes";
    double n = (double)p->n;
    for (int c = 0; c < 3; c++) {
        const char *problem = sums_problem(p->sum[c], p->sum_sq[c], n);
        if (problem)
            return problem;
    }
    /* the luminance's sum is the luminance of the RGB sums (film_sum_lum) */
    return sums_problem(film_sum_lum(p), p->sum_lum_sq, n);
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
