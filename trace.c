/* trace.c - unidirectional path tracing with next-event estimation and multiple importance
 * sampling, and the tile-scheduled render loop.
 * Estimator: Kajiya 1986, eq. 1, L(x, wo) = Le(x, wo) + int f(x, wo, wi) L(x', -wi) |cos| dwi,
 * sampled one path vertex at a time; direct light at each vertex from one light sample and one
 * BSDF sample combined by the power heuristic (Veach 1997, ch. 9); Russian roulette on the
 * throughput (PBRT 4e, ch. 13, "A Better Path Tracer").
 *
 * Glossary (PBRT's symbols): wo, wi - unit directions away from the surface (wo towards the
 * previous vertex, wi towards the next); n, ng, ns - normals (geometric, shading); L - radiance
 * carried to the camera; Le - emitted radiance; f - BSDF value; beta - path throughput
 * f |cos| / pdf accumulated along the path; pdf_sa, pdf_area - densities per steradian and per
 * unit area; pmf - discrete probability of picking a light. */
#include "trace.h"

#include <pthread.h>
#include <stdlib.h>
#include <time.h>

#include "camera.h"
#include "material.h"

/* PBRT 4e, ch. 6, "Robust Spawned Ray Origins": shadow rays stop this fraction short of the
 * light point, whose own origin is offset by its error bound. */
static const float SHADOW_EPSILON = 1e-4f;

#define NO_LIGHT UINT32_MAX

struct trace_scene {
    const struct scene *scene;
    struct bvh *bvh;
    struct camera camera;
    float *light_cdf;     /* n_lights + 1 entries, cdf[0] = 0, cdf[n] = 1: pick by power */
    uint32_t *tri_light;  /* light index of each triangle, or NO_LIGHT */
    uint32_t *quad_light; /* light index of each quad, or NO_LIGHT */
    uint32_t *sphere_light;
};

/* What a ray hit: the surface and, if the primitive is an area light, its light index. */
struct hit_record {
    struct surface sf;
    uint32_t light_idx;
};

static bool intersect(const struct trace_scene *ts, const struct ray *ray, struct hit_record *hr);
static bool occluded(const struct trace_scene *ts, const struct ray *ray);
static vec3 sky_radiance(const struct sky *sky, vec3 d);
static float light_pmf(const struct trace_scene *ts, uint32_t light_idx);
static uint32_t pick_light(const struct trace_scene *ts, float u);

/* A light sample seen from a reference point: direction, radiance, density and the shadow ray. */
struct light_sample {
    vec3 wi;        /* unit direction from the reference point to the light point */
    vec3 Le;        /* radiance arriving along -wi (intensity / dist^2 for point lights) */
    float pdf_sa;   /* solid-angle density of wi; 0 for a delta (point) light */
    bool is_delta;  /* point light: no MIS */
    struct ray shadow; /* from the offset reference point to the offset light point */
};

static bool sample_light(const struct trace_scene *ts, uint32_t light_idx,
                         const struct surface *ref, vec2 u, struct light_sample *ls);
static float light_pdf_sa(const struct trace_scene *ts, uint32_t light_idx,
                          const struct surface *ref, const struct surface *on_light, vec3 wi);
static struct ray spawn_ray(const struct surface *sf, vec3 d);

/* ---- the path loop ---- */

vec3 trace_radiance(const struct trace_scene *ts, const struct trace_options *opt,
                    struct ray ray, struct sampler *sampler, uint64_t *n_rays)
{
    const struct scene *scene = ts->scene;
    vec3 L = v3_splat(0.0f);
    vec3 beta = v3_splat(1.0f);
    float eta_scale = 1.0f;     /* product of etap^2 over refractions, undone for roulette */
    bool specular_bounce = false;
    float pdf_bsdf_prev = 0.0f; /* solid-angle pdf of the BSDF sample that made this ray */
    struct surface prev = {0};  /* the vertex the ray left from (used once depth > 0) */
    uint32_t depth_cap = opt->max_depth == TRACE_DEPTH_INFINITE ? TRACE_DEPTH_CAP : opt->max_depth;

    for (uint32_t depth = 0;;) {
        struct hit_record hr;
        (*n_rays)++;
        if (!intersect(ts, &ray, &hr)) {
            /* escaped: sky radiance (not light-sampled, so BSDF sampling takes it whole) */
            L = v3_add(L, v3_mul(beta, sky_radiance(&scene->sky, v3_normalize(ray.d))));
            break;
        }
        const struct surface *sf = &hr.sf;
        const struct material *m = &scene->materials[sf->mat_idx];
        vec3 wo_world = v3_normalize(v3_neg(ray.d));

        /* emission at the hit: L += beta Le w_bsdf (w_bsdf = 1 for camera and specular rays) */
        vec3 Le = mat_emission(m, sf->ng, wo_world);
        if (!v3_is_zero(Le)) {
            float w_bsdf = 1.0f;
            if (depth > 0 && !specular_bounce && hr.light_idx != NO_LIGHT) {
                float pdf_light = light_pmf(ts, hr.light_idx) *
                                  light_pdf_sa(ts, hr.light_idx, &prev, sf, v3_neg(wo_world));
                w_bsdf = mis_power(pdf_bsdf_prev, pdf_light);
            }
            L = v3_add(L, v3_scale(v3_mul(beta, Le), w_bsdf));
        }
        if (depth++ == depth_cap)
            break;

        /* local shading frame: z = ns */
        vec3 t, b;
        v3_basis(sf->ns, &t, &b);
        vec3 wo = v3(v3_dot(wo_world, t), v3_dot(wo_world, b), v3_dot(wo_world, sf->ns));
        uint32_t dim0 = SAMPLE_DIM_BOUNCE0 + (depth - 1) * SAMPLE_DIMS_PER_BOUNCE;

        /* sample a light (next-event estimation):
         * L += beta f |cos theta_i| Le / (pmf pdf_light) * w_light */
        if (!mat_is_specular(m) && scene->n_lights > 0) {
            sample_set_dim(sampler, dim0 + SAMPLE_BOUNCE_LIGHT_CHOICE);
            uint32_t light_idx = pick_light(ts, sample_1d(sampler));
            vec2 u_light = sample_2d(sampler);
            struct light_sample ls;
            if (sample_light(ts, light_idx, sf, u_light, &ls)) {
                vec3 wi = v3(v3_dot(ls.wi, t), v3_dot(ls.wi, b), v3_dot(ls.wi, sf->ns));
                /* reflection only towards the geometric side of wo: no leaks through
                 * surfaces whose shading normal disagrees with the geometry */
                bool same_side = v3_dot(ls.wi, sf->ng) * v3_dot(wo_world, sf->ng) > 0.0f;
                vec3 f = same_side ? mat_eval(m, wo, wi) : v3_splat(0.0f);
                if (!v3_is_zero(f)) {
                    (*n_rays)++;
                    if (!occluded(ts, &ls.shadow)) {
                        float pmf = light_pmf(ts, light_idx);
                        float cos_i = fabsf(wi.z);
                        vec3 contrib = v3_scale(v3_mul(v3_mul(beta, f), ls.Le), cos_i / pmf);
                        if (ls.is_delta) {
                            L = v3_add(L, contrib);
                        } else {
                            float pdf_light = pmf * ls.pdf_sa;
                            float w_light = mis_power(pdf_light, mat_pdf(m, wo, wi));
                            L = v3_add(L, v3_scale(contrib, w_light / ls.pdf_sa));
                        }
                    }
                }
            }
        }

        /* sample the BSDF: beta *= f |cos theta_i| / pdf */
        sample_set_dim(sampler, dim0 + SAMPLE_BOUNCE_BSDF_LOBE);
        float u_lobe = sample_1d(sampler);
        vec2 u_dir = sample_2d(sampler);
        struct mat_sample bs;
        if (!mat_sample(m, wo, u_lobe, u_dir, &bs))
            break;
        vec3 wi_world = v3_from_local(bs.wi, t, b, sf->ns);
        if (!bs.is_specular && v3_dot(wi_world, sf->ng) * v3_dot(wo_world, sf->ng) <= 0.0f)
            break; /* a reflection sample below the geometric surface carries no light */
        beta = v3_mul(beta, v3_scale(bs.f, fabsf(bs.wi.z) / bs.pdf_sa));
        if (bs.is_specular && bs.wi.z * wo.z < 0.0f) {
            /* refraction: f was divided by etap^2; roulette looks at the unscaled beta */
            float eta_rel = wo.z > 0.0f ? m->ior : 1.0f / m->ior;
            eta_scale *= eta_rel * eta_rel;
        }
        specular_bounce = bs.is_specular;
        pdf_bsdf_prev = bs.pdf_sa;
        prev = *sf;
        ray = spawn_ray(sf, wi_world);

        /* Russian roulette: continue with probability 1 - q, q = max(0, 1 - max(beta eta^2)) */
        float rr_beta = v3_max_comp(beta) * eta_scale;
        if (rr_beta < 1.0f && depth > 1) {
            float q = fmaxf(0.0f, 1.0f - rr_beta);
            sample_set_dim(sampler, dim0 + SAMPLE_BOUNCE_ROULETTE);
            if (sample_1d(sampler) < q)
                break;
            beta = v3_scale(beta, 1.0f / (1.0f - q));
        }
        if (v3_is_zero(beta))
            break;
    }
    return L;
}

/* ---- scene queries ---- */

static struct surface triangle_surface(const struct scene *scene, uint32_t tri_idx, float u,
                                       float v)
{
    const struct scene_tri *tri = &scene->tris[tri_idx];
    vec3 p0 = scene->positions[tri->v[0]];
    vec3 p1 = scene->positions[tri->v[1]];
    vec3 p2 = scene->positions[tri->v[2]];
    float b0 = 1.0f - u - v;
    struct surface sf;
    /* p from barycentrics, error gamma(7) sum |b_i p_i| (PBRT 4e, ch. 6, "Managing Rounding
     * Error": triangle intersection error bounds) */
    vec3 bp0 = v3_scale(p0, b0), bp1 = v3_scale(p1, u), bp2 = v3_scale(p2, v);
    sf.p = v3_add(v3_add(bp0, bp1), bp2);
    vec3 abs_sum = v3_add(v3_add(v3(fabsf(bp0.x), fabsf(bp0.y), fabsf(bp0.z)),
                                 v3(fabsf(bp1.x), fabsf(bp1.y), fabsf(bp1.z))),
                          v3(fabsf(bp2.x), fabsf(bp2.y), fabsf(bp2.z)));
    sf.p_error = v3_scale(abs_sum, mcpt_gamma(7));
    sf.ng = v3_normalize(v3_cross(v3_sub(p1, p0), v3_sub(p2, p0)));
    sf.ns = sf.ng;
    if (tri->vn[0] >= 0 && tri->vn[1] >= 0 && tri->vn[2] >= 0) {
        vec3 ns = v3_add(v3_add(v3_scale(scene->normals[tri->vn[0]], b0),
                                v3_scale(scene->normals[tri->vn[1]], u)),
                         v3_scale(scene->normals[tri->vn[2]], v));
        float len = v3_length(ns);
        if (len > 0.0f && isfinite(len)) {
            ns = v3_scale(ns, 1.0f / len);
            sf.ns = v3_dot(ns, sf.ng) < 0.0f ? v3_neg(ns) : ns;
        }
    }
    sf.uv = (vec2){u, v};
    if (tri->vt[0] >= 0 && tri->vt[1] >= 0 && tri->vt[2] >= 0) {
        vec2 t0 = scene->uvs[tri->vt[0]], t1 = scene->uvs[tri->vt[1]], t2 = scene->uvs[tri->vt[2]];
        sf.uv = (vec2){b0 * t0.x + u * t1.x + v * t2.x, b0 * t0.y + u * t1.y + v * t2.y};
    }
    sf.mat_idx = tri->mat_idx;
    return sf;
}

enum hit_kind { HIT_NONE, HIT_TRI, HIT_SPHERE, HIT_QUAD, HIT_PLANE };

static bool intersect(const struct trace_scene *ts, const struct ray *ray_in,
                      struct hit_record *hr)
{
    const struct scene *scene = ts->scene;
    struct ray ray = *ray_in;
    enum hit_kind kind = HIT_NONE;
    uint32_t idx = 0;
    struct bvh_hit bh;
    if (bvh_intersect(ts->bvh, &ray, &bh)) {
        kind = HIT_TRI;
        idx = bh.prim_idx;
        ray.t_max = bh.t;
    }
    float t;
    for (uint32_t i = 0; i < scene->n_spheres; i++)
        if (shape_sphere_intersect(&scene->spheres[i], &ray, &t)) {
            kind = HIT_SPHERE;
            idx = i;
            ray.t_max = t;
        }
    for (uint32_t i = 0; i < scene->n_quads; i++)
        if (shape_quad_intersect(&scene->quads[i], &ray, &t)) {
            kind = HIT_QUAD;
            idx = i;
            ray.t_max = t;
        }
    for (uint32_t i = 0; i < scene->n_planes; i++)
        if (shape_plane_intersect(&scene->planes[i], &ray, &t)) {
            kind = HIT_PLANE;
            idx = i;
            ray.t_max = t;
        }
    switch (kind) {
    case HIT_NONE:
        return false;
    case HIT_TRI:
        hr->sf = triangle_surface(scene, idx, bh.u, bh.v);
        hr->light_idx = ts->tri_light[idx];
        return true;
    case HIT_SPHERE:
        hr->sf = shape_sphere_surface(&scene->spheres[idx], &ray, ray.t_max);
        hr->light_idx = ts->sphere_light[idx];
        return true;
    case HIT_QUAD:
        hr->sf = shape_quad_surface(&scene->quads[idx], &ray, ray.t_max);
        hr->light_idx = ts->quad_light[idx];
        return true;
    case HIT_PLANE:
        hr->sf = shape_plane_surface(&scene->planes[idx], &ray, ray.t_max);
        hr->light_idx = NO_LIGHT;
        return true;
    }
    return false;
}

static bool occluded(const struct trace_scene *ts, const struct ray *ray)
{
    const struct scene *scene = ts->scene;
    float t;
    for (uint32_t i = 0; i < scene->n_spheres; i++)
        if (shape_sphere_intersect(&scene->spheres[i], ray, &t))
            return true;
    for (uint32_t i = 0; i < scene->n_quads; i++)
        if (shape_quad_intersect(&scene->quads[i], ray, &t))
            return true;
    for (uint32_t i = 0; i < scene->n_planes; i++)
        if (shape_plane_intersect(&scene->planes[i], ray, &t))
            return true;
    return bvh_occluded(ts->bvh, ray);
}

/* PBRT 4e, ch. 6, "Robust Spawned Ray Origins": SpawnRay */
static struct ray spawn_ray(const struct surface *sf, vec3 d)
{
    struct ray r;
    r.o = offset_ray_origin(sf->p, sf->p_error, sf->ng, d);
    r.d = d;
    r.t_min = 0.0f;
    r.t_max = INFINITY;
    return r;
}

/* PBRT 4e, ch. 6, "Robust Spawned Ray Origins": SpawnRayTo between two offset points; the ray
 * covers t in (0, 1 - SHADOW_EPSILON) of d = p_to' - p_from'. */
static struct ray spawn_ray_to(const struct surface *from, vec3 p_to, vec3 p_to_error, vec3 n_to)
{
    struct ray r;
    r.o = offset_ray_origin(from->p, from->p_error, from->ng, v3_sub(p_to, from->p));
    vec3 pt = v3_is_zero(n_to) ? p_to : offset_ray_origin(p_to, p_to_error, n_to, v3_sub(r.o, p_to));
    r.d = v3_sub(pt, r.o);
    r.t_min = 0.0f;
    r.t_max = 1.0f - SHADOW_EPSILON;
    return r;
}

static vec3 sky_radiance(const struct sky *sky, vec3 d)
{
    switch (sky->kind) {
    case SKY_NONE:
        return v3_splat(0.0f);
    case SKY_CONSTANT:
        return sky->radiance;
    case SKY_GRADIENT: {
        float s = fmaxf(0.0f, d.y); /* lerp(horizon, zenith, max(d.y, 0)) */
        return v3_add(v3_scale(sky->horizon, 1.0f - s), v3_scale(sky->zenith, s));
    }
    }
    return v3_splat(0.0f);
}

/* ---- lights ---- */

static float triangle_area(const struct scene *scene, uint32_t tri_idx, vec3 *ng)
{
    const struct scene_tri *tri = &scene->tris[tri_idx];
    vec3 p0 = scene->positions[tri->v[0]];
    vec3 c = v3_cross(v3_sub(scene->positions[tri->v[1]], p0),
                      v3_sub(scene->positions[tri->v[2]], p0));
    float len = v3_length(c);
    if (ng)
        *ng = len > 0.0f ? v3_scale(c, 1.0f / len) : v3_splat(0.0f);
    return 0.5f * len;
}

/* Emitted power (luminance) of an area light, for light selection: Phi = pi A Le (one side). */
static double light_power(const struct scene *scene, const struct light *l)
{
    const struct material *m;
    double area;
    switch (l->kind) {
    case LIGHT_TRIANGLE:
        m = &scene->materials[scene->tris[l->prim_idx].mat_idx];
        area = triangle_area(scene, l->prim_idx, NULL);
        break;
    case LIGHT_QUAD:
        m = &scene->materials[scene->quads[l->prim_idx].mat_idx];
        area = v3_length(v3_cross(scene->quads[l->prim_idx].e1, scene->quads[l->prim_idx].e2));
        break;
    case LIGHT_SPHERE: {
        const struct sphere *s = &scene->spheres[l->prim_idx];
        m = &scene->materials[s->mat_idx];
        area = 4.0 * MCPT_PI * (double)s->radius * s->radius;
        break;
    }
    case LIGHT_POINT:
        return 4.0 * MCPT_PI * v3_luminance(l->intensity); /* Phi = 4 pi I */
    default:
        return 0.0;
    }
    double sides = m->two_sided_emission ? 2.0 : 1.0;
    return MCPT_PI * area * sides * v3_luminance(m->Le);
}

static float light_pmf(const struct trace_scene *ts, uint32_t light_idx)
{
    return ts->light_cdf[light_idx + 1] - ts->light_cdf[light_idx];
}

static uint32_t pick_light(const struct trace_scene *ts, float u)
{
    /* binary search for the first cdf entry above u: light i has cdf[i] <= u < cdf[i+1] */
    uint32_t lo = 0, hi = ts->scene->n_lights;
    while (hi - lo > 1) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (ts->light_cdf[mid] <= u)
            lo = mid;
        else
            hi = mid;
    }
    while (light_pmf(ts, lo) == 0.0f && lo + 1 < ts->scene->n_lights)
        lo++; /* never return a zero-probability light */
    return lo;
}

/* Sphere cone sampling: PBRT 4e, ch. 6, "Spheres", Sphere::Sample(ctx, u): directions uniform in
 * the cone subtended by the sphere, pdf_sa = 1 / (2 pi (1 - cos theta_max)). */
static float sphere_cone_pdf(const struct sphere *s, vec3 ref_p)
{
    float dist2 = v3_dot(v3_sub(ref_p, s->center), v3_sub(ref_p, s->center));
    float sin2_theta_max = s->radius * s->radius / dist2;
    float cos_theta_max = sqrtf(fmaxf(0.0f, 1.0f - sin2_theta_max));
    float one_minus_cos = 1.0f - cos_theta_max;
    if (sin2_theta_max < 0.00068523f) /* sin^2(1.5 deg): Taylor expansion keeps precision */
        one_minus_cos = sin2_theta_max / 2.0f;
    return 1.0f / (2.0f * MCPT_PI * one_minus_cos);
}

static vec3 sphere_ref_origin(const struct sphere *s, const struct surface *ref)
{
    return offset_ray_origin(ref->p, ref->p_error, ref->ng, v3_sub(s->center, ref->p));
}

static bool sample_light(const struct trace_scene *ts, uint32_t light_idx,
                         const struct surface *ref, vec2 u, struct light_sample *ls)
{
    const struct scene *scene = ts->scene;
    const struct light *l = &scene->lights[light_idx];
    vec3 p, p_error, n;
    const struct material *m;
    float pdf_area;
    switch (l->kind) {
    case LIGHT_POINT: {
        vec3 d = v3_sub(l->position, ref->p);
        float dist2 = v3_dot(d, d);
        if (!(dist2 > 0.0f))
            return false;
        ls->wi = v3_scale(d, 1.0f / sqrtf(dist2));
        ls->Le = v3_scale(l->intensity, 1.0f / dist2); /* I / r^2 */
        ls->pdf_sa = 0.0f;
        ls->is_delta = true;
        ls->shadow = spawn_ray_to(ref, l->position, v3_splat(0.0f), v3_splat(0.0f));
        return true;
    }
    case LIGHT_TRIANGLE: {
        const struct scene_tri *tri = &scene->tris[l->prim_idx];
        vec3 p0 = scene->positions[tri->v[0]];
        vec3 p1 = scene->positions[tri->v[1]];
        vec3 p2 = scene->positions[tri->v[2]];
        vec2 bc = sample_uniform_triangle(u);
        float b2 = 1.0f - bc.x - bc.y;
        vec3 bp0 = v3_scale(p0, bc.x), bp1 = v3_scale(p1, bc.y), bp2 = v3_scale(p2, b2);
        p = v3_add(v3_add(bp0, bp1), bp2);
        p_error = v3_scale(v3_add(v3_add(v3(fabsf(bp0.x), fabsf(bp0.y), fabsf(bp0.z)),
                                         v3(fabsf(bp1.x), fabsf(bp1.y), fabsf(bp1.z))),
                                  v3(fabsf(bp2.x), fabsf(bp2.y), fabsf(bp2.z))),
                           mcpt_gamma(6));
        pdf_area = 1.0f / triangle_area(scene, l->prim_idx, &n);
        m = &scene->materials[tri->mat_idx];
        break;
    }
    case LIGHT_QUAD: {
        const struct quad *q = &scene->quads[l->prim_idx];
        vec3 a = v3_scale(q->e1, u.x), bb = v3_scale(q->e2, u.y);
        p = v3_add(v3_add(q->corner, a), bb);
        p_error = v3_scale(v3_add(v3_add(v3(fabsf(q->corner.x), fabsf(q->corner.y),
                                            fabsf(q->corner.z)),
                                         v3(fabsf(a.x), fabsf(a.y), fabsf(a.z))),
                                  v3(fabsf(bb.x), fabsf(bb.y), fabsf(bb.z))),
                           mcpt_gamma(4));
        vec3 c = v3_cross(q->e1, q->e2);
        pdf_area = 1.0f / v3_length(c);
        n = v3_normalize(c);
        m = &scene->materials[q->mat_idx];
        break;
    }
    case LIGHT_SPHERE: {
        const struct sphere *s = &scene->spheres[l->prim_idx];
        m = &scene->materials[s->mat_idx];
        /* inside/outside is decided for the reference point offset towards the centre, so a
         * point on the sphere itself counts as inside (PBRT 4e, ch. 6, "Spheres") */
        vec3 origin = sphere_ref_origin(s, ref);
        vec3 wc = v3_sub(s->center, origin);
        float dist2 = v3_dot(wc, wc);
        if (dist2 <= s->radius * s->radius) {
            /* inside the sphere: uniform area sampling, converted to solid angle below */
            float z = 1.0f - 2.0f * u.x, r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
            float phi = 2.0f * MCPT_PI * u.y;
            n = v3(r * cosf(phi), r * sinf(phi), z);
            pdf_area = 1.0f / (4.0f * MCPT_PI * s->radius * s->radius);
        } else {
            /* cone sampling, PBRT 4e, ch. 6, "Spheres" */
            float sin2_theta_max = s->radius * s->radius / dist2;
            float sin_theta_max = sqrtf(sin2_theta_max);
            float cos_theta_max = sqrtf(fmaxf(0.0f, 1.0f - sin2_theta_max));
            float cos_theta = (cos_theta_max - 1.0f) * u.x + 1.0f;
            float sin2_theta = 1.0f - cos_theta * cos_theta;
            if (sin2_theta_max < 0.00068523f) { /* sin^2(1.5 deg): Taylor expansion */
                sin2_theta = sin2_theta_max * u.x;
                cos_theta = sqrtf(1.0f - sin2_theta);
            }
            /* angle alpha from the centre to the sampled point, seen from the sphere centre */
            float cos_alpha = sin2_theta / sin_theta_max +
                              cos_theta * sqrtf(fmaxf(0.0f, 1.0f - sin2_theta / sin2_theta_max));
            float sin_alpha = sqrtf(fmaxf(0.0f, 1.0f - cos_alpha * cos_alpha));
            float phi = 2.0f * MCPT_PI * u.y;
            vec3 wz = v3_scale(wc, -1.0f / sqrtf(dist2)); /* centre -> reference point */
            vec3 wx, wy;
            v3_basis(wz, &wx, &wy);
            n = v3_from_local(v3(sin_alpha * cosf(phi), sin_alpha * sinf(phi), cos_alpha), wx,
                              wy, wz);
            pdf_area = -1.0f; /* marks a solid-angle pdf */
        }
        vec3 rn = v3_scale(n, s->radius);
        p = v3_add(s->center, rn);
        p_error = v3_add(v3_scale(v3(fabsf(rn.x), fabsf(rn.y), fabsf(rn.z)), mcpt_gamma(5)),
                         v3_scale(v3(fabsf(p.x), fabsf(p.y), fabsf(p.z)), mcpt_gamma(1)));
        if (pdf_area < 0.0f) {
            vec3 d = v3_sub(p, ref->p);
            float dist = v3_length(d);
            if (!(dist > 0.0f))
                return false;
            ls->wi = v3_scale(d, 1.0f / dist);
            ls->pdf_sa = sphere_cone_pdf(s, origin);
            ls->Le = mat_emission(m, n, v3_neg(ls->wi));
            ls->is_delta = false;
            ls->shadow = spawn_ray_to(ref, p, p_error, n);
            return ls->pdf_sa > 0.0f && !v3_is_zero(ls->Le);
        }
        break;
    }
    default:
        return false;
    }
    /* area -> solid angle: pdf_sa = pdf_area * dist^2 / |cos theta_light| */
    vec3 d = v3_sub(p, ref->p);
    float dist2 = v3_dot(d, d);
    if (!(dist2 > 0.0f))
        return false;
    float dist = sqrtf(dist2);
    ls->wi = v3_scale(d, 1.0f / dist);
    float cos_light = fabsf(v3_dot(n, ls->wi));
    if (!(cos_light > 0.0f))
        return false;
    ls->pdf_sa = pdf_area * dist2 / cos_light;
    ls->Le = mat_emission(m, n, v3_neg(ls->wi));
    ls->is_delta = false;
    ls->shadow = spawn_ray_to(ref, p, p_error, n);
    return isfinite(ls->pdf_sa) && !v3_is_zero(ls->Le);
}

/* Solid-angle density with which sample_light(light_idx) picks the direction wi from ref_p,
 * given the point on_light that a ray along wi hit. */
static float light_pdf_sa(const struct trace_scene *ts, uint32_t light_idx,
                          const struct surface *ref, const struct surface *on_light, vec3 wi)
{
    vec3 ref_p = ref->p;
    const struct scene *scene = ts->scene;
    const struct light *l = &scene->lights[light_idx];
    float pdf_area;
    switch (l->kind) {
    case LIGHT_TRIANGLE:
        pdf_area = 1.0f / triangle_area(scene, l->prim_idx, NULL);
        break;
    case LIGHT_QUAD:
        pdf_area = 1.0f / v3_length(v3_cross(scene->quads[l->prim_idx].e1,
                                             scene->quads[l->prim_idx].e2));
        break;
    case LIGHT_SPHERE: {
        const struct sphere *s = &scene->spheres[l->prim_idx];
        vec3 origin = sphere_ref_origin(s, ref);
        vec3 wc = v3_sub(s->center, origin);
        if (v3_dot(wc, wc) > s->radius * s->radius)
            return sphere_cone_pdf(s, origin);
        pdf_area = 1.0f / (4.0f * MCPT_PI * s->radius * s->radius);
        break;
    }
    default:
        return 0.0f;
    }
    vec3 d = v3_sub(on_light->p, ref_p);
    float cos_light = fabsf(v3_dot(on_light->ng, wi));
    if (!(cos_light > 0.0f))
        return 0.0f;
    return pdf_area * v3_dot(d, d) / cos_light;
}

/* ---- preparation ---- */

struct trace_scene *trace_prepare(const struct scene *scene, int n_threads,
                                  struct mcpt_error *err)
{
    struct trace_scene *ts = calloc(1, sizeof *ts);
    uint32_t *indices = NULL;
    double *power = NULL;
    if (!ts)
        goto oom;
    ts->scene = scene;
    if (!camera_init(&ts->camera, &scene->camera, scene->width, scene->height, err))
        goto fail;

    indices = malloc(sizeof(uint32_t) * 3 * (size_t)(scene->n_tris ? scene->n_tris : 1));
    if (!indices)
        goto oom;
    for (uint32_t i = 0; i < scene->n_tris; i++)
        for (int k = 0; k < 3; k++)
            indices[3 * (size_t)i + k] = scene->tris[i].v[k];
    ts->bvh = bvh_build(scene->positions, indices, scene->n_tris, n_threads);
    if (!ts->bvh)
        goto oom;

    ts->tri_light = malloc(sizeof(uint32_t) * (scene->n_tris + 1));
    ts->quad_light = malloc(sizeof(uint32_t) * (scene->n_quads + 1));
    ts->sphere_light = malloc(sizeof(uint32_t) * (scene->n_spheres + 1));
    ts->light_cdf = malloc(sizeof(float) * (scene->n_lights + 1));
    power = malloc(sizeof(double) * (scene->n_lights + 1));
    if (!ts->tri_light || !ts->quad_light || !ts->sphere_light || !ts->light_cdf || !power)
        goto oom;
    for (uint32_t i = 0; i < scene->n_tris; i++)
        ts->tri_light[i] = NO_LIGHT;
    for (uint32_t i = 0; i < scene->n_quads; i++)
        ts->quad_light[i] = NO_LIGHT;
    for (uint32_t i = 0; i < scene->n_spheres; i++)
        ts->sphere_light[i] = NO_LIGHT;

    /* light selection proportional to emitted power: pmf_i = Phi_i / sum Phi */
    double total = 0.0;
    for (uint32_t i = 0; i < scene->n_lights; i++) {
        const struct light *l = &scene->lights[i];
        if (l->kind == LIGHT_TRIANGLE)
            ts->tri_light[l->prim_idx] = i;
        else if (l->kind == LIGHT_QUAD)
            ts->quad_light[l->prim_idx] = i;
        else if (l->kind == LIGHT_SPHERE)
            ts->sphere_light[l->prim_idx] = i;
        power[i] = light_power(scene, l);
        total += power[i];
    }
    double acc = 0.0;
    ts->light_cdf[0] = 0.0f;
    for (uint32_t i = 0; i < scene->n_lights; i++) {
        acc += total > 0.0 ? power[i] : 1.0;
        ts->light_cdf[i + 1] = (float)(acc / (total > 0.0 ? total : (double)scene->n_lights));
    }
    if (scene->n_lights > 0)
        ts->light_cdf[scene->n_lights] = 1.0f;
    free(power);
    free(indices);
    return ts;
oom:
    mcpt_error_set(err, "", 0, 0, "out of memory preparing the scene");
fail:
    free(power);
    free(indices);
    trace_free(ts);
    return NULL;
}

void trace_free(struct trace_scene *ts)
{
    if (!ts)
        return;
    bvh_free(ts->bvh);
    free(ts->light_cdf);
    free(ts->tri_light);
    free(ts->quad_light);
    free(ts->sphere_light);
    free(ts);
}

struct bvh_stats trace_bvh_stats(const struct trace_scene *ts) { return bvh_get_stats(ts->bvh); }

struct ray trace_camera_ray(const struct trace_scene *ts, float px, float py, vec2 u_lens)
{
    return camera_ray(&ts->camera, px, py, u_lens);
}

/* ---- the render loop: tiles handed out by an atomic counter ---- */

struct render_job {
    const struct trace_scene *ts;
    const struct trace_options *opt;
    struct film *film;
    uint32_t tiles_x;
    uint32_t n_tiles;
    atomic_uint next_tile;
    atomic_uint_fast64_t samples_done;
    atomic_int n_running;
};

struct worker {
    pthread_t thread;
    struct render_job *job;
    struct trace_result result;
};

static void render_pixel(struct render_job *job, struct worker *w, uint32_t x, uint32_t y)
{
    const struct trace_options *opt = job->opt;
    struct film *film = job->film;
    uint32_t pixel_idx = y * (uint32_t)film->width + x;
    struct film_pixel *px = &film->pixels[pixel_idx];
    uint64_t done = 0;
    struct sampler sampler;
    while (px->n + px->n_dropped < opt->spp) {
        if (opt->cancel && atomic_load_explicit(opt->cancel, memory_order_relaxed)) {
            w->result.cancelled = true;
            break;
        }
        uint32_t sample_idx = opt->sample_offset + px->n + px->n_dropped;
        sample_start(&sampler, opt->sampler, opt->seed, pixel_idx, sample_idx);
        /* box filter: uniform jitter inside the pixel */
        vec2 u_pixel = sample_2d(&sampler);
        vec2 u_lens = sample_2d(&sampler);
        struct ray ray = camera_ray(&job->ts->camera, (float)x + u_pixel.x, (float)y + u_pixel.y,
                                    u_lens);
        vec3 L = trace_radiance(job->ts, opt, ray, &sampler, &w->result.n_rays);
        if (v3_is_finite(L)) {
            film_add(px, L);
        } else {
            if (w->result.n_nonfinite == 0) {
                w->result.first_bad_x = x;
                w->result.first_bad_y = y;
                w->result.first_bad_sample = sample_idx;
            }
            w->result.n_nonfinite++;
            px->n_dropped++;
        }
        done++;
    }
    w->result.n_samples += done;
    atomic_fetch_add_explicit(&job->samples_done, done, memory_order_relaxed);
}

static void *render_worker(void *arg)
{
    struct worker *w = arg;
    struct render_job *job = w->job;
    for (;;) {
        uint32_t tile = atomic_fetch_add(&job->next_tile, 1);
        if (tile >= job->n_tiles)
            break;
        uint32_t x0 = (tile % job->tiles_x) * TRACE_TILE_SIZE;
        uint32_t y0 = (tile / job->tiles_x) * TRACE_TILE_SIZE;
        uint32_t x1 = x0 + TRACE_TILE_SIZE, y1 = y0 + TRACE_TILE_SIZE;
        if (x1 > (uint32_t)job->film->width)
            x1 = (uint32_t)job->film->width;
        if (y1 > (uint32_t)job->film->height)
            y1 = (uint32_t)job->film->height;
        for (uint32_t y = y0; y < y1; y++)
            for (uint32_t x = x0; x < x1; x++)
                render_pixel(job, w, x, y);
        if (w->result.cancelled)
            break;
    }
    atomic_fetch_sub(&job->n_running, 1);
    return NULL;
}

bool trace_render(const struct trace_scene *ts, const struct trace_options *opt, struct film *film,
                  struct trace_result *result, struct mcpt_error *err)
{
    memset(result, 0, sizeof *result);
    int n_threads = opt->n_threads > 0 ? opt->n_threads : 1;
    struct render_job job = {.ts = ts, .opt = opt, .film = film};
    job.tiles_x = ((uint32_t)film->width + TRACE_TILE_SIZE - 1) / TRACE_TILE_SIZE;
    uint32_t tiles_y = ((uint32_t)film->height + TRACE_TILE_SIZE - 1) / TRACE_TILE_SIZE;
    job.n_tiles = job.tiles_x * tiles_y;
    atomic_init(&job.next_tile, 0);
    atomic_init(&job.samples_done, 0);
    atomic_init(&job.n_running, n_threads);

    uint64_t total = 0;
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    for (size_t i = 0; i < n_pixels; i++) {
        uint32_t taken = film->pixels[i].n + film->pixels[i].n_dropped;
        total += taken < opt->spp ? opt->spp - taken : 0;
    }

    struct worker *workers = calloc((size_t)n_threads, sizeof *workers);
    if (!workers) {
        mcpt_error_set(err, "", 0, 0, "out of memory starting %d threads", n_threads);
        return false;
    }
    int started = 0;
    for (; started < n_threads; started++) {
        workers[started].job = &job;
        if (pthread_create(&workers[started].thread, NULL, render_worker, &workers[started]))
            break;
    }
    if (started < n_threads)
        atomic_fetch_sub(&job.n_running, n_threads - started);
    if (started == 0) {
        free(workers);
        mcpt_error_set(err, "", 0, 0, "cannot start render threads");
        return false;
    }
    /* the calling thread reports progress until the workers are done */
    const struct timespec tick = {0, 20 * 1000 * 1000}; /* 20 ms poll */
    int ticks = 0;
    while (atomic_load(&job.n_running) > 0) {
        nanosleep(&tick, NULL);
        if (opt->progress && ++ticks % 5 == 0)
            opt->progress(opt->progress_user, atomic_load(&job.samples_done), total);
    }
    for (int i = 0; i < started; i++) {
        pthread_join(workers[i].thread, NULL);
        const struct trace_result *r = &workers[i].result;
        if (r->n_nonfinite && !result->n_nonfinite) {
            result->first_bad_x = r->first_bad_x;
            result->first_bad_y = r->first_bad_y;
            result->first_bad_sample = r->first_bad_sample;
        }
        result->n_samples += r->n_samples;
        result->n_rays += r->n_rays;
        result->n_nonfinite += r->n_nonfinite;
        result->cancelled |= r->cancelled;
    }
    if (opt->progress)
        opt->progress(opt->progress_user, atomic_load(&job.samples_done), total);
    free(workers);
    return true;
}
