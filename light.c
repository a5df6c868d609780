/* light.c - the light table: each light's emitted power, the pick by power, and per light the
 * sampling of a direction from a reference point and its solid-angle density.
 * Lights: emissive triangles, quads and spheres (area lights: their shape samples the point,
 * shape.c), point lights (delta) and the sky (cosine-weighted about the shading normal).
 * Picking: Walker's alias method over the powers, pmf_i = Phi_i / sum Phi (PBRT 4e, ch. 12,
 * "Light Sampling", power light sampler).  Sampling and densities: PBRT 4e, ch. 12, "Light
 * Sources" (SampleLi, PDF_Li); every density returned is per unit solid angle.  This file traces
 * no ray: the integrator (trace.c) turns a sample into a shadow ray. */
#include "light.h"

#include <stdlib.h>

struct light_table {
    const struct scene *scene;
    struct sample_alias_bin *bins; /* n_lights entries: pick a light by power */
    uint32_t n_lights;             /* scene->n_lights, plus 1 for the sky when it is not black */
    uint32_t sky_idx;              /* light index of the sky (the last), or LIGHT_NONE */
    uint32_t *tri_light;           /* light index of each triangle, or LIGHT_NONE */
    uint32_t *quad_light;          /* light index of each quad, or LIGHT_NONE */
    uint32_t *sphere_light;        /* light index of each sphere, or LIGHT_NONE */
    struct triangle_plane *planes; /* by light index: each emitting triangle's plane (shape.h) */
    bool by_solid_angle;           /* triangles and quads by solid angle (render light-sampling) */
};

vec3 light_sky_radiance(const struct sky *sky, vec3 d)
{
    switch (sky->kind) {
    case SKY_NONE:
        return v3_splat(0.0f);
    case SKY_CONSTANT:
        return sky->radiance;
    case SKY_GRADIENT: {
        float s = max_f(0.0f, d.y); /* lerp(horizon, zenith, max(d.y, 0)) */
        return v3_add(v3_scale(sky->horizon, 1.0f - s), v3_scale(sky->zenith, s));
    }
    }
    return v3_splat(0.0f);
}

static void triangle_corners(const struct scene *scene, uint32_t tri_idx, vec3 p[3])
{
    for (int k = 0; k < 3; k++)
        p[k] = scene->positions[scene->tris[tri_idx].v[k]];
}

/* ---- power ---- */

/* Emitted power (luminance) of a scene light, for light selection: Phi = pi A Le per emitting
 * side of an area light, Phi = 4 pi I for a point light.  *area receives A (0 for a point). */
static double light_power(const struct scene *scene, const struct light *l, double *area)
{
    const struct material *m;
    vec3 p[3];
    *area = 0.0;
    switch (l->kind) {
    case LIGHT_TRIANGLE:
        m = &scene->materials[scene->tris[l->prim_idx].mat_idx];
        triangle_corners(scene, l->prim_idx, p);
        *area = shape_triangle_area(p, NULL);
        break;
    case LIGHT_QUAD:
        m = &scene->materials[scene->quads[l->prim_idx].mat_idx];
        *area = shape_quad_area(&scene->quads[l->prim_idx]);
        break;
    case LIGHT_SPHERE: {
        const struct sphere *s = &scene->spheres[l->prim_idx];
        m = &scene->materials[s->mat_idx];
        *area = 4.0 * MCPT_PI * (double)s->radius * s->radius;
        break;
    }
    case LIGHT_POINT:
        return 4.0 * MCPT_PI * v3_luminance(l->intensity); /* Phi = 4 pi I */
    default:
        return 0.0;
    }
    double sides = m->two_sided_emission ? 2.0 : 1.0;
    return MCPT_PI * *area * sides * v3_luminance(m->Le);
}

/* Power of the sky as PBRT 4e counts an infinite light's (ch. 12, "Uniform Infinite Lights"):
 * Phi = 4 pi^2 r^2 L_avg for the scene's bounding sphere of radius r; a gradient sky's average
 * over the sphere is 3/4 horizon + 1/4 zenith (the mean of max(d.y, 0) is 1/4). */
static double sky_power(const struct sky *sky, double radius)
{
    vec3 avg = sky->kind == SKY_CONSTANT
                   ? sky->radiance
                   : v3_add(v3_scale(sky->horizon, 0.75f), v3_scale(sky->zenith, 0.25f));
    return 4.0 * MCPT_PI * MCPT_PI * radius * radius * v3_luminance(avg);
}

/* Radius of a bounding sphere of the scene's finite geometry, point lights and camera (planes
 * are infinite and left out); 1 when there is nothing to bound. */
static double scene_radius(const struct scene *scene)
{
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
#define GROW(P, R)                                                                                 \
    do {                                                                                           \
        vec3 p_ = (P);                                                                             \
        double r_ = (R);                                                                           \
        for (int k_ = 0; k_ < 3; k_++) {                                                           \
            lo[k_] = fmin(lo[k_], v3_get(p_, k_) - r_);                                            \
            hi[k_] = fmax(hi[k_], v3_get(p_, k_) + r_);                                            \
        }                                                                                          \
    } while (0)
    for (uint32_t i = 0; i < scene->n_positions; i++)
        GROW(scene->positions[i], 0.0);
    for (uint32_t i = 0; i < scene->n_spheres; i++)
        GROW(scene->spheres[i].center, scene->spheres[i].radius);
    for (uint32_t i = 0; i < scene->n_quads; i++) {
        const struct quad *q = &scene->quads[i];
        vec3 c = d3_to_float(q->corner), e1 = d3_to_float(q->e1), e2 = d3_to_float(q->e2);
        GROW(c, 0.0);
        GROW(v3_add(c, v3_add(e1, e2)), 0.0);
        GROW(v3_add(c, e1), 0.0);
        GROW(v3_add(c, e2), 0.0);
    }
    for (uint32_t i = 0; i < scene->n_lights; i++)
        if (scene->lights[i].kind == LIGHT_POINT)
            GROW(scene->lights[i].position, 0.0);
    GROW(scene->camera.eye, 0.0);
#undef GROW
    double d2 = 0.0;
    for (int k = 0; k < 3; k++)
        d2 += (hi[k] - lo[k]) * (hi[k] - lo[k]);
    double r = 0.5 * sqrt(d2);
    return r > 0.0 && isfinite(r) ? r : 1.0;
}

/* The bad-input error for scene light l whose power Phi (area A) is not finite: the scene
 * records no file position for a primitive, so the message names the emitter by kind, index,
 * material and a corner. */
static void power_error(const struct scene *scene, const struct light *l, double phi, double area,
                        struct mcpt_error *err)
{
    const char *kind = l->kind == LIGHT_TRIANGLE ? "triangle" : "quad";
    uint32_t mat_idx;
    vec3 corner;
    if (l->kind == LIGHT_TRIANGLE) {
        mat_idx = scene->tris[l->prim_idx].mat_idx;
        corner = scene->positions[scene->tris[l->prim_idx].v[0]];
    } else {
        mat_idx = scene->quads[l->prim_idx].mat_idx;
        corner = d3_to_float(scene->quads[l->prim_idx].corner);
    }
    char got[64];
    if (!isfinite(area))
        snprintf(got, sizeof got, "an area beyond float range");
    else
        snprintf(got, sizeof got, "power %g", phi);
    mcpt_error_set(err, "", 0, 0,
                   "emissive %s %u (material '%s', corner %g,%g,%g): expected an emitter of "
                   "finite power pi A Le, got %s",
                   kind, l->prim_idx, scene->materials[mat_idx].name, (double)corner.x,
                   (double)corner.y, (double)corner.z, got);
}

/* ---- the table ---- */

struct light_table *light_table_build(const struct scene *scene, struct mcpt_error *err)
{
    double *power = NULL;
    struct light_table *lt = calloc(1, sizeof *lt);
    if (!lt)
        goto oom;
    lt->scene = scene;
    lt->by_solid_angle = scene->render.light_sampling == RENDER_LIGHT_SOLID_ANGLE;
    /* the scene's lights, then the sky if it shines */
    bool has_sky = scene->sky.kind != SKY_NONE && sky_power(&scene->sky, 1.0) > 0.0;
    lt->n_lights = scene->n_lights + (has_sky ? 1u : 0u);
    lt->sky_idx = has_sky ? scene->n_lights : LIGHT_NONE;
    lt->tri_light = malloc(sizeof(uint32_t) * ((size_t)scene->n_tris + 1));
    lt->quad_light = malloc(sizeof(uint32_t) * ((size_t)scene->n_quads + 1));
    lt->sphere_light = malloc(sizeof(uint32_t) * ((size_t)scene->n_spheres + 1));
    lt->bins = malloc(sizeof(struct sample_alias_bin) * ((size_t)lt->n_lights + 1));
    power = malloc(sizeof(double) * ((size_t)lt->n_lights + 1));
    lt->planes = malloc(sizeof(struct triangle_plane) * ((size_t)scene->n_lights + 1));
    if (!lt->tri_light || !lt->quad_light || !lt->sphere_light || !lt->bins || !power ||
        !lt->planes)
        goto oom;
    for (uint32_t i = 0; i < scene->n_tris; i++)
        lt->tri_light[i] = LIGHT_NONE;
    for (uint32_t i = 0; i < scene->n_quads; i++)
        lt->quad_light[i] = LIGHT_NONE;
    for (uint32_t i = 0; i < scene->n_spheres; i++)
        lt->sphere_light[i] = LIGHT_NONE;

    /* light selection proportional to emitted power: pmf_i = Phi_i / sum Phi (alias table) */
    for (uint32_t i = 0; i < scene->n_lights; i++) {
        const struct light *l = &scene->lights[i];
        if (l->kind == LIGHT_TRIANGLE) {
            lt->tri_light[l->prim_idx] = i;
            vec3 p[3];
            triangle_corners(scene, l->prim_idx, p);
            shape_triangle_plane(p, scene_tri_groove(scene, l->prim_idx), &lt->planes[i]);
        } else if (l->kind == LIGHT_QUAD)
            lt->quad_light[l->prim_idx] = i;
        else if (l->kind == LIGHT_SPHERE)
            lt->sphere_light[l->prim_idx] = i;
        double area;
        power[i] = light_power(scene, l, &area);
        if (!isfinite(power[i])) {
            power_error(scene, l, power[i], area, err);
            goto fail;
        }
    }
    if (has_sky)
        power[lt->sky_idx] = sky_power(&scene->sky, scene_radius(scene));
    if (lt->n_lights > 0 && !sample_alias_build(power, lt->n_lights, lt->bins))
        goto oom; /* the powers are finite and >= 0: only memory can fail */
    free(power);
    return lt;
oom:
    mcpt_error_runtime(err, NULL, "out of memory building the light table");
fail:
    free(power);
    light_table_free(lt);
    return NULL;
}

void light_table_free(struct light_table *lt)
{
    if (!lt)
        return;
    free(lt->bins);
    free(lt->tri_light);
    free(lt->quad_light);
    free(lt->sphere_light);
    free(lt->planes);
    free(lt);
}

uint32_t light_count(const struct light_table *lt) { return lt->n_lights; }

uint32_t light_sky_idx(const struct light_table *lt) { return lt->sky_idx; }

uint32_t light_idx_of(const struct light_table *lt, enum light_kind kind, uint32_t prim_idx)
{
    switch (kind) {
    case LIGHT_TRIANGLE:
        return lt->tri_light[prim_idx];
    case LIGHT_QUAD:
        return lt->quad_light[prim_idx];
    case LIGHT_SPHERE:
        return lt->sphere_light[prim_idx];
    case LIGHT_POINT:
        break;
    }
    return LIGHT_NONE;
}

bool light_is_delta(const struct light_table *lt, uint32_t light_idx)
{
    return light_idx < lt->scene->n_lights && lt->scene->lights[light_idx].kind == LIGHT_POINT;
}

uint32_t light_pick(const struct light_table *lt, float u, float *pmf)
{
    return sample_alias_pick(lt->bins, lt->n_lights, u, pmf);
}

float light_pmf(const struct light_table *lt, uint32_t light_idx)
{
    return light_idx < lt->n_lights ? lt->bins[light_idx].pmf : 0.0f;
}

/* ---- sampling and densities, per kind of light ---- */

/* The sky: wi cosine-weighted about n_sky, pdf_sa = cos theta / pi. */
static bool sample_sky(const struct sky *sky, vec3 n_sky, vec2 u, struct light_sample *ls)
{
    vec3 t, b;
    v3_basis(n_sky, &t, &b);
    vec3 w = sample_cosine_hemisphere(u);
    ls->wi = v3_normalize(v3_from_local(w, t, b, n_sky));
    ls->pdf_sa = pdf_cosine_hemisphere(w.z);
    ls->Le = light_sky_radiance(sky, ls->wi);
    ls->is_delta = false;
    ls->is_infinite = true;
    return ls->pdf_sa > 0.0f && !v3_is_zero(ls->Le);
}

/* A point light: the one direction to it, Le = I / r^2 (PBRT 4e, ch. 12, "Point Lights"). */
static bool sample_point(const struct light *l, const struct surface *ref, struct light_sample *ls)
{
    vec3 d = v3_sub(l->position, ref->p);
    float dist2 = v3_dot(d, d);
    if (!(dist2 > 0.0f))
        return false;
    ls->wi = v3_scale(d, 1.0f / sqrtf(dist2));
    ls->Le = v3_scale(l->intensity, 1.0f / dist2);
    ls->pdf_sa = 0.0f;
    ls->is_delta = true;
    ls->is_infinite = false;
    ls->p = l->position;
    ls->p_error = v3_splat(0.0f);
    ls->n = v3_splat(0.0f);
    return true;
}

/* Whether the point p_ref lies behind the plane through p0 spanned by edges e1 and e2 (front:
 * e1 x e2) of a flat emitter of material m that emits on its front side only: then no point
 * of it sends light to p_ref (mat_emission), and sampling one would be wasted.  In double: the
 * triple product of float differences scales as the cube of the scene's unit, which leaves
 * float's range (0 below a scale of about 1e-13, inf above 1e13; tests/extremes, Cornell box
 * from 1e-15 to 1e15). */
static bool is_behind(const struct material *m, struct dvec3 p0, struct dvec3 n, vec3 p_ref)
{
    if (m->two_sided_emission)
        return false;
    double r[3] = {(double)p_ref.x - p0.x, (double)p_ref.y - p0.y, (double)p_ref.z - p0.z};
    return n.x * r[0] + n.y * r[1] + n.z * r[2] <= 0.0;
}

/* Whether the point ref lies on or inside sphere s of material m that emits outwards only:
 * then every segment from ref to a point of the sphere meets that point from inside, where
 * mat_emission gives 0, so sampling one would be wasted; and where ref and the point lie on the
 * sphere a few rounding errors apart, the rounded direction can point either way: a diffuse
 * sphere of radius 1 at x = 1e5 sampled from inside counted a few such samples as lit, with
 * the tiny distance's huge weight.  "On" is within ref's own error bound (in double). */
static bool is_within(const struct material *m, const struct sphere *s, const struct surface *ref)
{
    if (m->two_sided_emission)
        return false;
    double d[3] = {(double)ref->p.x - s->center.x, (double)ref->p.y - s->center.y,
                   (double)ref->p.z - s->center.z};
    double e[3] = {ref->p_error.x, ref->p_error.y, ref->p_error.z};
    double reach = (double)s->radius + sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
    return d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= reach * reach * (1.0 + 0x1p-40);
}

bool light_sample(const struct light_table *lt, uint32_t light_idx, const struct surface *ref,
                  const vec3 *n_sky_p, const vec2 *u_p, struct light_sample *ls)
{
    const vec3 n_sky = {n_sky_p->x, n_sky_p->y, n_sky_p->z}; /* read a float at a time (light.h) */
    const vec2 u = {u_p->x, u_p->y};
    const struct scene *scene = lt->scene;
    if (light_idx == lt->sky_idx)
        return sample_sky(&scene->sky, n_sky, u, ls);
    if (light_idx >= scene->n_lights)
        return false;
    const struct light *l = &scene->lights[light_idx];
    /* an area light: its shape samples the point and gives pdf_sa (shape.c) */
    struct shape_sample ss;
    uint32_t mat_idx;
    bool ok;
    switch (l->kind) {
    case LIGHT_POINT:
        return sample_point(l, ref, ls);
    case LIGHT_TRIANGLE: {
        const struct triangle_plane *tp = &lt->planes[light_idx];
        mat_idx = scene->tris[l->prim_idx].mat_idx;
        if (is_behind(&scene->materials[mat_idx], d3(tp->p0), tp->c, ref->p))
            return false;
        if (lt->by_solid_angle) {
            vec3 p[3];
            triangle_corners(scene, l->prim_idx, p);
            ok = shape_triangle_sample_solid_angle(p, ref, u, &ss);
        } else {
            ok = shape_triangle_plane_sample(tp, ref, u, &ss);
        }
        break;
    }
    case LIGHT_QUAD: {
        const struct quad *q = &scene->quads[l->prim_idx];
        mat_idx = q->mat_idx;
        const double e1[3] = {q->e1.x, q->e1.y, q->e1.z};
        const double e2[3] = {q->e2.x, q->e2.y, q->e2.z};
        struct dvec3 n = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                          e1[0] * e2[1] - e1[1] * e2[0]};
        if (is_behind(&scene->materials[mat_idx], q->corner, n, ref->p))
            return false;
        ok = lt->by_solid_angle ? shape_quad_sample_solid_angle(q, ref, u, &ss)
                                : shape_quad_sample(q, ref, u, &ss);
        break;
    }
    case LIGHT_SPHERE: {
        const struct sphere *s = &scene->spheres[l->prim_idx];
        mat_idx = s->mat_idx;
        if (is_within(&scene->materials[mat_idx], s, ref))
            return false;
        ok = shape_sphere_sample(s, ref, n_sky, u, &ss);
        break;
    }
    default:
        return false;
    }
    if (!ok)
        return false;
    ls->wi = ss.wi;
    ls->pdf_sa = ss.pdf_sa;
    ls->Le = mat_emission(&scene->materials[mat_idx], ss.n, v3_neg(ss.wi));
    ls->is_delta = false;
    ls->is_infinite = false;
    ls->p = ss.p;
    ls->p_error = ss.p_error;
    ls->n = ss.n;
    return !v3_is_zero(ls->Le);
}

float light_pdf(const struct light_table *lt, uint32_t light_idx, const struct surface *ref,
                vec3 n_sky, const struct surface *on, vec3 wi)
{
    const struct scene *scene = lt->scene;
    if (light_idx == lt->sky_idx)
        return pdf_cosine_hemisphere(max_f(0.0f, v3_dot(wi, n_sky)));
    if (light_idx >= scene->n_lights)
        return 0.0f;
    const struct light *l = &scene->lights[light_idx];
    switch (l->kind) {
    case LIGHT_TRIANGLE: {
        if (!lt->by_solid_angle)
            return shape_triangle_plane_pdf(&lt->planes[light_idx], ref, on, wi);
        vec3 p[3];
        triangle_corners(scene, l->prim_idx, p);
        return shape_triangle_pdf_solid_angle(p, ref, on, wi);
    }
    case LIGHT_QUAD: {
        const struct quad *q = &scene->quads[l->prim_idx];
        return lt->by_solid_angle ? shape_quad_pdf_solid_angle(q, ref, on, wi)
                                  : shape_quad_pdf(q, ref, on, wi);
    }
    case LIGHT_SPHERE: {
        const struct sphere *s = &scene->spheres[l->prim_idx];
        return is_within(&scene->materials[s->mat_idx], s, ref)
                   ? 0.0f
                   : shape_sphere_pdf(s, ref, n_sky, wi);
    }
    case LIGHT_POINT:
        break;
    }
    return 0.0f; /* a delta light: no direction found otherwise has it */
}
