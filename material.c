/* material.c - BSDFs and emission.
 * Contract (all kinds): wo and wi are unit vectors pointing away from the surface, in the local
 * shading frame whose +z is the shading normal ns (not flipped towards wo: a BSDF decides by the
 * signs of wo.z and wi.z which side it is on).  f excludes the cosine; the integrator applies
 * |cos theta_i|.  pdfs are per unit solid angle.  Specular (delta) kinds return f and pdf of the
 * delta lobe from mat_sample only; mat_eval and mat_pdf return 0 for them.
 * References: PBRT 4e, ch. 9, "Diffuse Reflection", "Specular Reflection and Transmission",
 * "Dielectric BSDF". */
#include "material.h"

#include "sample.h"

static bool same_hemisphere(vec3 a, vec3 b) { return a.z * b.z > 0.0f; }

/* Fresnel reflectance of a dielectric interface for unpolarised light, PBRT 4e, ch. 9,
 * "The Fresnel Equations", FrDielectric: eta = n_inside / n_outside; cos_theta_i < 0 means
 * the light arrives from inside. */
static float fresnel_dielectric(float cos_theta_i, float eta)
{
    cos_theta_i = fminf(1.0f, fmaxf(-1.0f, cos_theta_i));
    if (cos_theta_i < 0.0f) {
        eta = 1.0f / eta;
        cos_theta_i = -cos_theta_i;
    }
    float sin2_theta_i = 1.0f - cos_theta_i * cos_theta_i;
    float sin2_theta_t = sin2_theta_i / (eta * eta);
    if (sin2_theta_t >= 1.0f)
        return 1.0f; /* total internal reflection */
    float cos_theta_t = sqrtf(fmaxf(0.0f, 1.0f - sin2_theta_t));
    float r_parl = (eta * cos_theta_i - cos_theta_t) / (eta * cos_theta_i + cos_theta_t);
    float r_perp = (cos_theta_i - eta * cos_theta_t) / (cos_theta_i + eta * cos_theta_t);
    return 0.5f * (r_parl * r_parl + r_perp * r_perp);
}

/* Snell refraction of wo about +z, PBRT 4e, ch. 9, "Specular Reflection and Transmission",
 * Refract: returns false on total internal reflection; *etap is the relative index crossed. */
static bool refract(vec3 wo, float eta, vec3 *wt, float *etap)
{
    float cos_theta_i = wo.z;
    vec3 n = v3(0.0f, 0.0f, 1.0f);
    if (cos_theta_i < 0.0f) {
        eta = 1.0f / eta;
        cos_theta_i = -cos_theta_i;
        n = v3(0.0f, 0.0f, -1.0f);
    }
    float sin2_theta_i = fmaxf(0.0f, 1.0f - cos_theta_i * cos_theta_i);
    float sin2_theta_t = sin2_theta_i / (eta * eta);
    if (sin2_theta_t >= 1.0f)
        return false;
    float cos_theta_t = sqrtf(1.0f - sin2_theta_t);
    /* wt = -wo / eta + (cos_theta_i / eta - cos_theta_t) n */
    *wt = v3_add(v3_scale(wo, -1.0f / eta), v3_scale(n, cos_theta_i / eta - cos_theta_t));
    *etap = eta;
    return true;
}

vec3 mat_eval(const struct material *m, vec3 wo, vec3 wi)
{
    switch (m->kind) {
    case MAT_DIFFUSE:
        /* Lambert: f = albedo / pi on the side of wo */
        return same_hemisphere(wo, wi) ? v3_scale(m->albedo, MCPT_INV_PI) : v3_splat(0.0f);
    case MAT_MIRROR:
    case MAT_DIELECTRIC:
        return v3_splat(0.0f);
    }
    return v3_splat(0.0f);
}

bool mat_sample(const struct material *m, vec3 wo, float u_lobe, vec2 u, struct mat_sample *s)
{
    switch (m->kind) {
    case MAT_DIFFUSE: {
        if (wo.z == 0.0f)
            return false;
        vec3 wi = sample_cosine_hemisphere(u);
        if (wo.z < 0.0f)
            wi.z = -wi.z;
        s->wi = wi;
        s->pdf_sa = pdf_cosine_hemisphere(fabsf(wi.z));
        s->f = v3_scale(m->albedo, MCPT_INV_PI);
        s->is_specular = false;
        return s->pdf_sa > 0.0f;
    }
    case MAT_MIRROR: {
        /* wi = reflect(wo) about +z; f = specular / |cos theta_i|, delta pdf 1 */
        if (wo.z == 0.0f)
            return false;
        s->wi = v3(-wo.x, -wo.y, wo.z);
        s->f = v3_scale(m->specular, 1.0f / fabsf(wo.z));
        s->pdf_sa = 1.0f;
        s->is_specular = true;
        return true;
    }
    case MAT_DIELECTRIC: {
        /* choose reflection with probability R / (R + T) = R, PBRT 4e, ch. 9, "Dielectric BSDF" */
        if (wo.z == 0.0f)
            return false;
        float R = fresnel_dielectric(wo.z, m->ior);
        float T = 1.0f - R;
        vec3 wt;
        float etap;
        if (u_lobe < R || !refract(wo, m->ior, &wt, &etap)) {
            s->wi = v3(-wo.x, -wo.y, wo.z);
            s->f = v3_scale(m->specular, R / fabsf(wo.z));
            s->pdf_sa = R;
        } else {
            /* radiance crossing into a medium of relative index etap is scaled by 1 / etap^2
             * (PBRT 4e, ch. 9, "Non-Symmetric Scattering and Refraction") */
            s->wi = wt;
            s->f = v3_scale(m->specular, T / (fabsf(wt.z) * etap * etap));
            s->pdf_sa = T;
        }
        s->is_specular = true;
        return s->pdf_sa > 0.0f;
    }
    }
    return false;
}

float mat_pdf(const struct material *m, vec3 wo, vec3 wi)
{
    switch (m->kind) {
    case MAT_DIFFUSE:
        return same_hemisphere(wo, wi) ? pdf_cosine_hemisphere(fabsf(wi.z)) : 0.0f;
    case MAT_MIRROR:
    case MAT_DIELECTRIC:
        return 0.0f;
    }
    return 0.0f;
}

bool mat_is_specular(const struct material *m)
{
    return m->kind == MAT_MIRROR || m->kind == MAT_DIELECTRIC;
}

vec3 mat_emission(const struct material *m, vec3 ng, vec3 w)
{
    if (m->two_sided_emission || v3_dot(ng, w) > 0.0f)
        return m->Le;
    return v3_splat(0.0f);
}
