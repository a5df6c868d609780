/* tests/stats_test.c - stats.c: image metrics, the reference-noise correction, line fits with
 * their confidence intervals, the convergence outputs and the sampler laboratory.
 * - Metrics on synthetic images with known answers: constant offsets (exact MSE, MAE, relMSE,
 *   pbrt's MRSE, PSNR, bias) and Gaussian noise of known variance (MSE and its standard error).
 * - E[(a - r)^2] = MSE(a) + Var(r) for independent a, r (Whittle et al. 2017): the corrected MSE
 *   recovers the true MSE within its standard error; the uncorrected one does not.
 * - Student's t quantiles against numerical integration of the t density; OLS slopes exact on
 *   power laws; the 95% interval covers the true slope in about 95% of noisy trials.
 * - The error map's per-pixel terms of the relMSE.
 * - A run with --snapshots and --curve writes the same EXR bytes as a plain run; CSV header and
 *   JSON keys as documented in docs/convergence.md; compare reproduces a CSV row.  The pictures
 *   (plot, contact sheet, heat maps) are tests/plot_test.c's.
 * - The integrands' exact integrals against quadrature; independent sampling gives MSE ~ N^-1. */
#include <criterion/criterion.h>

#include <stdlib.h>
#include <sys/stat.h>

#include "film.h"
#include "image.h"
#include "sample.h"
#include "stats.h"
#include "test_util.h"

/* ---- helpers ---- */

/* A standard normal deviate (Box & Muller 1958) from two PCG32 uniforms in (0, 1). */
static double gauss(struct pcg32 *rng)
{
    double u1 = ((double)sample_pcg32_next(rng) + 0.5) * 0x1p-32;
    double u2 = ((double)sample_pcg32_next(rng) + 0.5) * 0x1p-32;
    return sqrt(-2.0 * log(u1)) * cos(2.0 * 3.14159265358979323846 * u2);
}

/* Planar image storage for the synthetic tests: R, G, B, then variances. */
struct planes {
    int width;
    int height;
    float *data; /* 6 planes */
};

static struct stats_image planes_image(struct planes *p, int width, int height, bool with_var)
{
    size_t n = (size_t)width * (size_t)height;
    p->width = width;
    p->height = height;
    p->data = calloc(6 * n, sizeof(float));
    cr_assert(p->data);
    struct stats_image img = {.width = width, .height = height};
    for (int c = 0; c < 3; c++) {
        img.rgb[c] = p->data + (size_t)c * n;
        img.var[c] = with_var ? p->data + (size_t)(3 + c) * n : NULL;
    }
    return img;
}

static float *plane(struct planes *p, int k)
{
    return p->data + (size_t)k * (size_t)p->width * (size_t)p->height;
}

/* ---- metrics ---- */

/* a = r + (0.1, -0.2, 0.05) on r = 0.5: every metric has a closed form. */
Test(stats, metrics_constant_offset)
{
    struct planes pa, pr;
    struct stats_image a = planes_image(&pa, 8, 4, false), r = planes_image(&pr, 8, 4, false);
    const double delta[3] = {0.1, -0.2, 0.05};
    for (int c = 0; c < 3; c++)
        for (int i = 0; i < 32; i++) {
            plane(&pr, c)[i] = 0.5f;
            plane(&pa, c)[i] = (float)(0.5 + delta[c]);
        }
    struct stats_metrics m;
    struct mcpt_error err;
    cr_assert(stats_compare(&a, &r, &m, &err));
    double d2 = 0.0, d1 = 0.0;
    for (int c = 0; c < 3; c++) {
        double d = (double)(float)(0.5 + delta[c]) - 0.5; /* the offset as stored in float */
        d2 += d * d / 3.0;
        d1 += fabs(d) / 3.0;
        cr_assert_float_eq(m.bias[c], d, 1e-12);
    }
    cr_assert_eq(m.n_values, 96u);
    cr_assert_float_eq(m.mse, d2, 1e-12);
    cr_assert_float_eq(m.rmse, sqrt(d2), 1e-12);
    cr_assert_float_eq(m.mae, d1, 1e-12);
    cr_assert_float_eq(m.relmse, d2 / (0.25 + 0.01), 1e-12);    /* (a-r)^2 / (r^2 + 0.01) */
    cr_assert_float_eq(m.mrse_pbrt, d2 / (0.51 * 0.51), 1e-12); /* (a-r)^2 / (r + 0.01)^2 */
    cr_assert_float_eq(m.psnr_db, -10.0 * log10(d2), 1e-9);     /* peak 1 */
    cr_assert_float_eq(m.mse_se, 0.0, 1e-15);                   /* every pixel alike */
    cr_assert(isnan(m.noise_floor) && isnan(m.mse_corrected));  /* r has no variance */
    free(pa.data);
    free(pr.data);
}

/* A variance below 0 in the reference (no render writes one; found by probing) is skipped like
 * a NaN one: its value is not counted, and the noise floor holds only variances >= 0. */
Test(stats, negative_reference_variance_skipped)
{
    struct planes pa, pr;
    struct stats_image a = planes_image(&pa, 4, 2, false), r = planes_image(&pr, 4, 2, true);
    for (int c = 0; c < 3; c++)
        for (int i = 0; i < 8; i++) {
            plane(&pr, c)[i] = 0.5f;
            plane(&pa, c)[i] = 0.5f;
            plane(&pr, 3 + c)[i] = 0.25f;
        }
    plane(&pr, 3)[5] = -1.0f; /* variance.R of pixel 5 */
    struct stats_metrics m;
    struct mcpt_error err;
    cr_assert(stats_compare(&a, &r, &m, &err), "%s", err.msg);
    cr_assert_eq(m.n_skipped, 1u);
    cr_assert_eq(m.n_values, 23u);
    cr_assert_float_eq(m.noise_floor, 0.25, 1e-12);
    free(pa.data);
    free(pr.data);
}

/* a = r + N(0, sigma^2) per value: MSE -> sigma^2 within 4 standard errors, and the standard
 * error itself matches theory, sqrt(2 / (3 n_pixels)) sigma^2 (a pixel's three squared
 * Gaussian errors sum to a scaled chi-square with 3 degrees of freedom). */
Test(stats, metrics_known_noise)
{
    const int w = 128, h = 64;
    const double sigma = 0.05;
    struct planes pa, pr;
    struct stats_image a = planes_image(&pa, w, h, false), r = planes_image(&pr, w, h, false);
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 12345, 1);
    for (int c = 0; c < 3; c++)
        for (int i = 0; i < w * h; i++) {
            double truth = 0.2 + 0.6 * (double)(i % w) / w;
            plane(&pr, c)[i] = (float)truth;
            plane(&pa, c)[i] = (float)(truth + sigma * gauss(&rng));
        }
    struct stats_metrics m;
    struct mcpt_error err;
    cr_assert(stats_compare(&a, &r, &m, &err));
    double se_theory = sqrt(2.0 / (3.0 * w * h)) * sigma * sigma;
    cr_assert(fabs(m.mse_se / se_theory - 1.0) < 0.1, "se %g, theory %g", m.mse_se, se_theory);
    cr_assert(fabs(m.mse - sigma * sigma) < 4.0 * m.mse_se, "mse %g +- %g, expected %g", m.mse,
              m.mse_se, sigma * sigma);
    free(pa.data);
    free(pr.data);
}

/* Films of Gaussian samples around a known image: the reference has 16 samples a pixel, the
 * image 4, so the reference's noise (sigma^2 / 16) is a quarter of the image's true MSE
 * (sigma^2 / 4).  The corrected MSE recovers sigma^2 / 4 within 3 standard errors using the
 * reference's estimated variance of the mean; the uncorrected one is off by many. */
Test(stats, noise_correction_recovers_true_mse)
{
    const int w = 96, h = 96;
    const double sigma = 0.2;
    struct film fa, fr;
    struct mcpt_error err;
    cr_assert(film_init(&fa, w, h, &err));
    cr_assert(film_init(&fr, w, h, &err));
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 777, 3);
    for (int i = 0; i < w * h; i++) {
        vec3 truth = v3(0.5f + 0.3f * (float)(i % w) / w, 0.4f, 0.3f + 0.2f * (float)(i / w) / h);
        for (int k = 0; k < 16; k++) {
            vec3 x = v3(truth.x + (float)(sigma * gauss(&rng)),
                        truth.y + (float)(sigma * gauss(&rng)),
                        truth.z + (float)(sigma * gauss(&rng)));
            film_add(&fr.pixels[i], x);
            if (k < 4) {
                vec3 y = v3(truth.x + (float)(sigma * gauss(&rng)),
                            truth.y + (float)(sigma * gauss(&rng)),
                            truth.z + (float)(sigma * gauss(&rng)));
                film_add(&fa.pixels[i], y);
            }
        }
    }
    float *pa = malloc(sizeof(float) * 7 * w * h), *pr = malloc(sizeof(float) * 7 * w * h);
    cr_assert(pa && pr);
    struct stats_image a, r;
    stats_image_from_film(&fa, pa, &a);
    stats_image_from_film(&fr, pr, &r);
    struct stats_metrics m;
    cr_assert(stats_compare(&a, &r, &m, &err));
    double truth = sigma * sigma / 4.0;
    cr_assert(fabs(m.noise_floor / (sigma * sigma / 16.0) - 1.0) < 0.05, "floor %g", m.noise_floor);
    cr_assert(fabs(m.mse_corrected - truth) < 3.0 * m.mse_corrected_se,
              "corrected %g +- %g, true MSE %g", m.mse_corrected, m.mse_corrected_se, truth);
    cr_assert(fabs(m.mse - truth) > 10.0 * m.mse_se, "uncorrected %g should be biased", m.mse);
    /* the image's own variance estimates its MSE too */
    cr_assert(fabs(m.mean_variance / truth - 1.0) < 0.05, "own variance %g", m.mean_variance);
    free(pa);
    free(pr);
    film_free(&fa);
    film_free(&fr);
}

/* stats_compare_where keeps only the pixels whose reference luminance 0.2126 R + 0.7152 G +
 * 0.0722 B is <= the bound: a "lamp" pixel of reference 12 with a large error is left out, and
 * the metrics are those of the other pixels (error 0.1 in each channel: MSE 0.01, bias 0.1);
 * with the bound at infinity they are stats_compare's. */
Test(stats, compare_where_leaves_out_bright_pixels)
{
    struct planes pa, pr;
    struct stats_image a = planes_image(&pa, 4, 2, true), r = planes_image(&pr, 4, 2, true);
    for (int c = 0; c < 3; c++)
        for (int i = 0; i < 8; i++) {
            plane(&pr, c)[i] = i == 5 ? 12.0f : 0.5f;
            plane(&pa, c)[i] = i == 5 ? 9.0f : 0.6f;
            plane(&pr, 3 + c)[i] = 1e-4f;
            plane(&pa, 3 + c)[i] = 2e-4f;
        }
    struct stats_metrics m, all, where_inf;
    struct mcpt_error err;
    cr_assert(stats_compare_where(&a, &r, 1.0, &m, &err));
    cr_assert(stats_compare(&a, &r, &all, &err));
    cr_assert(stats_compare_where(&a, &r, INFINITY, &where_inf, &err));
    double d = (double)0.6f - 0.5;
    cr_assert_eq(m.n_values, 21u);
    cr_assert_eq(m.n_pixels_masked, 1u);
    cr_assert_float_eq(m.mse, d * d, 1e-12);
    cr_assert_float_eq(m.bias[1], d, 1e-12);
    cr_assert_float_eq(m.noise_floor, (double)1e-4f, 1e-12);
    cr_assert_float_eq(m.mean_variance, (double)2e-4f, 1e-12);
    cr_assert_eq(all.n_values, 24u);
    cr_assert_eq(all.n_pixels_masked, 0u);
    cr_assert(all.mse > 1.0, "the lamp pixel's error counts without the bound");
    cr_assert_eq(where_inf.mse, all.mse);
    cr_assert(!stats_compare_where(&a, &r, NAN, &m, &err));
    cr_assert_str_eq(err.msg, "expected a luminance bound, got nan");
    free(pa.data);
    free(pr.data);
}

/* Images of different sizes are refused with an "expected ..., got ..." message. */
Test(stats, compare_size_mismatch)
{
    struct planes pa, pr;
    struct stats_image a = planes_image(&pa, 4, 4, false), r = planes_image(&pr, 4, 5, false);
    struct stats_metrics m;
    struct mcpt_error err;
    cr_assert(!stats_compare(&a, &r, &m, &err));
    cr_assert_str_eq(err.msg, "expected a reference of the image's size 4x4, got 4x5");
    free(pa.data);
    free(pr.data);
}

/* The error map's pixel i is the mean over its finite channels of (a - r)^2 / (r^2 + 0.01):
 * the relMSE's terms, so its mean is the relMSE when every channel is finite.  NaN where no
 * channel is finite. */
Test(stats, relative_error_map_terms)
{
    struct planes pa, pr;
    struct stats_image a = planes_image(&pa, 3, 1, false), r = planes_image(&pr, 3, 1, false);
    for (int c = 0; c < 3; c++)
        for (int i = 0; i < 3; i++) {
            plane(&pr, c)[i] = 0.5f;
            plane(&pa, c)[i] = 0.5f;
        }
    plane(&pa, 0)[0] = 0.75f; /* pixel 0: one channel off by 1/4 */
    plane(&pa, 1)[1] = NAN;   /* pixel 1: exact, one channel not finite */
    plane(&pa, 2)[1] = 0.25f; /*          and one off by 1/4 */
    for (int c = 0; c < 3; c++)
        plane(&pr, c)[2] = INFINITY; /* pixel 2: no finite channel */
    double e[3];
    stats_relative_error_map(&a, &r, e);
    double term = 0.0625 / (0.25 + STATS_RELMSE_EPS);
    cr_assert_float_eq(e[0], term / 3.0, 1e-15, "%.17g", e[0]);
    cr_assert_float_eq(e[1], term / 2.0, 1e-15, "%.17g", e[1]);
    cr_assert(isnan(e[2]));
    free(pa.data);
    free(pr.data);
}

/* ---- fits ---- */

/* Student's t density, for checking the quantiles. */
static double t_pdf(double t, double v)
{
    return exp(lgamma((v + 1.0) / 2.0) - lgamma(v / 2.0)) / sqrt(v * 3.14159265358979323846) *
           pow(1.0 + t * t / v, -(v + 1.0) / 2.0);
}

/* P(T <= q) = 1/2 + int_0^q pdf (composite Simpson, 20000 intervals) is 0.975 at the quantile,
 * for the table (dof <= 30) and the Cornish-Fisher expansion (dof > 30). */
Test(stats, t_quantile_matches_integral)
{
    const unsigned dofs[] = {1, 2, 3, 5, 8, 11, 20, 29, 30, 31, 40, 100, 1000};
    for (size_t k = 0; k < sizeof dofs / sizeof dofs[0]; k++) {
        double v = dofs[k], q = stats_t_quantile_975(dofs[k]);
        const int m = 20000;
        double h = q / m, sum = t_pdf(0.0, v) + t_pdf(q, v);
        for (int i = 1; i < m; i++)
            sum += (i % 2 ? 4.0 : 2.0) * t_pdf(i * h, v);
        double cdf = 0.5 + sum * h / 3.0;
        cr_assert(fabs(cdf - 0.975) < 2e-5, "dof %u: t %.5f has cdf %.6f", dofs[k], q, cdf);
    }
    cr_assert(isnan(stats_t_quantile_975(0)));
}

/* y = 3.7 x^-0.73 at x = 1, 2, ..., 4096: the log-log slope is -0.73 and R^2 is 1. */
Test(stats, fit_exact_power_law)
{
    double x[13], y[13];
    for (int i = 0; i < 13; i++) {
        x[i] = log(exp2(i));
        y[i] = log(3.7 * pow(exp2(i), -0.73));
    }
    struct stats_fit fit;
    cr_assert(stats_fit_line(x, y, 13, &fit));
    cr_assert_eq(fit.n, 13u);
    cr_assert_float_eq(fit.slope, -0.73, 1e-12);
    cr_assert_float_eq(fit.intercept, log(3.7), 1e-12);
    cr_assert_float_eq(fit.r2, 1.0, 1e-12);
    cr_assert(fit.ci_lo <= -0.73 && fit.ci_hi >= -0.73 && fit.ci_hi - fit.ci_lo < 1e-9);
    /* non-finite points are left out */
    y[5] = NAN;
    cr_assert(stats_fit_line(x, y, 13, &fit));
    cr_assert_eq(fit.n, 12u);
    cr_assert_float_eq(fit.slope, -0.73, 1e-12);
}

/* y = 1 - 0.5 x + N(0, 0.1^2) at 6 points (4 degrees of freedom, where the t quantile 2.776
 * differs most from the normal's 1.96, which would cover only 88%): over 4000 trials the 95%
 * interval covers -0.5 in 95% of them, within 3.5 binomial standard deviations
 * (sqrt(0.95 0.05 / 4000) = 0.0034); the mean slope is unbiased. */
Test(stats, fit_ci_coverage)
{
    const int trials = 4000;
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 2024, 7);
    int covered = 0;
    double sum_slope = 0.0;
    for (int t = 0; t < trials; t++) {
        double x[6], y[6];
        for (int i = 0; i < 6; i++) {
            x[i] = i * log(2.0);
            y[i] = 1.0 - 0.5 * x[i] + 0.1 * gauss(&rng);
        }
        struct stats_fit fit;
        cr_assert(stats_fit_line(x, y, 6, &fit));
        covered += fit.ci_lo <= -0.5 && -0.5 <= fit.ci_hi;
        sum_slope += fit.slope;
    }
    double coverage = (double)covered / trials;
    cr_assert(fabs(coverage - 0.95) < 3.5 * 0.0034, "coverage %.4f", coverage);
    cr_assert(fabs(sum_slope / trials + 0.5) < 0.002, "mean slope %.5f", sum_slope / trials);
}

/* A curve of n_seeds runs at spp 1 .. 4096 with mse = (1/N)^(1 + delta_s) exp(eta) per seed:
 * delta_s the run's own slope offset, eta independent noise per point. */
static void synthetic_curve(struct stats_curve *c, size_t n_seeds, double sd_delta, double sd_eta,
                            struct pcg32 *rng)
{
    struct stats_run_info info = {.scene = "synthetic",
                                  .sampler = "independent",
                                  .integrator = "path-mis",
                                  .width = 1,
                                  .height = 1};
    stats_curve_init(c, &info);
    c->cap_points = n_seeds * 13;
    c->points = calloc(c->cap_points, sizeof *c->points);
    cr_assert(c->points);
    for (size_t k = 0; k < n_seeds; k++) {
        double delta = sd_delta * gauss(rng);
        for (int e = 0; e <= 12; e++) {
            double n = exp2(e);
            c->points[c->n_points++] = (struct stats_point){.seed = 100 + k,
                                                            .spp = (uint32_t)n,
                                                            .seconds = 0.01 * n,
                                                            .source = STATS_ERR_REFERENCE,
                                                            .mse = pow(n, -(1.0 + delta)) *
                                                                   exp(sd_eta * gauss(rng))};
        }
    }
}

/* The seed bootstrap of the MSE slope: on exact power laws it collapses onto the slope; with
 * runs whose own slopes scatter (sd 0.05) but whose points lie on their lines, it sees the
 * scatter between runs (width about 2 1.96 0.05 / sqrt(16) = 0.05) where the OLS interval of
 * the averaged curve does not; fewer than 4 seeds give none. */
Test(stats, seed_bootstrap_interval)
{
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 99, 9);
    struct stats_curve c;
    struct stats_summary s;
    synthetic_curve(&c, 8, 0.0, 0.0, &rng);
    cr_assert(stats_summarize(&c, 0.0, &s));
    cr_assert_eq(s.n_seeds, 8u);
    cr_assert_eq(s.n_rows, 13u);
    cr_assert_float_eq(s.mse_fit.slope, -1.0, 1e-12);
    cr_assert_float_eq(s.rmse_fit.slope, -0.5, 1e-12);
    cr_assert_float_eq(s.mse_slope_boot_lo, -1.0, 1e-12);
    cr_assert_float_eq(s.mse_slope_boot_hi, -1.0, 1e-12);
    cr_assert_float_eq(s.time_fit.slope, 0.01, 1e-12);    /* seconds per spp */
    cr_assert_float_eq(s.time_fit.intercept, 0.0, 1e-12); /* no overhead */
    /* half the last RMSE needs 4x the spp under N^-1/2, 4 x 4096 x 0.01 s */
    cr_assert_float_eq(s.target_spp, 16384.0, 1e-6);
    cr_assert_float_eq(s.target_seconds, 163.84, 1e-8);
    stats_summary_free(&s);
    stats_curve_free(&c);

    synthetic_curve(&c, 16, 0.05, 0.01, &rng);
    cr_assert(stats_summarize(&c, 0.0, &s));
    double boot = s.mse_slope_boot_hi - s.mse_slope_boot_lo;
    double ols = s.mse_fit.ci_hi - s.mse_fit.ci_lo;
    cr_assert(boot > 0.025 && boot < 0.1, "bootstrap width %g", boot);
    cr_assert(boot > 5.0 * ols, "bootstrap %g vs OLS %g", boot, ols);
    cr_assert(s.mse_slope_boot_lo < s.mse_fit.slope && s.mse_fit.slope < s.mse_slope_boot_hi);
    stats_summary_free(&s);
    stats_curve_free(&c);

    synthetic_curve(&c, 3, 0.05, 0.01, &rng);
    cr_assert(stats_summarize(&c, 0.0, &s));
    cr_assert(isnan(s.mse_slope_boot_lo) && isnan(s.mse_slope_boot_hi));
    stats_summary_free(&s);
    stats_curve_free(&c);
}

/* Snapshots fall at the powers of two and at the final spp. */
Test(stats, next_pow2)
{
    cr_assert_eq(stats_next_pow2(0, 4096), 1u);
    cr_assert_eq(stats_next_pow2(1, 4096), 2u);
    cr_assert_eq(stats_next_pow2(3, 4096), 4u);
    cr_assert_eq(stats_next_pow2(2048, 4096), 4096u);
    cr_assert_eq(stats_next_pow2(512, 1000), 1000u);
    cr_assert_eq(stats_next_pow2(0, 1), 1u);
    cr_assert_eq(stats_next_pow2(0x80000000u, UINT32_MAX), UINT32_MAX);
}

/* ---- curve outputs ---- */

/* The keys of the first JSON object at depth want_depth of s (1: the object s starts with),
 * comma-separated in order. */
static void json_keys(const char *s, int want_depth, char *out, size_t out_bytes)
{
    int depth = 0;
    bool in_str = false, done_first = false;
    const char *str_start = NULL;
    out[0] = '\0';
    for (const char *p = s; *p && !done_first; p++) {
        if (in_str) {
            if (*p == '\\')
                p++;
            else if (*p == '"') {
                in_str = false;
                const char *q = p + 1;
                while (*q == ' ')
                    q++;
                if (*q == ':' && depth == want_depth) {
                    size_t len = strlen(out);
                    snprintf(out + len, out_bytes - len, "%s%.*s", len ? "," : "",
                             (int)(p - str_start), str_start);
                }
            }
            continue;
        }
        if (*p == '"') {
            in_str = true;
            str_start = p + 1;
        } else if (*p == '{' || *p == '[') {
            depth++;
        } else if (*p == '}' || *p == ']') {
            done_first = depth == want_depth; /* the first object at that depth is over */
            depth--;
        }
    }
}

static char *read_text(const char *path)
{
    static char buf[1 << 16];
    cr_assert(test_read_file(path, buf, sizeof buf) >= 0, "cannot open %s", path);
    return buf;
}

/* A synthetic curve of three points written as CSV and JSON: the header line and the keys are
 * the documented ones (golden strings, docs/convergence.md). */
Test(stats, csv_json_formats)
{
    struct film film;
    struct mcpt_error err;
    cr_assert(film_init(&film, 8, 8, &err));
    struct planes pr;
    struct stats_image ref = planes_image(&pr, 8, 8, true);
    for (int c = 0; c < 3; c++)
        for (int i = 0; i < 64; i++) {
            plane(&pr, c)[i] = 0.5f;
            plane(&pr, 3 + c)[i] = 1e-4f;
        }
    struct stats_run_info info = {.scene = "s.txt",
                                  .reference = "ref.exr",
                                  .sampler = "sobol",
                                  .integrator = "path-mis",
                                  .max_depth = UINT32_MAX,
                                  .width = 8,
                                  .height = 8};
    struct stats_curve curve;
    stats_curve_init(&curve, &info);
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 5, 5);
    for (uint32_t spp = 1; spp <= 4; spp *= 2) {
        for (int i = 0; i < 64; i++)
            while (film.pixels[i].n < spp)
                film_add(&film.pixels[i], v3_splat(0.5f + 0.3f * (float)gauss(&rng)));
        cr_assert(stats_curve_add(&curve, &film, &ref, 9, spp, 0.1 * spp, NULL, &err));
    }
    struct stats_summary sum;
    cr_assert(stats_summarize(&curve, 0.0, &sum));
    char dir[256];
    test_make_dir(dir, sizeof dir, "stats");
    char csv[300], json[300];
    snprintf(csv, sizeof csv, "%s/c.csv", dir);
    snprintf(json, sizeof json, "%s/c.json", dir);
    cr_assert(stats_write_csv(csv, &curve, &err), "%s", err.msg);
    cr_assert(stats_write_json(json, &curve, &sum, &err), "%s", err.msg);

    const char *text = read_text(csv);
    const char *golden_header =
        "spp,seconds,mse,rmse,relmse,psnr_db,mean_variance,efficiency,sampler,integrator,seed,"
        "error_source,time_to_unit_variance,mse_raw,psnr_raw_db,noise_floor,mrse_pbrt,mae,"
        "max_depth\n";
    cr_assert(strncmp(text, golden_header, strlen(golden_header)) == 0, "header: %.200s", text);
    int n_lines = 0;
    for (const char *p = text; *p; p++)
        n_lines += *p == '\n';
    cr_assert_eq(n_lines, 4);
    const char *row2 = strchr(strchr(text, '\n') + 1, '\n') + 1; /* the 2-spp row */
    cr_assert(strncmp(row2, "2,0.2,", 6) == 0, "row: %.80s", row2);
    cr_assert(strstr(row2, ",sobol,path-mis,9,reference-corrected,") != NULL, "%.200s", row2);
    cr_assert(strstr(row2, ",inf\n") != NULL, "max_depth inf: %.200s", row2);

    text = read_text(json);
    char keys[1024];
    json_keys(text, 1, keys, sizeof keys);
    cr_assert_str_eq(keys, "format,scene,reference,width,height,sampler,integrator,max_depth,"
                           "seeds,error_source,noise_floor,mse_fit,rmse_fit,mse_raw_fit,"
                           "mse_slope_bootstrap_ci95,seconds_per_spp,overhead_seconds,"
                           "time_fit_r2,target,rows");
    json_keys(strstr(text, "\"rows\""), 2, keys, sizeof keys);
    cr_assert_str_eq(keys, "spp,n_seeds,seconds,mse_mean,mse_std,rmse,psnr_db,mean_variance,"
                           "efficiency,time_to_unit_variance,mse_raw_mean,noise_floor");
    json_keys(strstr(text, "\"mse_fit\""), 1, keys, sizeof keys);
    cr_assert_str_eq(keys, "slope,intercept,r2,slope_se,ci95,n_points");
    cr_assert(strstr(text, "\"format\": \"mcpt-convergence-1\"") != NULL);

    stats_summary_free(&sum);
    stats_curve_free(&curve);
    film_free(&film);
    free(pr.data);
    test_remove_dir(dir);
}

/* ---- the command line: snapshots, compare, integrate ---- */

static char tmpdir[256];

static void setup(void) { test_make_dir(tmpdir, sizeof tmpdir, "stats_cli"); }
static void teardown(void) { test_remove_dir(tmpdir); }

/* Runs mcpt with args (NULL-terminated), stdout to tmpdir/stdout.txt; returns the exit status. */
static int run_mcpt(const char *const *args)
{
    char out_path[300];
    snprintf(out_path, sizeof out_path, "%s/stdout.txt", tmpdir);
    return test_run_mcpt(args, out_path, NULL, 0);
}

static bool same_bytes(const char *a, const char *b)
{
    FILE *fa = fopen(a, "rb"), *fb = fopen(b, "rb");
    cr_assert(fa && fb);
    bool same = true;
    for (;;) {
        int ca = fgetc(fa), cb = fgetc(fb);
        if (ca != cb) {
            same = false;
            break;
        }
        if (ca == EOF)
            break;
    }
    fclose(fa);
    fclose(fb);
    return same;
}

/* The channel data of two EXRs are identical, byte for byte. */
static void assert_same_exr_data(const char *a, const char *b)
{
    struct image ia, ib;
    struct mcpt_error err;
    cr_assert(image_read_exr(a, &ia, &err), "%s", err.msg);
    cr_assert(image_read_exr(b, &ib, &err), "%s", err.msg);
    cr_assert_eq(ia.n_channels, ib.n_channels);
    size_t n = (size_t)ia.width * (size_t)ia.height;
    cr_assert_eq(ia.width, ib.width);
    cr_assert_eq(ia.height, ib.height);
    for (int c = 0; c < ia.n_channels; c++) {
        cr_assert_str_eq(ia.names[c], ib.names[c]);
        cr_assert(memcmp(ia.data[c], ib.data[c], n * sizeof(float)) == 0, "channel %s differs",
                  ia.names[c]);
    }
    image_free(&ia);
    image_free(&ib);
}

/* trace_render continues each pixel from its count, so a progressive run with snapshots at
 * 1, 2, 4, 8, 12 spp (and previews between passes) ends on the same image as one call:
 * identical EXR bytes, for every sampler (the stratified one's strata must be those of the final
 * spp), and with --seeds the image is the first seed's.  SOURCE_DATE_EPOCH leaves the render
 * time out of the EXR header, the one attribute in which two runs may differ. */
Test(stats, snapshot_run_equals_plain_run, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(60))
{
    cr_assert_eq(setenv("SOURCE_DATE_EPOCH", "0", 1), 0); /* inherited by the mcpt runs */
    const char *samplers[] = {"sobol", "stratified", "independent"};
    for (int k = 0; k < 3; k++) {
        char plain[300], snap[300], curve[300];
        snprintf(plain, sizeof plain, "%s/plain-%s.exr", tmpdir, samplers[k]);
        snprintf(snap, sizeof snap, "%s/snap-%s.exr", tmpdir, samplers[k]);
        snprintf(curve, sizeof curve, "%s/curve-%s.csv", tmpdir, samplers[k]);
        const char *a[] = {"scenes/cornell-box.txt",
                           "--width",
                           "16",
                           "--height",
                           "12",
                           "--spp",
                           "12",
                           "--seed",
                           "5",
                           "--sampler",
                           samplers[k],
                           "-o",
                           plain,
                           "--quiet",
                           NULL};
        cr_assert_eq(run_mcpt(a), 0);
        /* the independent run also repeats itself for seeds 6 and 7: OUT.exr stays seed 5's */
        const char *b[] = {"scenes/cornell-box.txt",
                           "--width",
                           "16",
                           "--height",
                           "12",
                           "--spp",
                           "12",
                           "--seed",
                           "5",
                           "--sampler",
                           samplers[k],
                           "-o",
                           snap,
                           "--snapshots",
                           "pow2",
                           "--curve",
                           curve,
                           "--preview-every",
                           "0.001",
                           k == 2 ? "--seeds" : NULL,
                           "3",
                           NULL};
        cr_assert_eq(run_mcpt(b), 0);
        assert_same_exr_data(plain, snap);
        cr_assert(same_bytes(plain, snap), "%s: EXR files differ", samplers[k]);
    }
    /* the snapshots and the curve's companions exist; the CSV has the 5 measured rows */
    const char *files[] = {"snap-sobol-spp01.exr",   "snap-sobol-spp08.png", "snap-sobol-spp12.exr",
                           "snap-sobol-contact.png", "curve-sobol.json",     "curve-sobol.svg"};
    for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
        char path[400];
        struct stat st;
        snprintf(path, sizeof path, "%s/%s", tmpdir, files[i]);
        cr_assert(stat(path, &st) == 0, "missing %s", files[i]);
    }
    char path[400];
    snprintf(path, sizeof path, "%s/curve-sobol.csv", tmpdir);
    const char *text = read_text(path);
    int n_lines = 0;
    for (const char *p = text; *p; p++)
        n_lines += *p == '\n';
    cr_assert_eq(n_lines, 6, "%s", text);
    cr_assert(strstr(text, "\n12,") != NULL);
    snprintf(path, sizeof path, "%s/curve-independent.csv", tmpdir);
    text = read_text(path);
    n_lines = 0;
    for (const char *p = text; *p; p++)
        n_lines += *p == '\n';
    cr_assert_eq(n_lines, 16, "3 seeds x 5 spp: %s", text);
    cr_assert(strstr(text, ",independent,path-mis,7,own-variance,") != NULL, "%s", text);
}

/* mcpt compare on a snapshot against the reference of its run prints, as JSON, the documented
 * keys and exactly the CSV row's mse_raw (the same floats, the same formula). */
Test(stats, compare_reproduces_curve_row, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(60))
{
    char ref[300], out[300], curve[300], snap4[300], heat[300];
    snprintf(ref, sizeof ref, "%s/ref.exr", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(curve, sizeof curve, "%s/curve.csv", tmpdir);
    snprintf(snap4, sizeof snap4, "%s/out-spp4.exr", tmpdir);
    snprintf(heat, sizeof heat, "%s/heat.png", tmpdir);
    const char *a[] = {"scenes/cornell-box.txt",
                       "--width",
                       "16",
                       "--height",
                       "16",
                       "--spp",
                       "64",
                       "--seed",
                       "99",
                       "-o",
                       ref,
                       "--quiet",
                       NULL};
    cr_assert_eq(run_mcpt(a), 0);
    const char *b[] = {"scenes/cornell-box.txt",
                       "--width",
                       "16",
                       "--height",
                       "16",
                       "--spp",
                       "8",
                       "--seed",
                       "1",
                       "-o",
                       out,
                       "--snapshots",
                       "pow2",
                       "--reference",
                       ref,
                       "--curve",
                       curve,
                       "--quiet",
                       NULL};
    cr_assert_eq(run_mcpt(b), 0);
    const char *text = read_text(curve);
    const char *row = strstr(text, "\n4,");
    cr_assert(row);
    char mse_raw[64] = "";
    const char *p = row + 1;
    for (int col = 0; col < 13; col++)
        p = strchr(p, ',') + 1;
    snprintf(mse_raw, sizeof mse_raw, "%.*s", (int)(strchr(p, ',') - p), p);

    const char *c[] = {"compare", snap4, ref, "--json", "--heatmap", heat, NULL};
    cr_assert_eq(run_mcpt(c), 0);
    char stdout_path[300];
    snprintf(stdout_path, sizeof stdout_path, "%s/stdout.txt", tmpdir);
    text = read_text(stdout_path);
    char keys[1024];
    json_keys(text, 1, keys, sizeof keys);
    cr_assert_str_eq(keys, "image,reference,width,height,n_values,n_skipped,mse,mse_se,rmse,"
                           "relmse,mrse_pbrt,mae,psnr_db,bias,noise_floor,mse_corrected,"
                           "mse_corrected_se,rmse_corrected,relmse_corrected,psnr_corrected_db,"
                           "mean_variance,relmse_own,max_ref_luminance,n_pixels_masked");
    char want[96];
    snprintf(want, sizeof want, "\"mse\": %s,", mse_raw);
    cr_assert(strstr(text, want) != NULL, "want %s in %s", want, text);
    struct stat st;
    cr_assert(stat(heat, &st) == 0 && st.st_size > 0);

    /* bad input: exit 2 (missing file, wrong size, missing argument) */
    const char *missing[] = {"compare", snap4, "no-such.exr", NULL};
    cr_assert_eq(run_mcpt(missing), 2);
    char small[300];
    snprintf(small, sizeof small, "%s/small.exr", tmpdir);
    const char *d[] = {"scenes/cornell-box.txt",
                       "--width",
                       "8",
                       "--height",
                       "8",
                       "--spp",
                       "1",
                       "-o",
                       small,
                       "--quiet",
                       NULL};
    cr_assert_eq(run_mcpt(d), 0);
    const char *mismatch[] = {"compare", small, ref, NULL};
    cr_assert_eq(run_mcpt(mismatch), 2);
    const char *one[] = {"compare", small, NULL};
    cr_assert_eq(run_mcpt(one), 2);
    const char *bad_ref[] = {"scenes/cornell-box.txt",
                             "--width",
                             "8",
                             "--height",
                             "8",
                             "--spp",
                             "2",
                             "-o",
                             out,
                             "--reference",
                             ref,
                             "--quiet",
                             NULL};
    cr_assert_eq(run_mcpt(bad_ref), 2);
}

/* ---- the sampler laboratory ---- */

/* Each exact integral against the midpoint rule on a 2000 x 2000 grid: to 1e-6 for the smooth
 * integrands, to 1e-3 for the discontinuous ones (the grid misclassifies cells along an edge). */
Test(stats, integrand_exact_values)
{
    for (int f = 0; f < STATS_FN_COUNT; f++) {
        const int n = 2000;
        double sum = 0.0;
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++)
                sum += stats_integrand_eval((enum stats_integrand)f, (i + 0.5) / n, (j + 0.5) / n);
        double quad = sum / ((double)n * n), exact = stats_integrand_exact((enum stats_integrand)f);
        bool smooth = f == STATS_FN_GAUSSIAN || f == STATS_FN_POLYNOMIAL;
        cr_assert(fabs(quad - exact) < (smooth ? 1e-6 : 1e-3), "%s: quadrature %.7f, exact %.7f",
                  stats_integrand_name((enum stats_integrand)f), quad, exact);
        enum stats_integrand back;
        cr_assert(stats_integrand_parse(stats_integrand_name((enum stats_integrand)f), &back));
        cr_assert_eq((int)back, f);
    }
}

/* Independent points: MSE = Var f / N exactly in expectation, so the fitted slope over
 * N = 1 .. 1024 (64 seeds) is -1 within its 95% interval (widened by 0.05 for the fit's own
 * noise), and the MSE at N = 1 is Var f = I - I^2 for the disk's 0/1 integrand within 4
 * standard errors. */
Test(stats, integrate_independent_is_n_to_minus_one)
{
    struct stats_integrate_row rows[11];
    size_t n = stats_integrate(STATS_FN_DISK, SAMPLER_INDEPENDENT, 1024, 64, 0, rows);
    cr_assert_eq(n, 11u);
    double x[11], y[11];
    for (size_t i = 0; i < n; i++) {
        x[i] = log((double)rows[i].spp);
        y[i] = log(rows[i].mse);
    }
    struct stats_fit fit;
    cr_assert(stats_fit_line(x, y, n, &fit));
    cr_assert(fit.ci_lo - 0.05 <= -1.0 && -1.0 <= fit.ci_hi + 0.05, "slope %.3f [%.3f, %.3f]",
              fit.slope, fit.ci_lo, fit.ci_hi);
    double i_disk = stats_integrand_exact(STATS_FN_DISK);
    cr_assert(fabs(rows[0].mse - (i_disk - i_disk * i_disk)) < 4.0 * rows[0].mse_se);
}
