/* ggx_albedo_gen.c - generates material_ggx_table.inc, the GGX coat albedo table of material.c.
 * For each roughness node r_j = j / 31 (alpha = r^2) and cos theta node mu_i = (i / 31)^2 (dense
 * towards grazing angles, where the albedo changes fastest) it computes
 *   E1(mu) = int D G2 / (4 mu) dwi,  E5(mu) = int (1 - wo.h)^5 D G2 / (4 mu) dwi
 * as the mean of the VNDF sample weight G2 / G1(wo) (Heitz 2018, eq. 3 and sec. 4) over the
 * unit square of uniforms, by nested adaptive Simpson (tolerance GEN_TOL), with the very
 * functions material.c renders with.  Then it checks bilinear interpolation against the true
 * values at the centre and edge midpoints of every cell (a 2x finer grid) and raises each node
 * by SAFETY times the largest shortfall of the cells around it plus 10 GEN_TOL, capped at 1, so
 * that the interpolated table bounds the true albedo from above.  Row 0 is the smooth limit
 * (E1 = 1, E5 = (1 - mu)^5), which material.c evaluates exactly; mu = 0 is computed at
 * mu = 1e-4 (the limit; 0 itself divides by zero).  The sample weights do not involve D, so
 * the table depends only on G1, G2 and the VNDF warp.
 * Run `make ggx-table` from the repository root (about 20 s); it does the equivalent of
 *   cc -std=c11 -D_DEFAULT_SOURCE -O2 -I. tests/data/trace/ggx_albedo_gen.c material.c sample.c \
 *       -lm -o build/ggx_albedo_gen && build/ggx_albedo_gen > material_ggx_table.inc */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "material.h"

#define N_R 32
#define N_MU 32
#define GEN_TOL 1e-5 /* absolute tolerance of each integral */
#define SAFETY 3.0   /* nodes are raised by SAFETY times the largest shortfall seen */
#define MU_MIN 1e-4  /* where mu = 0 is evaluated */

struct ctx {
    vec3 wo;
    float alpha;
    double u1; /* fixed outer coordinate */
    int which; /* 0: E1, 1: E5 */
};

static double weight(const struct ctx *c, double u1, double u2)
{
    vec3 m = mat_ggx_sample_vndf(c->wo, c->alpha, (vec2){(float)u1, (float)u2});
    float wo_m = v3_dot(c->wo, m);
    vec3 wi = v3_sub(v3_scale(m, 2.0f * wo_m), c->wo);
    if (!(wi.z > 0.0f) || !(wo_m > 0.0f))
        return 0.0;
    double w = (double)mat_ggx_G2(c->wo, wi, c->alpha) / mat_ggx_G1(c->wo, c->alpha);
    if (c->which == 1) {
        double k = 1.0 - wo_m;
        w *= k * k * k * k * k;
    }
    return w;
}

typedef double (*fn1)(struct ctx *c, double t);

static double simpson(fn1 f, struct ctx *c, double a, double b, double fa, double fm, double fb,
                      double whole, double eps, int depth, int min_depth)
{
    double m = 0.5 * (a + b), flm = f(c, 0.5 * (a + m)), frm = f(c, 0.5 * (m + b));
    double left = (m - a) / 6.0 * (fa + 4.0 * flm + fm);
    double right = (b - m) / 6.0 * (fm + 4.0 * frm + fb);
    double diff = left + right - whole;
    if (depth <= 0 || (min_depth <= 0 && fabs(diff) <= 15.0 * eps))
        return left + right + diff / 15.0;
    return simpson(f, c, a, m, fa, flm, fm, left, 0.5 * eps, depth - 1, min_depth - 1) +
           simpson(f, c, m, b, fm, frm, fb, right, 0.5 * eps, depth - 1, min_depth - 1);
}

static double integrate(fn1 f, struct ctx *c, double eps)
{
    double fa = f(c, 0.0), fm = f(c, 0.5), fb = f(c, 1.0);
    return simpson(f, c, 0.0, 1.0, fa, fm, fb, (fa + 4.0 * fm + fb) / 6.0, eps, 16, 3);
}

static double inner(struct ctx *c, double u2) { return weight(c, c->u1, u2); }

static double outer(struct ctx *c, double u1)
{
    struct ctx ci = *c;
    ci.u1 = u1;
    return integrate(inner, &ci, GEN_TOL);
}

/* True E1 (which = 0) or E5 (which = 1) at (mu, roughness). */
static double true_e(double mu, double r, int which)
{
    double alpha = r * r;
    if (alpha < MAT_ALPHA_SMOOTH) {
        double k = 1.0 - mu;
        return which == 0 ? 1.0 : k * k * k * k * k;
    }
    mu = fmax(mu, MU_MIN);
    struct ctx c = {v3((float)sqrt(1.0 - mu * mu), 0.0f, (float)mu), (float)alpha, 0.0, which};
    return integrate(outer, &c, GEN_TOL);
}

/* A float as a C literal that reads back exactly: "%.9g" plus ".0" where it has no '.' or 'e'. */
static const char *literal(float f, char *buf)
{
    snprintf(buf, 32, "%.9g", f);
    if (!strpbrk(buf, ".e"))
        strcat(buf, ".0");
    strcat(buf, "f");
    return buf;
}

static double node[N_R][N_MU][2];
static double raise_by[N_R][N_MU][2];

/* the table's coordinate along cos theta: mu = x^2 */
static double mu_of(double x) { return x * x; }

static double interp(int k, double mu, double r)
{
    double x = sqrt(mu) * (N_MU - 1), y = r * (N_R - 1);
    int i = x >= N_MU - 1 ? N_MU - 2 : (int)x, j = y >= N_R - 1 ? N_R - 2 : (int)y;
    double tx = x - i, ty = y - j;
    double a = node[j][i][k] + tx * (node[j][i + 1][k] - node[j][i][k]);
    double b = node[j + 1][i][k] + tx * (node[j + 1][i + 1][k] - node[j + 1][i][k]);
    return a + ty * (b - a);
}

int main(void)
{
    for (int j = 0; j < N_R; j++)
        for (int i = 0; i < N_MU; i++)
            for (int k = 0; k < 2; k++)
                node[j][i][k] = true_e(mu_of((double)i / (N_MU - 1)), (double)j / (N_R - 1), k);
    /* shortfall of the interpolant inside each cell, at its centre and edge midpoints; in the
     * first roughness cell only at the roughness where the table starts to serve
     * (alpha = MAT_ALPHA_SMOOTH) */
    static double fine[2 * N_R - 1][2 * N_MU - 1][2];
    for (int y = 0; y < 2 * N_R - 1; y++)
        for (int x = 0; x < 2 * N_MU - 1; x++)
            for (int k = 0; k < 2; k++) {
                if (x % 2 == 0 && y % 2 == 0)
                    continue; /* a node */
                double mu = mu_of(0.5 * x / (N_MU - 1)), r = 0.5 * y / (N_R - 1);
                if (y < 2)
                    r = sqrt(MAT_ALPHA_SMOOTH) * 1.01;
                fine[y][x][k] = true_e(mu, r, k) - interp(k, mu, r);
            }
    double worst = 0.0;
    for (int j = 0; j + 1 < N_R; j++)
        for (int i = 0; i + 1 < N_MU; i++)
            for (int k = 0; k < 2; k++) {
                double cell = 0.0;
                for (int dy = 0; dy <= 2; dy++)
                    for (int dx = 0; dx <= 2; dx++)
                        if (dx % 2 || dy % 2)
                            cell = fmax(cell, fine[2 * j + dy][2 * i + dx][k]);
                worst = fmax(worst, cell);
                for (int dj = 0; dj < 2; dj++)
                    for (int di = 0; di < 2; di++)
                        raise_by[j + dj][i + di][k] = fmax(raise_by[j + dj][i + di][k], cell);
            }
    printf("/* material_ggx_table.inc - generated by tests/data/trace/ggx_albedo_gen.c; do not "
           "edit.\n * GGX_E[j][i] = {E1, E5} at roughness j / %d, cos theta (i / %d)^2, raised to "
           "an upper bound\n * (largest interpolation shortfall %.3g, raised by %.0f times it "
           "plus %.0e). */\n",
           N_R - 1, N_MU - 1, worst, SAFETY, 10.0 * GEN_TOL);
    float stored[N_R][N_MU][2];
    printf("static const float GGX_E[GGX_TABLE_N_R][GGX_TABLE_N_MU][2] = {\n");
    for (int j = 0; j < N_R; j++) {
        printf("    {");
        for (int i = 0; i < N_MU; i++) {
            for (int k = 0; k < 2; k++) {
                double v = node[j][i][k];
                if (j > 0)
                    v = fmin(1.0, v + SAFETY * raise_by[j][i][k] + 10.0 * GEN_TOL);
                float f = (float)v;
                if ((double)f < v)
                    f = nextafterf(f, 2.0f);
                stored[j][i][k] = f;
            }
            char b0[32], b1[32];
            printf("%s{%s, %s},", i % 3 == 0 ? "\n        " : " ", literal(stored[j][i][0], b0),
                   literal(stored[j][i][1], b1));
        }
        printf("\n    },\n");
    }
    printf("};\n");
    /* E_avg = 2 int E mu dmu of each row, exactly for E linear in x between nodes:
     * mu = x^2, 2 mu dmu = 4 x^3 dx, int (a + b (x - x0)) 4 x^3 dx over [x0, x1] */
    printf("static const float GGX_E_AVG[GGX_TABLE_N_R][2] = {\n");
    for (int j = 0; j < N_R; j++) {
        double avg[2] = {0.0, 0.0};
        for (int k = 0; k < 2; k++)
            for (int i = 0; i + 1 < N_MU; i++) {
                double x0 = (double)i / (N_MU - 1), x1 = (double)(i + 1) / (N_MU - 1);
                double a = stored[j][i][k], b = (stored[j][i + 1][k] - a) / (x1 - x0);
                double p4 = pow(x1, 4) - pow(x0, 4), p5 = pow(x1, 5) - pow(x0, 5);
                avg[k] += (a - b * x0) * p4 + b * 4.0 * p5 / 5.0;
            }
        char b0[32], b1[32];
        printf("    {%s, %s},\n", literal((float)avg[0], b0), literal((float)avg[1], b1));
    }
    printf("};\n");
    fprintf(stderr, "largest interpolation shortfall %.3g\n", worst);
    return 0;
}
