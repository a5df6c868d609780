/* light.h - the lights of a scene as next-event estimation sees them: the light table (the
 * scene's lights in order, then the sky when it is not black), a pick by emitted power, and for
 * each light a sampled direction from a reference point with its solid-angle density, and that
 * density for a direction found otherwise (by BSDF sampling, for MIS).  PBRT 4e, ch. 12, "Light
 * Sources" and "Light Sampling".  Light indices run 0 .. light_count() - 1. */
#ifndef MCPT_LIGHT_H
#define MCPT_LIGHT_H

#include "scene.h"

#define LIGHT_NONE UINT32_MAX /* the light index of a primitive that does not emit */

struct light_table; /* opaque: the scene, the alias table of powers, primitive -> light index */

/* Builds the light table of scene, which must outlive it: every light's emitted power (Phi =
 * pi A Le per emitting side of an area light, 4 pi I for a point light, PBRT 4e's power of a
 * uniform infinite light for the sky) and the alias table that picks lights in proportion to it.
 * Returns NULL and fills *err on failure: a bad-input error naming the light when a power is not
 * finite (an emitter whose area overflows float), a runtime error when memory runs out. */
struct light_table *light_table_build(const struct scene *scene, struct mcpt_error *err);
void light_table_free(struct light_table *lt);

/* Number of lights; the sky, if it shines, is the last. */
uint32_t light_count(const struct light_table *lt);
/* The light index of the sky, or LIGHT_NONE when the sky is black. */
uint32_t light_sky_idx(const struct light_table *lt);
/* The light index of the emissive primitive prim_idx of the given kind (LIGHT_TRIANGLE,
 * LIGHT_QUAD or LIGHT_SPHERE), or LIGHT_NONE when it does not emit. */
uint32_t light_idx_of(const struct light_table *lt, enum light_kind kind, uint32_t prim_idx);
/* Whether light light_idx is a delta light (a point light): no ray can hit it, no MIS. */
bool light_is_delta(const struct light_table *lt, uint32_t light_idx);

/* The light that u in [0, 1) picks, with probability *pmf = Phi_i / sum Phi (Walker's alias
 * method, sample.h).  light_count() must be > 0. */
uint32_t light_pick(const struct light_table *lt, float u, float *pmf);
/* The probability with which light_pick returns light_idx (0 outside the table). */
float light_pmf(const struct light_table *lt, uint32_t light_idx);

/* A light sample seen from a reference point (PBRT 4e's LightLiSample). */
struct light_sample {
    vec3 wi;          /* unit direction from the reference point to the light */
    vec3 Le;          /* radiance arriving along -wi (I / r^2 for a point light) */
    float pdf_sa;     /* density of wi per unit solid angle; 0 for a delta light */
    bool is_delta;    /* a point light: wi was certain, no MIS */
    bool is_infinite; /* the sky: the light lies at infinity along wi; p, p_error, n unused */
    vec3 p;           /* the point on the light, where a shadow ray ends */
    vec3 p_error;     /* its absolute error bound (0 for a point light) */
    vec3 n;           /* its unit geometric normal; 0 for a point light (no offset at that end) */
};

/* Samples light light_idx from the surface point ref with uniforms u: triangles and quads
 * uniformly by area, spheres seen from outside uniformly in their cone of directions and from
 * inside cosine-weighted about n_sky (shape.h), point lights by their one direction, the sky
 * cosine-weighted about n_sky (the shading normal turned to the side being lit).  False when
 * the sample carries no light (back of a one-sided emitter, degenerate geometry); *ls is then
 * unspecified.  n_sky and u come by pointer: by value, gcc assembled them in memory a float at
 * a time and read them back 8 bytes at once, which the CPU cannot forward from the narrower
 * stores (docs/performance.md, "Store forwarding"). */
bool light_sample(const struct light_table *lt, uint32_t light_idx, const struct surface *ref,
                  const vec3 *n_sky, const vec2 *u, struct light_sample *ls);
/* The solid-angle density with which light_sample picks the unit direction wi from ref, given
 * the point `on` where the ray along wi first meets light light_idx (NULL for the sky, which
 * needs only wi and n_sky); 0 for delta lights and indices outside the table. */
float light_pdf(const struct light_table *lt, uint32_t light_idx, const struct surface *ref,
                vec3 n_sky, const struct surface *on, vec3 wi);

/* Radiance of the sky along the unit direction d (an escaped ray sees it; SKY_NONE is black). */
vec3 light_sky_radiance(const struct sky *sky, vec3 d);

#endif
