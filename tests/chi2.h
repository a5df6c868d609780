/* tests/chi2.h - header-only chi-square goodness-of-fit test for sampling routines, after the
 * chi2 tests of Mitsuba (Jakob et al., mitsuba3, python/mitsuba/chi2.py): draw n samples, count
 * them on a grid over the domain, integrate the pdf over every cell (nested adaptive Simpson),
 * pool cells whose expected count is below 5, and turn Pearson's statistic into a p-value with
 * the regularised upper incomplete gamma function Q(dof / 2, chi2 / 2).  A test rejects at
 * significance CHI2_ALPHA = 0.01, Bonferroni-corrected: p < 0.01 / n_tests fails.
 *
 * Usage (see tests/material_test.c for real ones):
 *   static bool draw(void *ctx, const float u[3], vec3 *w) { *w = my_warp(u[0], u[1]); ... }
 *   static double density(void *ctx, vec3 w) { return my_pdf(w); }  // per sr, or per area
 *   struct chi2_spec spec = chi2_sphere(draw, density, &ctx);       // or chi2_plane(...)
 *   struct chi2_result r;
 *   chi2_run(&spec, &r);
 *   cr_assert(chi2_accept(&r, n_tests), "%s", r.msg);
 * Discrete distributions (lobe choice, alias tables): chi2_counts(expected, observed, ...). */
#ifndef MCPT_TESTS_CHI2_H
#define MCPT_TESTS_CHI2_H

#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "vec.h"

#define CHI2_ALPHA 0.01       /* significance level before the Bonferroni correction */
#define CHI2_MIN_EXPECTED 5.0 /* cells expected to hold fewer samples are pooled (Cochran 1954) */

enum chi2_domain {
    CHI2_SPHERE, /* unit vectors; cells over (cos theta in [-1, 1]) x (phi in [-pi, pi]), so
                    every cell has the same solid angle; pdf per steradian */
    CHI2_PLANE,  /* points (x, y) of [x0, x1] x [y0, y1] (z ignored); pdf per unit area */
};

/* Draws one sample from three uniforms in [0, 1); false = no sample (counted as a miss, which
 * is expected with probability 1 - integral of the pdf over the domain). */
typedef bool (*chi2_sample_fn)(void *ctx, const float u[3], vec3 *out);
/* Density of the sampled point w (unit vector, or (x, y, 0) on the plane). */
typedef double (*chi2_pdf_fn)(void *ctx, vec3 w);

struct chi2_spec {
    enum chi2_domain domain;
    chi2_sample_fn sample;
    chi2_pdf_fn pdf;
    void *ctx;
    uint64_t n_samples;    /* default 1000000 */
    int n_rows;            /* cells along cos theta (or y); default 32 */
    int n_cols;            /* cells along phi (or x); default 64 */
    double x0, x1, y0, y1; /* CHI2_PLANE bounds */
    uint64_t seed;         /* of the uniforms; default 1 */
};

struct chi2_result {
    double statistic;    /* Pearson's sum (O - E)^2 / E over the pooled cells */
    int dof;             /* cells after pooling, minus 1 */
    double p_value;      /* Q(dof / 2, statistic / 2); 0 when a sample fell where pdf = 0 */
    double pdf_integral; /* integral of the pdf over the domain (1 for a complete sampler) */
    uint64_t n_missed;   /* draws that returned false */
    char msg[256];       /* a one-line summary for assertion messages */
};

/* The regularised upper incomplete gamma function Q(a, x) = Gamma(a, x) / Gamma(a): series for
 * x < a + 1, Lentz's continued fraction otherwise (Press et al., Numerical Recipes, 3rd ed.,
 * sec. 6.2, gser/gcf). */
static inline double chi2_gamma_q(double a, double x)
{
    if (x <= 0.0)
        return 1.0;
    double log_prefix = -x + a * log(x) - lgamma(a);
    if (x < a + 1.0) {
        double ap = a, del = 1.0 / a, sum = del;
        for (int i = 0; i < 100000 && fabs(del) > fabs(sum) * 1e-15; i++) {
            ap += 1.0;
            del *= x / ap;
            sum += del;
        }
        return 1.0 - sum * exp(log_prefix);
    }
    const double tiny = 1e-300;
    double b = x + 1.0 - a, c = 1.0 / tiny, d = 1.0 / b, h = d;
    for (int i = 1; i < 100000; i++) {
        double an = -i * (i - a);
        b += 2.0;
        d = an * d + b;
        if (fabs(d) < tiny)
            d = tiny;
        c = b + an / c;
        if (fabs(c) < tiny)
            c = tiny;
        d = 1.0 / d;
        double del = d * c;
        h *= del;
        if (fabs(del - 1.0) < 1e-15)
            break;
    }
    return exp(log_prefix) * h;
}

/* P(X >= statistic) for X chi-square distributed with dof degrees of freedom. */
static inline double chi2_p_value(double statistic, int dof)
{
    return dof > 0 ? chi2_gamma_q(0.5 * dof, 0.5 * statistic) : 1.0;
}

/* Does r pass at CHI2_ALPHA with a Bonferroni correction over n_tests tests? */
static inline bool chi2_accept(const struct chi2_result *r, int n_tests)
{
    return r->p_value >= CHI2_ALPHA / (n_tests > 0 ? n_tests : 1);
}

static inline int chi2_cmp_expected(const void *a, const void *b)
{
    const double *x = a, *y = b;
    return (x[0] > y[0]) - (x[0] < y[0]);
}

/* Pearson's test of observed counts against expected counts (both n_cells long, expected summing
 * to the number of draws).  Cells expected to hold fewer than CHI2_MIN_EXPECTED are pooled into
 * one; a pool still below it joins the smallest remaining cell.  Any count in a cell with
 * expected count below 1e-9 fails outright (p = 0): the sampler produced what its pdf says is
 * impossible.  Fills statistic, dof, p_value and msg. */
static inline void chi2_counts(const double *expected, const uint64_t *observed, size_t n_cells,
                               struct chi2_result *r)
{
    double *pairs = malloc(sizeof(double) * 2 * (n_cells ? n_cells : 1));
    r->statistic = 0.0;
    r->dof = 0;
    r->p_value = 0.0;
    if (!pairs) {
        snprintf(r->msg, sizeof r->msg, "chi2: out of memory");
        return;
    }
    for (size_t i = 0; i < n_cells; i++) {
        if (expected[i] < 1e-9 && observed[i] > 0) {
            snprintf(r->msg, sizeof r->msg, "chi2: %llu samples in cell %zu, where the pdf is 0",
                     (unsigned long long)observed[i], i);
            free(pairs);
            return;
        }
        pairs[2 * i] = expected[i];
        pairs[2 * i + 1] = (double)observed[i];
    }
    qsort(pairs, n_cells, 2 * sizeof(double), chi2_cmp_expected);
    double pool_e = 0.0, pool_o = 0.0, stat = 0.0;
    size_t first = 0;
    while (first < n_cells && pairs[2 * first] < CHI2_MIN_EXPECTED) {
        pool_e += pairs[2 * first];
        pool_o += pairs[2 * first + 1];
        first++;
    }
    int n_bins = 0;
    if (pool_e > 0.0 && pool_e < CHI2_MIN_EXPECTED && first < n_cells) {
        pairs[2 * first] += pool_e; /* a small pool joins the smallest regular cell */
        pairs[2 * first + 1] += pool_o;
    } else if (pool_e > 0.0) {
        stat += (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
        n_bins++;
    }
    for (size_t i = first; i < n_cells; i++) {
        double e = pairs[2 * i], o = pairs[2 * i + 1];
        stat += (o - e) * (o - e) / e;
        n_bins++;
    }
    free(pairs);
    r->statistic = stat;
    r->dof = n_bins - 1;
    r->p_value = chi2_p_value(stat, r->dof);
    snprintf(r->msg, sizeof r->msg, "chi2 = %.1f, dof = %d, p = %.3g", stat, r->dof, r->p_value);
}

/* ---- integration of the pdf over a cell: nested adaptive Simpson ---- */

struct chi2_integrand {
    const struct chi2_spec *spec;
    double outer;   /* the fixed row coordinate while integrating along a row */
    double x0, x1;  /* the cell's column interval */
    double eps_row; /* absolute tolerance of one integral along a row */
};

/* The pdf at row coordinate y (cos theta, or y) and column coordinate x (phi, or x); the
 * sphere's parameterisation (cos theta, phi) has unit Jacobian: d omega = d(cos theta) d phi. */
static inline double chi2_pdf_at(const struct chi2_spec *s, double y, double x)
{
    vec3 w;
    if (s->domain == CHI2_SPHERE) {
        double sin_theta = sqrt(fmax(0.0, 1.0 - y * y));
        w = v3((float)(sin_theta * cos(x)), (float)(sin_theta * sin(x)), (float)y);
    } else {
        w = v3((float)x, (float)y, 0.0f);
    }
    double p = s->pdf(s->ctx, w);
    return isfinite(p) ? p : 0.0;
}

typedef double (*chi2_fn1)(struct chi2_integrand *it, double t);

static inline double chi2_simpson(chi2_fn1 f, struct chi2_integrand *it, double a, double b,
                                  double fa, double fm, double fb, double whole, double eps,
                                  int depth, int min_depth)
{
    double m = 0.5 * (a + b), lm = 0.5 * (a + m), rm = 0.5 * (m + b);
    double flm = f(it, lm), frm = f(it, rm);
    double left = (m - a) / 6.0 * (fa + 4.0 * flm + fm);
    double right = (b - m) / 6.0 * (fm + 4.0 * frm + fb);
    double diff = left + right - whole;
    if (depth <= 0 || (min_depth <= 0 && fabs(diff) <= 15.0 * eps))
        return left + right + diff / 15.0; /* Richardson extrapolation */
    return chi2_simpson(f, it, a, m, fa, flm, fm, left, 0.5 * eps, depth - 1, min_depth - 1) +
           chi2_simpson(f, it, m, b, fm, frm, fb, right, 0.5 * eps, depth - 1, min_depth - 1);
}

static inline double chi2_integrate(chi2_fn1 f, struct chi2_integrand *it, double a, double b,
                                    double eps)
{
    double fa = f(it, a), fm = f(it, 0.5 * (a + b)), fb = f(it, b);
    double whole = (b - a) / 6.0 * (fa + 4.0 * fm + fb);
    return chi2_simpson(f, it, a, b, fa, fm, fb, whole, eps, 14, 2);
}

static inline double chi2_inner(struct chi2_integrand *it, double x)
{
    return chi2_pdf_at(it->spec, it->outer, x);
}

static inline double chi2_outer(struct chi2_integrand *it, double y)
{
    struct chi2_integrand inner = {it->spec, y, it->x0, it->x1, it->eps_row};
    return chi2_integrate(chi2_inner, &inner, it->x0, it->x1, it->eps_row);
}

/* ---- the test ---- */

static inline struct chi2_spec chi2_sphere(chi2_sample_fn sample, chi2_pdf_fn pdf, void *ctx)
{
    return (struct chi2_spec){.domain = CHI2_SPHERE,
                              .sample = sample,
                              .pdf = pdf,
                              .ctx = ctx,
                              .n_samples = 1000000,
                              .n_rows = 32,
                              .n_cols = 64,
                              .seed = 1};
}

static inline struct chi2_spec chi2_plane(chi2_sample_fn sample, chi2_pdf_fn pdf, void *ctx,
                                          double x0, double x1, double y0, double y1)
{
    return (struct chi2_spec){.domain = CHI2_PLANE,
                              .sample = sample,
                              .pdf = pdf,
                              .ctx = ctx,
                              .n_samples = 1000000,
                              .n_rows = 32,
                              .n_cols = 32,
                              .x0 = x0,
                              .x1 = x1,
                              .y0 = y0,
                              .y1 = y1,
                              .seed = 1};
}

/* SplitMix64 (Steele et al. 2014): the test's own uniforms, independent of sample.c. */
static inline float chi2_uniform(uint64_t *state)
{
    uint64_t z = (*state += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    z ^= z >> 31;
    return (float)(z >> 40) * 0x1p-24f;
}

/* Runs the test of spec: fills *r (statistic, dof, p_value, pdf_integral, n_missed, msg).
 * A sample outside the domain (not unit length, outside the bounds, or NaN) fails it with
 * p = 0.  The misses form one more cell, expected n (1 - pdf_integral). */
static inline void chi2_run(const struct chi2_spec *spec, struct chi2_result *r)
{
    int rows = spec->n_rows, cols = spec->n_cols;
    size_t n_cells = (size_t)rows * (size_t)cols + 1; /* the last cell: misses */
    double *expected = calloc(n_cells, sizeof(double));
    uint64_t *observed = calloc(n_cells, sizeof(uint64_t));
    *r = (struct chi2_result){0};
    if (!expected || !observed) {
        snprintf(r->msg, sizeof r->msg, "chi2: out of memory");
        goto done;
    }
    bool sphere = spec->domain == CHI2_SPHERE;
    double y0 = sphere ? -1.0 : spec->y0, y1 = sphere ? 1.0 : spec->y1;
    double x0 = sphere ? -MCPT_PI : spec->x0, x1 = sphere ? MCPT_PI : spec->x1;
    double dy = (y1 - y0) / rows, dx = (x1 - x0) / cols;
    double n = (double)spec->n_samples;

    /* histogram */
    uint64_t state = spec->seed ? spec->seed : 1;
    for (uint64_t i = 0; i < spec->n_samples; i++) {
        float u[3] = {chi2_uniform(&state), chi2_uniform(&state), chi2_uniform(&state)};
        vec3 w;
        if (!spec->sample(spec->ctx, u, &w)) {
            observed[n_cells - 1]++;
            continue;
        }
        double y, x;
        if (sphere) {
            double len = sqrt((double)w.x * w.x + (double)w.y * w.y + (double)w.z * w.z);
            if (!(fabs(len - 1.0) < 1e-3)) {
                snprintf(r->msg, sizeof r->msg,
                         "chi2: sample %llu is not a unit vector "
                         "(%g, %g, %g)",
                         (unsigned long long)i, w.x, w.y, w.z);
                goto done;
            }
            y = fmin(1.0, fmax(-1.0, w.z / len));
            x = atan2(w.y, w.x);
        } else {
            y = w.y;
            x = w.x;
        }
        if (!(y >= y0 && y <= y1 && x >= x0 && x <= x1)) {
            snprintf(r->msg, sizeof r->msg, "chi2: sample %llu outside the domain (%g, %g, %g)",
                     (unsigned long long)i, w.x, w.y, w.z);
            goto done;
        }
        int row = (int)((y - y0) / dy), col = (int)((x - x0) / dx);
        row = row < 0 ? 0 : row >= rows ? rows - 1 : row;
        col = col < 0 ? 0 : col >= cols ? cols - 1 : col;
        observed[(size_t)row * cols + col]++;
    }
    r->n_missed = observed[n_cells - 1];

    /* expected counts: n times the pdf integrated over each cell, to a tolerance well below
     * one count */
    double total = 0.0;
    for (int row = 0; row < rows; row++)
        for (int col = 0; col < cols; col++) {
            struct chi2_integrand it = {spec, 0.0, x0 + col * dx, x0 + (col + 1) * dx,
                                        1e-3 / n / dy};
            double p = chi2_integrate(chi2_outer, &it, y0 + row * dy, y0 + (row + 1) * dy,
                                      1e-3 / n);
            expected[(size_t)row * cols + col] = n * p;
            total += p;
        }
    r->pdf_integral = total;
    expected[n_cells - 1] = n * fmax(0.0, 1.0 - total);
    chi2_counts(expected, observed, n_cells, r);
    char tail[128];
    snprintf(tail, sizeof tail, ", pdf integral %.5f, %llu of %llu missed", total,
             (unsigned long long)r->n_missed, (unsigned long long)spec->n_samples);
    size_t used = strlen(r->msg);
    snprintf(r->msg + used, sizeof r->msg - used, "%s", tail);
done:
    free(expected);
    free(observed);
}

#endif
