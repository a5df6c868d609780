/* tests/material_test.c - material.c: mat_pdf agrees with mat_sample, Lambertian reciprocity
 * and albedo, Fresnel at normal incidence ((n - 1) / (n + 1))^2, total internal reflection
 * beyond the critical angle, and refraction obeying Snell's law (PBRT 4e, ch. 9). */
#include <criterion/criterion.h>

#include "material.h"
#include "sample.h"

static vec3 dir(float theta, float phi)
{
    return v3(sinf(theta) * cosf(phi), sinf(theta) * sinf(phi), cosf(theta));
}

/* Lambert: f(wo, wi) = f(wi, wo) = albedo / pi; sampled pdf equals mat_pdf; the estimate
 * f cos / pdf equals the albedo exactly for cosine sampling. */
Test(material, diffuse_sample_pdf_reciprocity)
{
    struct material m = {.kind = MAT_DIFFUSE, .albedo = v3(0.5f, 0.25f, 1.0f)};
    vec3 wo = dir(0.7f, 0.3f);
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 1, 2);
    for (int i = 0; i < 1000; i++) {
        struct mat_sample s;
        vec2 u = {sample_pcg32_float(&rng), sample_pcg32_float(&rng)};
        cr_assert(mat_sample(&m, wo, 0.5f, u, &s));
        cr_assert_float_eq(s.pdf_sa, mat_pdf(&m, wo, s.wi), 1e-6f);
        vec3 f = mat_eval(&m, wo, s.wi), fr = mat_eval(&m, s.wi, wo);
        cr_assert_float_eq(f.x, fr.x, 0.0f);
        cr_assert_float_eq(f.x * s.wi.z / s.pdf_sa, 0.5f, 1e-5f);
    }
    cr_assert_eq(mat_eval(&m, wo, v3(0, 0, -1)).x, 0.0f, "no transmission");
}

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

/* One-sided emission faces the geometric normal; two-sided faces both ways. */
Test(material, emission_sides)
{
    struct material m = {.kind = MAT_DIFFUSE, .Le = v3(1, 2, 3)};
    cr_assert_eq(mat_emission(&m, v3(0, 1, 0), v3(0, 1, 0)).y, 2.0f);
    cr_assert_eq(mat_emission(&m, v3(0, 1, 0), v3(0, -1, 0)).y, 0.0f);
    m.two_sided_emission = true;
    cr_assert_eq(mat_emission(&m, v3(0, 1, 0), v3(0, -1, 0)).y, 2.0f);
}
