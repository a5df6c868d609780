/* stats.c - how far an image is from the truth, and how fast that distance shrinks.
 * Metrics of an image against a reference (MSE, relMSE, PSNR, ...) with the reference's own
 * noise removed (Whittle et al. 2017, "Analysis of reported error in Monte Carlo rendered
 * images"); convergence curves over spp and seeds (Celarek et al. 2019, "Quantifying the Error
 * of Light Transport Algorithms"); least-squares fits on log-log axes with Student-t intervals;
 * their CSV, JSON and text; and the sampler laboratory, which measures the same error (MSE
 * over seeds) for estimates of 2-D integrals with known values.  Pictures of these numbers are
 * drawn by plot.c.  Formats: docs/convergence.md.  Nothing here changes a render. */
#include "stats.h"

#include <stdlib.h>

#include "file.h"

/* ---- the metrics ----
 * a = the image, r = the reference, one value per pixel channel; each metric is a mean over
 * every pixel channel (R, G and B of every pixel):
 *   MSE       = mean (a - r)^2                 variance + bias^2 of the estimator; ~ 1/N in MC
 *   RMSE      = sqrt(MSE)                      in radiance units; ~ N^-1/2
 *   relMSE    = mean (a - r)^2 / (r^2 + 0.01)  scale-free: dark and bright regions weigh alike;
 *                                              the 0.01 keeps black pixels from dividing by 0
 *   MRSE_pbrt = mean (a - r)^2 / (r + 0.01)^2  pbrt-v4's Image::MRSE, as imgtool diff prints it
 *   MAE       = mean |a - r|                   less dominated by rare bright outliers
 *   PSNR      = 10 log10(peak^2 / MSE)         peak 1 (display white at exposure 0), on the
 *                                              linear, unclamped values: PSNR is MSE in dB
 *   bias_c    = mean (a_c - r_c)               a systematic offset, per channel
 * Reference noise: a and r are independent estimates of the true image mu, r unbiased, so
 *   E[(a - r)^2] = E[(a - mu)^2] + E[(r - mu)^2] = MSE_true(a) + Var(r)
 * and MSE - mean Var(r) estimates a's own MSE.  mean Var(r), the noise floor, is the least MSE a
 * comparison against r can show: uncorrected curves flatten there (the Unity study's plateau).
 * Without a reference, the image's own variance of the mean estimates its MSE (an unbiased
 * estimator's MSE is its variance). */

static double psnr_of(double mse)
{
    if (isnan(mse))
        return NAN;
    return mse > 0.0 ? 10.0 * log10(STATS_PSNR_PEAK * STATS_PSNR_PEAK / mse) : INFINITY;
}

static double sqrt_or_nan(double v) { return v > 0.0 ? sqrt(v) : NAN; }

bool stats_image_from_exr(const struct image *img, const char *path, struct stats_image *out,
                          struct mcpt_error *err)
{
    memset(out, 0, sizeof *out);
    out->width = img->width;
    out->height = img->height;
    int rgb[3];
    size_t prefix_len;
    if (!image_find_rgb(img, rgb, &prefix_len)) {
        char got[256] = "";
        size_t len = 0;
        for (int k = 0; k < img->n_channels && len + 40 < sizeof got; k++)
            len += (size_t)snprintf(got + len, sizeof got - len, "%s%s", k ? ", " : "",
                                    img->names[k]);
        mcpt_error_set(err, path, 0, 0, "expected " IMAGE_RGB_EXPECTED ", got %s",
                       img->n_channels ? got : "none");
        return false;
    }
    /* the variances and counts mcpt writes beside them, in the same layer */
    static const char *var_names[3] = {"variance.R", "variance.G", "variance.B"};
    int n_var = 0;
    for (int c = 0; c < 3; c++) {
        out->rgb[c] = img->data[rgb[c]];
        int idx = image_find_beside(img, rgb[0], prefix_len, var_names[c]);
        if (idx >= 0) {
            out->var[c] = img->data[idx];
            n_var++;
        }
    }
    if (n_var < 3)
        out->var[0] = out->var[1] = out->var[2] = NULL;
    int idx = image_find_beside(img, rgb[0], prefix_len, "samples");
    out->count = idx >= 0 ? img->data[idx] : NULL;
    /* an image without one pixel the metrics can use would give NaN for every one of them */
    size_t n_pixels = (size_t)img->width * (size_t)img->height;
    for (size_t i = 0; i < n_pixels; i++) {
        bool usable = true;
        for (int c = 0; c < 3; c++)
            usable = usable && isfinite(out->rgb[c][i]) &&
                     (!out->var[0] || (out->var[c][i] >= 0.0f && isfinite(out->var[c][i])));
        if (usable)
            return true;
    }
    mcpt_error_set(err, path, 0, 0,
                   "expected a pixel with finite R, G and B%s, got none in %dx%d",
                   out->var[0] ? " and variances >= 0" : "", img->width, img->height);
    return false;
}

void stats_image_from_film(const struct film *film, float *planes, struct stats_image *out)
{
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    float *mean[3], *var[3];
    for (int c = 0; c < 3; c++) {
        mean[c] = planes + (size_t)c * n_pixels;
        var[c] = planes + (size_t)(3 + c) * n_pixels;
        out->rgb[c] = mean[c];
        out->var[c] = var[c];
    }
    out->count = planes + 6 * n_pixels;
    out->width = film->width;
    out->height = film->height;
    film_resolve(film, mean, var, planes + 6 * n_pixels);
}

/* Running mean and sum of squared deviations (Welford 1962), for standard errors. */
struct welford {
    double n;
    double mean;
    double m2;
};

static void welford_add(struct welford *w, double x)
{
    w->n += 1.0;
    double d = x - w->mean;
    w->mean += d / w->n;
    w->m2 += d * (x - w->mean);
}

static double welford_var(const struct welford *w)
{
    return w->n > 1.0 ? w->m2 / (w->n - 1.0) : NAN;
}

bool stats_compare(const struct stats_image *a, const struct stats_image *ref,
                   struct stats_metrics *m, struct mcpt_error *err)
{
    return stats_compare_where(a, ref, INFINITY, m, err);
}

/* Whether pixel i of ref is compared: its luminance 0.2126 R + 0.7152 G + 0.0722 B is at most
 * max_lum (a pixel whose luminance is NaN counts as included: its channels are skipped
 * one by one, as without a mask). */
static bool pixel_included(const struct stats_image *ref, size_t i, double max_lum)
{
    if (!ref || isinf(max_lum))
        return true;
    double lum = 0.2126 * ref->rgb[0][i] + 0.7152 * ref->rgb[1][i] + 0.0722 * ref->rgb[2][i];
    return !(lum > max_lum);
}

bool stats_compare_where(const struct stats_image *a, const struct stats_image *ref,
                         double max_ref_luminance, struct stats_metrics *m, struct mcpt_error *err)
{
    if (ref && (ref->width != a->width || ref->height != a->height)) {
        mcpt_error_set(err, "", 0, 0, "expected a reference of the image's size %dx%d, got %dx%d",
                       a->width, a->height, ref->width, ref->height);
        return false;
    }
    if (isnan(max_ref_luminance)) {
        mcpt_error_set(err, "", 0, 0, "expected a luminance bound, got nan");
        return false;
    }
    double nan = NAN;
    *m = (struct stats_metrics){
        .width = a->width,
        .height = a->height,
        .mse = nan,
        .mse_se = nan,
        .rmse = nan,
        .relmse = nan,
        .mrse_pbrt = nan,
        .mae = nan,
        .psnr_db = nan,
        .bias = {nan, nan, nan},
        .noise_floor = nan,
        .mse_corrected = nan,
        .mse_corrected_se = nan,
        .rmse_corrected = nan,
        .relmse_corrected = nan,
        .psnr_corrected_db = nan,
        .mean_variance = nan,
        .relmse_own = nan,
        .max_ref_luminance = max_ref_luminance,
    };
    size_t n_pixels = (size_t)a->width * (size_t)a->height;
    for (size_t i = 0; i < n_pixels; i++)
        m->n_pixels_masked += !pixel_included(ref, i, max_ref_luminance);
    bool has_var_a = a->var[0] && a->var[1] && a->var[2];
    bool has_var_r = ref && ref->var[0] && ref->var[1] && ref->var[2];

    /* the image's own variance: known when every pixel has at least two samples */
    if (has_var_a) {
        bool known = true;
        for (size_t i = 0; a->count && i < n_pixels; i++)
            known &= a->count[i] >= 2.0f;
        double sum_var = 0.0, sum_rel = 0.0;
        size_t n = 0;
        for (size_t i = 0; known && i < n_pixels; i++)
            for (int c = 0; c < 3; c++) {
                double v = a->var[c][i], x = a->rgb[c][i];
                /* a variance below 0 (no render writes one) is skipped like a NaN */
                if (!(v >= 0.0 && isfinite(v)) || !isfinite(x) ||
                    !pixel_included(ref, i, max_ref_luminance))
                    continue;
                sum_var += v;
                sum_rel += v / (x * x + STATS_RELMSE_EPS);
                n++;
            }
        if (known && n) {
            m->mean_variance = sum_var / (double)n;
            m->relmse_own = sum_rel / (double)n;
        }
    }
    if (!ref)
        return true;

    double sum_sq = 0.0, sum_rel = 0.0, sum_mrse = 0.0, sum_abs = 0.0, sum_var_r = 0.0;
    double sum_rel_corr = 0.0, sum_bias[3] = {0.0, 0.0, 0.0};
    size_t n_bias[3] = {0, 0, 0};
    struct welford w_sq = {0}, w_corr = {0}; /* per-pixel sums, for the standard errors */
    for (size_t i = 0; i < n_pixels; i++) {
        double pix_sq = 0.0, pix_corr = 0.0;
        int pix_n = 0;
        if (!pixel_included(ref, i, max_ref_luminance))
            continue;
        for (int c = 0; c < 3; c++) {
            double x = a->rgb[c][i], r = ref->rgb[c][i];
            double var_r = has_var_r ? ref->var[c][i] : 0.0;
            if (!isfinite(x) || !isfinite(r) || !(var_r >= 0.0 && isfinite(var_r))) {
                m->n_skipped++;
                continue;
            }
            double d = x - r;
            /* se = (a - r)^2; rel = se / (r^2 + eps); mrse = se / (r + eps)^2 */
            double se = d * d;
            sum_sq += se;
            sum_rel += se / (r * r + STATS_RELMSE_EPS);
            sum_mrse += se / ((r + STATS_MRSE_EPS) * (r + STATS_MRSE_EPS));
            sum_abs += fabs(d);
            sum_bias[c] += d;
            n_bias[c]++;
            sum_var_r += var_r;
            sum_rel_corr += (se - var_r) / (r * r + STATS_RELMSE_EPS);
            pix_sq += se;
            pix_corr += se - var_r;
            pix_n++;
        }
        if (pix_n) {
            welford_add(&w_sq, pix_sq);
            welford_add(&w_corr, pix_corr);
        }
        m->n_values += (size_t)pix_n;
    }
    if (!m->n_values)
        return true;
    double n = (double)m->n_values;
    /* mse = sum over pixels of s_pix / n, pixels independent: Var(mse) = n_pix Var(s_pix) / n^2 */
    m->mse = sum_sq / n;
    m->mse_se = sqrt(w_sq.n * welford_var(&w_sq)) / n;
    m->rmse = sqrt(m->mse);
    m->relmse = sum_rel / n;
    m->mrse_pbrt = sum_mrse / n;
    m->mae = sum_abs / n;
    m->psnr_db = psnr_of(m->mse);
    for (int c = 0; c < 3; c++)
        m->bias[c] = n_bias[c] ? sum_bias[c] / (double)n_bias[c] : NAN;
    if (has_var_r) {
        m->noise_floor = sum_var_r / n;
        m->mse_corrected = m->mse - m->noise_floor;
        m->mse_corrected_se = sqrt(w_corr.n * welford_var(&w_corr)) / n;
        m->rmse_corrected = sqrt_or_nan(m->mse_corrected);
        m->relmse_corrected = sum_rel_corr / n;
        m->psnr_corrected_db = m->mse_corrected > 0.0 ? psnr_of(m->mse_corrected) : NAN;
    }
    return true;
}

void stats_relative_error_map(const struct stats_image *a, const struct stats_image *r, double *e)
{
    size_t n_pixels = (size_t)a->width * (size_t)a->height;
    for (size_t i = 0; i < n_pixels; i++) {
        /* e = mean over channels of (a - r)^2 / (r^2 + 0.01): the relMSE's terms */
        double sum = 0.0;
        int n = 0;
        for (int c = 0; c < 3; c++) {
            double x = a->rgb[c][i], ref = r->rgb[c][i];
            if (isfinite(x) && isfinite(ref)) {
                sum += (x - ref) * (x - ref) / (ref * ref + STATS_RELMSE_EPS);
                n++;
            }
        }
        e[i] = n ? sum / n : NAN;
    }
}

/* ---- number formatting shared by the writers ---- */

/* CSV and text: "%.9g", or nan / inf / -inf. */
static const char *fmt_num(char *buf, size_t buf_bytes, double v)
{
    if (isnan(v))
        snprintf(buf, buf_bytes, "nan");
    else if (isinf(v))
        snprintf(buf, buf_bytes, "%s", v > 0 ? "inf" : "-inf");
    else
        snprintf(buf, buf_bytes, "%.9g", v);
    return buf;
}

/* JSON has no NaN or infinity: those become null. */
static void json_num(FILE *f, double v)
{
    if (isfinite(v))
        fprintf(f, "%.9g", v);
    else
        fputs("null", f);
}

static void json_str(FILE *f, const char *s)
{
    if (!s) {
        fputs("null", f);
        return;
    }
    fputc('"', f);
    for (; *s; s++) {
        unsigned char ch = (unsigned char)*s;
        if (ch == '"' || ch == '\\')
            fprintf(f, "\\%c", ch);
        else if (ch < 0x20)
            fprintf(f, "\\u%04x", ch);
        else
            fputc(ch, f);
    }
    fputc('"', f);
}

void stats_print_metrics(FILE *f, const struct stats_metrics *m, const char *a_path,
                         const char *ref_path)
{
    char b[4][64];
    fprintf(f, "image              %s\nreference          %s\n", a_path, ref_path);
    fprintf(f, "size               %dx%d, %zu values compared, %zu skipped (NaN or infinite)\n",
            m->width, m->height, m->n_values, m->n_skipped);
    if (!isinf(m->max_ref_luminance))
        fprintf(f, "pixels             %zu left out: reference luminance > %s\n",
                m->n_pixels_masked, fmt_num(b[0], 64, m->max_ref_luminance));
    fprintf(f, "mse                %s  (standard error %s)\n", fmt_num(b[0], 64, m->mse),
            fmt_num(b[1], 64, m->mse_se));
    fprintf(f, "rmse               %s\n", fmt_num(b[0], 64, m->rmse));
    fprintf(f, "relmse             %s  mean (a-r)^2/(r^2+0.01)\n", fmt_num(b[0], 64, m->relmse));
    fprintf(f, "mrse_pbrt          %s  mean (a-r)^2/(r+0.01)^2, pbrt-v4 MRSE\n",
            fmt_num(b[0], 64, m->mrse_pbrt));
    fprintf(f, "mae                %s\n", fmt_num(b[0], 64, m->mae));
    fprintf(f, "psnr_db            %s  peak 1, linear values, not clamped\n",
            fmt_num(b[0], 64, m->psnr_db));
    fprintf(f, "bias               R %s  G %s  B %s  mean (a-r)\n", fmt_num(b[0], 64, m->bias[0]),
            fmt_num(b[1], 64, m->bias[1]), fmt_num(b[2], 64, m->bias[2]));
    if (!isnan(m->noise_floor)) {
        fprintf(f,
                "noise_floor        %s  mean variance of the reference: the least MSE it "
                "can show\n",
                fmt_num(b[0], 64, m->noise_floor));
        fprintf(f, "mse_corrected      %s  (standard error %s)  mse - noise_floor\n",
                fmt_num(b[0], 64, m->mse_corrected), fmt_num(b[1], 64, m->mse_corrected_se));
        fprintf(f, "rmse_corrected     %s\n", fmt_num(b[0], 64, m->rmse_corrected));
        fprintf(f, "relmse_corrected   %s\n", fmt_num(b[0], 64, m->relmse_corrected));
        fprintf(f, "psnr_corrected_db  %s\n", fmt_num(b[0], 64, m->psnr_corrected_db));
    } else {
        fprintf(f, "noise_floor        unknown: the reference has no variance.R/G/B channels\n");
    }
    if (!isnan(m->mean_variance))
        fprintf(f,
                "mean_variance      %s  the image's own MSE estimate (its variance "
                "channels)\n",
                fmt_num(b[0], 64, m->mean_variance));
}

void stats_write_metrics_json(FILE *f, const struct stats_metrics *m, const char *a_path,
                              const char *ref_path)
{
    fputs("{\"image\": ", f);
    json_str(f, a_path);
    fputs(", \"reference\": ", f);
    json_str(f, ref_path);
    fprintf(f, ", \"width\": %d, \"height\": %d, \"n_values\": %zu, \"n_skipped\": %zu", m->width,
            m->height, m->n_values, m->n_skipped);
    const struct {
        const char *key;
        double v;
    } fields[] = {
        {"mse", m->mse},         {"mse_se", m->mse_se},       {"rmse", m->rmse},
        {"relmse", m->relmse},   {"mrse_pbrt", m->mrse_pbrt}, {"mae", m->mae},
        {"psnr_db", m->psnr_db},
    };
    for (size_t i = 0; i < sizeof fields / sizeof fields[0]; i++) {
        fprintf(f, ", \"%s\": ", fields[i].key);
        json_num(f, fields[i].v);
    }
    fputs(", \"bias\": [", f);
    for (int c = 0; c < 3; c++) {
        json_num(f, m->bias[c]);
        fputs(c < 2 ? ", " : "]", f);
    }
    const struct {
        const char *key;
        double v;
    } more[] = {
        {"noise_floor", m->noise_floor},
        {"mse_corrected", m->mse_corrected},
        {"mse_corrected_se", m->mse_corrected_se},
        {"rmse_corrected", m->rmse_corrected},
        {"relmse_corrected", m->relmse_corrected},
        {"psnr_corrected_db", m->psnr_corrected_db},
        {"mean_variance", m->mean_variance},
        {"relmse_own", m->relmse_own},
        {"max_ref_luminance", m->max_ref_luminance},
    };
    for (size_t i = 0; i < sizeof more / sizeof more[0]; i++) {
        fprintf(f, ", \"%s\": ", more[i].key);
        json_num(f, more[i].v);
    }
    fprintf(f, ", \"n_pixels_masked\": %zu}\n", m->n_pixels_masked);
}

/* ---- line fits ---- */

/* t(0.975, dof) for dof = 1 .. 30, to 4 decimals, as in the standard tables (computed by
 * integrating the t density; tests/stats_test.c checks them the same way). */
static const double T975[31] = {
    NAN,    12.7062, 4.3027, 3.1824, 2.7764, 2.5706, 2.4469, 2.3646, 2.3060, 2.2622, 2.2281,
    2.2010, 2.1788,  2.1604, 2.1448, 2.1314, 2.1199, 2.1098, 2.1009, 2.0930, 2.0860, 2.0796,
    2.0739, 2.0687,  2.0639, 2.0595, 2.0555, 2.0518, 2.0484, 2.0452, 2.0423,
};

double stats_t_quantile_975(unsigned dof)
{
    if (dof == 0)
        return NAN;
    if (dof <= 30)
        return T975[dof];
    /* Abramowitz & Stegun 1964, eq. 26.7.5: t = x + g1/v + g2/v^2 + g3/v^3 + g4/v^4 with x the
     * normal quantile; error < 1e-7 for v > 30 */
    const double x = 1.959963984540054; /* normal 0.975 quantile */
    double x2 = x * x, v = (double)dof;
    double g1 = (x2 + 1.0) * x / 4.0;
    double g2 = ((5.0 * x2 + 16.0) * x2 + 3.0) * x / 96.0;
    double g3 = (((3.0 * x2 + 19.0) * x2 + 17.0) * x2 - 15.0) * x / 384.0;
    double g4 = ((((79.0 * x2 + 776.0) * x2 + 1482.0) * x2 - 1920.0) * x2 - 945.0) * x / 92160.0;
    return x + g1 / v + g2 / (v * v) + g3 / (v * v * v) + g4 / (v * v * v * v);
}

bool stats_fit_line(const double *x, const double *y, size_t n, struct stats_fit *fit)
{
    double nan = NAN;
    *fit = (struct stats_fit){.slope = nan,
                              .intercept = nan,
                              .r2 = nan,
                              .slope_se = nan,
                              .ci_lo = nan,
                              .ci_hi = nan};
    double sx = 0.0, sy = 0.0;
    for (size_t i = 0; i < n; i++)
        if (isfinite(x[i]) && isfinite(y[i])) {
            sx += x[i];
            sy += y[i];
            fit->n++;
        }
    if (fit->n < 2)
        return false;
    double mx = sx / (double)fit->n, my = sy / (double)fit->n;
    /* slope = Sxy / Sxx, intercept = mean y - slope mean x (centred sums: no cancellation) */
    double sxx = 0.0, sxy = 0.0, syy = 0.0;
    for (size_t i = 0; i < n; i++)
        if (isfinite(x[i]) && isfinite(y[i])) {
            sxx += (x[i] - mx) * (x[i] - mx);
            sxy += (x[i] - mx) * (y[i] - my);
            syy += (y[i] - my) * (y[i] - my);
        }
    if (!(sxx > 0.0))
        return false;
    fit->slope = sxy / sxx;
    fit->intercept = my - fit->slope * mx;
    double sse = 0.0;
    for (size_t i = 0; i < n; i++)
        if (isfinite(x[i]) && isfinite(y[i])) {
            double e = y[i] - (fit->intercept + fit->slope * x[i]);
            sse += e * e;
        }
    fit->r2 = syy > 0.0 ? 1.0 - sse / syy : 1.0;
    if (fit->n >= 3) {
        /* Var(slope) = s^2 / Sxx with s^2 = SSE / (n - 2); CI slope -+ t(0.975, n - 2) se */
        fit->slope_se = sqrt(sse / (double)(fit->n - 2) / sxx);
        double t = stats_t_quantile_975((unsigned)(fit->n - 2));
        fit->ci_lo = fit->slope - t * fit->slope_se;
        fit->ci_hi = fit->slope + t * fit->slope_se;
    }
    return true;
}

/* ---- convergence curves ---- */

const char *stats_error_source_name(enum stats_error_source source)
{
    switch (source) {
    case STATS_ERR_REFERENCE_CORRECTED:
        return "reference-corrected";
    case STATS_ERR_REFERENCE:
        return "reference";
    case STATS_ERR_OWN_VARIANCE:
        return "own-variance";
    }
    return "?";
}

void stats_curve_init(struct stats_curve *c, const struct stats_run_info *info)
{
    memset(c, 0, sizeof *c);
    snprintf(c->scene, sizeof c->scene, "%s", info->scene ? info->scene : "");
    snprintf(c->reference, sizeof c->reference, "%s", info->reference ? info->reference : "");
    snprintf(c->sampler, sizeof c->sampler, "%s", info->sampler ? info->sampler : "");
    snprintf(c->integrator, sizeof c->integrator, "%s", info->integrator ? info->integrator : "");
    c->max_depth = info->max_depth;
    c->width = info->width;
    c->height = info->height;
}

void stats_curve_free(struct stats_curve *c)
{
    free(c->points);
    free(c->planes);
    memset(c, 0, sizeof *c);
}

bool stats_curve_add(struct stats_curve *c, const struct film *film, const struct stats_image *ref,
                     uint64_t seed, uint32_t spp, double seconds, struct stats_image *measured,
                     struct mcpt_error *err)
{
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    if (!c->planes) {
        c->planes = malloc(sizeof(float) * 7 * n_pixels);
        if (!c->planes)
            goto oom;
    }
    if (c->n_points == c->cap_points) {
        size_t cap = c->cap_points ? 2 * c->cap_points : 64;
        struct stats_point *p = realloc(c->points, cap * sizeof *p);
        if (!p)
            goto oom;
        c->points = p;
        c->cap_points = cap;
    }
    struct stats_image img;
    stats_image_from_film(film, c->planes, &img);
    struct stats_metrics m;
    if (!stats_compare(&img, ref, &m, err))
        return false;

    struct stats_point *p = &c->points[c->n_points];
    *p = (struct stats_point){.seed = seed,
                              .spp = spp,
                              .seconds = seconds,
                              .mean_variance = m.mean_variance,
                              .mse_raw = m.mse,
                              .psnr_raw_db = m.psnr_db,
                              .noise_floor = m.noise_floor,
                              .mrse_pbrt = m.mrse_pbrt,
                              .mae = m.mae};
    if (ref && !isnan(m.noise_floor)) {
        p->source = STATS_ERR_REFERENCE_CORRECTED;
        p->mse = m.mse_corrected;
        p->relmse = m.relmse_corrected;
    } else if (ref) {
        p->source = STATS_ERR_REFERENCE;
        p->mse = m.mse;
        p->relmse = m.relmse;
    } else {
        p->source = STATS_ERR_OWN_VARIANCE;
        p->mse = m.mean_variance;
        p->relmse = m.relmse_own;
    }
    p->rmse = sqrt_or_nan(p->mse);
    /* a corrected MSE <= 0 lies below the reference's noise: no PSNR can be claimed */
    p->psnr_db = p->source == STATS_ERR_REFERENCE_CORRECTED && !(p->mse > 0.0) ? NAN
                                                                               : psnr_of(p->mse);
    /* efficiency = 1 / (MSE time) (PBRT 4e, ch. 2, "Error in Monte Carlo Estimators");
     * time to unit variance = V time, its own-variance counterpart */
    p->efficiency = p->mse > 0.0 && seconds > 0.0 ? 1.0 / (p->mse * seconds) : NAN;
    p->time_to_unit_variance = p->mean_variance * seconds;

    if (measured)
        *measured = img;
    c->n_points++;
    return true;
oom:
    mcpt_error_runtime(err, NULL, "out of memory recording the convergence curve");
    return false;
}

uint32_t stats_next_pow2(uint32_t spp_done, uint32_t spp_final)
{
    uint64_t p = 1;
    while (p <= spp_done)
        p <<= 1;
    return p < spp_final ? (uint32_t)p : spp_final;
}

/* ---- summary: the curve over seeds, and its fits ---- */

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static int cmp_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

/* The seed bootstrap of the MSE slope (Efron & Tibshirani 1993, "An Introduction to the
 * Bootstrap", ch. 13, percentile interval): resample whole seeds with replacement, average
 * their MSE per spp, refit; the 2.5th and 97.5th percentiles of the refitted slopes bound it.
 * Resampling whole runs keeps each run's correlation across spp (its later snapshots contain
 * its earlier samples), which the OLS interval ignores.  seeds: the n_seeds distinct seeds. */
static void seed_bootstrap(const struct stats_curve *c, struct stats_summary *s,
                           const uint64_t *seeds)
{
    s->mse_slope_boot_lo = s->mse_slope_boot_hi = NAN;
    size_t k = s->n_seeds, n = s->n_rows, b_max = STATS_BOOTSTRAP_RESAMPLES;
    if (k < STATS_BOOTSTRAP_MIN_SEEDS || n < 3)
        return;
    double *mse = malloc(k * n * sizeof *mse); /* mse[seed * n + row] */
    double *x = malloc(n * sizeof *x), *y = malloc(n * sizeof *y);
    double *slopes = malloc(b_max * sizeof *slopes);
    if (!mse || !x || !y || !slopes)
        goto done;
    for (size_t i = 0; i < k * n; i++)
        mse[i] = NAN;
    for (size_t i = 0; i < c->n_points; i++) {
        size_t si = 0, r = 0;
        while (seeds[si] != c->points[i].seed)
            si++;
        while (s->rows[r].spp != c->points[i].spp)
            r++;
        mse[si * n + r] = c->points[i].mse;
    }
    for (size_t r = 0; r < n; r++)
        x[r] = log((double)s->rows[r].spp);
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 0x5eedb007u, 1); /* fixed: the same curve gives the same interval */
    size_t n_slopes = 0;
    for (size_t b = 0; b < b_max; b++) {
        for (size_t r = 0; r < n; r++)
            y[r] = 0.0;
        for (size_t j = 0; j < k; j++) {
            size_t si = sample_pcg32_bounded(&rng, (uint32_t)k);
            for (size_t r = 0; r < n; r++)
                y[r] += mse[si * n + r] / (double)k;
        }
        for (size_t r = 0; r < n; r++)
            y[r] = y[r] > 0.0 ? log(y[r]) : NAN;
        struct stats_fit fit;
        if (stats_fit_line(x, y, n, &fit) && fit.n == s->mse_fit.n)
            slopes[n_slopes++] = fit.slope;
    }
    if (n_slopes >= b_max / 2) {
        qsort(slopes, n_slopes, sizeof *slopes, cmp_double);
        s->mse_slope_boot_lo = slopes[(size_t)(0.025 * (double)(n_slopes - 1) + 0.5)];
        s->mse_slope_boot_hi = slopes[(size_t)(0.975 * (double)(n_slopes - 1) + 0.5)];
    }
done:
    free(mse);
    free(x);
    free(y);
    free(slopes);
}

bool stats_summarize(const struct stats_curve *c, double target_rmse, struct stats_summary *s)
{
    memset(s, 0, sizeof *s);
    s->source = c->n_points ? c->points[0].source : STATS_ERR_OWN_VARIANCE;
    double nan = NAN;
    s->target_rmse = s->target_spp = s->target_seconds = nan;
    s->mse_slope_boot_lo = s->mse_slope_boot_hi = nan;
    size_t cap = c->n_points + 1;
    uint32_t *spps = calloc(cap, sizeof *spps);
    double *x = calloc(cap, sizeof *x);
    double *y = calloc(cap, sizeof *y);
    uint64_t *seeds = calloc(cap, sizeof *seeds);
    s->rows = calloc(cap, sizeof *s->rows);
    bool ok = spps && x && y && seeds && s->rows;
    if (!ok) {
        free(s->rows);
        s->rows = NULL;
        goto done;
    }
    /* distinct spp values, increasing; distinct seeds */
    for (size_t i = 0; i < c->n_points; i++)
        spps[i] = c->points[i].spp;
    qsort(spps, c->n_points, sizeof *spps, cmp_u32);
    for (size_t i = 0; i < c->n_points; i++) {
        if (s->n_rows == 0 || s->rows[s->n_rows - 1].spp != spps[i])
            s->rows[s->n_rows++].spp = spps[i];
        bool seen = false;
        for (size_t k = 0; k < s->n_seeds; k++)
            seen |= seeds[k] == c->points[i].seed;
        if (!seen)
            seeds[s->n_seeds++] = c->points[i].seed;
    }
    for (size_t r = 0; r < s->n_rows; r++) {
        struct stats_ensemble_row *row = &s->rows[r];
        struct welford w_mse = {0};
        double sum_sec = 0.0, sum_var = 0.0, sum_raw = 0.0, sum_floor = 0.0;
        for (size_t i = 0; i < c->n_points; i++) {
            const struct stats_point *p = &c->points[i];
            if (p->spp != row->spp)
                continue;
            welford_add(&w_mse, p->mse);
            sum_sec += p->seconds;
            sum_var += p->mean_variance;
            sum_raw += p->mse_raw;
            sum_floor += p->noise_floor;
            row->n_seeds++;
        }
        double k = (double)row->n_seeds;
        row->mse_mean = w_mse.mean;
        row->mse_std = sqrt(welford_var(&w_mse));
        row->rmse = sqrt_or_nan(row->mse_mean);
        row->psnr_db = psnr_of(row->mse_mean);
        row->seconds = sum_sec / k;
        row->mean_variance = sum_var / k;
        row->efficiency = row->mse_mean > 0.0 && row->seconds > 0.0
                              ? 1.0 / (row->mse_mean * row->seconds)
                              : NAN;
        row->time_to_unit_variance = row->mean_variance * row->seconds;
        row->mse_raw_mean = sum_raw / k;
        row->noise_floor = sum_floor / k;
    }
    /* ln mse = a + b ln spp: b = -1 for an unbiased Monte Carlo estimator; rmse: b = -1/2 */
    for (size_t r = 0; r < s->n_rows; r++) {
        x[r] = log((double)s->rows[r].spp);
        y[r] = s->rows[r].mse_mean > 0.0 ? log(s->rows[r].mse_mean) : NAN;
    }
    stats_fit_line(x, y, s->n_rows, &s->mse_fit);
    for (size_t r = 0; r < s->n_rows; r++)
        y[r] = s->rows[r].rmse > 0.0 ? log(s->rows[r].rmse) : NAN;
    stats_fit_line(x, y, s->n_rows, &s->rmse_fit);
    if (s->source != STATS_ERR_OWN_VARIANCE) {
        for (size_t r = 0; r < s->n_rows; r++)
            y[r] = s->rows[r].mse_raw_mean > 0.0 ? log(s->rows[r].mse_raw_mean) : NAN;
        stats_fit_line(x, y, s->n_rows, &s->mse_raw_fit);
    } else {
        stats_fit_line(NULL, NULL, 0, &s->mse_raw_fit);
    }
    seed_bootstrap(c, s, seeds);
    /* seconds = overhead + (seconds per spp) spp */
    for (size_t r = 0; r < s->n_rows; r++) {
        x[r] = (double)s->rows[r].spp;
        y[r] = s->rows[r].seconds;
    }
    stats_fit_line(x, y, s->n_rows, &s->time_fit);

    /* extrapolation: ln target = a + b ln spp  =>  spp = exp((ln target - a) / b) */
    if (s->n_rows)
        s->target_rmse = target_rmse > 0.0 ? target_rmse : s->rows[s->n_rows - 1].rmse / 2.0;
    if (s->rmse_fit.n >= 2 && s->rmse_fit.slope < 0.0 && s->target_rmse > 0.0) {
        s->target_spp = exp((log(s->target_rmse) - s->rmse_fit.intercept) / s->rmse_fit.slope);
        if (s->time_fit.n >= 2)
            s->target_seconds = s->time_fit.intercept + s->time_fit.slope * s->target_spp;
    }
done:
    free(spps);
    free(x);
    free(y);
    free(seeds);
    return ok;
}

void stats_summary_free(struct stats_summary *s)
{
    free(s->rows);
    memset(s, 0, sizeof *s);
}

/* ---- CSV, JSON and text ---- */

void stats_depth_name(uint32_t max_depth, char *buf, size_t buf_bytes)
{
    if (max_depth == UINT32_MAX)
        snprintf(buf, buf_bytes, "inf");
    else
        snprintf(buf, buf_bytes, "%u", max_depth);
}

bool stats_write_csv(const char *path, const struct stats_curve *c, struct mcpt_error *err)
{
    struct file_atomic o;
    if (!file_atomic_open(&o, path, err) || !file_atomic_stream(&o, err))
        return false;
    char depth[16], b[13][40];
    stats_depth_name(c->max_depth, depth, sizeof depth);
    fprintf(o.f, "%s\n", STATS_CSV_HEADER);
    for (size_t i = 0; i < c->n_points; i++) {
        const struct stats_point *p = &c->points[i];
        fprintf(o.f, "%u,%s,%s,%s,%s,%s,%s,%s,%s,%s,%llu,%s,%s,%s,%s,%s,%s,%s,%s\n", p->spp,
                fmt_num(b[0], 40, p->seconds), fmt_num(b[1], 40, p->mse),
                fmt_num(b[2], 40, p->rmse), fmt_num(b[3], 40, p->relmse),
                fmt_num(b[4], 40, p->psnr_db), fmt_num(b[5], 40, p->mean_variance),
                fmt_num(b[6], 40, p->efficiency), c->sampler, c->integrator,
                (unsigned long long)p->seed, stats_error_source_name(p->source),
                fmt_num(b[7], 40, p->time_to_unit_variance), fmt_num(b[8], 40, p->mse_raw),
                fmt_num(b[9], 40, p->psnr_raw_db), fmt_num(b[10], 40, p->noise_floor),
                fmt_num(b[11], 40, p->mrse_pbrt), fmt_num(b[12], 40, p->mae), depth);
    }
    return file_atomic_commit(&o, err);
}

static void json_fit(FILE *f, const char *key, const struct stats_fit *fit)
{
    fprintf(f, "  \"%s\": ", key);
    if (fit->n < 2 || isnan(fit->slope)) {
        fputs("null,\n", f);
        return;
    }
    fputs("{\"slope\": ", f);
    json_num(f, fit->slope);
    fputs(", \"intercept\": ", f);
    json_num(f, fit->intercept);
    fputs(", \"r2\": ", f);
    json_num(f, fit->r2);
    fputs(", \"slope_se\": ", f);
    json_num(f, fit->slope_se);
    fputs(", \"ci95\": [", f);
    json_num(f, fit->ci_lo);
    fputs(", ", f);
    json_num(f, fit->ci_hi);
    fprintf(f, "], \"n_points\": %zu},\n", fit->n);
}

bool stats_write_json(const char *path, const struct stats_curve *c, const struct stats_summary *s,
                      struct mcpt_error *err)
{
    struct file_atomic o;
    FILE *f;
    if (!file_atomic_open(&o, path, err) || !(f = file_atomic_stream(&o, err)))
        return false;
    char depth[16];
    stats_depth_name(c->max_depth, depth, sizeof depth);
    fputs("{\n  \"format\": \"mcpt-convergence-1\",\n  \"scene\": ", f);
    json_str(f, c->scene);
    fputs(",\n  \"reference\": ", f);
    json_str(f, c->reference[0] ? c->reference : NULL);
    fprintf(f, ",\n  \"width\": %d,\n  \"height\": %d,\n  \"sampler\": ", c->width, c->height);
    json_str(f, c->sampler);
    fputs(",\n  \"integrator\": ", f);
    json_str(f, c->integrator);
    fprintf(f, ",\n  \"max_depth\": \"%s\",\n  \"seeds\": [", depth);
    /* the seeds in order of first appearance */
    size_t n_seeds = 0;
    for (size_t i = 0; i < c->n_points; i++) {
        bool seen = false;
        for (size_t k = 0; k < i; k++)
            seen |= c->points[k].seed == c->points[i].seed;
        if (!seen)
            fprintf(f, "%s%llu", n_seeds++ ? ", " : "", (unsigned long long)c->points[i].seed);
    }
    fputs("],\n  \"error_source\": ", f);
    json_str(f, stats_error_source_name(s->source));
    fputs(",\n  \"noise_floor\": ", f);
    json_num(f, s->n_rows ? s->rows[s->n_rows - 1].noise_floor : NAN);
    fputs(",\n", f);
    json_fit(f, "mse_fit", &s->mse_fit);
    json_fit(f, "rmse_fit", &s->rmse_fit);
    json_fit(f, "mse_raw_fit", &s->mse_raw_fit);
    fputs("  \"mse_slope_bootstrap_ci95\": ", f);
    if (isnan(s->mse_slope_boot_lo)) {
        fputs("null,\n", f);
    } else {
        fputc('[', f);
        json_num(f, s->mse_slope_boot_lo);
        fputs(", ", f);
        json_num(f, s->mse_slope_boot_hi);
        fputs("],\n", f);
    }
    fputs("  \"seconds_per_spp\": ", f);
    json_num(f, s->time_fit.slope);
    fputs(",\n  \"overhead_seconds\": ", f);
    json_num(f, s->time_fit.intercept);
    fputs(",\n  \"time_fit_r2\": ", f);
    json_num(f, s->time_fit.r2);
    fputs(",\n  \"target\": {\"rmse\": ", f);
    json_num(f, s->target_rmse);
    fputs(", \"spp\": ", f);
    json_num(f, s->target_spp);
    fputs(", \"seconds\": ", f);
    json_num(f, s->target_seconds);
    fputs("},\n  \"rows\": [\n", f);
    for (size_t r = 0; r < s->n_rows; r++) {
        const struct stats_ensemble_row *row = &s->rows[r];
        fprintf(f, "    {\"spp\": %u, \"n_seeds\": %zu, \"seconds\": ", row->spp, row->n_seeds);
        const struct {
            const char *key;
            double v;
        } fields[] = {
            {"mse_mean", row->mse_mean},
            {"mse_std", row->mse_std},
            {"rmse", row->rmse},
            {"psnr_db", row->psnr_db},
            {"mean_variance", row->mean_variance},
            {"efficiency", row->efficiency},
            {"time_to_unit_variance", row->time_to_unit_variance},
            {"mse_raw_mean", row->mse_raw_mean},
            {"noise_floor", row->noise_floor},
        };
        json_num(f, row->seconds);
        for (size_t i = 0; i < sizeof fields / sizeof fields[0]; i++) {
            fprintf(f, ", \"%s\": ", fields[i].key);
            json_num(f, fields[i].v);
        }
        fprintf(f, "}%s\n", r + 1 < s->n_rows ? "," : "");
    }
    fputs("  ]\n}\n", f);
    return file_atomic_commit(&o, err);
}

static void print_fit(FILE *f, const char *what, const struct stats_fit *fit)
{
    if (fit->n < 2 || isnan(fit->slope))
        return;
    fprintf(f, "%-16s ~ spp^%+.4f", what, fit->slope);
    if (fit->n >= 3)
        fprintf(f, "  95%% CI [%+.4f, %+.4f]", fit->ci_lo, fit->ci_hi);
    fprintf(f, "  R^2 %.5f  (%zu points)\n", fit->r2, fit->n);
}

void stats_print_summary(FILE *f, const struct stats_curve *c, const struct stats_summary *s)
{
    char b[8][40];
    fprintf(f, "convergence: %s, %dx%d, sampler %s, integrator %s, %zu seed%s; error: %s", c->scene,
            c->width, c->height, c->sampler, c->integrator, s->n_seeds, s->n_seeds == 1 ? "" : "s",
            stats_error_source_name(s->source));
    if (s->source == STATS_ERR_REFERENCE_CORRECTED && s->n_rows)
        fprintf(f, " (noise floor %.4g removed)", s->rows[s->n_rows - 1].noise_floor);
    fputc('\n', f);
    fprintf(f, "%8s %10s %12s %12s %12s %9s %12s %12s\n", "spp", "seconds", "mse", "mse_std",
            "rmse", "psnr_db", "efficiency", "time_unit_var");
    for (size_t r = 0; r < s->n_rows; r++) {
        const struct stats_ensemble_row *row = &s->rows[r];
        fprintf(f, "%8u %10.4f %12s %12s %12s %9.3f %12s %12s\n", row->spp, row->seconds,
                fmt_num(b[0], 40, row->mse_mean), fmt_num(b[1], 40, row->mse_std),
                fmt_num(b[2], 40, row->rmse), row->psnr_db, fmt_num(b[3], 40, row->efficiency),
                fmt_num(b[4], 40, row->time_to_unit_variance));
    }
    print_fit(f, "MSE", &s->mse_fit);
    if (!isnan(s->mse_slope_boot_lo))
        fprintf(f, "%-16s   seed-bootstrap 95%% CI of the MSE slope [%+.4f, %+.4f] (%zu seeds)\n",
                "", s->mse_slope_boot_lo, s->mse_slope_boot_hi, s->n_seeds);
    print_fit(f, "RMSE", &s->rmse_fit);
    if (s->source == STATS_ERR_REFERENCE_CORRECTED)
        print_fit(f, "uncorrected MSE", &s->mse_raw_fit);
    if (s->time_fit.n >= 2)
        fprintf(f, "time             %.6g s per spp + %.4g s overhead  R^2 %.5f\n",
                s->time_fit.slope, s->time_fit.intercept, s->time_fit.r2);
    if (isfinite(s->target_spp))
        fprintf(f, "target RMSE %.4g: about %.0f spp, %.3g s (extrapolated from the fits)\n",
                s->target_rmse, s->target_spp, s->target_seconds);
}

/* ---- the sampler laboratory ----
 * Each integrand f on [0,1]^2 has a known integral I; the estimate of n samples is
 * F_n = (1/n) sum f(u_i) with u_i the sampler's points, and MSE(n) = E[(F_n - I)^2] over seeds.
 * Independent points give MSE ~ n^-1 for every f; stratified and low-discrepancy points do
 * better the smoother f is (PBRT 4e, ch. 8, "Sampling and Reconstruction"). */

#define GAUSS_SIGMA 0.15 /* standard deviation of the Gaussian bump, in [0,1] units */

const char *stats_integrand_name(enum stats_integrand f)
{
    switch (f) {
    case STATS_FN_STEP:
        return "step";
    case STATS_FN_DISK:
        return "disk";
    case STATS_FN_CHECKER:
        return "checkerboard";
    case STATS_FN_GAUSSIAN:
        return "gaussian";
    case STATS_FN_POLYNOMIAL:
        return "polynomial";
    case STATS_FN_COUNT:
        break;
    }
    return "?";
}

bool stats_integrand_parse(const char *name, enum stats_integrand *f)
{
    for (int k = 0; k < STATS_FN_COUNT; k++)
        if (strcmp(name, stats_integrand_name((enum stats_integrand)k)) == 0) {
            *f = (enum stats_integrand)k;
            return true;
        }
    return false;
}

double stats_integrand_eval(enum stats_integrand f, double x, double y)
{
    switch (f) {
    case STATS_FN_STEP:
        return x < 1.0 / 3.0 ? 1.0 : 0.0;
    case STATS_FN_DISK:
        return x * x + y * y < 1.0 ? 1.0 : 0.0;
    case STATS_FN_CHECKER:
        return ((int)(10.0 * x) + (int)(10.0 * y)) % 2 == 0 ? 1.0 : 0.0;
    case STATS_FN_GAUSSIAN: {
        double dx = x - 0.5, dy = y - 0.5;
        return exp(-(dx * dx + dy * dy) / (2.0 * GAUSS_SIGMA * GAUSS_SIGMA));
    }
    case STATS_FN_POLYNOMIAL:
        return x * x + y * y + x * y;
    case STATS_FN_COUNT:
        break;
    }
    return NAN;
}

double stats_integrand_exact(enum stats_integrand f)
{
    switch (f) {
    case STATS_FN_STEP:
        return 1.0 / 3.0;
    case STATS_FN_DISK:
        return 0.78539816339744830962; /* pi / 4 */
    case STATS_FN_CHECKER:
        return 0.5; /* 50 of the 100 cells */
    case STATS_FN_GAUSSIAN: {
        /* separable: (int_0^1 exp(-(x-1/2)^2 / (2 s^2)) dx)^2 = (s sqrt(2 pi) erf(1 / (2 s
         * sqrt 2)))^2 */
        double one_d = GAUSS_SIGMA * sqrt(2.0 * 3.14159265358979323846) *
                       erf(0.5 / (GAUSS_SIGMA * sqrt(2.0)));
        return one_d * one_d;
    }
    case STATS_FN_POLYNOMIAL:
        return 11.0 / 12.0; /* 1/3 + 1/3 + 1/4 */
    case STATS_FN_COUNT:
        break;
    }
    return NAN;
}

size_t stats_integrate(enum stats_integrand f, enum sampler_kind kind, uint32_t spp_max,
                       uint32_t n_seeds, uint64_t seed, struct stats_integrate_row *rows)
{
    double exact = stats_integrand_exact(f);
    size_t n_rows = 0;
    for (uint64_t spp = 1; spp <= spp_max; spp *= 2) {
        struct welford w = {0};
        for (uint32_t k = 0; k < n_seeds; k++) {
            /* F_n = (1/n) sum_i f(u_i): points 0 .. n-1 of pixel 0, one stratified set */
            double sum = 0.0;
            for (uint32_t i = 0; i < spp; i++) {
                struct sampler sm;
                sample_start_spp(&sm, kind, seed + k, 0, i, (uint32_t)spp);
                vec2 u = sample_2d(&sm);
                sum += stats_integrand_eval(f, u.x, u.y);
            }
            double d = sum / (double)spp - exact;
            welford_add(&w, d * d);
        }
        rows[n_rows++] = (struct stats_integrate_row){.spp = (uint32_t)spp,
                                                      .mse = w.mean,
                                                      .mse_se = sqrt(welford_var(&w) / w.n)};
    }
    return n_rows;
}
