/* material.c - BSDFs, textures and emission.
 * Contract (all kinds): wo and wi are unit vectors pointing away from the surface, in the local
 * shading frame whose +z is the shading normal ns (not flipped towards wo: a BSDF decides by the
 * signs of wo.z and wi.z which side it is on; reflection-only kinds reflect on the side of wo).
 * f excludes the cosine; the integrator applies |cos theta_i|.  pdfs are per unit solid angle.
 * Delta lobes come from mat_sample only; mat_eval and mat_pdf cover the non-delta lobes.
 * Kinds: Lambert (PBRT 4e, ch. 9, "Diffuse Reflection"); mirror and smooth dielectric (ch. 9,
 * "Specular Reflection and Transmission", "Dielectric BSDF"); GGX conductor (Walter et al. 2007,
 * eq. 20; Heitz 2014, eq. 99; Heitz 2018 VNDF sampling; Schlick 1994 Fresnel); plastic: Lambert
 * base under a GGX coat, coupled by the coat's directional albedo (Kelemen & Szirmay-Kalos 2001,
 * "A Microfacet Based Coupled Specular-Matte BRDF Model with Importance Sampling", sec. 3). */
#include "material.h"

#include "sample.h"

static bool same_hemisphere(vec3 a, vec3 b) { return a.z * b.z > 0.0f; }
static float clamp01(float x) { return min_f(1.0f, max_f(0.0f, x)); }
static float ggx_alpha(const struct material *m) { return m->roughness * m->roughness; }
static bool is_smooth(const struct material *m) { return ggx_alpha(m) < MAT_ALPHA_SMOOTH; }
static vec3 reflect_z(vec3 w) { return v3(-w.x, -w.y, w.z); }

static vec3 fresnel_schlick(vec3 F0, float cos_theta);
static float fresnel_dielectric(float cos_theta_i, float eta);
static bool refract(vec3 wo, float eta, vec3 *wt, float *etap);
static vec3 coat_albedo(vec3 F0, float cos_theta, float roughness);
static vec3 coat_albedo_avg(vec3 F0, float roughness);
static vec3 conductor_f(vec3 F0, float alpha, vec3 wo, vec3 wi);
static vec3 plastic_diffuse_f(const struct material *m, vec3 wo, vec3 wi);
static float plastic_spec_prob(const struct material *m, vec3 wo);

/* ---- the three functions, one case per kind ---- */

vec3 mat_eval(const struct material *m, vec3 wo, vec3 wi)
{
    if (!same_hemisphere(wo, wi))
        return v3_splat(0.0f); /* no kind has a non-delta transmission lobe */
    switch (m->kind) {
    case MAT_DIFFUSE:
    case MAT_DIFFUSE_UNIFORM:
        /* Lambert: f = albedo / pi */
        return v3_scale(m->albedo, MCPT_INV_PI);
    case MAT_MIRROR:
    case MAT_DIELECTRIC:
        return v3_splat(0.0f);
    case MAT_CONDUCTOR:
        return is_smooth(m) ? v3_splat(0.0f) : conductor_f(m->specular, ggx_alpha(m), wo, wi);
    case MAT_PLASTIC: {
        /* f = f_coat + f_base */
        vec3 f = plastic_diffuse_f(m, wo, wi);
        if (!is_smooth(m))
            f = v3_add(f, conductor_f(m->specular, ggx_alpha(m), wo, wi));
        return f;
    }
    }
    return v3_splat(0.0f);
}

bool mat_sample(const struct material *m, vec3 wo, float u_lobe, vec2 u, struct mat_sample *s)
{
    if (wo.z == 0.0f)
        return false;
    float side = wo.z > 0.0f ? 1.0f : -1.0f; /* reflection kinds sample on the side of wo */
    s->is_specular = false;
    switch (m->kind) {
    case MAT_DIFFUSE: {
        /* cosine-weighted hemisphere: pdf = cos theta_i / pi, so f cos / pdf = albedo */
        vec3 wi = sample_cosine_hemisphere(u);
        s->wi = v3(wi.x, wi.y, side * wi.z);
        s->pdf_sa = pdf_cosine_hemisphere(wi.z);
        s->f = v3_scale(m->albedo, MCPT_INV_PI);
        return s->pdf_sa > 0.0f;
    }
    case MAT_DIFFUSE_UNIFORM: {
        /* uniform hemisphere: pdf = 1 / (2 pi), so f cos / pdf = 2 albedo cos theta_i */
        vec3 wi = sample_uniform_hemisphere(u);
        s->wi = v3(wi.x, wi.y, side * wi.z);
        s->pdf_sa = pdf_uniform_hemisphere();
        s->f = v3_scale(m->albedo, MCPT_INV_PI);
        return wi.z > 0.0f;
    }
    case MAT_MIRROR:
        /* wi = reflect(wo) about +z; f = specular / |cos theta_i|, delta pdf 1 */
        s->wi = reflect_z(wo);
        s->f = v3_scale(m->specular, 1.0f / fabsf(wo.z));
        s->pdf_sa = 1.0f;
        s->is_specular = true;
        return true;
    case MAT_DIELECTRIC: {
        /* choose reflection with probability R / (R + T) = R, PBRT 4e, ch. 9, "Dielectric BSDF";
         * the surface reflection is untinted, the transmitted light takes the tint */
        float R = fresnel_dielectric(wo.z, m->ior);
        float T = 1.0f - R;
        vec3 wt;
        float etap;
        if (u_lobe < R || !refract(wo, m->ior, &wt, &etap)) {
            s->wi = reflect_z(wo);
            s->f = v3_splat(R / fabsf(wo.z));
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
    case MAT_CONDUCTOR: {
        vec3 wo_up = v3(wo.x, wo.y, fabsf(wo.z));
        if (is_smooth(m)) {
            /* smooth metal: a mirror weighted by F(cos theta_o) */
            s->wi = reflect_z(wo);
            s->f = v3_scale(fresnel_schlick(m->specular, wo_up.z), 1.0f / wo_up.z);
            s->pdf_sa = 1.0f;
            s->is_specular = true;
            return true;
        }
        /* visible normal m ~ D_wo, wi = reflect(wo, m): pdf = D_wo(m) / (4 |wo.m|) */
        float alpha = ggx_alpha(m);
        vec3 mn = mat_ggx_sample_vndf(wo_up, alpha, u);
        float wo_m = v3_dot(wo_up, mn);
        vec3 wi = v3_sub(v3_scale(mn, 2.0f * wo_m), wo_up);
        if (!(wi.z > 0.0f) || !(wo_m > 0.0f))
            return false; /* reflected below the surface: the sample carries nothing */
        s->pdf_sa = mat_ggx_pdf_vndf(wo_up, mn, alpha) / (4.0f * wo_m);
        s->f = conductor_f(m->specular, alpha, wo_up, wi);
        s->wi = v3(wi.x, wi.y, side * wi.z);
        return s->pdf_sa > 0.0f;
    }
    case MAT_PLASTIC: {
        /* pick the coat with probability p_spec (its share of the albedo), else the base */
        float p_spec = plastic_spec_prob(m, wo);
        vec3 wo_up = v3(wo.x, wo.y, fabsf(wo.z));
        vec3 wi;
        if (u_lobe < p_spec) {
            if (is_smooth(m)) {
                /* the smooth coat's delta lobe: f cos / pdf = F(cos theta_o) / p_spec */
                s->wi = reflect_z(wo);
                s->f = v3_scale(fresnel_schlick(m->specular, wo_up.z), 1.0f / wo_up.z);
                s->pdf_sa = p_spec;
                s->is_specular = true;
                return p_spec > 0.0f;
            }
            vec3 mn = mat_ggx_sample_vndf(wo_up, ggx_alpha(m), u);
            wi = v3_sub(v3_scale(mn, 2.0f * v3_dot(wo_up, mn)), wo_up);
            if (!(wi.z > 0.0f))
                return false;
        } else {
            wi = sample_cosine_hemisphere(u);
        }
        s->wi = v3(wi.x, wi.y, side * wi.z);
        s->f = mat_eval(m, wo, s->wi);
        s->pdf_sa = mat_pdf(m, wo, s->wi);
        return s->pdf_sa > 0.0f;
    }
    }
    return false;
}

float mat_pdf(const struct material *m, vec3 wo, vec3 wi)
{
    if (!same_hemisphere(wo, wi))
        return 0.0f;
    vec3 wo_up = v3(wo.x, wo.y, fabsf(wo.z)), wi_up = v3(wi.x, wi.y, fabsf(wi.z));
    switch (m->kind) {
    case MAT_DIFFUSE:
        return pdf_cosine_hemisphere(wi_up.z);
    case MAT_DIFFUSE_UNIFORM:
        return pdf_uniform_hemisphere();
    case MAT_MIRROR:
    case MAT_DIELECTRIC:
        return 0.0f;
    case MAT_CONDUCTOR: {
        if (is_smooth(m))
            return 0.0f;
        /* pdf(wi) = D_wo(h) / (4 |wo.h|), h = normalize(wo + wi) */
        vec3 h = v3_add(wo_up, wi_up);
        if (v3_is_zero(h))
            return 0.0f;
        h = v3_normalize(h);
        return mat_ggx_pdf_vndf(wo_up, h, ggx_alpha(m)) / (4.0f * v3_dot(wo_up, h));
    }
    case MAT_PLASTIC: {
        /* pdf = p_spec pdf_coat + (1 - p_spec) cos theta_i / pi (the smooth coat's delta lobe
         * has no density) */
        float p_spec = plastic_spec_prob(m, wo);
        float pdf = (1.0f - p_spec) * pdf_cosine_hemisphere(wi_up.z);
        vec3 h = v3_add(wo_up, wi_up);
        if (!is_smooth(m) && !v3_is_zero(h)) {
            h = v3_normalize(h);
            pdf += p_spec * mat_ggx_pdf_vndf(wo_up, h, ggx_alpha(m)) / (4.0f * v3_dot(wo_up, h));
        }
        return pdf;
    }
    }
    return 0.0f;
}

bool mat_is_specular(const struct material *m)
{
    return m->kind == MAT_MIRROR || m->kind == MAT_DIELECTRIC ||
           (m->kind == MAT_CONDUCTOR && is_smooth(m));
}

bool mat_has_delta(const struct material *m)
{
    return mat_is_specular(m) || (m->kind == MAT_PLASTIC && is_smooth(m));
}

vec3 mat_emission(const struct material *m, vec3 ng, vec3 w)
{
    if (m->two_sided_emission || v3_dot(ng, w) > 0.0f)
        return m->Le;
    return v3_splat(0.0f);
}

vec3 mat_albedo_at(const struct material *m, vec3 p, vec2 uv)
{
    if (!(m->checker_scale > 0.0f))
        return m->albedo;
    /* cell index sum k; odd cells take the second colour */
    double s = m->checker_scale, k;
    if (m->checker_uv)
        k = floor(uv.x / s) + floor(uv.y / s);
    else
        k = floor(p.x / s + 0.5) + floor(p.y / s + 0.5) + floor(p.z / s + 0.5);
    return fmod(fabs(k), 2.0) == 1.0 ? m->checker_albedo : m->albedo;
}

/* ---- Fresnel ---- */

/* Schlick 1994, "An Inexpensive BRDF Model for Physically-based Rendering", eq. 15:
 * F = F0 + (1 - F0) (1 - cos theta)^5, per channel. */
static vec3 fresnel_schlick(vec3 F0, float cos_theta)
{
    float c = 1.0f - clamp01(cos_theta);
    float c5 = (c * c) * (c * c) * c;
    return v3_add(F0, v3_scale(v3_sub(v3_splat(1.0f), F0), c5));
}

/* Fresnel reflectance of a dielectric interface for unpolarised light, PBRT 4e, ch. 9,
 * "The Fresnel Equations", FrDielectric: eta = n_inside / n_outside; cos_theta_i < 0 means
 * the light arrives from inside. */
static float fresnel_dielectric(float cos_theta_i, float eta)
{
    cos_theta_i = min_f(1.0f, max_f(-1.0f, cos_theta_i));
    if (cos_theta_i < 0.0f) {
        eta = 1.0f / eta;
        cos_theta_i = -cos_theta_i;
    }
    float sin2_theta_i = 1.0f - cos_theta_i * cos_theta_i;
    float sin2_theta_t = sin2_theta_i / (eta * eta);
    if (sin2_theta_t >= 1.0f)
        return 1.0f; /* total internal reflection */
    float cos_theta_t = sqrtf(max_f(0.0f, 1.0f - sin2_theta_t));
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
    float sin2_theta_i = max_f(0.0f, 1.0f - cos_theta_i * cos_theta_i);
    float sin2_theta_t = sin2_theta_i / (eta * eta);
    if (sin2_theta_t >= 1.0f)
        return false;
    float cos_theta_t = sqrtf(1.0f - sin2_theta_t);
    /* wt = -wo / eta + (cos_theta_i / eta - cos_theta_t) n */
    *wt = v3_add(v3_scale(wo, -1.0f / eta), v3_scale(n, cos_theta_i / eta - cos_theta_t));
    *etap = eta;
    return true;
}

/* ---- GGX microfacets ---- */

float mat_ggx_D(vec3 m, float alpha)
{
    if (!(m.z > 0.0f))
        return 0.0f;
    /* D = alpha^2 / (pi (cos^2 theta_m (alpha^2 - 1) + 1)^2)  (Walter et al. 2007, eq. 33),
     * written with sin^2 theta_m = m.x^2 + m.y^2, which keeps its precision near the normal
     * where 1 - cos^2 would cancel: D = alpha^2 / (pi (sin^2 + alpha^2 cos^2)^2) */
    float a2 = alpha * alpha;
    float t = (m.x * m.x + m.y * m.y) + a2 * (m.z * m.z);
    return a2 / (MCPT_PI * t * t);
}

/* Lambda(w) = (-1 + sqrt(1 + alpha^2 tan^2 theta)) / 2  (Heitz 2014, eq. 86) */
static float ggx_lambda(vec3 w, float alpha)
{
    float cos2 = w.z * w.z;
    float sin2 = max_f(0.0f, w.x * w.x + w.y * w.y);
    if (cos2 == 0.0f)
        return INFINITY;
    return 0.5f * (sqrtf(1.0f + alpha * alpha * sin2 / cos2) - 1.0f);
}

float mat_ggx_G1(vec3 w, float alpha) { return 1.0f / (1.0f + ggx_lambda(w, alpha)); }

float mat_ggx_G2(vec3 wo, vec3 wi, float alpha)
{
    return 1.0f / (1.0f + ggx_lambda(wo, alpha) + ggx_lambda(wi, alpha));
}

vec3 mat_ggx_sample_vndf(vec3 wo, float alpha, vec2 u)
{
    /* Heitz 2018, listing 1: stretch wo to the hemisphere configuration (alpha = 1) */
    vec3 vh = v3_normalize(v3(alpha * wo.x, alpha * wo.y, wo.z));
    /* orthonormal basis (T1, T2, vh) */
    float lensq = vh.x * vh.x + vh.y * vh.y;
    vec3 t1 = lensq > 0.0f ? v3_scale(v3(-vh.y, vh.x, 0.0f), 1.0f / sqrtf(lensq))
                           : v3(1.0f, 0.0f, 0.0f);
    vec3 t2 = v3_cross(vh, t1);
    /* a uniform disk point, its second coordinate warped onto the projected hemisphere */
    float r = sqrtf(u.x), phi = 2.0f * MCPT_PI * u.y;
    float p1 = r * cosf(phi), p2 = r * sinf(phi);
    float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * sqrtf(max_f(0.0f, 1.0f - p1 * p1)) + s * p2;
    /* reproject onto the hemisphere, then unstretch */
    vec3 nh = v3_add(v3_add(v3_scale(t1, p1), v3_scale(t2, p2)),
                     v3_scale(vh, sqrtf(max_f(0.0f, 1.0f - p1 * p1 - p2 * p2))));
    return v3_normalize(v3(alpha * nh.x, alpha * nh.y, max_f(1e-6f, nh.z)));
}

float mat_ggx_pdf_vndf(vec3 wo, vec3 m, float alpha)
{
    /* D_wo(m) = G1(wo) max(0, wo.m) D(m) / wo.z  (Heitz 2018, eq. 3) */
    float wo_m = v3_dot(wo, m);
    if (!(wo_m > 0.0f) || !(wo.z > 0.0f))
        return 0.0f;
    return mat_ggx_G1(wo, alpha) * wo_m * mat_ggx_D(m, alpha) / wo.z;
}

/* Rough conductor, Walter et al. 2007, eq. 20 with the height-correlated G2:
 * f = F(wo.h) D(h) G2(wo, wi) / (4 |cos theta_o| |cos theta_i|), h = normalize(wo + wi).
 * wo and wi on the same side; evaluated as if both were above the surface. */
static vec3 conductor_f(vec3 F0, float alpha, vec3 wo, vec3 wi)
{
    wo.z = fabsf(wo.z);
    wi.z = fabsf(wi.z);
    vec3 h = v3_add(wo, wi);
    if (v3_is_zero(h) || wo.z == 0.0f || wi.z == 0.0f)
        return v3_splat(0.0f);
    h = v3_normalize(h);
    float scale = mat_ggx_D(h, alpha) * mat_ggx_G2(wo, wi, alpha) / (4.0f * wo.z * wi.z);
    return v3_scale(fresnel_schlick(F0, v3_dot(wo, h)), scale);
}

/* ---- plastic: the coat's albedo couples the base ---- */

/* Kelemen & Szirmay-Kalos 2001, sec. 3, with the coat albedo E(mu) of the table below:
 *   f_base = albedo / pi (1 - E(mu_o)) (1 - E(mu_i)) / (1 - E_avg),  E_avg = 2 int E(mu) mu dmu,
 * reciprocal, and its albedo is exactly albedo (1 - E(mu_o)); E bounds the coat's true albedo
 * from above, so coat + base never reflect more than arrives. */
static float coupled_base(float albedo, float e_o, float e_i, float e_avg)
{
    float denom = 1.0f - e_avg; /* 0 only for a perfect mirror coat, which leaves no base */
    return denom > 1e-6f ? albedo * MCPT_INV_PI * (1.0f - e_o) * (1.0f - e_i) / denom : 0.0f;
}

static vec3 plastic_diffuse_f(const struct material *m, vec3 wo, vec3 wi)
{
    vec3 e_o = coat_albedo(m->specular, fabsf(wo.z), m->roughness);
    vec3 e_i = coat_albedo(m->specular, fabsf(wi.z), m->roughness);
    vec3 e_avg = coat_albedo_avg(m->specular, m->roughness);
    return v3(coupled_base(m->albedo.x, e_o.x, e_i.x, e_avg.x),
              coupled_base(m->albedo.y, e_o.y, e_i.y, e_avg.y),
              coupled_base(m->albedo.z, e_o.z, e_i.z, e_avg.z));
}

/* Probability of sampling the coat: its share of the directional albedo (the Fresnel-weighted
 * lobe choice), p = lum(E(mu_o)) / (lum(E(mu_o)) + lum(albedo (1 - E(mu_o)))). */
static float plastic_spec_prob(const struct material *m, vec3 wo)
{
    vec3 e = coat_albedo(m->specular, fabsf(wo.z), m->roughness);
    float spec = v3_luminance(e);
    float base = v3_luminance(v3_mul(m->albedo, v3_sub(v3_splat(1.0f), e)));
    return spec + base > 0.0f ? spec / (spec + base) : 1.0f;
}

/* The GGX coat albedo with Schlick Fresnel splits into two F0-free integrals (Karis 2013,
 * "Real Shading in Unreal Engine 4", split sum):
 *   E(mu) = F0 E1(mu) + (1 - F0) E5(mu),
 *   E1(mu) = int D G2 / (4 mu) dwi (F = 1),  E5(mu) = int (1 - wo.h)^5 D G2 / (4 mu) dwi.
 * Both are tabulated over (roughness, sqrt(mu)) and interpolated bilinearly; a smooth surface
 * has E1 = 1, E5 = (1 - mu)^5 exactly. */
#define GGX_TABLE_N_R 32  /* roughness nodes r_j = j / 31 */
#define GGX_TABLE_N_MU 32 /* cos theta nodes mu_i = (i / 31)^2: dense towards grazing angles */
static const float GGX_E[GGX_TABLE_N_R][GGX_TABLE_N_MU][2];
static const float GGX_E_AVG[GGX_TABLE_N_R][2];

static void ggx_table(float mu, float roughness, float *e1, float *e5)
{
    float x = sqrtf(clamp01(mu)) * (GGX_TABLE_N_MU - 1);
    float y = clamp01(roughness) * (GGX_TABLE_N_R - 1);
    int i = x >= GGX_TABLE_N_MU - 1 ? GGX_TABLE_N_MU - 2 : (int)x;
    int j = y >= GGX_TABLE_N_R - 1 ? GGX_TABLE_N_R - 2 : (int)y;
    float tx = x - (float)i, ty = y - (float)j;
    for (int k = 0; k < 2; k++) {
        float a = GGX_E[j][i][k] + tx * (GGX_E[j][i + 1][k] - GGX_E[j][i][k]);
        float b = GGX_E[j + 1][i][k] + tx * (GGX_E[j + 1][i + 1][k] - GGX_E[j + 1][i][k]);
        *(k == 0 ? e1 : e5) = a + ty * (b - a);
    }
}

static vec3 coat_albedo(vec3 F0, float cos_theta, float roughness)
{
    float e1, e5;
    if (roughness * roughness < MAT_ALPHA_SMOOTH) {
        float c = 1.0f - clamp01(cos_theta);
        e1 = 1.0f;
        e5 = (c * c) * (c * c) * c;
    } else {
        ggx_table(cos_theta, roughness, &e1, &e5);
    }
    return v3_add(v3_scale(F0, e1), v3_scale(v3_sub(v3_splat(1.0f), F0), e5));
}

/* E_avg = 2 int_0^1 E(mu) mu dmu of the interpolated table: exact per roughness node (the
 * generator integrates each row, piecewise linear in sqrt(mu), in closed form), linear between
 * nodes like the table itself. */
static vec3 coat_albedo_avg(vec3 F0, float roughness)
{
    float a1, a5;
    if (roughness * roughness < MAT_ALPHA_SMOOTH) {
        a1 = 1.0f;
        a5 = 1.0f / 21.0f; /* 2 int (1 - mu)^5 mu dmu = 2 B(2, 6) = 1 / 21 */
    } else {
        float y = clamp01(roughness) * (GGX_TABLE_N_R - 1);
        int j = y >= GGX_TABLE_N_R - 1 ? GGX_TABLE_N_R - 2 : (int)y;
        float ty = y - (float)j;
        a1 = GGX_E_AVG[j][0] + ty * (GGX_E_AVG[j + 1][0] - GGX_E_AVG[j][0]);
        a5 = GGX_E_AVG[j][1] + ty * (GGX_E_AVG[j + 1][1] - GGX_E_AVG[j][1]);
    }
    return v3_add(v3_scale(F0, a1), v3_scale(v3_sub(v3_splat(1.0f), F0), a5));
}

float mat_ggx_albedo(float cos_theta, float roughness, float F0)
{
    return coat_albedo(v3_splat(F0), cos_theta, roughness).x;
}

/* ---- the coat albedo table ----
 * Generated by tests/data/trace/ggx_albedo_gen.c (`make ggx-table`): E1 and E5 at
 * each node by nested adaptive Simpson over the VNDF sample space, then every node raised by
 * three times the largest amount by which bilinear interpolation falls below the true value in
 * the cells around it (checked at cell centres and edge midpoints) plus 1e-4, and capped at 1,
 * so that the interpolated table is an upper bound on the true albedo (tests/material_test.c
 * checks it at random points).  GGX_E_AVG holds the exact 2 int E mu dmu of each row. */
#include "material_ggx_table.inc"
