/* plot.c - pictures of results, drawn by hand so that mcpt needs no plotting library: the
 * convergence plot as SVG 1.1 text, and PNGs (through image.c) of the contact sheet and the heat
 * maps, labelled in a 5 x 7 bitmap font and coloured by viridis (van der Walt & Smith 2015).
 * It computes no statistic: the numbers come from stats.c (metrics, curves, fits) and film.c
 * (sample counts); here they are only placed on log axes and mapped to colours.  Formats:
 * docs/convergence.md. */
#include "plot.h"

#include <limits.h>
#include <stdlib.h>

#include "file.h"
#include "image.h"

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
    fprintf(f,
            "<clipPath id=\"%s\"><rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\"/>"
            "</clipPath>\n",
            p->clip_id, p->x0, p->y0, p->x1 - p->x0, p->y1 - p->y0);
    fprintf(f,
            "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"white\" "
            "stroke=\"#333\"/>\n",
            p->x0, p->y0, p->x1 - p->x0, p->y1 - p->y0);
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
                fprintf(f,
                        "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\" font-size=\"12\">10"
                        "<tspan dy=\"-6\" font-size=\"9\">%d</tspan></text>\n",
                        p->x0 - 6, y + 4, k);
        }
    }
    for (size_t i = 0; i < n_xticks; i++) {
        double x = panel_x(p, xticks_log[i]);
        fprintf(f, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#ccc\"/>\n", x,
                p->y0, x, p->y1);
        fprintf(f,
                "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\" font-size=\"12\">%s"
                "</text>\n",
                x, p->y1 + 16, xtick_labels[i]);
    }
    fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\" font-size=\"13\">%s</text>\n",
            (p->x0 + p->x1) / 2, p->y1 + 36, x_title);
    fprintf(f,
            "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\" font-size=\"13\" "
            "transform=\"rotate(-90 %.1f %.1f)\">%s</text>\n",
            p->x0 - 48, (p->y0 + p->y1) / 2, p->x0 - 48, (p->y0 + p->y1) / 2, y_title);
}

/* A polyline through the points with finite log10 coordinates; markers as circles if r > 0. */
static void svg_series(FILE *f, const struct panel *p, const double *lx, const double *ly, size_t n,
                       const char *color, const char *dash, double marker_r)
{
    fprintf(f,
            "<polyline clip-path=\"url(#%s)\" fill=\"none\" stroke=\"%s\" stroke-width=\"1.8\""
            "%s%s%s points=\"",
            p->clip_id, color, dash ? " stroke-dasharray=\"" : "", dash ? dash : "",
            dash ? "\"" : "");
    for (size_t i = 0; i < n; i++)
        if (isfinite(lx[i]) && isfinite(ly[i]))
            fprintf(f, "%.1f,%.1f ", panel_x(p, lx[i]), panel_y(p, ly[i]));
    fputs("\"/>\n", f);
    for (size_t i = 0; marker_r > 0 && i < n; i++)
        if (isfinite(lx[i]) && isfinite(ly[i]))
            fprintf(f,
                    "<circle clip-path=\"url(#%s)\" cx=\"%.1f\" cy=\"%.1f\" r=\"%.1f\" "
                    "fill=\"%s\"/>\n",
                    p->clip_id, panel_x(p, lx[i]), panel_y(p, ly[i]), marker_r, color);
}

static void svg_legend(FILE *f, double x, double y, int row, const char *color, const char *dash,
                       const char *label)
{
    double yy = y + 17.0 * row;
    fprintf(f,
            "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\" "
            "stroke-width=\"1.8\"%s%s%s/>\n",
            x, yy - 4, x + 24, yy - 4, color, dash ? " stroke-dasharray=\"" : "", dash ? dash : "",
            dash ? "\"" : "");
    fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" font-size=\"12\">", x + 30, yy);
    svg_text_escaped(f, label);
    fputs("</text>\n", f);
}

/* The line of slope `slope` (log-log) through the centroid of the finite points, across p. */
static void svg_ideal(FILE *f, const struct panel *p, const double *lx, const double *ly, size_t n,
                      double slope)
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

#define UNCORRECTED_DASH "5,3" /* SVG stroke-dasharray of the uncorrected RMSE curve */

/* The summary's rows as drawn, in log10 units: one value per row in each array (NAN where a
 * value cannot be drawn), and the ranges they cover. */
struct svg_data {
    size_t n;      /* rows */
    double *buf;   /* the seven arrays below, one allocation */
    double *lspp;  /* spp */
    double *lsec;  /* seconds */
    double *lrmse; /* RMSE by the summary's error source */
    double *lraw;  /* uncorrected RMSE against the reference (corrected runs only) */
    double *llo;   /* error bar ends: sqrt(mean MSE -+ std over seeds) */
    double *lhi;
    double *lfit;      /* the RMSE fit at each spp */
    bool corrected;    /* the error has the reference's noise removed */
    double floor_rmse; /* sqrt of the reference's noise floor (linear units); NAN when unknown */
    double ymin, ymax; /* range of every RMSE drawn */
    double smin, smax; /* range of the seconds */
};

/* Fills d from s; false when out of memory. */
static bool svg_data_init(struct svg_data *d, const struct stats_summary *s)
{
    size_t n = s->n_rows;
    d->n = n;
    d->buf = malloc(sizeof(double) * (7 * n + 1));
    if (!d->buf)
        return false;
    d->lspp = d->buf, d->lsec = d->buf + n, d->lrmse = d->buf + 2 * n, d->lraw = d->buf + 3 * n;
    d->llo = d->buf + 4 * n, d->lhi = d->buf + 5 * n, d->lfit = d->buf + 6 * n;
    d->corrected = s->source == STATS_ERR_REFERENCE_CORRECTED;
    double floor_mse = d->corrected && n ? s->rows[n - 1].noise_floor : NAN;
    d->floor_rmse = floor_mse > 0.0 ? sqrt(floor_mse) : NAN;
    /* log10 of everything drawn; the y range covers all of it */
    d->ymin = d->smin = INFINITY;
    d->ymax = d->smax = -INFINITY;
    for (size_t r = 0; r < n; r++) {
        const struct stats_ensemble_row *row = &s->rows[r];
        d->lspp[r] = log10((double)row->spp);
        d->lsec[r] = row->seconds > 0.0 ? log10(row->seconds) : NAN;
        d->lrmse[r] = row->rmse > 0.0 ? log10(row->rmse) : NAN;
        d->lraw[r] = d->corrected && row->mse_raw_mean > 0.0 ? 0.5 * log10(row->mse_raw_mean) : NAN;
        double lo = row->mse_mean - row->mse_std, hi = row->mse_mean + row->mse_std;
        d->llo[r] = s->n_seeds > 1 && lo > 0.0 ? 0.5 * log10(lo) : NAN;
        d->lhi[r] = s->n_seeds > 1 && hi > 0.0 ? 0.5 * log10(hi) : NAN;
        double vals[4] = {d->lrmse[r], d->lraw[r], d->llo[r], d->lhi[r]};
        for (int k = 0; k < 4; k++)
            if (isfinite(vals[k])) {
                d->ymin = fmin(d->ymin, vals[k]);
                d->ymax = fmax(d->ymax, vals[k]);
            }
        if (isfinite(d->lsec[r])) {
            d->smin = fmin(d->smin, d->lsec[r]);
            d->smax = fmax(d->smax, d->lsec[r]);
        }
        d->lfit[r] = s->rmse_fit.n >= 2
                         ? (s->rmse_fit.intercept + s->rmse_fit.slope * log((double)row->spp)) /
                               log(10.0)
                         : NAN;
    }
    if (isfinite(d->floor_rmse)) {
        d->ymin = fmin(d->ymin, log10(d->floor_rmse));
        d->ymax = fmax(d->ymax, log10(d->floor_rmse));
    }
    if (!isfinite(d->ymin)) {
        d->ymin = -3.0;
        d->ymax = 0.0;
    }
    if (!isfinite(d->smin)) {
        d->smin = -2.0;
        d->smax = 0.0;
    }
    return true;
}

/* Tick positions (log10) on an x axis, with their labels. */
struct svg_ticks {
    size_t n;
    double at[64];
    char labels[64][24];
    const char *label_ptrs[64];
};

static void svg_tick_add(struct svg_ticks *t, double at, const char *label)
{
    if (t->n >= 64)
        return;
    t->at[t->n] = at;
    snprintf(t->labels[t->n], sizeof t->labels[t->n], "%s", label);
    t->label_ptrs[t->n] = t->labels[t->n];
    t->n++;
}

/* The left panel, RMSE against spp, and its legend; fills *p1 (the right panel shares its y). */
static void svg_panel_spp(FILE *f, const struct stats_summary *s, const struct svg_data *d,
                          struct panel *p1)
{
    size_t n = d->n;
    *p1 = (struct panel){.x0 = 85,
                         .x1 = 480,
                         .y0 = 45,
                         .y1 = 410,
                         .ylo = floor(d->ymin),
                         .yhi = ceil(d->ymax),
                         .clip_id = "clip_spp"};
    if (p1->yhi - p1->ylo < 1.0)
        p1->yhi = p1->ylo + 1.0;
    double xlo = n ? d->lspp[0] : 0.0, xhi = n ? d->lspp[n - 1] : 1.0;
    if (xhi - xlo < 0.3) {
        xlo -= 0.3;
        xhi += 0.3;
    }
    p1->xlo = xlo - 0.04 * (xhi - xlo);
    p1->xhi = xhi + 0.04 * (xhi - xlo);
    /* spp ticks: powers of two, at most 8 labelled */
    struct svg_ticks ticks = {0};
    int e_lo = (int)ceil(xlo / log10(2.0) - 1e-9), e_hi = (int)floor(xhi / log10(2.0) + 1e-9);
    int step = (e_hi - e_lo) / 8 + 1;
    for (int e = e_lo; e <= e_hi && ticks.n < 64; e += step) {
        if (e < 0 || e > 62)
            continue;
        char label[24];
        snprintf(label, sizeof label, "%llu", 1ULL << e);
        svg_tick_add(&ticks, e * log10(2.0), label);
    }
    svg_axes(f, p1, ticks.at, ticks.n, ticks.label_ptrs, "samples per pixel", "RMSE");
    svg_ideal(f, p1, d->lspp, d->lrmse, n, -0.5);
    if (d->corrected) {
        double fx[2] = {p1->xlo, p1->xhi};
        double fy[2] = {log10(d->floor_rmse), log10(d->floor_rmse)};
        if (isfinite(d->floor_rmse))
            svg_series(f, p1, fx, fy, 2, "#d62728", "8,4", 0.0);
    }
    svg_series(f, p1, d->lspp, d->lfit, n, "#1f77b4", "6,3", 0.0);
    for (size_t r = 0; r < n; r++)
        if (isfinite(d->llo[r]) && isfinite(d->lhi[r]))
            fprintf(f,
                    "<line clip-path=\"url(#clip_spp)\" x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" "
                    "y2=\"%.1f\" stroke=\"#1f77b4\"/>\n",
                    panel_x(p1, d->lspp[r]), panel_y(p1, d->llo[r]), panel_x(p1, d->lspp[r]),
                    panel_y(p1, d->lhi[r]));
    svg_series(f, p1, d->lspp, d->lrmse, n, "#1f77b4", NULL, 3.0);
    /* the uncorrected curve often lies on the corrected one (where the reference's noise is
     * small): drawn dashed, on top, with smaller markers, so both stay visible */
    if (d->corrected)
        svg_series(f, p1, d->lspp, d->lraw, n, "#ff7f0e", UNCORRECTED_DASH, 1.8);
    char line[160];
    int row = 0;
    double lx = p1->x0 - 40, ly = p1->y1 + 62; /* legends below the panels */
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
    if (!isnan(s->mse_slope_boot_lo)) { /* the MSE slope's interval, halved: RMSE = MSE^1/2 */
        snprintf(line, sizeof line, "seed-bootstrap 95%% CI of the slope [%.3f, %.3f]",
                 s->mse_slope_boot_lo / 2.0, s->mse_slope_boot_hi / 2.0);
        svg_legend(f, lx, ly, row++, "none", NULL, line);
    }
    svg_legend(f, lx, ly, row++, "#666", "2,4", "ideal N^-1/2 through the points");
    if (d->corrected) {
        svg_legend(f, lx, ly, row++, "#ff7f0e", UNCORRECTED_DASH, "uncorrected RMSE vs reference");
        svg_legend(f, lx, ly, row++, "#d62728", "8,4", "reference noise floor");
    }
}

/* The right panel, RMSE against render seconds, on p1's y range, and its legend. */
static void svg_panel_seconds(FILE *f, const struct stats_summary *s, const struct svg_data *d,
                              const struct panel *p1)
{
    struct panel p2 = {.x0 = 590,
                       .x1 = 985,
                       .y0 = 45,
                       .y1 = 410,
                       .ylo = p1->ylo,
                       .yhi = p1->yhi,
                       .xlo = floor(d->smin),
                       .xhi = ceil(d->smax),
                       .clip_id = "clip_sec"};
    if (p2.xhi - p2.xlo < 1.0)
        p2.xhi = p2.xlo + 1.0;
    struct svg_ticks ticks = {0};
    for (int k = (int)p2.xlo; k <= (int)p2.xhi && ticks.n < 64; k++) {
        char label[24];
        snprintf(label, sizeof label, "%g", pow(10.0, k));
        svg_tick_add(&ticks, k, label);
    }
    svg_axes(f, &p2, ticks.at, ticks.n, ticks.label_ptrs, "render seconds", "RMSE");
    svg_ideal(f, &p2, d->lsec, d->lrmse, d->n, -0.5);
    svg_series(f, &p2, d->lsec, d->lrmse, d->n, "#1f77b4", NULL, 3.0);
    int row = 0;
    svg_legend(f, p2.x0 - 40, p2.y1 + 62, row++, "#1f77b4", NULL, "RMSE");
    svg_legend(f, p2.x0 - 40, p2.y1 + 62, row++, "#666", "2,4", "ideal t^-1/2 through the points");
    if (s->time_fit.n >= 2) {
        char line[160];
        snprintf(line, sizeof line, "time = %.4g s per spp x spp + %.3g s overhead (R^2 %.4f)",
                 s->time_fit.slope, s->time_fit.intercept, s->time_fit.r2);
        svg_legend(f, p2.x0 - 40, p2.y1 + 62, row++, "none", NULL, line);
    }
}

bool plot_write_svg(const char *path, const struct stats_curve *c, const struct stats_summary *s,
                    struct mcpt_error *err)
{
    struct svg_data d;
    if (!svg_data_init(&d, s)) {
        mcpt_error_runtime(err, path, "out of memory drawing the plot");
        return false;
    }
    struct file_atomic o;
    FILE *f;
    if (!file_atomic_open(&o, path, err) || !(f = file_atomic_stream(&o, err))) {
        free(d.buf);
        return false;
    }
    fputs("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\" "
          "width=\"1000\" height=\"600\" viewBox=\"0 0 1000 600\" "
          "font-family=\"Helvetica, Arial, sans-serif\">\n"
          "<rect width=\"1000\" height=\"600\" fill=\"white\"/>\n",
          f);
    char depth[16];
    stats_depth_name(c->max_depth, depth, sizeof depth);
    fprintf(f, "<text x=\"500\" y=\"24\" text-anchor=\"middle\" font-size=\"15\">");
    svg_text_escaped(f, c->scene);
    fprintf(f, ": %dx%d, sampler %s, %s, max depth %s, %zu seed%s, error: %s</text>\n", c->width,
            c->height, c->sampler, c->integrator, depth, s->n_seeds, s->n_seeds == 1 ? "" : "s",
            stats_error_source_name(s->source));
    struct panel p1;
    svg_panel_spp(f, s, &d, &p1);
    svg_panel_seconds(f, s, &d, &p1);
    fputs("</svg>\n", f);
    free(d.buf);
    return file_atomic_commit(&o, err);
}

/* ---- text in 8-bit images: a 5 x 7 pixel font for printable ASCII ----
 * In the style of the character generators of 1980s LCD controllers.  Row r (top first) of the
 * glyph of character ch is FONT[ch - 32][r]; bit 4 is the leftmost pixel. */
static const uint8_t FONT[95][PLOT_FONT_H] = {
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

int plot_draw_text(uint8_t *rgb8, int width, int height, int x, int y, int scale, const char *text,
                   const uint8_t color[3])
{
    int advance = (PLOT_FONT_W + 1) * scale;
    int x_at = x;
    for (const char *p = text; *p; p++, x_at += advance) {
        unsigned char ch = (unsigned char)*p;
        for (int r = 0; r < PLOT_FONT_H; r++) {
            /* outside printable ASCII: an outlined box */
            uint8_t bits = ch >= 32 && ch < 127 ? FONT[ch - 32][r]
                                                : (r == 0 || r == PLOT_FONT_H - 1 ? 0x1F : 0x11);
            for (int col = 0; col < PLOT_FONT_W; col++)
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

#define THUMB_SIZE 160 /* pixels: a contact-sheet tile's longer side, about */

/* An sRGB thumbnail of img: box-filtered down by a whole factor when larger than THUMB_SIZE,
 * else repeated up by a whole factor. */
static bool make_thumb(const struct stats_image *img, const struct image_look *look,
                       struct plot_thumb *t)
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
    struct image_srgb srgb;
    image_srgb_init(&srgb);
    double scale = exp2((double)look->exposure);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            int x0 = x / up * down, y0 = y / up * down; /* source block of down x down pixels */
            double v[3], d[3];
            for (int c = 0; c < 3; c++) {
                double sum = 0.0;
                for (int dy = 0; dy < down; dy++)
                    for (int dx = 0; dx < down; dx++)
                        sum += img->rgb[c][(size_t)(y0 + dy) * (size_t)img->width + x0 + dx];
                v[c] = sum / (down * down) * scale;
            }
            image_tonemap_rgb(look->tonemap, v, d);
            for (int c = 0; c < 3; c++)
                t->rgb8[((size_t)y * w + x) * 3 + c] = image_srgb8(&srgb, d[c]);
        }
    return true;
}

bool plot_sheet_add(struct plot_sheet *sheet, const struct stats_image *img, uint32_t spp,
                    double psnr_db, enum stats_error_source source, const struct image_look *look,
                    struct mcpt_error *err)
{
    if (sheet->n_thumbs == sheet->cap_thumbs) {
        size_t cap = sheet->cap_thumbs ? 2 * sheet->cap_thumbs : 16;
        struct plot_thumb *t = realloc(sheet->thumbs, cap * sizeof *t);
        if (!t)
            goto oom;
        sheet->thumbs = t;
        sheet->cap_thumbs = cap;
    }
    struct plot_thumb *t = &sheet->thumbs[sheet->n_thumbs];
    *t = (struct plot_thumb){.spp = spp, .psnr_db = psnr_db, .source = source};
    if (!make_thumb(img, look, t))
        goto oom;
    sheet->n_thumbs++;
    return true;
oom:
    mcpt_error_runtime(err, NULL, "out of memory recording the convergence curve");
    return false;
}

void plot_sheet_free(struct plot_sheet *sheet)
{
    for (size_t i = 0; i < sheet->n_thumbs; i++)
        free(sheet->thumbs[i].rgb8);
    free(sheet->thumbs);
    memset(sheet, 0, sizeof *sheet);
}

bool plot_write_contact_sheet(const char *path, const struct plot_sheet *c, struct mcpt_error *err)
{
    if (!c->n_thumbs) {
        mcpt_error_runtime(err, path, "expected snapshots for the contact sheet, got none");
        return false;
    }
    const int scale = 2, margin = 8, label_h = 3 * (PLOT_FONT_H + 3) * scale;
    int tile_w = 0, tile_h = 0;
    for (size_t i = 0; i < c->n_thumbs; i++) {
        tile_w = c->thumbs[i].width > tile_w ? c->thumbs[i].width : tile_w;
        tile_h = c->thumbs[i].height > tile_h ? c->thumbs[i].height : tile_h;
    }
    int min_w = 12 * (PLOT_FONT_W + 1) * scale; /* room for "4096 spp" and "99.9 dB est" */
    tile_w = tile_w > min_w ? tile_w : min_w;
    int cols = c->n_thumbs < 5 ? (int)c->n_thumbs : 5;
    int rows = (int)((c->n_thumbs + (size_t)cols - 1) / (size_t)cols);
    int cell_w = tile_w + margin, cell_h = tile_h + label_h + margin;
    int width = margin + cols * cell_w, height = margin + rows * cell_h;
    uint8_t *rgb8 = malloc((size_t)width * (size_t)height * 3);
    if (!rgb8) {
        mcpt_error_runtime(err, path, "out of memory drawing the contact sheet");
        return false;
    }
    fill_rect(rgb8, width, height, 0, 0, width, height, BACKGROUND);
    for (size_t i = 0; i < c->n_thumbs; i++) {
        const struct plot_thumb *t = &c->thumbs[i];
        int x0 = margin + (int)(i % (size_t)cols) * cell_w;
        int y0 = margin + (int)(i / (size_t)cols) * cell_h;
        for (int y = 0; y < t->height; y++)
            memcpy(rgb8 + ((size_t)(y0 + y) * (size_t)width + (size_t)x0) * 3,
                   t->rgb8 + (size_t)y * (size_t)t->width * 3, (size_t)t->width * 3);
        char text[48];
        snprintf(text, sizeof text, "%u spp", t->spp);
        int ty = y0 + t->height + 3 * scale;
        plot_draw_text(rgb8, width, height, x0, ty, scale, text, WHITE);
        if (isnan(t->psnr_db))
            snprintf(text, sizeof text,
                     t->source == STATS_ERR_REFERENCE_CORRECTED ? "below ref noise"
                                                                : "no estimate");
        else if (isinf(t->psnr_db))
            snprintf(text, sizeof text, "inf dB");
        else
            snprintf(text, sizeof text, "%.1f dB%s", t->psnr_db,
                     t->source == STATS_ERR_OWN_VARIANCE ? " est" : "");
        plot_draw_text(rgb8, width, height, x0, ty + (PLOT_FONT_H + 3) * scale, scale, text, WHITE);
        /* the PSNR is this one seed's, while the summary's table averages over the seeds */
        snprintf(text, sizeof text, "seed %llu%s", (unsigned long long)c->seed,
                 c->n_seeds > 1 ? " only" : "");
        plot_draw_text(rgb8, width, height, x0, ty + 2 * (PLOT_FONT_H + 3) * scale, scale, text,
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

#define HEATMAP_MIN_WIDTH 256  /* pixels: narrower images are scaled up by a whole factor */
#define HEATMAP_LEGEND_ROWS 43 /* font pixels: the sum of the legend rows above */

/* viridis (van der Walt & Smith 2015, matplotlib's default colour map), 9 stops at t = k / 8,
 * linearly interpolated: perceptually uniform and readable in grey and by colour-blind readers. */
static void viridis8(double t, uint8_t out[3])
{
    static const uint8_t STOPS[9][3] = {
        {68, 1, 84},    {71, 44, 122}, {59, 81, 139},  {44, 113, 142}, {33, 144, 141},
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
    plot_draw_text(hm->rgb8, hm->width, hm->height, 4 * s, hm->y_legend + 4 * s, s, title, WHITE);
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
    int w = (int)strlen(label) * (PLOT_FONT_W + 1) * s - s;
    int xt = x - w / 2;
    xt = xt < 0 ? 0 : xt + w > hm->width ? hm->width - w : xt;
    plot_draw_text(hm->rgb8, hm->width, hm->height, xt, y_tick + 5 * s, s, label, WHITE);
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

bool plot_write_error_heatmap(const char *path, const struct stats_image *a,
                              const struct stats_image *r, struct mcpt_error *err)
{
    size_t n_pixels = (size_t)a->width * (size_t)a->height;
    double *e = malloc(n_pixels * sizeof *e); /* log10 relative squared error per pixel */
    double *sorted = malloc(n_pixels * sizeof *e);
    struct heatmap hm = {0};
    bool ok = false;
    if (!e || !sorted)
        goto oom;
    stats_relative_error_map(a, r, e);
    size_t n_pos = 0;
    for (size_t i = 0; i < n_pixels; i++) {
        e[i] = e[i] > 0.0 ? log10(e[i]) : -INFINITY; /* NAN (no finite channel) too */
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
        mcpt_error_runtime(err, path, "expected an image small enough to map, got %dx%d", a->width,
                           a->height);
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
    mcpt_error_runtime(err, path, "out of memory drawing the heat map");
done:
    free(e);
    free(sorted);
    free(hm.rgb8);
    return ok;
}

bool plot_write_count_heatmap(const char *path, const struct film *film, struct mcpt_error *err)
{
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    uint32_t lo = UINT32_MAX, hi = 0;
    for (size_t i = 0; i < n_pixels; i++) {
        uint32_t n = film->pixels[i].n + film->pixels[i].n_dropped;
        lo = n < lo ? n : lo;
        hi = n > hi ? n : hi;
    }
    struct heatmap hm;
    if (!heatmap_layout(&hm, film->width, film->height) || hm.width > 65535 || hm.height > 65535) {
        mcpt_error_runtime(err, path,
                           "expected a film whose sample-count map is at most 65535 "
                           "pixels a side, got a %dx%d film",
                           film->width, film->height);
        return false;
    }
    if (!heatmap_begin(&hm, "samples per pixel")) {
        mcpt_error_runtime(err, path, "out of memory drawing the sample-count map");
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
