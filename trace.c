/* trace.c - unidirectional path tracing with next-event estimation and multiple importance
 * sampling, and the tile-scheduled render loop.
 * Estimator: Kajiya 1986, eq. 1, L(x, wo) = Le(x, wo) + int f(x, wo, wi) L(x', -wi) |cos| dwi,
 * sampled one path vertex at a time.  At each vertex the emitted light that arrives directly is
 * estimated by N light samples (next-event estimation) and one BSDF sample, combined by the
 * power heuristic with sample counts (Veach 1997, sec. 9.2.4, eq. 9.13); the teaching
 * estimators (--direct) drop one strategy or sample directions independently of the BSDF.
 * Russian roulette on the throughput or with a fixed probability (PBRT 4e, ch. 13, "A Better
 * Path Tracer").  Lights: emissive triangles, quads, spheres, point lights and the sky, picked by
 * power with an alias table.
 *
 * Glossary (PBRT's symbols): wo, wi - unit directions away from the surface (wo towards the
 * previous vertex, wi towards the next); n, ng, ns - normals (geometric, shading); L - radiance
 * carried to the camera; Le - emitted radiance; f - BSDF value; beta - path throughput
 * f |cos| / pdf accumulated along the path; pdf_sa, pdf_area - densities per steradian and per
 * unit area; pmf - discrete probability of picking a light; N - light samples per vertex. */
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
    struct sample_alias_bin *light_bins; /* n_lights entries: pick a light by power */
    uint32_t n_lights;    /* scene->n_lights, plus 1 for the sky when it is not black */
    uint32_t sky_light;   /* light index of the sky (the last), or NO_LIGHT */
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
static float light_pdf_sa(const struct trace_scene *ts, uint32_t light_idx,
                          const struct surface *ref, vec3 n_sky, vec3 p_light, vec3 ng_light,
                          vec3 wi);
static bool light_is_delta(const struct trace_scene *ts, uint32_t light_idx);
static struct ray spawn_ray(const struct surface *sf, vec3 d);
static vec3 sample_one_light(const struct trace_scene *ts, const struct trace_options *opt,
                             const struct material *m, const struct surface *sf, vec3 wo_world,
                             vec3 n_sky, float u_choice, vec2 u_light, uint64_t *n_rays);
static bool sample_direction(const struct material *m, vec3 wo, enum render_direct direct,
                             float u_lobe, vec2 u, struct mat_sample *s);

/* Does the image keep a contribution that left the light n_bounces scattering events before
 * reaching the camera?  Direct: 0 (emission seen directly) and 1; indirect: the rest. */
static bool split_keeps(enum render_split split, uint32_t n_bounces)
{
    return split == RENDER_SPLIT_FULL || (split == RENDER_SPLIT_DIRECT) == (n_bounces <= 1);
}

/* ---- the path loop ---- */

vec3 trace_radiance(const struct trace_scene *ts, const struct trace_options *opt,
                    struct ray ray, struct sampler *sampler, uint64_t *n_rays)
{
    const struct scene *scene = ts->scene;
    const uint32_t n_ls = opt->light_samples ? opt->light_samples : 1;
    const uint32_t rr_depth = opt->rr_depth ? opt->rr_depth : TRACE_RR_DEPTH_DEFAULT;
    /* inf (TRACE_DEPTH_INFINITE) and anything deeper stop at the cap, which also keeps the
     * bounce dimensions below sample.h's SAMPLE_DIM_LIGHT_EXTRA */
    uint32_t depth_cap = opt->max_depth < TRACE_DEPTH_CAP ? opt->max_depth : TRACE_DEPTH_CAP;
    if (opt->split == RENDER_SPLIT_DIRECT && depth_cap > 1)
        depth_cap = 1; /* nothing beyond the first bounce is kept */
    vec3 L = v3_splat(0.0f);
    vec3 beta = v3_splat(1.0f);
    float eta_scale = 1.0f;     /* product of etap^2 over refractions, undone for roulette */
    bool specular_bounce = false;
    float pdf_bsdf_prev = 0.0f; /* solid-angle pdf of the direction sample that made this ray */
    struct surface prev = {0};  /* the vertex the ray left from (used once depth > 0) */
    vec3 prev_n_sky = v3_splat(0.0f);
    struct sampler extra;       /* light samples 1 .. N-1 (sample.h, SAMPLE_DIM_LIGHT_EXTRA) */
    bool extra_started = false;

    for (uint32_t depth = 0;;) {
        /* find the next vertex (depth = bounces so far) */
        struct hit_record hr;
        (*n_rays)++;
        bool hit = intersect(ts, &ray, &hr);
        vec3 wo_world = v3_normalize(v3_neg(ray.d));

        /* emission where the ray ends, or the sky where it escapes:
         * L += beta Le w_bsdf, w_bsdf = pdf_bsdf^2 / (pdf_bsdf^2 + (N pmf pdf_light)^2) */
        vec3 Le = hit ? mat_emission(&scene->materials[hr.sf.mat_idx], hr.sf.ng, wo_world)
                      : sky_radiance(&scene->sky, v3_neg(wo_world));
        uint32_t light_idx = hit ? hr.light_idx : ts->sky_light;
        if (!v3_is_zero(Le) && split_keeps(opt->split, depth)) {
            float w_bsdf = 1.0f; /* camera rays, specular bounces, emitters no light sample finds */
            if (depth > 0 && !specular_bounce && light_idx != NO_LIGHT) {
                if (opt->direct == RENDER_DIRECT_LIGHT) {
                    w_bsdf = 0.0f; /* light sampling alone counts this emitter */
                } else if (opt->direct == RENDER_DIRECT_MIS) {
                    vec3 p_light = hit ? hr.sf.p : v3_splat(0.0f);
                    vec3 ng_light = hit ? hr.sf.ng : v3_splat(0.0f);
                    float pdf_light = (float)n_ls * ts->light_bins[light_idx].pmf *
                                      light_pdf_sa(ts, light_idx, &prev, prev_n_sky, p_light,
                                                   ng_light, v3_neg(wo_world));
                    w_bsdf = mis_power(pdf_bsdf_prev, pdf_light);
                }
            }
            L = v3_add(L, v3_scale(v3_mul(beta, Le), w_bsdf));
        }
        if (!hit || depth++ == depth_cap)
            break;

        /* the material at the vertex, its albedo texture looked up */
        const struct surface *sf = &hr.sf;
        const struct material *m = &scene->materials[sf->mat_idx];
        struct material m_textured;
        if (m->checker_scale > 0.0f) {
            m_textured = *m;
            m_textured.albedo = mat_albedo_at(m, sf->p, sf->uv);
            m = &m_textured;
        }

        /* local shading frame: z = ns; the sky is sampled about ns turned to the side of wo */
        vec3 t, b;
        v3_basis(sf->ns, &t, &b);
        vec3 wo = v3(v3_dot(wo_world, t), v3_dot(wo_world, b), v3_dot(wo_world, sf->ns));
        vec3 n_sky = wo.z >= 0.0f ? sf->ns : v3_neg(sf->ns);
        uint32_t bounce = depth - 1;
        uint32_t dim0 = SAMPLE_DIM_BOUNCE0 + bounce * SAMPLE_DIMS_PER_BOUNCE;

        /* sample the lights (next-event estimation), N samples:
         * L += beta (1/N) sum_j f |cos theta_i| Le / (pmf pdf_light) w_light,
         * w_light = (N pmf pdf_light)^2 / ((N pmf pdf_light)^2 + pdf_bsdf^2) */
        if (!mat_is_specular(m) && ts->n_lights > 0 && split_keeps(opt->split, depth)) {
            for (uint32_t j = 0; j < n_ls; j++) {
                struct sampler *s = sampler;
                if (j == 0) {
                    sample_set_dim(sampler, dim0 + SAMPLE_BOUNCE_LIGHT_CHOICE);
                } else {
                    if (!extra_started) {
                        extra = *sampler;
                        extra_started = true;
                    }
                    s = &extra;
                    uint32_t slot = bounce * (n_ls - 1) + j - 1; /* sample.h's extra block */
                    sample_set_dim(&extra, SAMPLE_DIM_LIGHT_EXTRA + SAMPLE_DIMS_PER_LIGHT * slot);
                }
                float u_choice = sample_1d(s);
                vec2 u_light = sample_2d(s);
                vec3 Ld = sample_one_light(ts, opt, m, sf, wo_world, n_sky, u_choice, u_light,
                                           n_rays);
                L = v3_add(L, v3_mul(beta, Ld));
            }
        }

        /* sample the next direction: beta *= f |cos theta_i| / pdf */
        sample_set_dim(sampler, dim0 + SAMPLE_BOUNCE_BSDF_LOBE);
        float u_lobe = sample_1d(sampler);
        vec2 u_dir = sample_2d(sampler);
        struct mat_sample bs;
        if (!sample_direction(m, wo, opt->direct, u_lobe, u_dir, &bs))
            break;
        vec3 wi_world = v3_from_local(bs.wi, t, b, sf->ns);
        /* the geometric normal decides the side: a reflection must stay on the side of wo, a
         * refraction must cross, whatever the shading normal says (no leaks) */
        bool is_reflection = bs.wi.z * wo.z > 0.0f;
        bool stays = v3_dot(wi_world, sf->ng) * v3_dot(wo_world, sf->ng) > 0.0f;
        if (is_reflection != stays)
            break;
        beta = v3_mul(beta, v3_scale(bs.f, fabsf(bs.wi.z) / bs.pdf_sa));
        if (!is_reflection) {
            /* refraction: f was divided by etap^2; roulette looks at the unscaled beta */
            float eta_rel = wo.z > 0.0f ? m->ior : 1.0f / m->ior;
            eta_scale *= eta_rel * eta_rel;
        }
        specular_bounce = bs.is_specular;
        pdf_bsdf_prev = bs.pdf_sa;
        prev = *sf;
        prev_n_sky = n_sky;
        ray = spawn_ray(sf, wi_world);

        /* Russian roulette after bounce rr_depth: continue with probability p, beta /= p;
         * p = min(1, max(beta) eta^2) by throughput, or the fixed --rr p */
        if (depth >= rr_depth) {
            float p = opt->rr_prob > 0.0f ? opt->rr_prob
                                          : fminf(1.0f, v3_max_comp(beta) * eta_scale);
            if (p < 1.0f) {
                sample_set_dim(sampler, dim0 + SAMPLE_BOUNCE_ROULETTE);
                if (!(sample_1d(sampler) < p))
                    break;
                beta = v3_scale(beta, 1.0f / p);
            }
        }
        if (v3_is_zero(beta))
            break;
    }
    return L;
}

/* One light sample at surface sf (next-event estimation), unweighted by beta:
 *   Ld = f |cos theta_i| Le / (N pmf pdf_light) w_light   (area lights and the sky),
 *   Ld = f |cos theta_i| I / (N pmf r^2)                 (point lights: delta, no MIS).
 * The estimators without light sampling still sample point lights here: nothing else can find
 * a delta light. */
static vec3 sample_one_light(const struct trace_scene *ts, const struct trace_options *opt,
                             const struct material *m, const struct surface *sf, vec3 wo_world,
                             vec3 n_sky, float u_choice, vec2 u_light, uint64_t *n_rays)
{
    const vec3 zero = v3_splat(0.0f);
    const uint32_t n_ls = opt->light_samples ? opt->light_samples : 1;
    float pmf;
    uint32_t light_idx = sample_alias_pick(ts->light_bins, ts->n_lights, u_choice, &pmf);
    bool nee = opt->direct == RENDER_DIRECT_MIS || opt->direct == RENDER_DIRECT_LIGHT;
    if (!nee && !light_is_delta(ts, light_idx))
        return zero;
    struct trace_light_sample ls;
    if (!trace_sample_light(ts, light_idx, sf, n_sky, u_light, &ls))
        return zero;
    /* reflection only towards the geometric side of wo: no leaks through surfaces whose
     * shading normal disagrees with the geometry (no material has a non-delta transmission) */
    if (v3_dot(ls.wi, sf->ng) * v3_dot(wo_world, sf->ng) <= 0.0f)
        return zero;
    vec3 t, b;
    v3_basis(sf->ns, &t, &b);
    vec3 wo = v3(v3_dot(wo_world, t), v3_dot(wo_world, b), v3_dot(wo_world, sf->ns));
    vec3 wi = v3(v3_dot(ls.wi, t), v3_dot(ls.wi, b), v3_dot(ls.wi, sf->ns));
    vec3 f = mat_eval(m, wo, wi);
    if (v3_is_zero(f))
        return zero;
    (*n_rays)++;
    if (occluded(ts, &ls.shadow))
        return zero;
    vec3 Ld = v3_scale(v3_mul(f, ls.Le), fabsf(wi.z) / ((float)n_ls * pmf));
    if (ls.is_delta)
        return Ld;
    float w_light = 1.0f;
    if (opt->direct == RENDER_DIRECT_MIS)
        w_light = mis_power((float)n_ls * pmf * ls.pdf_sa, mat_pdf(m, wo, wi));
    return v3_scale(Ld, w_light / ls.pdf_sa);
}

/* The next direction from wo: the BSDF's own sampling, or for --direct cosine | hemisphere a
 * direction independent of the BSDF (cosine-weighted or uniform over the hemisphere of wo) at
 * materials without a delta lobe; a delta lobe can only be found by sampling it. */
static bool sample_direction(const struct material *m, vec3 wo, enum render_direct direct,
                             float u_lobe, vec2 u, struct mat_sample *s)
{
    bool is_cosine = direct == RENDER_DIRECT_COSINE;
    if ((!is_cosine && direct != RENDER_DIRECT_HEMISPHERE) || mat_has_delta(m))
        return mat_sample(m, wo, u_lobe, u, s);
    if (wo.z == 0.0f)
        return false;
    vec3 wi = is_cosine ? sample_cosine_hemisphere(u) : sample_uniform_hemisphere(u);
    s->pdf_sa = is_cosine ? pdf_cosine_hemisphere(wi.z) : pdf_uniform_hemisphere();
    s->wi = v3(wi.x, wi.y, wo.z > 0.0f ? wi.z : -wi.z);
    s->f = mat_eval(m, wo, s->wi);
    s->is_specular = false;
    return s->pdf_sa > 0.0f && wi.z > 0.0f;
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

/* Emitted power (luminance) of a scene light, for light selection: Phi = pi A Le per emitting
 * side of an area light, Phi = 4 pi I for a point light. */
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

static bool light_is_delta(const struct trace_scene *ts, uint32_t light_idx)
{
    return light_idx < ts->scene->n_lights && ts->scene->lights[light_idx].kind == LIGHT_POINT;
}

/* Sphere cone sampling: PBRT 4e, ch. 6, "Spheres", Sphere::Sample(ctx, u): directions uniform in
 * the cone subtended by the sphere, pdf_sa = 1 / (2 pi (1 - cos theta_max)). */
static float sphere_cone_pdf(const struct sphere *s, vec3 ref_p)
{
    float dist2 = v3_dot(v3_sub(ref_p, s->center), v3_sub(ref_p, s->center));
    struct sample_cone cone = sample_cone_from_sin2(s->radius * s->radius / dist2);
    return pdf_uniform_cone(&cone);
}

static vec3 sphere_ref_origin(const struct sphere *s, const struct surface *ref)
{
    return offset_ray_origin(ref->p, ref->p_error, ref->ng, v3_sub(s->center, ref->p));
}

uint32_t trace_n_lights(const struct trace_scene *ts) { return ts->n_lights; }

float trace_light_pmf(const struct trace_scene *ts, uint32_t light_idx)
{
    return light_idx < ts->n_lights ? ts->light_bins[light_idx].pmf : 0.0f;
}

bool trace_sample_light(const struct trace_scene *ts, uint32_t light_idx,
                        const struct surface *ref, vec3 n_sky, vec2 u,
                        struct trace_light_sample *ls)
{
    const struct scene *scene = ts->scene;
    if (light_idx == ts->sky_light) {
        /* the sky: cosine-weighted about n_sky, pdf_sa = cos theta / pi */
        vec3 t, b;
        v3_basis(n_sky, &t, &b);
        vec3 w = sample_cosine_hemisphere(u);
        ls->wi = v3_normalize(v3_from_local(w, t, b, n_sky));
        ls->pdf_sa = pdf_cosine_hemisphere(w.z);
        ls->Le = sky_radiance(&scene->sky, ls->wi);
        ls->is_delta = false;
        ls->shadow = spawn_ray(ref, ls->wi);
        return ls->pdf_sa > 0.0f && !v3_is_zero(ls->Le);
    }
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
        /* uniform by area: barycentrics by the square-root warp, pdf_area = 1 / A */
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
        /* uniform by area: p = corner + u0 e1 + u1 e2, pdf_area = 1 / |e1 x e2| */
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
            n = sample_uniform_sphere(u);
            pdf_area = 1.0f / (4.0f * MCPT_PI * s->radius * s->radius);
        } else {
            /* cone sampling, PBRT 4e, ch. 6, "Spheres" */
            float sin2_theta_max = s->radius * s->radius / dist2;
            float sin_theta_max = sqrtf(sin2_theta_max);
            struct sample_cone cone = sample_cone_from_sin2(sin2_theta_max);
            float cos_theta, sin2_theta;
            sample_uniform_cone_theta(u.x, &cone, &cos_theta, &sin2_theta);
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

/* Solid-angle density with which trace_sample_light(light_idx) picks the direction wi from ref,
 * given the point p_light (geometric normal ng_light) that a ray along wi meets on the light;
 * the sky needs only wi and n_sky. */
static float light_pdf_sa(const struct trace_scene *ts, uint32_t light_idx,
                          const struct surface *ref, vec3 n_sky, vec3 p_light, vec3 ng_light,
                          vec3 wi)
{
    const struct scene *scene = ts->scene;
    if (light_idx == ts->sky_light)
        return pdf_cosine_hemisphere(fmaxf(0.0f, v3_dot(wi, n_sky)));
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
    /* area -> solid angle: pdf_sa = pdf_area * dist^2 / |cos theta_light| */
    vec3 d = v3_sub(p_light, ref->p);
    float cos_light = fabsf(v3_dot(ng_light, wi));
    if (!(cos_light > 0.0f))
        return 0.0f;
    return pdf_area * v3_dot(d, d) / cos_light;
}

/* Ray-triangle test for trace_light_pdf (Moller & Trumbore 1997, "Fast, Minimum Storage
 * Ray/Triangle Intersection"), in double: only tests use it. */
static bool ray_triangle(vec3 p0, vec3 p1, vec3 p2, const struct ray *ray, float *t_hit)
{
    double e1[3] = {p1.x - p0.x, p1.y - p0.y, p1.z - p0.z};
    double e2[3] = {p2.x - p0.x, p2.y - p0.y, p2.z - p0.z};
    double d[3] = {ray->d.x, ray->d.y, ray->d.z};
    double s[3] = {ray->o.x - p0.x, ray->o.y - p0.y, ray->o.z - p0.z};
    double pv[3] = {d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2],
                    d[0] * e2[1] - d[1] * e2[0]};
    double det = e1[0] * pv[0] + e1[1] * pv[1] + e1[2] * pv[2];
    if (det == 0.0)
        return false;
    double bu = (s[0] * pv[0] + s[1] * pv[1] + s[2] * pv[2]) / det;
    double qv[3] = {s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2],
                    s[0] * e1[1] - s[1] * e1[0]};
    double bv = (d[0] * qv[0] + d[1] * qv[1] + d[2] * qv[2]) / det;
    double t = (e2[0] * qv[0] + e2[1] * qv[1] + e2[2] * qv[2]) / det;
    if (bu < 0.0 || bv < 0.0 || bu + bv > 1.0 || !(t > ray->t_min && t < ray->t_max))
        return false;
    *t_hit = (float)t;
    return true;
}

float trace_light_pdf(const struct trace_scene *ts, uint32_t light_idx,
                      const struct surface *ref, vec3 n_sky, vec3 wi)
{
    const struct scene *scene = ts->scene;
    if (light_idx >= ts->n_lights || light_is_delta(ts, light_idx))
        return 0.0f;
    if (light_idx == ts->sky_light)
        return light_pdf_sa(ts, light_idx, ref, n_sky, v3_splat(0.0f), v3_splat(0.0f), wi);
    /* find where the ray along wi meets this light's primitive, alone */
    const struct light *l = &scene->lights[light_idx];
    struct ray ray = spawn_ray(ref, wi);
    struct surface on;
    float t;
    switch (l->kind) {
    case LIGHT_TRIANGLE: {
        const struct scene_tri *tri = &scene->tris[l->prim_idx];
        vec3 p0 = scene->positions[tri->v[0]];
        if (!ray_triangle(p0, scene->positions[tri->v[1]], scene->positions[tri->v[2]], &ray,
                          &t))
            return 0.0f;
        on.p = v3_add(ray.o, v3_scale(ray.d, t));
        triangle_area(scene, l->prim_idx, &on.ng);
        break;
    }
    case LIGHT_QUAD:
        if (!shape_quad_intersect(&scene->quads[l->prim_idx], &ray, &t))
            return 0.0f;
        on = shape_quad_surface(&scene->quads[l->prim_idx], &ray, t);
        break;
    case LIGHT_SPHERE:
        if (!shape_sphere_intersect(&scene->spheres[l->prim_idx], &ray, &t))
            return 0.0f;
        on = shape_sphere_surface(&scene->spheres[l->prim_idx], &ray, t);
        break;
    default:
        return 0.0f;
    }
    return light_pdf_sa(ts, light_idx, ref, n_sky, on.p, on.ng, wi);
}

/* ---- preparation ---- */

/* Radius of a bounding sphere of the scene's finite geometry, point lights and camera (planes
 * are infinite and left out); 1 when there is nothing to bound. */
static double scene_radius(const struct scene *scene)
{
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
#define GROW(P, R)                                                                                \
    do {                                                                                          \
        vec3 p_ = (P);                                                                            \
        double r_ = (R);                                                                          \
        for (int k_ = 0; k_ < 3; k_++) {                                                          \
            lo[k_] = fmin(lo[k_], v3_get(p_, k_) - r_);                                           \
            hi[k_] = fmax(hi[k_], v3_get(p_, k_) + r_);                                           \
        }                                                                                         \
    } while (0)
    for (uint32_t i = 0; i < scene->n_positions; i++)
        GROW(scene->positions[i], 0.0);
    for (uint32_t i = 0; i < scene->n_spheres; i++)
        GROW(scene->spheres[i].center, scene->spheres[i].radius);
    for (uint32_t i = 0; i < scene->n_quads; i++) {
        const struct quad *q = &scene->quads[i];
        GROW(q->corner, 0.0);
        GROW(v3_add(q->corner, v3_add(q->e1, q->e2)), 0.0);
        GROW(v3_add(q->corner, q->e1), 0.0);
        GROW(v3_add(q->corner, q->e2), 0.0);
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

    /* the light table: the scene's lights, then the sky if it shines */
    bool has_sky = scene->sky.kind != SKY_NONE && sky_power(&scene->sky, 1.0) > 0.0;
    ts->n_lights = scene->n_lights + (has_sky ? 1u : 0u);
    ts->sky_light = has_sky ? scene->n_lights : NO_LIGHT;
    ts->tri_light = malloc(sizeof(uint32_t) * (scene->n_tris + 1));
    ts->quad_light = malloc(sizeof(uint32_t) * (scene->n_quads + 1));
    ts->sphere_light = malloc(sizeof(uint32_t) * (scene->n_spheres + 1));
    ts->light_bins = malloc(sizeof(struct sample_alias_bin) * (ts->n_lights + 1));
    power = malloc(sizeof(double) * (ts->n_lights + 1));
    if (!ts->tri_light || !ts->quad_light || !ts->sphere_light || !ts->light_bins || !power)
        goto oom;
    for (uint32_t i = 0; i < scene->n_tris; i++)
        ts->tri_light[i] = NO_LIGHT;
    for (uint32_t i = 0; i < scene->n_quads; i++)
        ts->quad_light[i] = NO_LIGHT;
    for (uint32_t i = 0; i < scene->n_spheres; i++)
        ts->sphere_light[i] = NO_LIGHT;

    /* light selection proportional to emitted power: pmf_i = Phi_i / sum Phi (alias table) */
    for (uint32_t i = 0; i < scene->n_lights; i++) {
        const struct light *l = &scene->lights[i];
        if (l->kind == LIGHT_TRIANGLE)
            ts->tri_light[l->prim_idx] = i;
        else if (l->kind == LIGHT_QUAD)
            ts->quad_light[l->prim_idx] = i;
        else if (l->kind == LIGHT_SPHERE)
            ts->sphere_light[l->prim_idx] = i;
        power[i] = light_power(scene, l);
    }
    if (has_sky)
        power[ts->sky_light] = sky_power(&scene->sky, scene_radius(scene));
    if (ts->n_lights > 0 && !sample_alias_build(power, ts->n_lights, ts->light_bins))
        goto oom; /* the powers are finite and >= 0: only memory can fail */
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
    free(ts->light_bins);
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
    uint32_t set_spp; /* samples per stratified set (sample_start_spp) */
    atomic_uint next_tile;
    atomic_uint_fast64_t samples_done; /* for progress: taken, plus the budget of stopped pixels */
    atomic_int n_running;
};

struct worker {
    pthread_t thread;
    struct render_job *job;
    struct trace_result result;
};

bool trace_adaptive_stop(double s1, double s2, uint64_t n, double tolerance, double floor_lum)
{
    if (n == 0)
        return false;
    /* mu = s1 / n, sigma^2 = s2 / n - mu^2, I = 1.96 sigma / sqrt(n): stop when I <= T max(mu,
     * floor), squared to avoid the square roots: 1.96^2 sigma^2 / n <= (T max(mu, floor))^2 */
    double dn = (double)n;
    double mu = s1 / dn;
    double sigma2 = fmax(0.0, s2 / dn - mu * mu); /* rounding can make a zero variance < 0 */
    double bound = tolerance * fmax(mu, floor_lum);
    return 1.96 * 1.96 * sigma2 / dn <= bound * bound;
}

/* Adaptive sampling: whether pixel px, at a test point (min_spp + k batch samples taken), has
 * met the stopping rule.  It reads only the pixel's own sums, so the decision is the same
 * whichever thread, call or resumed run makes it. */
static bool adaptive_converged(const struct trace_options *opt, const struct film_pixel *px)
{
    uint32_t taken = px->n + px->n_dropped;
    uint32_t batch = opt->batch ? opt->batch : 1;
    if (!opt->adaptive || taken < opt->min_spp || (taken - opt->min_spp) % batch != 0)
        return false;
    return trace_adaptive_stop(film_sum_lum(px), px->sum_lum_sq, px->n, opt->tolerance,
                               opt->adaptive_floor);
}

static void render_pixel(struct render_job *job, struct worker *w, uint32_t x, uint32_t y)
{
    const struct trace_options *opt = job->opt;
    struct film *film = job->film;
    uint32_t pixel_idx = y * (uint32_t)film->width + x;
    struct film_pixel *px = &film->pixels[pixel_idx];
    uint64_t done = 0;
    uint64_t skipped = 0; /* samples an adaptive stop saved, counted as progress */
    struct sampler sampler;
    while (px->n + px->n_dropped < opt->spp) {
        if (opt->cancel && atomic_load_explicit(opt->cancel, memory_order_relaxed)) {
            w->result.cancelled = true;
            break;
        }
        if (adaptive_converged(opt, px)) {
            skipped = opt->spp - (px->n + px->n_dropped);
            break;
        }
        uint32_t sample_idx = opt->sample_offset + px->n + px->n_dropped;
        sample_start_spp(&sampler, opt->sampler, opt->seed, pixel_idx, sample_idx, job->set_spp);
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
    atomic_fetch_add_explicit(&job->samples_done, done + skipped, memory_order_relaxed);
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
    /* stratified sets: as the caller says, else one set per pixel, or per batch when adaptive
     * (the final count is unknown then; every test point min_spp + k batch with min_spp a
     * multiple of batch sees whole sets) */
    job.set_spp = opt->sampler_spp ? opt->sampler_spp
                  : opt->adaptive  ? (opt->batch ? opt->batch : 1)
                                   : opt->spp;
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
