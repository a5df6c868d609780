/* tests/material_test.c - material.c: every sampling routine against its pdf by chi-square
 * (Mitsuba-style, tests/chi2.h): cosine and uniform hemisphere (the two Lambert kinds), GGX
 * visible normals (Heitz 2018, eq. 3), the rough conductor and the plastic, and the dielectric's
 * Fresnel lobe choice; BSDF reciprocity f(wo, wi) = f(wi, wo); white-furnace albedo <= 1 for
 * every kind, the GGX conductor's (F = 1) albedo decreasing with roughness, the plastic's coat
 * table bounding the true coat albedo from above (Kelemen & Szirmay-Kalos 2001 coupling); GGX D
 * and VNDF normalisation; Fresnel at normal incidence ((n - 1) / (n + 1))^2 and Schlick's F0,
 * total internal reflection beyond the critical angle, Snell's law (PBRT 4e, ch. 9); the
 * checker texture. */
#include <criterion/criterion.h>

#include "chi2.h"
#include "material.h"
#include "sample.h"

/* chi-square tests in this file, for the Bonferroni correction */
#define N_CHI2_TESTS 12

static vec3 dir(float theta, float phi)
{
    return v3(sinf(theta) * cosf(phi), sinf(theta) * sinf(phi), cosf(theta));
}

static float uniform(struct pcg32 *rng) { return sample_pcg32_float(rng); }

/* ---- chi-square of the BSDF samplers: mat_sample against mat_pdf ---- */

struct bsdf_ctx {
    struct material m;
    vec3 wo;
};

static bool bsdf_draw(void *ctx, const float u[3], vec3 *w)
{
    struct bsdf_ctx *c = ctx;
    struct mat_sample s;
    if (!mat_sample(&c->m, c->wo, u[2], (vec2){u[0], u[1]}, &s) || s.is_specular)
        return false;
    *w = s.wi;
    return true;
}

static double bsdf_density(void *ctx, vec3 w)
{
    struct bsdf_ctx *c = ctx;
    return mat_pdf(&c->m, c->wo, w);
}

static void check_bsdf_chi2(struct material m, vec3 wo, const char *what)
{
    struct bsdf_ctx c = {m, wo};
    struct chi2_spec spec = chi2_sphere(bsdf_draw, bsdf_density, &c);
    struct chi2_result r;
    chi2_run(&spec, &r);
    cr_assert(chi2_accept(&r, N_CHI2_TESTS), "%s: %s", what, r.msg);
    cr_assert(r.pdf_integral <= 1.0 + 1e-3, "%s: pdf integrates to %f", what, r.pdf_integral);
}

/* Cosine-weighted hemisphere sampling (MAT_DIFFUSE), from above and from below the surface. */
Test(material, chi2_diffuse_cosine)
{
    struct material m = {.kind = MAT_DIFFUSE, .albedo = v3(0.5f, 0.5f, 0.5f)};
    check_bsdf_chi2(m, dir(0.5f, 1.0f), "diffuse, wo above");
    check_bsdf_chi2(m, dir(2.5f, 1.0f), "diffuse, wo below");
}

/* Uniform hemisphere sampling (MAT_DIFFUSE_UNIFORM). */
Test(material, chi2_diffuse_uniform)
{
    struct material m = {.kind = MAT_DIFFUSE_UNIFORM, .albedo = v3(0.5f, 0.5f, 0.5f)};
    check_bsdf_chi2(m, dir(1.2f, -2.0f), "uniform diffuse");
}

/* The rough conductor's VNDF-based sampling: near-normal and grazing wo, two roughnesses; the
 * misses (reflections below the surface) must match 1 - integral of mat_pdf. */
Test(material, chi2_conductor)
{
    struct material m = {.kind = MAT_CONDUCTOR,
                         .specular = v3(0.9f, 0.6f, 0.3f),
                         .roughness = 0.6f};
    check_bsdf_chi2(m, dir(0.3f, 0.4f), "conductor r = 0.6, 17 deg");
    m.roughness = 0.4f;
    check_bsdf_chi2(m, dir(1.3f, 2.0f), "conductor r = 0.4, 74 deg");
}

/* The plastic's mixture: coat (VNDF) or base (cosine), chosen by the coat's albedo share. */
Test(material, chi2_plastic)
{
    struct material m = {.kind = MAT_PLASTIC,
                         .albedo = v3(0.8f, 0.3f, 0.2f),
                         .specular = v3(0.04f, 0.04f, 0.04f),
                         .roughness = 0.5f};
    check_bsdf_chi2(m, dir(1.1f, 0.7f), "plastic r = 0.5");
    m.specular = v3(0.5f, 0.5f, 0.5f);
    m.roughness = 0.35f;
    check_bsdf_chi2(m, dir(0.2f, -0.7f), "plastic r = 0.35, F0 0.5");
}

/* GGX visible normals (Heitz 2018, listing 1) against D_wo(m) (eq. 3), which integrates to 1. */
struct vndf_ctx {
    vec3 wo;
    float alpha;
};

static bool vndf_draw(void *ctx, const float u[3], vec3 *w)
{
    struct vndf_ctx *c = ctx;
    *w = mat_ggx_sample_vndf(c->wo, c->alpha, (vec2){u[0], u[1]});
    return true;
}

static double vndf_density(void *ctx, vec3 w)
{
    struct vndf_ctx *c = ctx;
    return mat_ggx_pdf_vndf(c->wo, w, c->alpha);
}

Test(material, chi2_ggx_vndf)
{
    struct vndf_ctx cases[2] = {{dir(0.4f, 1.0f), 0.3f}, {dir(1.4f, -1.0f), 0.6f}};
    for (int k = 0; k < 2; k++) {
        struct chi2_spec spec = chi2_sphere(vndf_draw, vndf_density, &cases[k]);
        struct chi2_result r;
        chi2_run(&spec, &r);
        cr_assert(chi2_accept(&r, N_CHI2_TESTS), "case %d: %s", k, r.msg);
        cr_assert(fabs(r.pdf_integral - 1.0) < 1e-3, "case %d: D_wo integrates to %f", k,
                  r.pdf_integral);
    }
}

/* The dielectric picks reflection with probability R(theta) (exact Fresnel) and refraction with
 * 1 - R: counts of the two lobes over 200000 draws, at three angles from each side. */
Test(material, chi2_dielectric_lobe_choice)
{
    struct material m = {.kind = MAT_DIELECTRIC, .ior = 1.5f, .specular = v3(1, 1, 1)};
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 3, 4);
    const float thetas[3] = {0.2f, 1.0f, 1.45f};
    for (int side = 0; side < 2; side++)
        for (int k = 0; k < 3; k++) {
            vec3 wo = dir(side ? MCPT_PI - 0.3f * thetas[k] : thetas[k], 0.5f);
            struct mat_sample s;
            cr_assert(mat_sample(&m, wo, 0.0f, (vec2){0, 0}, &s));
            double R = s.pdf_sa; /* u_lobe = 0 always reflects: its probability is R */
            uint64_t counts[2] = {0, 0};
            const int n = 200000;
            for (int i = 0; i < n; i++) {
                cr_assert(mat_sample(&m, wo, uniform(&rng), (vec2){0, 0}, &s));
                counts[s.wi.z * wo.z > 0.0f ? 0 : 1]++;
            }
            double expected[2] = {n * R, n * (1.0 - R)};
            struct chi2_result r;
            chi2_counts(expected, counts, 2, &r);
            /* six sub-tests share this test's share of the significance level */
            cr_assert(chi2_accept(&r, 6 * N_CHI2_TESTS), "side %d theta %f: R %f, %s", side,
                      thetas[k], R, r.msg);
        }
}

/* ---- reciprocity, normalisation, albedo ---- */

/* f(wo, wi) = f(wi, wo) for every non-refractive kind, on both sides of the surface. */
Test(material, reciprocity)
{
    struct material ms[4] = {
        {.kind = MAT_DIFFUSE, .albedo = v3(0.5f, 0.25f, 1.0f)},
        {.kind = MAT_DIFFUSE_UNIFORM, .albedo = v3(0.5f, 0.25f, 1.0f)},
        {.kind = MAT_CONDUCTOR, .specular = v3(0.9f, 0.5f, 0.1f), .roughness = 0.4f},
        {.kind = MAT_PLASTIC,
         .albedo = v3(0.7f, 0.2f, 0.9f),
         .specular = v3(0.04f, 0.2f, 0.5f),
         .roughness = 0.3f},
    };
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 1, 2);
    for (int k = 0; k < 4; k++)
        for (int i = 0; i < 2000; i++) {
            float side = i % 2 ? 1.0f : -1.0f;
            vec3 wo = sample_uniform_hemisphere((vec2){uniform(&rng), uniform(&rng)});
            vec3 wi = sample_uniform_hemisphere((vec2){uniform(&rng), uniform(&rng)});
            wo.z *= side;
            wi.z *= side;
            vec3 a = mat_eval(&ms[k], wo, wi), b = mat_eval(&ms[k], wi, wo);
            for (int c = 0; c < 3; c++) {
                float x = v3_get(a, c), y = v3_get(b, c);
                cr_assert(fabsf(x - y) <= 1e-5f * fmaxf(1.0f, fabsf(x)),
                          "kind %d: f(wo, wi) %g != f(wi, wo) %g", k, x, y);
            }
            cr_assert(v3_is_zero(mat_eval(&ms[k], wo, v3(wi.x, wi.y, -wi.z))),
                      "kind %d: no transmission", k);
        }
}

/* Lambert: sampled pdf equals mat_pdf and f cos / pdf equals the albedo exactly under cosine
 * sampling. */
Test(material, diffuse_sample_pdf)
{
    struct material m = {.kind = MAT_DIFFUSE, .albedo = v3(0.5f, 0.25f, 1.0f)};
    vec3 wo = dir(0.7f, 0.3f);
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 1, 2);
    for (int i = 0; i < 1000; i++) {
        struct mat_sample s;
        vec2 u = {uniform(&rng), uniform(&rng)};
        cr_assert(mat_sample(&m, wo, 0.5f, u, &s));
        cr_assert_float_eq(s.pdf_sa, mat_pdf(&m, wo, s.wi), 1e-6f);
        cr_assert_float_eq(s.f.x * s.wi.z / s.pdf_sa, 0.5f, 1e-5f);
    }
}

/* int D(m) cos theta_m dm = 1 (Walter et al. 2007, eq. 4), by midpoint quadrature in
 * (cos theta, phi), for several alphas. */
Test(material, ggx_D_normalised)
{
    const float alphas[4] = {0.05f, 0.2f, 0.5f, 1.0f};
    for (int k = 0; k < 4; k++) {
        const int n = 20000;
        double sum = 0.0;
        for (int i = 0; i < n; i++) {
            /* substitute cos theta = 1 - t^4 to resolve the peak of small alphas */
            double t = (i + 0.5) / n, z = 1.0 - t * t * t * t, dz = 4.0 * t * t * t / n;
            vec3 m = v3((float)sqrt(1.0 - z * z), 0.0f, (float)z);
            sum += mat_ggx_D(m, alphas[k]) * z * dz * 2.0 * MCPT_PI; /* isotropic in phi */
        }
        cr_assert(fabs(sum - 1.0) < 2e-3, "alpha %f: int D cos = %f", alphas[k], sum);
    }
}

/* Mean of f |cos| / pdf over n BSDF samples (a furnace of radiance 1 seen from wo), with its
 * standard error; channel c. */
static void albedo(const struct material *m, vec3 wo, int n, struct pcg32 *rng, int c, double *mean,
                   double *se)
{
    double s = 0.0, s2 = 0.0;
    for (int i = 0; i < n; i++) {
        struct mat_sample bs;
        double w = 0.0;
        if (mat_sample(m, wo, uniform(rng), (vec2){uniform(rng), uniform(rng)}, &bs))
            w = v3_get(bs.f, c) * fabsf(bs.wi.z) / bs.pdf_sa;
        s += w;
        s2 += w * w;
    }
    *mean = s / n;
    *se = sqrt(fmax(0.0, s2 / n - *mean * *mean) / n);
}

/* White furnace: no kind reflects more than arrives.  Albedo 1 diffuse kinds give exactly 1;
 * the conductor with F0 = 1 and the white plastic stay at or below 1 (within 4 standard errors)
 * at every angle and roughness. */
Test(material, furnace_albedo_at_most_one)
{
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 9, 9);
    const float thetas[4] = {0.0f, 0.7f, 1.2f, 1.5f};
    const float rough[5] = {0.0f, 0.05f, 0.2f, 0.5f, 1.0f};
    const float F0s[3] = {0.04f, 0.5f, 1.0f};
    double mean, se;
    for (int t = 0; t < 4; t++) {
        vec3 wo = dir(thetas[t], 0.3f);
        struct material d = {.kind = MAT_DIFFUSE, .albedo = v3(1, 1, 1)};
        albedo(&d, wo, 2000, &rng, 0, &mean, &se);
        cr_assert_float_eq(mean, 1.0, 1e-5, "diffuse: %f", mean);
        d.kind = MAT_DIFFUSE_UNIFORM;
        albedo(&d, wo, 100000, &rng, 0, &mean, &se);
        cr_assert(fabs(mean - 1.0) < 4.0 * se, "uniform diffuse: %f +- %f", mean, se);
        for (int r = 0; r < 5; r++) {
            struct material c = {.kind = MAT_CONDUCTOR,
                                 .specular = v3(1, 1, 1),
                                 .roughness = rough[r]};
            albedo(&c, wo, 20000, &rng, 0, &mean, &se);
            cr_assert(mean <= 1.0 + 4.0 * se + 1e-6, "conductor r %f theta %f: %f +- %f", rough[r],
                      thetas[t], mean, se);
            for (int f = 0; f < 3; f++) {
                struct material p = {.kind = MAT_PLASTIC,
                                     .albedo = v3(1, 1, 1),
                                     .specular = v3_splat(F0s[f]),
                                     .roughness = rough[r]};
                albedo(&p, wo, 20000, &rng, 0, &mean, &se);
                cr_assert(mean <= 1.0 + 4.0 * se + 1e-6, "plastic r %f F0 %f theta %f: %f +- %f",
                          rough[r], F0s[f], thetas[t], mean, se);
                /* little is lost: only the coat's missing multiple scattering and the table's
                 * margin, so a white plastic stays near 1 */
                cr_assert(mean > 0.9 - 4.0 * se, "plastic r %f F0 %f theta %f: only %f", rough[r],
                          F0s[f], thetas[t], mean);
            }
        }
    }
}

/* The GGX conductor with F = 1 loses energy to the single-scattering model as it roughens: its
 * albedo decreases with roughness at normal and moderate incidence (at extreme grazing angles
 * it need not), by more than 4 combined standard errors per step. */
Test(material, conductor_albedo_decreases_with_roughness)
{
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 5, 6);
    const float thetas[3] = {0.0f, 0.6f, 1.0f};
    const float rough[5] = {0.1f, 0.3f, 0.5f, 0.7f, 1.0f};
    for (int t = 0; t < 3; t++) {
        double prev = 0.0, prev_se = 0.0;
        for (int r = 0; r < 5; r++) {
            struct material c = {.kind = MAT_CONDUCTOR,
                                 .specular = v3(1, 1, 1),
                                 .roughness = rough[r]};
            double mean, se;
            albedo(&c, dir(thetas[t], 0.0f), 40000, &rng, 0, &mean, &se);
            cr_assert(mean <= 1.0 + 4.0 * se, "theta %f r %f: albedo %f", thetas[t], rough[r],
                      mean);
            cr_assert(r == 0 || mean < prev - 4.0 * sqrt(se * se + prev_se * prev_se),
                      "theta %f: albedo %f at r %f not below %f", thetas[t], mean, rough[r], prev);
            prev = mean;
            prev_se = se;
        }
    }
}

/* The coat table is an upper bound: at random (cos theta, roughness), the tabulated E with
 * F0 = 1 (E1) and F0 = 0 (E5) is at least the VNDF Monte Carlo estimate of the true value
 * minus 4 standard errors. */
Test(material, coat_table_bounds_true_albedo)
{
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 12, 34);
    for (int k = 0; k < 60; k++) {
        float mu = uniform(&rng), r = 0.04f + 0.96f * uniform(&rng);
        if (k < 10)
            mu *= 0.05f; /* grazing, where the table needs its largest margins */
        float alpha = r * r;
        vec3 wo = v3(sqrtf(1.0f - mu * mu), 0.0f, mu);
        double s1 = 0, s1q = 0, s5 = 0, s5q = 0;
        const int n = 20000;
        for (int i = 0; i < n; i++) {
            vec3 m = mat_ggx_sample_vndf(wo, alpha, (vec2){uniform(&rng), uniform(&rng)});
            float wo_m = v3_dot(wo, m);
            vec3 wi = v3_sub(v3_scale(m, 2.0f * wo_m), wo);
            double w = 0.0;
            if (wi.z > 0.0f && wo_m > 0.0f)
                w = mat_ggx_G2(wo, wi, alpha) / mat_ggx_G1(wo, alpha);
            double k5 = pow(1.0 - wo_m, 5.0);
            s1 += w;
            s1q += w * w;
            s5 += w * k5;
            s5q += w * k5 * w * k5;
        }
        double e1 = s1 / n, e5 = s5 / n;
        double se1 = sqrt(fmax(0.0, s1q / n - e1 * e1) / n);
        double se5 = sqrt(fmax(0.0, s5q / n - e5 * e5) / n);
        float t1 = mat_ggx_albedo(mu, r, 1.0f), t5 = mat_ggx_albedo(mu, r, 0.0f);
        cr_assert(t1 >= e1 - 4.0 * se1 && t1 <= 1.0f, "mu %f r %f: E1 table %f < %f +- %f", mu, r,
                  t1, e1, se1);
        cr_assert(t5 >= e5 - 4.0 * se5, "mu %f r %f: E5 table %f < %f +- %f", mu, r, t5, e5, se5);
        /* and tight: the margin stays small away from grazing angles */
        if (mu > 0.2f)
            cr_assert(t1 - e1 < 0.01 + 4.0 * se1, "mu %f r %f: E1 table %f far above %f", mu, r, t1,
                      e1);
    }
}

/* ---- Fresnel, refraction, mirrors ---- */

/* Fresnel at normal incidence equals ((n - 1) / (n + 1))^2: the reflected fraction picked by
 * the lobe choice at u_lobe just below and above R. */
Test(material, dielectric_normal_incidence)
{
    struct material m = {.kind = MAT_DIELECTRIC, .ior = 1.5f, .specular = v3(1, 1, 1)};
    float R = (0.5f / 2.5f) * (0.5f / 2.5f);
    struct mat_sample s;
    cr_assert(mat_sample(&m, v3(0, 0, 1), 0.0f, (vec2){0, 0}, &s));
    cr_assert_float_eq(s.pdf_sa, R, 1e-6f);
    cr_assert_float_eq(s.wi.z, 1.0f, 1e-6f, "reflection");
    cr_assert(mat_sample(&m, v3(0, 0, 1), 0.999f, (vec2){0, 0}, &s));
    cr_assert_float_eq(s.pdf_sa, 1.0f - R, 1e-6f);
    cr_assert_float_eq(s.wi.z, -1.0f, 1e-6f, "transmission");
    /* radiance entering glass is scaled by 1 / eta^2: f cos / pdf = 1 / 1.5^2 */
    cr_assert_float_eq(s.f.x * fabsf(s.wi.z) / s.pdf_sa, 1.0f / 2.25f, 1e-5f);
    /* leaving: the same R from inside, and the radiance scaled by eta^2 */
    cr_assert(mat_sample(&m, v3(0, 0, -1), 0.999f, (vec2){0, 0}, &s));
    cr_assert_float_eq(s.pdf_sa, 1.0f - R, 1e-6f);
    cr_assert_float_eq(s.f.x * fabsf(s.wi.z) / s.pdf_sa, 2.25f, 1e-5f);
}

/* Schlick: the smooth conductor reflects F0 at normal incidence and approaches 1 at grazing. */
Test(material, conductor_schlick_fresnel)
{
    struct material m = {.kind = MAT_CONDUCTOR, .specular = v3(0.9f, 0.6f, 0.3f)};
    cr_assert(mat_is_specular(&m) && mat_has_delta(&m));
    struct mat_sample s;
    cr_assert(mat_sample(&m, v3(0, 0, 1), 0.5f, (vec2){0.5f, 0.5f}, &s));
    cr_assert(s.is_specular);
    cr_assert_float_eq(s.f.y * s.wi.z / s.pdf_sa, 0.6f, 1e-6f);
    vec3 grazing = dir(1.5607964f, 0.0f); /* cos = 0.01 */
    cr_assert(mat_sample(&m, grazing, 0.5f, (vec2){0.5f, 0.5f}, &s));
    float F = 0.3f + 0.7f * powf(0.99f, 5.0f);
    cr_assert_float_eq(s.f.z * s.wi.z / s.pdf_sa, F, 1e-4f);
}

/* Snell: sin(theta_t) = sin(theta_i) / eta entering; total internal reflection leaving beyond
 * the critical angle asin(1 / eta). */
Test(material, dielectric_snell_and_tir)
{
    struct material m = {.kind = MAT_DIELECTRIC, .ior = 1.5f, .specular = v3(1, 1, 1)};
    struct mat_sample s;
    vec3 wo = dir(0.6f, 1.0f);
    cr_assert(mat_sample(&m, wo, 0.999f, (vec2){0, 0}, &s));
    float sin_t = sqrtf(s.wi.x * s.wi.x + s.wi.y * s.wi.y);
    cr_assert_float_eq(sin_t, sinf(0.6f) / 1.5f, 1e-5f);
    cr_assert(s.wi.z < 0.0f);
    float critical = asinf(1.0f / 1.5f);
    vec3 inside = dir(MCPT_PI - (critical + 0.01f), 0.2f); /* below the surface, past critical */
    cr_assert(mat_sample(&m, inside, 0.999f, (vec2){0, 0}, &s));
    cr_assert(s.wi.z < 0.0f, "reflected back inside");
    cr_assert_float_eq(s.pdf_sa, 1.0f, 1e-6f, "R = 1 under total internal reflection");
    vec3 below_critical = dir(MCPT_PI - (critical - 0.01f), 0.2f);
    cr_assert(mat_sample(&m, below_critical, 0.999f, (vec2){0, 0}, &s));
    cr_assert(s.wi.z > 0.0f, "just inside the critical angle it still refracts out");
}

/* Mirror: wi is wo reflected about n and f cos / pdf equals the tint. */
Test(material, mirror)
{
    struct material m = {.kind = MAT_MIRROR, .specular = v3(0.9f, 0.8f, 0.7f)};
    struct mat_sample s;
    vec3 wo = dir(0.4f, 2.0f);
    cr_assert(mat_sample(&m, wo, 0.5f, (vec2){0.3f, 0.3f}, &s));
    cr_assert_float_eq(s.wi.x, -wo.x, 1e-6f);
    cr_assert_float_eq(s.wi.z, wo.z, 1e-6f);
    cr_assert_float_eq(s.f.y * s.wi.z / s.pdf_sa, 0.8f, 1e-6f);
    cr_assert(s.is_specular);
}

/* A smooth-coated plastic mixes a delta coat with a Lambert base: it has a delta lobe but is
 * not purely specular; the base's pdf excludes the coat's share. */
Test(material, smooth_plastic_lobes)
{
    struct material m = {.kind = MAT_PLASTIC,
                         .albedo = v3(0.5f, 0.5f, 0.5f),
                         .specular = v3(0.04f, 0.04f, 0.04f),
                         .roughness = 0.0f};
    cr_assert(mat_has_delta(&m) && !mat_is_specular(&m));
    vec3 wo = dir(0.3f, 0.0f);
    struct mat_sample s;
    cr_assert(mat_sample(&m, wo, 0.0f, (vec2){0.5f, 0.5f}, &s));
    cr_assert(s.is_specular, "u_lobe = 0 takes the coat");
    float p_spec = s.pdf_sa;
    cr_assert(p_spec > 0.0f && p_spec < 1.0f);
    cr_assert(mat_sample(&m, wo, 0.9999f, (vec2){0.5f, 0.5f}, &s));
    cr_assert(!s.is_specular, "u_lobe near 1 takes the base");
    cr_assert_float_eq(s.pdf_sa, (1.0f - p_spec) * s.wi.z * MCPT_INV_PI, 1e-6f);
}

/* ---- emission and texture ---- */

/* One-sided emission faces the geometric normal; two-sided faces both ways. */
Test(material, emission_sides)
{
    struct material m = {.kind = MAT_DIFFUSE, .Le = v3(1, 2, 3)};
    cr_assert_eq(mat_emission(&m, v3(0, 1, 0), v3(0, 1, 0)).y, 2.0f);
    cr_assert_eq(mat_emission(&m, v3(0, 1, 0), v3(0, -1, 0)).y, 0.0f);
    m.two_sided_emission = true;
    cr_assert_eq(mat_emission(&m, v3(0, 1, 0), v3(0, -1, 0)).y, 2.0f);
}

/* Checker: world cells of edge s centred on multiples of s (a floor at y = 0 is never on a
 * boundary, whatever the rounding of y); uv cells from (0, 0); no texture gives the albedo. */
Test(material, checker_texture)
{
    struct material m = {.kind = MAT_DIFFUSE,
                         .albedo = v3(1, 1, 1),
                         .checker_albedo = v3(0, 0, 0),
                         .checker_scale = 0.5f};
    vec2 uv = {0, 0};
    cr_assert_eq(mat_albedo_at(&m, v3(0.1f, 1e-7f, 0.1f), uv).x, 1.0f);
    cr_assert_eq(mat_albedo_at(&m, v3(0.1f, -1e-7f, 0.1f), uv).x, 1.0f);
    cr_assert_eq(mat_albedo_at(&m, v3(0.3f, 0.0f, 0.1f), uv).x, 0.0f, "next cell in x");
    cr_assert_eq(mat_albedo_at(&m, v3(0.3f, 0.0f, 0.3f), uv).x, 1.0f, "diagonal cell");
    cr_assert_eq(mat_albedo_at(&m, v3(-0.3f, 0.0f, 0.1f), uv).x, 0.0f, "negative side");
    m.checker_uv = true;
    m.checker_scale = 0.25f;
    cr_assert_eq(mat_albedo_at(&m, v3(9, 9, 9), (vec2){0.1f, 0.1f}).x, 1.0f);
    cr_assert_eq(mat_albedo_at(&m, v3(9, 9, 9), (vec2){0.3f, 0.1f}).x, 0.0f);
    m.checker_scale = 0.0f;
    cr_assert_eq(mat_albedo_at(&m, v3(0.3f, 0.0f, 0.1f), uv).x, 1.0f, "no texture");
}
