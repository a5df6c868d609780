/* material.h - BSDFs and emission.  A material is an enum kind plus parameters; mat_eval,
 * mat_sample and mat_pdf switch on the kind.  Directions wo, wi are unit vectors pointing away
 * from the surface, in the local shading frame (n = +z).  f excludes the cosine; pdfs are per
 * unit solid angle.  References: PBRT 4e, ch. 9, "Reflection Models". */
#ifndef MCPT_MATERIAL_H
#define MCPT_MATERIAL_H

#include "vec.h"

enum mat_kind {
    MAT_DIFFUSE,    /* Lambertian, f = albedo / pi */
    MAT_MIRROR,     /* perfect specular reflection, tinted by specular */
    MAT_DIELECTRIC, /* smooth glass: Fresnel-weighted reflection and refraction, ior */
};

struct material {
    char name[64];     /* unique within a scene */
    enum mat_kind kind;
    vec3 albedo;       /* diffuse reflectance (MAT_DIFFUSE) */
    vec3 specular;     /* reflectance tint (MAT_MIRROR), transmission tint (MAT_DIELECTRIC) */
    vec3 Le;           /* emitted radiance, one-sided (front = geometric normal side) */
    float ior;         /* index of refraction inside / outside (MAT_DIELECTRIC) */
    bool two_sided_emission; /* emits from both sides when true */
};

/* A BSDF sample.  f already includes any Fresnel weight; for a specular (delta) lobe, f and
 * pdf are both "delta" quantities whose ratio is the throughput weight f |cos| / pdf. */
struct mat_sample {
    vec3 wi;          /* sampled incident direction, local frame */
    vec3 f;           /* BSDF value for (wo, wi) */
    float pdf_sa;     /* solid-angle pdf of wi */
    bool is_specular; /* delta lobe: no MIS, no light sampling */
};

/* f(wo, wi), excluding the cosine.  Zero for specular kinds. */
vec3 mat_eval(const struct material *m, vec3 wo, vec3 wi);

/* Samples wi given wo from uniforms u_lobe (lobe choice) and u (direction).  Returns false when
 * no direction is produced (e.g. wo below the surface of a reflective BSDF). */
bool mat_sample(const struct material *m, vec3 wo, float u_lobe, vec2 u, struct mat_sample *s);

/* Solid-angle pdf with which mat_sample picks wi given wo.  Zero for specular kinds. */
float mat_pdf(const struct material *m, vec3 wo, vec3 wi);

/* True when the material has only delta lobes (no light sampling helps it). */
bool mat_is_specular(const struct material *m);

/* Emitted radiance leaving the surface towards w (world), with geometric normal ng. */
vec3 mat_emission(const struct material *m, vec3 ng, vec3 w);

#endif
