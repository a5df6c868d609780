/* stats.c - how far an image is from the truth, and how fast that distance shrinks.
 * Metrics of an image against a reference (MSE, relMSE, PSNR, ...) with the reference's own
 * noise removed (Whittle et al. 2017, "Analysis of reported error in Monte Carlo rendered
 * images"); convergence curves over spp and seeds (Celarek et al. 2019, "Quantifying the Error
 * of Light Transport Algorithms"); least-squares fits on log-log axes with Student-t intervals;
 * CSV, JSON, SVG and PNG writers; and the sampler laboratory's integrals on [0,1]^2.
 * Formats: docs/convergence.md.  Nothing here changes a render: it only reads films and images. */
#include "stats.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdlib.h>
#include <unistd.h>

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
    static const char *rgb_names[3] = {"R", "G", "B"};
    static const char *var_names[3] = {"variance.R", "variance.G", "variance.B"};
    memset(out, 0, sizeof *out);
    out->width = img->width;
    out->height = img->height;
    int n_var = 0;
    for (int c = 0; c < 3; c++) {
        int idx = image_find_channel(img, rgb_names[c]);
        if (idx < 0) {
            char got[256] = "";
            size_t len = 0;
            for (int k = 0; k < img->n_channels && len + 40 < sizeof got; k++)
                len += (size_t)snprintf(got + len, sizeof got - len, "%s%s", k ? ", " : "",
                                        img->names[k]);
            mcpt_error_set(err, path, 0, 0, "expected channels R, G and B, got %s",
                           img->n_channels ? got : "none");
            return false;
        }
        out->rgb[c] = img->data[idx];
        idx = image_find_channel(img, var_names[c]);
        if (idx >= 0) {
            out->var[c] = img->data[idx];
            n_var++;
        }
    }
    if (n_var < 3)
        out->var[0] = out->var[1] = out->var[2] = NULL;
    int idx = image_find_channel(img, "samples");
    out->count = idx >= 0 ? img->data[idx] : NULL;
    return true;
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
    if (ref && (ref->width != a->width || ref->height != a->height)) {
        mcpt_error_set(err, "", 0, 0, "expected a reference of the image's size %dx%d, got %dx%d",
                       a->width, a->height, ref->width, ref->height);
        return false;
    }
    double nan = NAN;
    *m = (struct stats_metrics){
        .width = a->width, .height = a->height,
        .mse = nan, .mse_se = nan, .rmse = nan, .relmse = nan, .mrse_pbrt = nan, .mae = nan,
        .psnr_db = nan, .bias = {nan, nan, nan}, .noise_floor = nan, .mse_corrected = nan,
        .mse_corrected_se = nan, .rmse_corrected = nan, .relmse_corrected = nan,
        .psnr_corrected_db = nan, .mean_variance = nan, .relmse_own = nan,
    };
    size_t n_pixels = (size_t)a->width * (size_t)a->height;
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
                if (!isfinite(v) || !isfinite(x))
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
        for (int c = 0; c < 3; c++) {
            double x = a->rgb[c][i], r = ref->rgb[c][i];
            double var_r = has_var_r ? ref->var[c][i] : 0.0;
            if (!isfinite(x) || !isfinite(r) || !isfinite(var_r)) {
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
        fprintf(f, "noise_floor        %s  mean variance of the reference: the least MSE it "
                "can show\n", fmt_num(b[0], 64, m->noise_floor));
        fprintf(f, "mse_corrected      %s  (standard error %s)  mse - noise_floor\n",
                fmt_num(b[0], 64, m->mse_corrected), fmt_num(b[1], 64, m->mse_corrected_se));
        fprintf(f, "rmse_corrected     %s\n", fmt_num(b[0], 64, m->rmse_corrected));
        fprintf(f, "relmse_corrected   %s\n", fmt_num(b[0], 64, m->relmse_corrected));
        fprintf(f, "psnr_corrected_db  %s\n", fmt_num(b[0], 64, m->psnr_corrected_db));
    } else {
        fprintf(f, "noise_floor        unknown: the reference has no variance.R/G/B channels\n");
    }
    if (!isnan(m->mean_variance))
        fprintf(f, "mean_variance      %s  the image's own MSE estimate (its variance "
                "channels)\n", fmt_num(b[0], 64, m->mean_variance));
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
        {"mse", m->mse}, {"mse_se", m->mse_se}, {"rmse", m->rmse}, {"relmse", m->relmse},
        {"mrse_pbrt", m->mrse_pbrt}, {"mae", m->mae}, {"psnr_db", m->psnr_db},
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
        {"noise_floor", m->noise_floor}, {"mse_corrected", m->mse_corrected},
        {"mse_corrected_se", m->mse_corrected_se}, {"rmse_corrected", m->rmse_corrected},
        {"relmse_corrected", m->relmse_corrected}, {"psnr_corrected_db", m->psnr_corrected_db},
        {"mean_variance", m->mean_variance}, {"relmse_own", m->relmse_own},
    };
    for (size_t i = 0; i < sizeof more / sizeof more[0]; i++) {
        fprintf(f, ", \"%s\": ", more[i].key);
        json_num(f, more[i].v);
    }
    fputs("}\n", f);
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
    *fit = (struct stats_fit){.slope = nan, .intercept = nan, .r2 = nan, .slope_se = nan,
                              .ci_lo = nan, .ci_hi = nan};
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

/* ---- text files written whole or not at all: a temporary name beside, fsync, rename ---- */

struct out_file {
    FILE *f;
    char tmp[4160]; /* "<path>.tmp.<pid>.<n>" */
};

static bool out_open(const char *path, struct out_file *o, struct mcpt_error *err)
{
    o->f = NULL;
    int fd = -1;
    for (int n = 0; n < 100 && fd < 0; n++) {
        int len = snprintf(o->tmp, sizeof o->tmp, "%s.tmp.%ld.%d", path, (long)getpid(), n);
        if (len < 0 || (size_t)len >= sizeof o->tmp) {
            errno = ENAMETOOLONG;
            break;
        }
        fd = open(o->tmp, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
        if (fd < 0 && errno != EEXIST)
            break;
    }
    if (fd >= 0)
        o->f = fdopen(fd, "w");
    if (!o->f) {
        mcpt_error_set(err, path, 0, 0, "cannot write: %s", strerror(errno));
        if (fd >= 0) {
            close(fd);
            unlink(o->tmp);
        }
        return false;
    }
    return true;
}

static bool out_commit(const char *path, struct out_file *o, struct mcpt_error *err)
{
    int error = 0;
    if (fflush(o->f) != 0 || ferror(o->f) || fsync(fileno(o->f)) != 0)
        error = errno ? errno : EIO;
    if (fclose(o->f) != 0 && !error)
        error = errno;
    if (!error && rename(o->tmp, path) != 0)
        error = errno;
    if (error) {
        mcpt_error_set(err, path, 0, 0, "cannot write: %s", strerror(error));
        unlink(o->tmp);
        return false;
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
    for (size_t i = 0; i < c->n_thumbs; i++)
        free(c->thumbs[i].rgb8);
    free(c->thumbs);
    free(c->points);
    free(c->planes);
    memset(c, 0, sizeof *c);
}

/* sRGB transfer function, IEC 61966-2-1, of a linear value clamped to [0, 1], to 8 bits. */
static uint8_t srgb8(double v)
{
    v = v > 0.0 ? (v < 1.0 ? v : 1.0) : 0.0;
    double e = v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
    return (uint8_t)(e * 255.0 + 0.5);
}

#define THUMB_SIZE 160 /* pixels: a contact-sheet tile's longer side, about */

/* An sRGB thumbnail of img: box-filtered down by a whole factor when larger than THUMB_SIZE,
 * else repeated up by a whole factor. */
static bool make_thumb(const struct stats_image *img, float exposure, struct stats_thumb *t)
{
    int longer = img->width > img->height ? img->width : img->height;
    int down = longer > THUMB_SIZE ? (longer + THUMB_SIZE - 1) / THUMB_SIZE : 1;
    int up = longer < THUMB_SIZE ? THUMB_SIZE / longer : 1;
    int w = img->width / down * up, h = img->height / down * up;
    if (w < 1 || h < 1)
        return false;
    t->rgb8 = malloc((size_t)w * (size_t)h * 3);
    if (!t->rgb8)
        return false;
    t->width = w;
    t->height = h;
    double scale = exp2((double)exposure);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            int x0 = x / up * down, y0 = y / up * down; /* source block of down x down pixels */
            for (int c = 0; c < 3; c++) {
                double sum = 0.0;
                for (int dy = 0; dy < down; dy++)
                    for (int dx = 0; dx < down; dx++)
                        sum += img->rgb[c][(size_t)(y0 + dy) * (size_t)img->width + x0 + dx];
                t->rgb8[((size_t)y * w + x) * 3 + c] = srgb8(sum / (down * down) * scale);
            }
        }
    return true;
}

bool stats_curve_add(struct stats_curve *c, const struct film *film, const struct stats_image *ref,
                     uint64_t seed, uint32_t spp, double seconds, bool keep_thumbnail,
                     float exposure, struct mcpt_error *err)
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
    *p = (struct stats_point){.seed = seed, .spp = spp, .seconds = seconds,
                              .mean_variance = m.mean_variance, .mse_raw = m.mse,
                              .psnr_raw_db = m.psnr_db, .noise_floor = m.noise_floor,
                              .mrse_pbrt = m.mrse_pbrt, .mae = m.mae};
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

    if (keep_thumbnail) {
        if (c->n_thumbs == c->cap_thumbs) {
            size_t cap = c->cap_thumbs ? 2 * c->cap_thumbs : 16;
            struct stats_thumb *t = realloc(c->thumbs, cap * sizeof *t);
            if (!t)
                goto oom;
            c->thumbs = t;
            c->cap_thumbs = cap;
        }
        struct stats_thumb *t = &c->thumbs[c->n_thumbs];
        *t = (struct stats_thumb){.spp = spp, .psnr_db = p->psnr_db, .source = p->source};
        if (!make_thumb(&img, exposure, t))
            goto oom;
        c->n_thumbs++;
    }
    c->n_points++;
    return true;
oom:
    mcpt_error_set(err, "", 0, 0, "out of memory recording the convergence curve");
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
                              ? 1.0 / (row->mse_mean * row->seconds) : NAN;
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

static void depth_name(uint32_t max_depth, char *buf, size_t buf_bytes)
{
    if (max_depth == UINT32_MAX)
        snprintf(buf, buf_bytes, "inf");
    else
        snprintf(buf, buf_bytes, "%u", max_depth);
}

bool stats_write_csv(const char *path, const struct stats_curve *c, struct mcpt_error *err)
{
    struct out_file o;
    if (!out_open(path, &o, err))
        return false;
    char depth[16], b[13][40];
    depth_name(c->max_depth, depth, sizeof depth);
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
    return out_commit(path, &o, err);
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
    struct out_file o;
    if (!out_open(path, &o, err))
        return false;
    FILE *f = o.f;
    char depth[16];
    depth_name(c->max_depth, depth, sizeof depth);
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
            {"mse_mean", row->mse_mean}, {"mse_std", row->mse_std}, {"rmse", row->rmse},
            {"psnr_db", row->psnr_db}, {"mean_variance", row->mean_variance},
            {"efficiency", row->efficiency},
            {"time_to_unit_variance", row->time_to_unit_variance},
            {"mse_raw_mean", row->mse_raw_mean}, {"noise_floor", row->noise_floor},
        };
        json_num(f, row->seconds);
        for (size_t i = 0; i < sizeof fields / sizeof fields[0]; i++) {
            fprintf(f, ", \"%s\": ", fields[i].key);
            json_num(f, fields[i].v);
        }
        fprintf(f, "}%s\n", r + 1 < s->n_rows ? "," : "");
    }
    fputs("  ]\n}\n", f);
    return out_commit(path, &o, err);
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

/* ---- the SVG plot: hand-written SVG 1.1 text, two log-log panels ---- */

/* A panel: its frame in SVG pixels and the log10 data range it shows. */
struct panel {
    double x0, x1, y0, y1; /* frame: left, right, top, bottom */
    double xlo, xhi;       /* log10 of the data at x0, x1 */
    double ylo, yhi;       /* log10 of the data at y1, y0 */
    const char *clip_id;
};

static double panel_x(const struct panel *p, double lx)
{
    return p->x0 + (lx - p->xlo) / (p->xhi - p->xlo) * (p->x1 - p->x0);
}

static double panel_y(const struct panel *p, double ly)
{
    return p->y1 - (ly - p->ylo) / (p->yhi - p->ylo) * (p->y1 - p->y0);
}

static void svg_text_escaped(FILE *f, const char *s)
{
    for (; *s; s++) {
        if (*s == '&')
            fputs("&amp;", f);
        else if (*s == '<')
            fputs("&lt;", f);
        else if (*s == '>')
            fputs("&gt;", f);
        else
            fputc(*s, f);
    }
}

/* Frame, grid, decade ticks on y ("10^k"), the given x ticks, axis titles, clip path. */
static void svg_axes(FILE *f, const struct panel *p, const double *xticks_log, size_t n_xticks,
                     const char *const *xtick_labels, const char *x_title, const char *y_title)
{
    fprintf(f, "<clipPath id=\"%s\"><rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\"/>"
               "</clipPath>\n", p->clip_id, p->x0, p->y0, p->x1 - p->x0, p->y1 - p->y0);
    fprintf(f, "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"white\" "
               "stroke=\"#333\"/>\n", p->x0, p->y0, p->x1 - p->x0, p->y1 - p->y0);
    bool minor = p->yhi - p->ylo <= 4.0;
    for (int k = (int)floor(p->ylo); k <= (int)ceil(p->yhi); k++) {
        for (int m = 1; m <= (minor ? 9 : 1); m++) {
            double ly = k + log10((double)m);
            if (ly < p->ylo - 1e-9 || ly > p->yhi + 1e-9)
                continue;
            double y = panel_y(p, ly);
            fprintf(f, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\"/>\n",
                    p->x0, y, p->x1, y, m == 1 ? "#ccc" : "#eee");
            if (m == 1)
                fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\" font-size=\"12\">10"
                           "<tspan dy=\"-6\" font-size=\"9\">%d</tspan></text>\n",
                        p->x0 - 6, y + 4, k);
        }
    }
    for (size_t i = 0; i < n_xticks; i++) {
        double x = panel_x(p, xticks_log[i]);
        fprintf(f, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#ccc\"/>\n", x,
                p->y0, x, p->y1);
        fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\" font-size=\"12\">%s"
                   "</text>\n", x, p->y1 + 16, xtick_labels[i]);
    }
    fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\" font-size=\"13\">%s</text>\n",
            (p->x0 + p->x1) / 2, p->y1 + 36, x_title);
    fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\" font-size=\"13\" "
               "transform=\"rotate(-90 %.1f %.1f)\">%s</text>\n",
            p->x0 - 48, (p->y0 + p->y1) / 2, p->x0 - 48, (p->y0 + p->y1) / 2, y_title);
}

/* A polyline through the points with finite log10 coordinates; markers as circles if r > 0. */
static void svg_series(FILE *f, const struct panel *p, const double *lx, const double *ly,
                       size_t n, const char *color, const char *dash, double marker_r)
{
    fprintf(f, "<polyline clip-path=\"url(#%s)\" fill=\"none\" stroke=\"%s\" stroke-width=\"1.8\""
               "%s%s%s points=\"", p->clip_id, color, dash ? " stroke-dasharray=\"" : "",
            dash ? dash : "", dash ? "\"" : "");
    for (size_t i = 0; i < n; i++)
        if (isfinite(lx[i]) && isfinite(ly[i]))
            fprintf(f, "%.1f,%.1f ", panel_x(p, lx[i]), panel_y(p, ly[i]));
    fputs("\"/>\n", f);
    for (size_t i = 0; marker_r > 0 && i < n; i++)
        if (isfinite(lx[i]) && isfinite(ly[i]))
            fprintf(f, "<circle clip-path=\"url(#%s)\" cx=\"%.1f\" cy=\"%.1f\" r=\"%.1f\" "
                       "fill=\"%s\"/>\n", p->clip_id, panel_x(p, lx[i]), panel_y(p, ly[i]),
                    marker_r, color);
}

static void svg_legend(FILE *f, double x, double y, int row, const char *color, const char *dash,
                       const char *label)
{
    double yy = y + 17.0 * row;
    fprintf(f, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\" "
               "stroke-width=\"1.8\"%s%s%s/>\n", x, yy - 4, x + 24, yy - 4, color,
            dash ? " stroke-dasharray=\"" : "", dash ? dash : "", dash ? "\"" : "");
    fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" font-size=\"12\">", x + 30, yy);
    svg_text_escaped(f, label);
    fputs("</text>\n", f);
}

/* The line of slope `slope` (log-log) through the centroid of the finite points, across p. */
static void svg_ideal(FILE *f, const struct panel *p, const double *lx, const double *ly,
                      size_t n, double slope)
{
    double sx = 0.0, sy = 0.0;
    size_t k = 0;
    for (size_t i = 0; i < n; i++)
        if (isfinite(lx[i]) && isfinite(ly[i])) {
            sx += lx[i];
            sy += ly[i];
            k++;
        }
    if (!k)
        return;
    double ends_x[2] = {p->xlo, p->xhi};
    double ends_y[2] = {sy / k + slope * (p->xlo - sx / k), sy / k + slope * (p->xhi - sx / k)};
    svg_series(f, p, ends_x, ends_y, 2, "#666", "2,4", 0.0);
}

bool stats_write_svg(const char *path, const struct stats_curve *c, const struct stats_summary *s,
                     struct mcpt_error *err)
{
    size_t n = s->n_rows;
    double *buf = malloc(sizeof(double) * (7 * n + 1));
    if (!buf) {
        mcpt_error_set(err, path, 0, 0, "out of memory drawing the plot");
        return false;
    }
    double *lspp = buf, *lsec = buf + n, *lrmse = buf + 2 * n, *lraw = buf + 3 * n;
    double *llo = buf + 4 * n, *lhi = buf + 5 * n, *lfit = buf + 6 * n;
    bool corrected = s->source == STATS_ERR_REFERENCE_CORRECTED;
    double floor_rmse = corrected && n ? sqrt_or_nan(s->rows[n - 1].noise_floor) : NAN;
    /* log10 of everything drawn; the y range covers all of it */
    double ymin = INFINITY, ymax = -INFINITY, smin = INFINITY, smax = -INFINITY;
    for (size_t r = 0; r < n; r++) {
        const struct stats_ensemble_row *row = &s->rows[r];
        lspp[r] = log10((double)row->spp);
        lsec[r] = row->seconds > 0.0 ? log10(row->seconds) : NAN;
        lrmse[r] = row->rmse > 0.0 ? log10(row->rmse) : NAN;
        lraw[r] = corrected && row->mse_raw_mean > 0.0 ? 0.5 * log10(row->mse_raw_mean) : NAN;
        /* error bars: sqrt(mean mse -+ std over seeds) */
        double lo = row->mse_mean - row->mse_std, hi = row->mse_mean + row->mse_std;
        llo[r] = s->n_seeds > 1 && lo > 0.0 ? 0.5 * log10(lo) : NAN;
        lhi[r] = s->n_seeds > 1 && hi > 0.0 ? 0.5 * log10(hi) : NAN;
        double vals[4] = {lrmse[r], lraw[r], llo[r], lhi[r]};
        for (int k = 0; k < 4; k++)
            if (isfinite(vals[k])) {
                ymin = fmin(ymin, vals[k]);
                ymax = fmax(ymax, vals[k]);
            }
        if (isfinite(lsec[r])) {
            smin = fmin(smin, lsec[r]);
            smax = fmax(smax, lsec[r]);
        }
        lfit[r] = s->rmse_fit.n >= 2
                      ? (s->rmse_fit.intercept + s->rmse_fit.slope * log((double)row->spp)) /
                            log(10.0)
                      : NAN;
    }
    if (isfinite(floor_rmse)) {
        ymin = fmin(ymin, log10(floor_rmse));
        ymax = fmax(ymax, log10(floor_rmse));
    }
    if (!isfinite(ymin)) {
        ymin = -3.0;
        ymax = 0.0;
    }
    if (!isfinite(smin)) {
        smin = -2.0;
        smax = 0.0;
    }
    struct out_file o;
    if (!out_open(path, &o, err)) {
        free(buf);
        return false;
    }
    FILE *f = o.f;
    fputs("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\" "
          "width=\"1000\" height=\"600\" viewBox=\"0 0 1000 600\" "
          "font-family=\"Helvetica, Arial, sans-serif\">\n"
          "<rect width=\"1000\" height=\"600\" fill=\"white\"/>\n", f);
    char depth[16];
    depth_name(c->max_depth, depth, sizeof depth);
    fprintf(f, "<text x=\"500\" y=\"24\" text-anchor=\"middle\" font-size=\"15\">");
    svg_text_escaped(f, c->scene);
    fprintf(f, ": %dx%d, sampler %s, %s, max depth %s, %zu seed%s, error: %s</text>\n", c->width,
            c->height, c->sampler, c->integrator, depth, s->n_seeds, s->n_seeds == 1 ? "" : "s",
            stats_error_source_name(s->source));

    struct panel p1 = {.x0 = 85, .x1 = 480, .y0 = 45, .y1 = 410,
                       .ylo = floor(ymin), .yhi = ceil(ymax), .clip_id = "clip_spp"};
    if (p1.yhi - p1.ylo < 1.0)
        p1.yhi = p1.ylo + 1.0;
    double xlo = n ? lspp[0] : 0.0, xhi = n ? lspp[n - 1] : 1.0;
    if (xhi - xlo < 0.3) {
        xlo -= 0.3;
        xhi += 0.3;
    }
    p1.xlo = xlo - 0.04 * (xhi - xlo);
    p1.xhi = xhi + 0.04 * (xhi - xlo);
    /* spp ticks: powers of two, at most 8 labelled */
    double ticks[64] = {0};
    char labels[64][24];
    const char *label_ptrs[64] = {0};
    size_t n_ticks = 0;
    int e_lo = (int)ceil(xlo / log10(2.0) - 1e-9), e_hi = (int)floor(xhi / log10(2.0) + 1e-9);
    int step = (e_hi - e_lo) / 8 + 1;
    for (int e = e_lo; e <= e_hi && n_ticks < 64; e += step) {
        if (e < 0 || e > 62)
            continue;
        ticks[n_ticks] = e * log10(2.0);
        snprintf(labels[n_ticks], sizeof labels[n_ticks], "%llu", 1ULL << e);
        label_ptrs[n_ticks] = labels[n_ticks];
        n_ticks++;
    }
    svg_axes(f, &p1, ticks, n_ticks, label_ptrs, "samples per pixel", "RMSE");
    svg_ideal(f, &p1, lspp, lrmse, n, -0.5);
    if (corrected) {
        svg_series(f, &p1, lspp, lraw, n, "#ff7f0e", NULL, 2.5);
        double fx[2] = {p1.xlo, p1.xhi}, fy[2] = {log10(floor_rmse), log10(floor_rmse)};
        if (isfinite(floor_rmse))
            svg_series(f, &p1, fx, fy, 2, "#d62728", "8,4", 0.0);
    }
    svg_series(f, &p1, lspp, lfit, n, "#1f77b4", "6,3", 0.0);
    for (size_t r = 0; r < n; r++)
        if (isfinite(llo[r]) && isfinite(lhi[r]))
            fprintf(f, "<line clip-path=\"url(#clip_spp)\" x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" "
                       "y2=\"%.1f\" stroke=\"#1f77b4\"/>\n", panel_x(&p1, lspp[r]),
                    panel_y(&p1, llo[r]), panel_x(&p1, lspp[r]), panel_y(&p1, lhi[r]));
    svg_series(f, &p1, lspp, lrmse, n, "#1f77b4", NULL, 3.0);
    char line[160];
    int row = 0;
    double lx = p1.x0 - 40, ly = p1.y1 + 62; /* legends below the panels */
    snprintf(line, sizeof line, "RMSE (%s)", stats_error_source_name(s->source));
    svg_legend(f, lx, ly, row++, "#1f77b4", NULL, line);
    if (s->n_seeds > 1) {
        snprintf(line, sizeof line, "bars: sqrt(mean MSE -+ 1 std over %zu seeds)", s->n_seeds);
        svg_legend(f, lx, ly, row++, "#1f77b4", "1,2", line);
    }
    if (s->rmse_fit.n >= 3) {
        snprintf(line, sizeof line, "fit: slope %.3f [%.3f, %.3f], R^2 %.4f", s->rmse_fit.slope,
                 s->rmse_fit.ci_lo, s->rmse_fit.ci_hi, s->rmse_fit.r2);
        svg_legend(f, lx, ly, row++, "#1f77b4", "6,3", line);
    }
    if (!isnan(s->mse_slope_boot_lo)) {
        snprintf(line, sizeof line, "seed-bootstrap 95%% CI of the slope [%.3f, %.3f]",
                 s->mse_slope_boot_lo / 2.0, s->mse_slope_boot_hi / 2.0);
        svg_legend(f, lx, ly, row++, "none", NULL, line);
    }
    svg_legend(f, lx, ly, row++, "#666", "2,4", "ideal N^-1/2 through the points");
    if (corrected) {
        svg_legend(f, lx, ly, row++, "#ff7f0e", NULL, "uncorrected RMSE vs reference");
        svg_legend(f, lx, ly, row++, "#d62728", "8,4", "reference noise floor");
    }

    struct panel p2 = {.x0 = 590, .x1 = 985, .y0 = 45, .y1 = 410, .ylo = p1.ylo, .yhi = p1.yhi,
                       .xlo = floor(smin), .xhi = ceil(smax), .clip_id = "clip_sec"};
    if (p2.xhi - p2.xlo < 1.0)
        p2.xhi = p2.xlo + 1.0;
    n_ticks = 0;
    for (int k = (int)p2.xlo; k <= (int)p2.xhi && n_ticks < 64; k++) {
        ticks[n_ticks] = k;
        snprintf(labels[n_ticks], sizeof labels[n_ticks], "%g", pow(10.0, k));
        label_ptrs[n_ticks] = labels[n_ticks];
        n_ticks++;
    }
    svg_axes(f, &p2, ticks, n_ticks, label_ptrs, "render seconds", "RMSE");
    svg_ideal(f, &p2, lsec, lrmse, n, -0.5);
    svg_series(f, &p2, lsec, lrmse, n, "#1f77b4", NULL, 3.0);
    row = 0;
    svg_legend(f, p2.x0 - 40, p2.y1 + 62, row++, "#1f77b4", NULL, "RMSE");
    svg_legend(f, p2.x0 - 40, p2.y1 + 62, row++, "#666", "2,4", "ideal t^-1/2 through the points");
    if (s->time_fit.n >= 2) {
        snprintf(line, sizeof line, "time = %.4g s per spp x spp + %.3g s overhead (R^2 %.4f)",
                 s->time_fit.slope, s->time_fit.intercept, s->time_fit.r2);
        svg_legend(f, p2.x0 - 40, p2.y1 + 62, row++, "none", NULL, line);
    }
    fputs("</svg>\n", f);
    free(buf);
    return out_commit(path, &o, err);
}

/* ---- text in 8-bit images: a 5 x 7 pixel font for printable ASCII ----
 * In the style of the character generators of 1980s LCD controllers.  Row r (top first) of the
 * glyph of character ch is FONT[ch - 32][r]; bit 4 is the leftmost pixel. */
static const uint8_t FONT[95][STATS_FONT_H] = {
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}, /*   */
    {0x04, 0x04, 0x04, 0x04, 0x00, 0x00, 0x04}, /* ! */
    {0x0A, 0x0A, 0x0A, 0x00, 0x00, 0x00, 0x00}, /* " */
    {0x0A, 0x0A, 0x1F, 0x0A, 0x1F, 0x0A, 0x0A}, /* # */
    {0x04, 0x0F, 0x14, 0x0E, 0x05, 0x1E, 0x04}, /* $ */
    {0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03}, /* % */
    {0x0C, 0x12, 0x14, 0x08, 0x15, 0x12, 0x0D}, /* & */
    {0x0C, 0x04, 0x08, 0x00, 0x00, 0x00, 0x00}, /* quote */
    {0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02}, /* ( */
    {0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08}, /* ) */
    {0x00, 0x04, 0x15, 0x0E, 0x15, 0x04, 0x00}, /* * */
    {0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00}, /* + */
    {0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08}, /* , */
    {0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00}, /* - */
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C}, /* . */
    {0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00}, /* / */
    {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E}, /* 0 */
    {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E}, /* 1 */
    {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F}, /* 2 */
    {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E}, /* 3 */
    {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02}, /* 4 */
    {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E}, /* 5 */
    {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E}, /* 6 */
    {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08}, /* 7 */
    {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E}, /* 8 */
    {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C}, /* 9 */
    {0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00}, /* : */
    {0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x04, 0x08}, /* ; */
    {0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02}, /* < */
    {0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00}, /* = */
    {0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08}, /* > */
    {0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04}, /* ? */
    {0x0E, 0x11, 0x01, 0x0D, 0x15, 0x15, 0x0E}, /* @ */
    {0x0E, 0x11, 0x11, 0x11, 0x1F, 0x11, 0x11}, /* A */
    {0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E}, /* B */
    {0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E}, /* C */
    {0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C}, /* D */
    {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F}, /* E */
    {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10}, /* F */
    {0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F}, /* G */
    {0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11}, /* H */
    {0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E}, /* I */
    {0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C}, /* J */
    {0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11}, /* K */
    {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F}, /* L */
    {0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11}, /* M */
    {0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11}, /* N */
    {0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E}, /* O */
    {0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10}, /* P */
    {0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D}, /* Q */
    {0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11}, /* R */
    {0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E}, /* S */
    {0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04}, /* T */
    {0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E}, /* U */
    {0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04}, /* V */
    {0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A}, /* W */
    {0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11}, /* X */
    {0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04}, /* Y */
    {0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F}, /* Z */
    {0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E}, /* [ */
    {0x00, 0x10, 0x08, 0x04, 0x02, 0x01, 0x00}, /* backslash */
    {0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E}, /* ] */
    {0x04, 0x0A, 0x11, 0x00, 0x00, 0x00, 0x00}, /* ^ */
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F}, /* _ */
    {0x08, 0x04, 0x02, 0x00, 0x00, 0x00, 0x00}, /* ` */
    {0x00, 0x00, 0x0E, 0x01, 0x0F, 0x11, 0x0F}, /* a */
    {0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1E}, /* b */
    {0x00, 0x00, 0x0E, 0x10, 0x10, 0x11, 0x0E}, /* c */
    {0x01, 0x01, 0x0D, 0x13, 0x11, 0x11, 0x0F}, /* d */
    {0x00, 0x00, 0x0E, 0x11, 0x1F, 0x10, 0x0E}, /* e */
    {0x06, 0x09, 0x08, 0x1C, 0x08, 0x08, 0x08}, /* f */
    {0x00, 0x0F, 0x11, 0x11, 0x0F, 0x01, 0x0E}, /* g */
    {0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11}, /* h */
    {0x04, 0x00, 0x0C, 0x04, 0x04, 0x04, 0x0E}, /* i */
    {0x02, 0x00, 0x06, 0x02, 0x02, 0x12, 0x0C}, /* j */
    {0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12}, /* k */
    {0x0C, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E}, /* l */
    {0x00, 0x00, 0x1A, 0x15, 0x15, 0x11, 0x11}, /* m */
    {0x00, 0x00, 0x16, 0x19, 0x11, 0x11, 0x11}, /* n */
    {0x00, 0x00, 0x0E, 0x11, 0x11, 0x11, 0x0E}, /* o */
    {0x00, 0x00, 0x1E, 0x11, 0x1E, 0x10, 0x10}, /* p */
    {0x00, 0x00, 0x0D, 0x13, 0x0F, 0x01, 0x01}, /* q */
    {0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10}, /* r */
    {0x00, 0x00, 0x0E, 0x10, 0x0E, 0x01, 0x1E}, /* s */
    {0x08, 0x08, 0x1C, 0x08, 0x08, 0x09, 0x06}, /* t */
    {0x00, 0x00, 0x11, 0x11, 0x11, 0x13, 0x0D}, /* u */
    {0x00, 0x00, 0x11, 0x11, 0x11, 0x0A, 0x04}, /* v */
    {0x00, 0x00, 0x11, 0x11, 0x15, 0x15, 0x0A}, /* w */
    {0x00, 0x00, 0x11, 0x0A, 0x04, 0x0A, 0x11}, /* x */
    {0x00, 0x00, 0x11, 0x11, 0x0F, 0x01, 0x0E}, /* y */
    {0x00, 0x00, 0x1F, 0x02, 0x04, 0x08, 0x1F}, /* z */
    {0x02, 0x04, 0x04, 0x08, 0x04, 0x04, 0x02}, /* { */
    {0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04}, /* | */
    {0x08, 0x04, 0x04, 0x02, 0x04, 0x04, 0x08}, /* } */
    {0x00, 0x00, 0x08, 0x15, 0x02, 0x00, 0x00}, /* ~ */
};

static void put_pixel(uint8_t *rgb8, int width, int height, int x, int y, const uint8_t color[3])
{
    if (x < 0 || y < 0 || x >= width || y >= height)
        return;
    memcpy(rgb8 + ((size_t)y * (size_t)width + (size_t)x) * 3, color, 3);
}

static void fill_rect(uint8_t *rgb8, int width, int height, int x0, int y0, int w, int h,
                      const uint8_t color[3])
{
    for (int y = y0; y < y0 + h; y++)
        for (int x = x0; x < x0 + w; x++)
            put_pixel(rgb8, width, height, x, y, color);
}

int stats_draw_text(uint8_t *rgb8, int width, int height, int x, int y, int scale,
                    const char *text, const uint8_t color[3])
{
    int advance = (STATS_FONT_W + 1) * scale;
    int x_at = x;
    for (const char *p = text; *p; p++, x_at += advance) {
        unsigned char ch = (unsigned char)*p;
        for (int r = 0; r < STATS_FONT_H; r++) {
            /* outside printable ASCII: an outlined box */
            uint8_t bits = ch >= 32 && ch < 127 ? FONT[ch - 32][r]
                                                : (r == 0 || r == STATS_FONT_H - 1 ? 0x1F : 0x11);
            for (int col = 0; col < STATS_FONT_W; col++)
                if (bits & (0x10 >> col))
                    fill_rect(rgb8, width, height, x_at + col * scale, y + r * scale, scale, scale,
                              color);
        }
    }
    int n = (int)strlen(text);
    return n ? n * advance - scale : 0;
}

static const uint8_t WHITE[3] = {255, 255, 255};
static const uint8_t BACKGROUND[3] = {32, 32, 32};

/* ---- the contact sheet: the snapshots side by side, labelled ---- */

bool stats_write_contact_sheet(const char *path, const struct stats_curve *c,
                               struct mcpt_error *err)
{
    if (!c->n_thumbs) {
        mcpt_error_set(err, path, 0, 0, "expected snapshots for the contact sheet, got none");
        return false;
    }
    const int scale = 2, margin = 8, label_h = 2 * (STATS_FONT_H + 3) * scale;
    int tile_w = 0, tile_h = 0;
    for (size_t i = 0; i < c->n_thumbs; i++) {
        tile_w = c->thumbs[i].width > tile_w ? c->thumbs[i].width : tile_w;
        tile_h = c->thumbs[i].height > tile_h ? c->thumbs[i].height : tile_h;
    }
    int min_w = 12 * (STATS_FONT_W + 1) * scale; /* room for "4096 spp" and "99.9 dB est" */
    tile_w = tile_w > min_w ? tile_w : min_w;
    int cols = c->n_thumbs < 5 ? (int)c->n_thumbs : 5;
    int rows = (int)((c->n_thumbs + (size_t)cols - 1) / (size_t)cols);
    int cell_w = tile_w + margin, cell_h = tile_h + label_h + margin;
    int width = margin + cols * cell_w, height = margin + rows * cell_h;
    uint8_t *rgb8 = malloc((size_t)width * (size_t)height * 3);
    if (!rgb8) {
        mcpt_error_set(err, path, 0, 0, "out of memory drawing the contact sheet");
        return false;
    }
    fill_rect(rgb8, width, height, 0, 0, width, height, BACKGROUND);
    for (size_t i = 0; i < c->n_thumbs; i++) {
        const struct stats_thumb *t = &c->thumbs[i];
        int x0 = margin + (int)(i % (size_t)cols) * cell_w;
        int y0 = margin + (int)(i / (size_t)cols) * cell_h;
        for (int y = 0; y < t->height; y++)
            memcpy(rgb8 + ((size_t)(y0 + y) * (size_t)width + (size_t)x0) * 3,
                   t->rgb8 + (size_t)y * (size_t)t->width * 3, (size_t)t->width * 3);
        char text[48];
        snprintf(text, sizeof text, "%u spp", t->spp);
        int ty = y0 + t->height + 3 * scale;
        stats_draw_text(rgb8, width, height, x0, ty, scale, text, WHITE);
        if (isnan(t->psnr_db))
            snprintf(text, sizeof text, t->source == STATS_ERR_REFERENCE_CORRECTED
                                            ? "below ref noise" : "no estimate");
        else if (isinf(t->psnr_db))
            snprintf(text, sizeof text, "inf dB");
        else
            snprintf(text, sizeof text, "%.1f dB%s", t->psnr_db,
                     t->source == STATS_ERR_OWN_VARIANCE ? " est" : "");
        stats_draw_text(rgb8, width, height, x0, ty + (STATS_FONT_H + 3) * scale, scale, text,
                        WHITE);
    }
    bool ok = image_write_png_rgb8(path, width, height, rgb8, err);
    free(rgb8);
    return ok;
}

/* ---- false-colour maps: the relative-error map and the sample-count map ----
 * Both draw one value t in [0, 1] per image pixel in viridis, the image scaled up by a whole
 * factor to at least HEATMAP_MIN_WIDTH pixels wide, above a legend: a title, the colour bar and
 * labelled ticks.  Legend rows, in font pixels s: margin 4, title 7, gap 4, bar 12, tick 3,
 * gap 2, labels 7, margin 4. */

#define HEATMAP_MIN_WIDTH 256 /* pixels: narrower images are scaled up by a whole factor */
#define HEATMAP_LEGEND_ROWS 43 /* font pixels: the sum of the legend rows above */

/* viridis (van der Walt & Smith 2015, matplotlib's default colour map), 9 stops at t = k / 8,
 * linearly interpolated: perceptually uniform and readable in grey and by colour-blind readers. */
static void viridis8(double t, uint8_t out[3])
{
    static const uint8_t STOPS[9][3] = {
        {68, 1, 84},   {71, 44, 122},  {59, 81, 139},  {44, 113, 142}, {33, 144, 141},
        {39, 173, 129}, {92, 200, 99}, {170, 220, 50}, {253, 231, 37},
    };
    t = t > 0.0 ? (t < 1.0 ? t : 1.0) : 0.0;
    double f = t * 8.0;
    int k = f >= 8.0 ? 7 : (int)f;
    double w = f - k;
    for (int c = 0; c < 3; c++)
        out[c] = (uint8_t)(STOPS[k][c] + w * (STOPS[k + 1][c] - STOPS[k][c]) + 0.5);
}

/* A map being drawn. */
struct heatmap {
    uint8_t *rgb8; /* interleaved RGB8, width x height, malloc'ed by heatmap_begin */
    int width;     /* pixels */
    int height;    /* pixels, legend included */
    int k;         /* map pixels per image pixel, each way */
    int s;         /* map pixels per font pixel, each way */
    int y_legend;  /* first row of the legend */
    int bar_x0;    /* the colour bar covers the columns [bar_x0, bar_x1) */
    int bar_x1;
};

/* Lays out the map of an image_w x image_h image (nothing drawn, hm->rgb8 NULL).  False when
 * its sides would not fit in an int. */
static bool heatmap_layout(struct heatmap *hm, int image_w, int image_h)
{
    int k = image_w < HEATMAP_MIN_WIDTH ? (HEATMAP_MIN_WIDTH + image_w - 1) / image_w : 1;
    int s = image_w * k >= 2 * HEATMAP_MIN_WIDTH ? 2 : 1;
    *hm = (struct heatmap){.k = k, .s = s};
    if ((int64_t)image_w * k > INT_MAX || (int64_t)image_h * k + HEATMAP_LEGEND_ROWS * s > INT_MAX)
        return false;
    hm->width = image_w * k;
    hm->y_legend = image_h * k;
    hm->height = hm->y_legend + HEATMAP_LEGEND_ROWS * s;
    hm->bar_x0 = 12 * s; /* margin 4, then room for the end ticks' labels */
    hm->bar_x1 = hm->width - 12 * s;
    return true;
}

/* Allocates the laid-out map and draws its background, title and colour bar.  False (rgb8
 * NULL) when out of memory. */
static bool heatmap_begin(struct heatmap *hm, const char *title)
{
    int s = hm->s, y_bar = hm->y_legend + 15 * s;
    hm->rgb8 = malloc((size_t)hm->width * (size_t)hm->height * 3);
    if (!hm->rgb8)
        return false;
    fill_rect(hm->rgb8, hm->width, hm->height, 0, 0, hm->width, hm->height, BACKGROUND);
    stats_draw_text(hm->rgb8, hm->width, hm->height, 4 * s, hm->y_legend + 4 * s, s, title,
                    WHITE);
    for (int x = hm->bar_x0; x < hm->bar_x1; x++) {
        uint8_t col[3];
        viridis8((double)(x - hm->bar_x0) / (double)(hm->bar_x1 - 1 - hm->bar_x0), col);
        fill_rect(hm->rgb8, hm->width, hm->height, x, y_bar, 1, 12 * s, col);
    }
    return true;
}

/* Paints image pixel (x, y) (a k x k block of the map) in the colour of t. */
static void heatmap_pixel(struct heatmap *hm, int x, int y, double t)
{
    uint8_t col[3];
    viridis8(t, col);
    fill_rect(hm->rgb8, hm->width, hm->height, x * hm->k, y * hm->k, hm->k, hm->k, col);
}

/* Draws a tick under the colour bar at fraction f of its length and, unless label is NULL, the
 * label centred under it (moved inside the map where it would stick out). */
static void heatmap_tick(struct heatmap *hm, double f, const char *label)
{
    int s = hm->s, y_tick = hm->y_legend + 27 * s;
    int x = hm->bar_x0 + (int)(f * (hm->bar_x1 - 1 - hm->bar_x0) + 0.5);
    fill_rect(hm->rgb8, hm->width, hm->height, x, y_tick, s, 3 * s, WHITE);
    if (!label)
        return;
    int w = (int)strlen(label) * (STATS_FONT_W + 1) * s - s;
    int xt = x - w / 2;
    xt = xt < 0 ? 0 : xt + w > hm->width ? hm->width - w : xt;
    stats_draw_text(hm->rgb8, hm->width, hm->height, xt, y_tick + 5 * s, s, label, WHITE);
}

bool stats_write_heatmap(const char *path, const struct stats_image *a,
                         const struct stats_image *r, struct mcpt_error *err)
{
    size_t n_pixels = (size_t)a->width * (size_t)a->height;
    double *e = malloc(n_pixels * sizeof *e);       /* log10 relative squared error per pixel */
    double *sorted = malloc(n_pixels * sizeof *e);
    struct heatmap hm = {0};
    bool ok = false;
    if (!e || !sorted)
        goto oom;
    /* e = mean over channels of (a - r)^2 / (r^2 + 0.01): the relMSE's terms */
    size_t n_pos = 0;
    for (size_t i = 0; i < n_pixels; i++) {
        double sum = 0.0;
        int n = 0;
        for (int c = 0; c < 3; c++) {
            double x = a->rgb[c][i], ref = r->rgb[c][i];
            if (isfinite(x) && isfinite(ref)) {
                sum += (x - ref) * (x - ref) / (ref * ref + STATS_RELMSE_EPS);
                n++;
            }
        }
        e[i] = n && sum > 0.0 ? log10(sum / n) : -INFINITY;
        if (isfinite(e[i]))
            sorted[n_pos++] = e[i];
    }
    /* whole decades from the 1st to the 99.9th percentile, 1 to 8 of them */
    int lo = -4, hi = 0;
    if (n_pos) {
        qsort(sorted, n_pos, sizeof *sorted, cmp_double);
        lo = (int)floor(sorted[(size_t)(0.01 * (double)(n_pos - 1))]);
        hi = (int)ceil(sorted[(size_t)(0.999 * (double)(n_pos - 1))]);
    }
    if (hi <= lo)
        hi = lo + 1;
    if (hi - lo > 8)
        lo = hi - 8;

    if (!heatmap_layout(&hm, a->width, a->height)) {
        mcpt_error_set(err, path, 0, 0, "expected an image small enough to map, got %dx%d",
                       a->width, a->height);
        goto done;
    }
    if (!heatmap_begin(&hm, "(a-r)^2/(r^2+0.01), mean RGB"))
        goto oom;
    for (int y = 0; y < a->height; y++)
        for (int x = 0; x < a->width; x++) {
            double e_xy = e[(size_t)y * (size_t)a->width + (size_t)x];
            heatmap_pixel(&hm, x, y, (e_xy - lo) / (hi - lo));
        }
    int label_every = (hi - lo + 5) / 6; /* at most about 6 labels */
    for (int d = lo; d <= hi; d++) {
        char label[16];
        snprintf(label, sizeof label, "1e%d", d);
        heatmap_tick(&hm, (double)(d - lo) / (hi - lo), (d - lo) % label_every ? NULL : label);
    }
    ok = image_write_png_rgb8(path, hm.width, hm.height, hm.rgb8, err);
    goto done;
oom:
    mcpt_error_set(err, path, 0, 0, "out of memory drawing the heat map");
done:
    free(e);
    free(sorted);
    free(hm.rgb8);
    return ok;
}

bool stats_write_count_heatmap(const char *path, const struct film *film, struct mcpt_error *err)
{
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    uint32_t lo = UINT32_MAX, hi = 0;
    for (size_t i = 0; i < n_pixels; i++) {
        uint32_t n = film->pixels[i].n + film->pixels[i].n_dropped;
        lo = n < lo ? n : lo;
        hi = n > hi ? n : hi;
    }
    struct heatmap hm;
    if (!heatmap_layout(&hm, film->width, film->height) || hm.width > 65535 ||
        hm.height > 65535) {
        mcpt_error_set(err, path, 0, 0, "expected a film whose sample-count map is at most 65535 "
                       "pixels a side, got a %dx%d film", film->width, film->height);
        return false;
    }
    if (!heatmap_begin(&hm, "samples per pixel")) {
        mcpt_error_set(err, path, 0, 0, "out of memory drawing the sample-count map");
        return false;
    }
    /* t = (n - lo) / (hi - lo), linear */
    double span = hi > lo ? (double)(hi - lo) : 1.0;
    for (int y = 0; y < film->height; y++)
        for (int x = 0; x < film->width; x++) {
            const struct film_pixel *p = &film->pixels[(size_t)y * (size_t)film->width + x];
            heatmap_pixel(&hm, x, y, (double)(p->n + p->n_dropped - lo) / span);
        }
    int n_ticks = hi > lo ? 5 : 1;
    for (int t = 0; t < n_ticks; t++) {
        double f = n_ticks > 1 ? t / (double)(n_ticks - 1) : 0.0;
        char label[16];
        snprintf(label, sizeof label, "%u", (unsigned)(lo + f * (double)(hi - lo) + 0.5));
        heatmap_tick(&hm, f, label);
    }
    bool ok = image_write_png_rgb8(path, hm.width, hm.height, hm.rgb8, err);
    free(hm.rgb8);
    return ok;
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
        rows[n_rows++] = (struct stats_integrate_row){
            .spp = (uint32_t)spp, .mse = w.mean, .mse_se = sqrt(welford_var(&w) / w.n)};
    }
    return n_rows;
}
