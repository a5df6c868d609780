/* stats.h - image error metrics against a reference, convergence curves with their fits, their
 * CSV, JSON and text, and the sampler laboratory (the MSE of Monte Carlo estimates of 2-D
 * integrals with known values).  Pictures of them (SVG plot, contact sheet, heat maps) are in
 * plot.h.  Formats are an interface, kept stable and documented in docs/convergence.md.
 * Nothing here changes a render. */
#ifndef MCPT_STATS_H
#define MCPT_STATS_H

#include <stdio.h>

#include "film.h"
#include "image.h"
#include "sample.h"

#define STATS_RELMSE_EPS 0.01 /* relMSE: (a - r)^2 / (r^2 + eps), eps guards dark pixels */
#define STATS_MRSE_EPS 0.01   /* pbrt-v4 Image::MRSE: (a - r)^2 / (r + eps)^2 */
#define STATS_PSNR_PEAK 1.0   /* PSNR peak: linear radiance 1 (display white at exposure 0) */

/* ---- images and metrics ---- */

/* A planar RGB image as the metrics read it; it points at data owned elsewhere. */
struct stats_image {
    int width;
    int height;
    const float *rgb[3]; /* R, G, B planes, width * height each, row-major */
    const float *var[3]; /* variance of the mean per channel, or all NULL when unknown */
    const float *count;  /* samples per pixel, or NULL when unknown */
};

/* Points out at the R, G, B channels of img and, when all three are present, at variance.R/G/B
 * and samples.  Fails (err: file = path, msg "expected ...") when a colour channel is missing,
 * or when no pixel has finite R, G, B (and, with variance channels, finite variances >= 0):
 * every metric would be NaN. */
bool stats_image_from_exr(const struct image *img, const char *path, struct stats_image *out,
                          struct mcpt_error *err);

/* Resolves film into planes (caller-owned, 7 * width * height floats: R, G, B, variance of the
 * mean R, G, B, sample count; the values mcpt writes to its EXR) and points out at them. */
void stats_image_from_film(const struct film *film, float *planes, struct stats_image *out);

/* Every metric of image a against reference r, averaged over the pixel channels both have
 * finite (n_values of them).  Fields that need what an image lacks are NAN. */
struct stats_metrics {
    int width;
    int height;
    size_t n_values;         /* pixel channels compared */
    size_t n_skipped;        /* pixel channels skipped: a or r NaN or infinite */
    double mse;              /* mean (a - r)^2 */
    double mse_se;           /* its standard error, pixels taken as independent */
    double rmse;             /* sqrt(mse) */
    double relmse;           /* mean (a - r)^2 / (r^2 + 0.01) */
    double mrse_pbrt;        /* pbrt-v4's MRSE: mean (a - r)^2 / (r + 0.01)^2 */
    double mae;              /* mean |a - r| */
    double psnr_db;          /* 10 log10(peak^2 / mse), peak 1, values not clamped */
    double bias[3];          /* mean (a - r) per channel R, G, B */
    double noise_floor;      /* mean variance of the mean of r (needs r's variance channels) */
    double mse_corrected;    /* mse - noise_floor: a's own MSE, r's noise removed */
    double mse_corrected_se; /* its standard error */
    double rmse_corrected;   /* sqrt(mse_corrected); NAN when mse_corrected <= 0 */
    double relmse_corrected; /* mean ((a - r)^2 - var r) / (r^2 + 0.01) */
    double psnr_corrected_db;
    double mean_variance;     /* mean variance of the mean of a (a's variance channels; NAN
                                when a has none or a pixel has fewer than 2 samples) */
    double relmse_own;        /* mean var a / (a^2 + 0.01): a's own relMSE estimate */
    double max_ref_luminance; /* only pixels whose reference luminance is <= this were
                                 compared (INFINITY: all) */
    size_t n_pixels_masked;   /* pixels left out by max_ref_luminance */
};

/* Compares a with ref (may be NULL: then only a's own-variance fields are filled).  Fails
 * (err: msg "expected ... WxH ..., got ...") when the sizes differ. */
bool stats_compare(const struct stats_image *a, const struct stats_image *ref,
                   struct stats_metrics *m, struct mcpt_error *err);
/* As stats_compare, over only the pixels whose reference luminance (Rec. 709 weights of its
 * R, G, B) is <= max_ref_luminance; e.g. the Cornell box without its lamp (luminance 12.5)
 * with 1.  A NaN max_ref_luminance is refused like a size mismatch; ref must not be NULL. */
bool stats_compare_where(const struct stats_image *a, const struct stats_image *ref,
                         double max_ref_luminance, struct stats_metrics *m, struct mcpt_error *err);

/* Writes m as "name value" lines (human) or as one JSON object whose keys are documented in
 * docs/convergence.md; a_path and ref_path are echoed. */
void stats_print_metrics(FILE *f, const struct stats_metrics *m, const char *a_path,
                         const char *ref_path);
void stats_write_metrics_json(FILE *f, const struct stats_metrics *m, const char *a_path,
                              const char *ref_path);

/* The per-pixel terms of the relMSE: e[i] = mean over the channels of pixel i where a and r
 * are both finite of (a - r)^2 / (r^2 + 0.01); NAN where none is.  a and r must have the same
 * size; e holds width * height values. */
void stats_relative_error_map(const struct stats_image *a, const struct stats_image *r, double *e);

/* ---- line fits ---- */

/* Ordinary least squares y = intercept + slope x with its 95% confidence interval. */
struct stats_fit {
    size_t n; /* points used (finite x and y) */
    double slope;
    double intercept;
    double r2;       /* coefficient of determination 1 - SSE / SST */
    double slope_se; /* standard error of the slope, sqrt(s^2 / Sxx), s^2 = SSE / (n - 2) */
    double ci_lo;    /* slope -+ t(0.975, n - 2) slope_se; NAN when n < 3 */
    double ci_hi;
};

/* The 0.975 quantile of Student's t with dof degrees of freedom (dof >= 1): a table for dof
 * <= 30, the Cornish-Fisher expansion of Abramowitz & Stegun 1964, eq. 26.7.5, beyond. */
double stats_t_quantile_975(unsigned dof);

/* Fits the points (x[i], y[i]) whose x and y are both finite; false (fit->n set) when fewer than
 * two remain or all x are equal. */
bool stats_fit_line(const double *x, const double *y, size_t n, struct stats_fit *fit);

/* ---- convergence curves: one row per (seed, spp) snapshot ---- */

enum stats_error_source {
    STATS_ERR_REFERENCE_CORRECTED, /* mse = mean (a - r)^2 - mean var r: reference noise removed */
    STATS_ERR_REFERENCE,           /* mse = mean (a - r)^2: the reference has no variance */
    STATS_ERR_OWN_VARIANCE,        /* mse = mean var a: no reference; a's own estimate */
};
/* "reference-corrected", "reference", "own-variance": the CSV's error_source column. */
const char *stats_error_source_name(enum stats_error_source source);

struct stats_point {
    uint64_t seed;
    uint32_t spp;
    double seconds; /* render time of this seed's passes up to this spp */
    enum stats_error_source source;
    double mse;                   /* by source; NAN when unknown */
    double rmse;                  /* sqrt(mse); NAN when mse <= 0 or unknown */
    double relmse;                /* by source */
    double psnr_db;               /* 10 log10(1 / mse) */
    double mean_variance;         /* mean variance of the mean of the image */
    double efficiency;            /* 1 / (mse seconds) */
    double time_to_unit_variance; /* mean_variance seconds */
    double mse_raw;               /* mean (a - r)^2; NAN without a reference (likewise below) */
    double psnr_raw_db;
    double noise_floor; /* mean variance of the reference */
    double mrse_pbrt;
    double mae;
};

/* What the CSV and JSON say about the run; the strings are copied. */
struct stats_run_info {
    const char *scene;      /* scene path */
    const char *reference;  /* reference path or NULL */
    const char *sampler;    /* e.g. "sobol" */
    const char *integrator; /* e.g. "path-mis" */
    uint32_t max_depth;     /* TRACE_DEPTH_INFINITE (UINT32_MAX) prints "inf" */
    int width;
    int height;
};

struct stats_curve {
    char scene[1024];
    char reference[1024]; /* "" without a reference */
    char sampler[32];
    char integrator[64];
    uint32_t max_depth;
    int width;
    int height;
    struct stats_point *points;
    size_t n_points;
    size_t cap_points;
    float *planes; /* scratch: 7 planes of width * height floats */
};

/* Starts an empty curve (allocates nothing yet). */
void stats_curve_init(struct stats_curve *c, const struct stats_run_info *info);
void stats_curve_free(struct stats_curve *c);

/* Measures film (its RGB means and variances of the mean, as they would be written) against ref
 * (NULL: no reference) and appends a point for (seed, spp, seconds).  measured (may be NULL)
 * receives the image as measured; it points into the curve's scratch planes and is valid until
 * the next call (a snapshot's thumbnail is made from it, plot_sheet_add).  False with *err when
 * out of memory (runtime) or when ref's size differs from the film's (bad input). */
bool stats_curve_add(struct stats_curve *c, const struct film *film, const struct stats_image *ref,
                     uint64_t seed, uint32_t spp, double seconds, struct stats_image *measured,
                     struct mcpt_error *err);

/* The next spp at which a power-of-two snapshot falls after spp_done: the smallest power of two
 * above it, or spp_final when that is smaller. */
uint32_t stats_next_pow2(uint32_t spp_done, uint32_t spp_final);

/* One spp of the curve over every seed: mean and spread of the error (Celarek et al. 2019). */
struct stats_ensemble_row {
    uint32_t spp;
    size_t n_seeds;
    double mse_mean;              /* mean over seeds of mse */
    double mse_std;               /* sample standard deviation over seeds; NAN for one seed */
    double rmse;                  /* sqrt(mse_mean) */
    double psnr_db;               /* 10 log10(1 / mse_mean) */
    double seconds;               /* mean over seeds */
    double mean_variance;         /* mean over seeds */
    double efficiency;            /* 1 / (mse_mean seconds) */
    double time_to_unit_variance; /* mean_variance seconds */
    double mse_raw_mean;          /* mean over seeds of mse_raw (NAN without reference) */
    double noise_floor;
};

struct stats_summary {
    struct stats_ensemble_row *rows; /* by increasing spp */
    size_t n_rows;
    size_t n_seeds;
    enum stats_error_source source;
    struct stats_fit mse_fit;     /* ln mse_mean = intercept + slope ln spp */
    struct stats_fit rmse_fit;    /* ln rmse = intercept + slope ln spp */
    struct stats_fit mse_raw_fit; /* uncorrected, against the reference (n = 0 without one) */
    double mse_slope_boot_lo;     /* seed-bootstrap 95% interval of mse_fit.slope; NAN with */
    double mse_slope_boot_hi;     /*   fewer than STATS_BOOTSTRAP_MIN_SEEDS seeds */
    struct stats_fit time_fit;    /* seconds = intercept (overhead) + slope (s per spp) spp */
    double target_rmse;           /* the RMSE extrapolated to */
    double target_spp;            /* spp the rmse fit needs for it; NAN when unknown */
    double target_seconds;        /* time_fit at target_spp */
};

#define STATS_BOOTSTRAP_RESAMPLES 2000 /* resamples of whole seeds for the slope's interval */
#define STATS_BOOTSTRAP_MIN_SEEDS 4    /* fewer seeds: no bootstrap interval */

/* Groups the curve's points by spp over seeds and fits them.  target_rmse <= 0 picks half the
 * RMSE of the last row (which the N^-1/2 law reaches at 4 times its spp).  False when out of
 * memory; *s is then empty. */
bool stats_summarize(const struct stats_curve *c, double target_rmse, struct stats_summary *s);
void stats_summary_free(struct stats_summary *s);

/* max_depth as the CSV, the JSON and the plot print it: "inf" for TRACE_DEPTH_INFINITE, else
 * the number. */
void stats_depth_name(uint32_t max_depth, char *buf, size_t buf_bytes);

/* The CSV: the header line STATS_CSV_HEADER then one row per point, in the order added. */
#define STATS_CSV_HEADER                                                                           \
    "spp,seconds,mse,rmse,relmse,psnr_db,mean_variance,efficiency,sampler,integrator,seed,"        \
    "error_source,time_to_unit_variance,mse_raw,psnr_raw_db,noise_floor,mrse_pbrt,mae,max_depth"
bool stats_write_csv(const char *path, const struct stats_curve *c, struct mcpt_error *err);
/* The JSON summary (keys in docs/convergence.md), the fits and the ensemble table. */
bool stats_write_json(const char *path, const struct stats_curve *c, const struct stats_summary *s,
                      struct mcpt_error *err);
/* The summary as text: the ensemble table, the fits and the extrapolation. */
void stats_print_summary(FILE *f, const struct stats_curve *c, const struct stats_summary *s);

/* ---- the sampler laboratory: integrals on [0,1]^2 whose value is known ---- */

enum stats_integrand {
    STATS_FN_STEP,       /* 1 where x < 1/3: a straight discontinuity; I = 1/3 */
    STATS_FN_DISK,       /* 1 where x^2 + y^2 < 1 (quarter disk): a curved one; I = pi/4 */
    STATS_FN_CHECKER,    /* 10 x 10 checkerboard: many discontinuities; I = 1/2 */
    STATS_FN_GAUSSIAN,   /* exp(-|p - (1/2, 1/2)|^2 / (2 0.15^2)): smooth, peaked */
    STATS_FN_POLYNOMIAL, /* x^2 + y^2 + x y: smooth; I = 11/12 */
    STATS_FN_COUNT
};
const char *stats_integrand_name(enum stats_integrand f);
bool stats_integrand_parse(const char *name, enum stats_integrand *f);
double stats_integrand_eval(enum stats_integrand f, double x, double y);
double stats_integrand_exact(enum stats_integrand f);

struct stats_integrate_row {
    uint32_t spp;
    double mse;    /* mean over seeds of (estimate - I)^2 */
    double mse_se; /* its standard error: sd over seeds / sqrt(seeds) */
};

/* For spp = 1, 2, 4, ..., spp_max (a power of two): n_seeds independent estimates (seeds seed,
 * seed + 1, ...) of the integral of f, each the mean of f at the sampler's points 0 .. spp - 1
 * of pixel 0 (sample_start_spp with set_spp = spp, dimensions 0-1), and their MSE.  rows needs
 * log2(spp_max) + 1 entries; returns how many were filled. */
size_t stats_integrate(enum stats_integrand f, enum sampler_kind kind, uint32_t spp_max,
                       uint32_t n_seeds, uint64_t seed, struct stats_integrate_row *rows);

#endif
