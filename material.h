/* material.h - BSDFs, textures and emission.  A material is an enum kind plus parameters; mat_eval,
 * mat_sample and mat_pdf switch on the kind.  Directions wo, wi are unit vectors pointing away
 * from the surface, in the local shading frame (n = +z).  f excludes the cosine; pdfs are per
 * unit solid angle.  References: PBRT 4e, ch. 9, "Reflection Models"; Walter et al. 2007,
 * "Microfacet Models for Refraction through Rough Surfaces"; Heitz 2014, "Understanding the
 * Masking-Shadowing Function in Microfacet-Based BRDFs"; Heitz 2018, "Sampling the GGX
 * Distribution of Visible Normals"; Kelemen & Szirmay-Kalos 2001, "A Microfacet Based Coupled
 * Specular-Matte BRDF Model with Importance Sampling". */
#ifndef MCPT_MATERIAL_H
#define MCPT_MATERIAL_H

#include "vec.h"

enum mat_kind {
    MAT_DIFFUSE,         /* Lambertian, f = albedo / pi, cosine-weighted sampling */
    MAT_MIRROR,          /* perfect specular reflection, tinted by specular */
    MAT_DIELECTRIC,      /* smooth glass: exact Fresnel reflection and refraction, ior */
    MAT_DIFFUSE_UNIFORM, /* Lambertian sampled uniformly over the hemisphere (teaching variant) */
    MAT_CONDUCTOR,       /* rough metal: GGX microfacet reflection, Schlick Fresnel F0 = specular */
    MAT_PLASTIC,         /* diffuse base (albedo) under a GGX coat (F0 = specular), coupled so that
                            the albedo never exceeds 1 (Kelemen & Szirmay-Kalos 2001) */
};

struct material {
    char name[64]; /* unique within a scene */
    enum mat_kind kind;
    vec3 albedo;             /* diffuse reflectance (diffuse kinds, the plastic's base) */
    vec3 specular;           /* reflectance tint (MAT_MIRROR), transmission tint (MAT_DIELECTRIC),
                          normal-incidence reflectance F0 (MAT_CONDUCTOR, MAT_PLASTIC) */
    vec3 Le;                 /* emitted radiance, one-sided (front = geometric normal side) */
    float ior;               /* index of refraction inside / outside (MAT_DIELECTRIC) */
    bool two_sided_emission; /* emits from both sides when true */
    float roughness;         /* perceptual roughness r in [0, 1] (MAT_CONDUCTOR, MAT_PLASTIC); GGX
                          alpha = r^2; alpha < MAT_ALPHA_SMOOTH is a perfectly smooth surface */
    vec3 checker_albedo;     /* the checker texture's second albedo */
    float checker_scale;     /* checker cell size (scene units, or uv units); 0 = no texture */
    bool checker_uv;         /* checker over the surface (u, v) instead of world space */
};

/* GGX alpha below which a surface is treated as perfectly smooth (a delta lobe), as PBRT 4e
 * does (ch. 9, "Roughness Using Microfacet Theory", EffectivelySmooth). */
#define MAT_ALPHA_SMOOTH 1e-3f

/* A BSDF sample.  f already includes any Fresnel weight; for a specular (delta) lobe, f and
 * pdf are both "delta" quantities whose ratio is the throughput weight f |cos| / pdf. */
struct mat_sample {
    vec3 wi;          /* sampled incident direction, local frame */
    vec3 f;           /* BSDF value for (wo, wi): every non-delta lobe, or the delta lobe */
    float pdf_sa;     /* solid-angle pdf of wi (a discrete probability for a delta lobe) */
    bool is_specular; /* delta lobe: no MIS, no light sampling */
};

/* f(wo, wi) of every non-delta lobe, excluding the cosine.  Zero for purely specular kinds. */
vec3 mat_eval(const struct material *m, vec3 wo, vec3 wi);

/* Samples wi given wo from uniforms u_lobe (lobe choice) and u (direction).  Returns false when
 * no direction is produced (e.g. wo in the plane of the surface, or a microfacet reflection
 * below the surface). */
bool mat_sample(const struct material *m, vec3 wo, float u_lobe, vec2 u, struct mat_sample *s);

/* Solid-angle pdf with which mat_sample picks wi given wo, non-delta lobes only (the lobe
 * choice included).  Zero for purely specular kinds. */
float mat_pdf(const struct material *m, vec3 wo, vec3 wi);

/* True when the material has only delta lobes (light sampling cannot help it). */
bool mat_is_specular(const struct material *m);
/* True when any lobe is a delta (mirror, glass, smooth conductor, smooth-coated plastic). */
bool mat_has_delta(const struct material *m);

/* Emitted radiance leaving the surface towards w (world), with geometric normal ng. */
vec3 mat_emission(const struct material *m, vec3 ng, vec3 w);

/* The albedo at world point p with surface coordinates uv: the checker texture when
 * checker_scale > 0 (world space: cells of edge checker_scale centred on its integer
 * multiples, so a surface at such a coordinate never sits on a cell boundary; uv space: cells
 * from (0, 0)), else m->albedo. */
vec3 mat_albedo_at(const struct material *m, vec3 p, vec2 uv);

/* ---- GGX (Trowbridge-Reitz) microfacets, isotropic, about +z; exposed for the tests ---- */

/* D(m) = alpha^2 / (pi (cos^2 theta_m (alpha^2 - 1) + 1)^2), per unit solid angle of m
 * (Walter et al. 2007, eq. 33); 0 below the surface. */
float mat_ggx_D(vec3 m, float alpha);
/* Smith G1(w) = 1 / (1 + Lambda(w)), Lambda(w) = (-1 + sqrt(1 + alpha^2 tan^2 theta)) / 2
 * (Heitz 2014, eqs. 43 and 86). */
float mat_ggx_G1(vec3 w, float alpha);
/* Height-correlated masking-shadowing G2 = 1 / (1 + Lambda(wo) + Lambda(wi)) (Heitz 2014,
 * eq. 99), for wo and wi on the same side. */
float mat_ggx_G2(vec3 wo, vec3 wi, float alpha);
/* A visible normal for wo (wo.z > 0), Heitz 2018, listing 1; its density per solid angle of
 * m is D_wo(m) = G1(wo) max(0, wo.m) D(m) / wo.z (Heitz 2018, eq. 3): mat_ggx_pdf_vndf. */
vec3 mat_ggx_sample_vndf(vec3 wo, float alpha, vec2 u);
float mat_ggx_pdf_vndf(vec3 wo, vec3 m, float alpha);
/* Directional albedo of the GGX coat with Schlick Fresnel of normal reflectance F0 (one
 * channel), as tabulated for the plastic: E(mu) = F0 E1(mu) + (1 - F0) E5(mu), an upper bound on
 * the true value (see the table at the end of material.c). */
float mat_ggx_albedo(float cos_theta, float roughness, float F0);

#endif
