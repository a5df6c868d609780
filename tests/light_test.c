/* tests/light_test.c - light.c (and the shape sampling of shape.c it calls): the light table,
 * the pick by power, each kind of light's sampling and density, and the errors of building.
 * - Sampling (triangle, quad, sphere seen from outside and inside, sky) by chi-square against
 *   light_pdf (tests/chi2.h, as Mitsuba's tests), each density integrating to 1; light_pdf at a
 *   sampled point equals the density light_sample returned (PBRT 4e, ch. 12, "Light Sources":
 *   SampleLi and PDF_Li agree; ch. 6, "Shape Interface": area to solid angle).
 * - Point lights: Le = I / r^2 along the one direction, delta, density 0 (PBRT 4e, ch. 12,
 *   "Point Lights").
 * - Picking: pmf_i = Phi_i / sum Phi with Phi = pi A Le per emitting side (PBRT 4e, ch. 12,
 *   "Light Sampling").
 * - Emitters whose power is not finite are bad input, named in the message; trace_prepare
 *   passes the error on. */
#include <criterion/criterion.h>

#include <stdlib.h>

#include "chi2.h"
#include "light.h"
#include "trace.h"
#include "test_util.h"

/* A light scene built in code: a two-sided emissive triangle, quad, sphere (seen from outside)
 * and sphere enclosing the reference point, and a gradient sky. */
static vec3 lt_positions[3] = {{-1.0f, -1.0f, 1.0f}, {2.0f, -1.0f, 1.5f}, {-1.0f, 2.0f, 1.0f}};
static struct scene_tri lt_tris[1] = {{.v = {0, 1, 2}, .vn = {-1, -1, -1}, .vt = {-1, -1, -1}}};
static struct material lt_materials[2];
static struct sphere lt_spheres[2];
static struct quad lt_quads[1];
static struct light lt_lights[5];

static struct scene light_scene(void)
{
    lt_materials[0] = (struct material){.name = "lamp",
                                        .kind = MAT_DIFFUSE,
                                        .Le = v3(1.0f, 2.0f, 3.0f),
                                        .two_sided_emission = true};
    lt_materials[1] = (struct material){.name = "glow",
                                        .kind = MAT_DIFFUSE,
                                        .Le = v3(0.5f, 0.5f, 0.5f),
                                        .two_sided_emission = true};
    lt_spheres[0] = (struct sphere){.center = v3(0.5f, 0.3f, 2.5f), .radius = 0.7f};
    lt_spheres[1] = (struct sphere){.center = v3(0.1f, -0.2f, 0.2f), .radius = 1.0f, .mat_idx = 1};
    lt_quads[0] = (struct quad){.corner = d3(v3(-0.5f, -2.0f, 0.3f)),
                                .e1 = d3(v3(1.0f, 0.0f, 0.2f)),
                                .e2 = d3(v3(0.0f, 0.3f, 1.0f))};
    lt_lights[0] = (struct light){.kind = LIGHT_TRIANGLE, .prim_idx = 0};
    lt_lights[1] = (struct light){.kind = LIGHT_QUAD, .prim_idx = 0};
    lt_lights[2] = (struct light){.kind = LIGHT_SPHERE, .prim_idx = 0};
    lt_lights[3] = (struct light){.kind = LIGHT_SPHERE, .prim_idx = 1};
    lt_lights[4] = (struct light){.kind = LIGHT_POINT,
                                  .position = v3(0.3f, 0.4f, 3.0f),
                                  .intensity = v3(2.0f, 1.0f, 0.5f)};
    struct scene s = {
        .camera = {.eye = v3(0, 0, 5), .look_at = v3(0, 0, 0), .up = v3(0, 1, 0), .fov_deg = 40.0f},
        .width = 4,
        .height = 4,
        .materials = lt_materials,
        .n_materials = 2,
        .positions = lt_positions,
        .n_positions = 3,
        .tris = lt_tris,
        .n_tris = 1,
        .spheres = lt_spheres,
        .n_spheres = 2,
        .quads = lt_quads,
        .n_quads = 1,
        .lights = lt_lights,
        .n_lights = 4, /* the point light joins where a test says so */
        .sky = {.kind = SKY_GRADIENT, .horizon = v3(1, 1, 1), .zenith = v3(0.2f, 0.3f, 1.0f)},
    };
    return s;
}

/* The same scene sampled by solid angle (render light-sampling=solid-angle), and with its
 * triangle and quad swapped for ones that take the other path there: a triangle that fills
 * almost the whole hemisphere of REF (solid angle above 6.22 sr: sampled uniformly by area,
 * PBRT 4e's bound) and a rectangular quad (by solid angle, Urena et al. 2013), where
 * light_scene's triangle goes by solid angle (Arvo 1995) and its parallelogram by area. */
static struct scene light_scene_variant(int variant)
{
    struct scene s = light_scene();
    if (variant == 0)
        return s;
    s.render.light_sampling = RENDER_LIGHT_SOLID_ANGLE;
    if (variant == 2) {
        lt_positions[0] = v3(-50.0f, -50.0f, 0.05f);
        lt_positions[1] = v3(100.0f, -50.0f, 0.05f);
        lt_positions[2] = v3(-50.0f, 100.0f, 0.05f);
        lt_quads[0].corner = d3(v3(-1.0f, -1.5f, 0.2f)); /* a rectangle of about 0.9 sr */
        lt_quads[0].e1 = d3(v3(2.0f, 0.0f, 0.4f));
        lt_quads[0].e2 = d3(v3(0.12f, 0.9f, -0.6f)); /* orthogonal to e1 */
    }
    return s;
}

/* light_table_build(s), which must succeed. */
static struct light_table *build(const struct scene *s)
{
    struct mcpt_error err;
    struct light_table *lt = light_table_build(s, &err);
    cr_assert(lt, "%s", err.msg);
    return lt;
}

static const struct surface REF = {.p = {0, 0, 0},
                                   .p_error = {0, 0, 0},
                                   .ng = {0, 0, 1},
                                   .ns = {0, 0, 1}};

/* Ray-triangle test in double (Moller & Trumbore 1997, "Fast, Minimum Storage Ray/Triangle
 * Intersection"): an independent reference for where a direction meets a triangle light. */
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

/* light_pdf of direction wi from ref, finding where the ray along wi meets light light_idx's
 * primitive alone (other primitives do not occlude it here); 0 where it misses. */
static float pdf_along(const struct light_table *lt, const struct scene *scene, uint32_t light_idx,
                       const struct surface *ref, vec3 n_sky, vec3 wi)
{
    if (light_idx == light_sky_idx(lt))
        return light_pdf(lt, light_idx, ref, n_sky, NULL, wi);
    const struct light *l = &scene->lights[light_idx];
    struct ray ray = {.o = offset_ray_origin(ref->p, ref->p_error, ref->ng, wi),
                      .d = wi,
                      .t_min = 0.0f,
                      .t_max = INFINITY};
    struct surface on;
    float t;
    switch (l->kind) {
    case LIGHT_TRIANGLE: {
        vec3 p[3];
        for (int k = 0; k < 3; k++)
            p[k] = scene->positions[scene->tris[l->prim_idx].v[k]];
        if (!ray_triangle(p[0], p[1], p[2], &ray, &t))
            return 0.0f;
        on.p = v3_add(ray.o, v3_scale(ray.d, t));
        shape_triangle_area(p, &on.ng);
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
    return light_pdf(lt, light_idx, ref, n_sky, &on, wi);
}

struct light_ctx {
    const struct light_table *lt;
    const struct scene *scene;
    uint32_t light_idx;
    vec3 n_sky;
};

static bool light_draw(void *ctx, const float u[3], vec3 *w)
{
    struct light_ctx *c = ctx;
    struct light_sample ls;
    if (!light_sample(c->lt, c->light_idx, &REF, &c->n_sky, &(vec2){u[0], u[1]}, &ls))
        return false;
    *w = ls.wi;
    return true;
}

static double light_density(void *ctx, vec3 w)
{
    struct light_ctx *c = ctx;
    return pdf_along(c->lt, c->scene, c->light_idx, &REF, c->n_sky, w);
}

/* Chi-square (tests/chi2.h) of the directions light_sample draws against light_pdf, for a
 * triangle and a quad by area, a triangle by solid angle (Arvo 1995) and by area above the
 * bound, a quad by area (a parallelogram) and by solid angle (a rectangle, Urena et al. 2013),
 * both by solid angle warped by the cosine at REF (PBRT 4e's bilinear warp), a sphere seen from
 * outside (cone sampling) and from inside (uniform area), and the sky (cosine about n_sky); each
 * density integrates to 1 (Bonferroni over the 9 tests: five lights, then the triangle and quad
 * of the two scenes by solid angle). */
Test(light, chi2_sampling, .timeout = TEST_TIMEOUT_S(120))
{
    for (int variant = 0; variant < 3; variant++) {
        struct scene s = light_scene_variant(variant);
        struct light_table *lt = build(&s);
        cr_assert_eq(light_count(lt), 5u, "four lights and the sky");
        cr_assert_eq(light_sky_idx(lt), 4u);
        vec3 n_sky = v3_normalize(v3(0.3f, 0.2f, 1.0f));
        for (uint32_t k = 0; k < (variant == 0 ? 5u : 2u); k++) {
            struct light_ctx c = {lt, &s, k, n_sky};
            struct chi2_spec spec = chi2_sphere(light_draw, light_density, &c);
            spec.n_samples = 500000;
            struct chi2_result r;
            chi2_run(&spec, &r);
            cr_assert(chi2_accept(&r, 9), "scene %d, light %u: %s", variant, k, r.msg);
            cr_assert(fabs(r.pdf_integral - 1.0) < 2e-3, "scene %d, light %u: pdf integrates to %f",
                      variant, k, r.pdf_integral);
        }
        light_table_free(lt);
    }
}

/* light_pdf at the sampled point (the point and its normal as the sample gives them) returns
 * the density light_sample returned: exactly for the spheres (the cone from outside, the cosine
 * from inside), whose two computations are the same formula, to 1e-4 by solid angle (the
 * density is the bilinear warp's at the inverse of the spherical map, which rounds), and to
 * float rounding by area (the sample measures to its exact point, light_pdf to where the ray
 * along the rounded wi meets the plane) and for the sky, whose sample measures cos theta before
 * normalising wi. */
Test(light, pdf_agrees_with_sample)
{
    for (int variant = 0; variant < 3; variant++) {
        struct scene s = light_scene_variant(variant);
        struct light_table *lt = build(&s);
        vec3 n_sky = v3_normalize(v3(-0.2f, 0.1f, 1.0f));
        struct pcg32 rng;
        sample_pcg32_seed(&rng, 3u, 9u);
        for (uint32_t k = 0; k < light_count(lt); k++) {
            int n_ok = 0;
            for (int i = 0; i < 2000; i++) {
                vec2 u = {sample_pcg32_float(&rng), sample_pcg32_float(&rng)};
                struct light_sample ls;
                if (!light_sample(lt, k, &REF, &n_sky, &u, &ls))
                    continue;
                n_ok++;
                cr_assert(!ls.is_delta && ls.pdf_sa > 0.0f && isfinite(ls.pdf_sa));
                cr_assert_eq(ls.is_infinite, k == light_sky_idx(lt));
                struct surface on = {.p = ls.p, .ng = ls.n};
                float pdf = light_pdf(lt, k, &REF, n_sky, ls.is_infinite ? NULL : &on, ls.wi);
                if (ls.is_infinite || (variant == 0 && k < 2))
                    cr_assert(fabsf(pdf / ls.pdf_sa - 1.0f) < 1e-5f, "light %u: %g vs %g", k, pdf,
                              ls.pdf_sa);
                else if (variant > 0 && k < 2)
                    cr_assert(fabsf(pdf / ls.pdf_sa - 1.0f) < 1e-4f,
                              "scene %d, light %u: light_pdf %g, light_sample %g", variant, k, pdf,
                              ls.pdf_sa);
                else
                    cr_assert_eq(pdf, ls.pdf_sa, "light %u: light_pdf %g, light_sample %g", k, pdf,
                                 ls.pdf_sa);
            }
            cr_assert(n_ok > 1000, "light %u: %d of 2000 samples carry light", k, n_ok);
        }
        light_table_free(lt);
    }
}

/* A one-sided emitter seen from behind its plane gives no sample (it sends no light there):
 * the triangle and the quad of the light scene made one-sided, from a point behind each. */
Test(light, one_sided_emitter_from_behind)
{
    struct scene s = light_scene();
    lt_materials[0].two_sided_emission = false;
    struct light_table *lt = build(&s);
    vec3 n_tri = v3_cross(v3_sub(lt_positions[1], lt_positions[0]),
                          v3_sub(lt_positions[2], lt_positions[0]));
    vec3 n_quad = v3_cross(d3_to_float(lt_quads[0].e1), d3_to_float(lt_quads[0].e2));
    for (uint32_t k = 0; k < 2; k++) {
        vec3 n = k == 0 ? n_tri : n_quad,
             p0 = k == 0 ? lt_positions[0] : d3_to_float(lt_quads[0].corner);
        struct surface front = REF, back = REF;
        front.p = v3_add(p0, v3_normalize(n));
        back.p = v3_sub(p0, v3_normalize(n));
        struct light_sample ls;
        cr_assert(light_sample(lt, k, &front, &front.ns, &(vec2){0.3f, 0.4f}, &ls), "light %u", k);
        cr_assert_not(light_sample(lt, k, &back, &back.ns, &(vec2){0.3f, 0.4f}, &ls), "light %u",
                      k);
    }
    light_table_free(lt);
}

/* A point light is a delta light: its sample is the one direction to it with Le = I / r^2
 * (PBRT 4e, ch. 12, "Point Lights"), and no direction found otherwise has a density. */
Test(light, point_light_is_delta)
{
    struct scene s = light_scene();
    s.n_lights = 5;
    s.sky.kind = SKY_NONE;
    struct light_table *lt = build(&s);
    cr_assert_eq(light_count(lt), 5u);
    cr_assert_eq(light_sky_idx(lt), LIGHT_NONE);
    cr_assert(light_is_delta(lt, 4) && !light_is_delta(lt, 0));
    struct light_sample ls;
    cr_assert(light_sample(lt, 4, &REF, &REF.ns, &(vec2){0.3f, 0.6f}, &ls));
    vec3 d = v3_sub(lt_lights[4].position, REF.p);
    float r2 = v3_dot(d, d);
    cr_assert(ls.is_delta && !ls.is_infinite && ls.pdf_sa == 0.0f);
    cr_assert_float_eq(v3_dot(ls.wi, v3_scale(d, 1.0f / sqrtf(r2))), 1.0f, 1e-6f);
    cr_assert_float_eq(ls.Le.x, lt_lights[4].intensity.x / r2, 1e-6f);
    cr_assert_float_eq(ls.Le.z, lt_lights[4].intensity.z / r2, 1e-6f);
    cr_assert_eq(light_pdf(lt, 4, &REF, REF.ns, NULL, ls.wi), 0.0f);
    cr_assert_eq(light_pdf(lt, 99, &REF, REF.ns, NULL, ls.wi), 0.0f, "outside the table");
    light_table_free(lt);
}

/* Light selection is proportional to power: pmf_i / pmf_j = Phi_i / Phi_j with Phi = pi A Le
 * per side for the area lights (luminance of Le), Phi = 4 pi I for a point light, and the pmfs
 * sum to 1; light_pick returns each light with its pmf. */
Test(light, pmf_proportional_to_power)
{
    struct scene s = light_scene();
    s.n_lights = 5;
    s.sky.kind = SKY_NONE;
    struct light_table *lt = build(&s);
    cr_assert_eq(light_count(lt), 5u);
    vec3 e1 = v3_sub(lt_positions[1], lt_positions[0]);
    vec3 e2 = v3_sub(lt_positions[2], lt_positions[0]);
    double lum0 = v3_luminance(lt_materials[0].Le), lum1 = v3_luminance(lt_materials[1].Le);
    double phi[5] = {
        2.0 * MCPT_PI * 0.5 * v3_length(v3_cross(e1, e2)) * lum0,
        2.0 * MCPT_PI *
            v3_length(v3_cross(d3_to_float(lt_quads[0].e1), d3_to_float(lt_quads[0].e2))) * lum0,
        2.0 * MCPT_PI * 4.0 * MCPT_PI * 0.7 * 0.7 * lum0,
        2.0 * MCPT_PI * 4.0 * MCPT_PI * 1.0 * lum1,
        4.0 * MCPT_PI * v3_luminance(lt_lights[4].intensity),
    };
    double total = phi[0] + phi[1] + phi[2] + phi[3] + phi[4], pmf_sum = 0.0;
    for (uint32_t k = 0; k < 5; k++) {
        cr_assert_float_eq(light_pmf(lt, k), phi[k] / total, 1e-5);
        pmf_sum += light_pmf(lt, k);
    }
    cr_assert_float_eq(pmf_sum, 1.0, 1e-5);
    cr_assert_eq(light_pmf(lt, 5), 0.0f, "outside the table");
    for (int i = 0; i < 1000; i++) {
        float pmf;
        uint32_t k = light_pick(lt, ((float)i + 0.5f) / 1000.0f, &pmf);
        cr_assert(k < 5);
        cr_assert_eq(pmf, light_pmf(lt, k));
    }
    light_table_free(lt);
}

/* Each emissive primitive has its light index, the rest LIGHT_NONE. */
Test(light, primitive_light_indices)
{
    struct scene s = light_scene();
    struct light_table *lt = build(&s);
    cr_assert_eq(light_idx_of(lt, LIGHT_TRIANGLE, 0), 0u);
    cr_assert_eq(light_idx_of(lt, LIGHT_QUAD, 0), 1u);
    cr_assert_eq(light_idx_of(lt, LIGHT_SPHERE, 0), 2u);
    cr_assert_eq(light_idx_of(lt, LIGHT_SPHERE, 1), 3u);
    cr_assert_eq(light_idx_of(lt, LIGHT_POINT, 0), LIGHT_NONE);
    light_table_free(lt);
    s.n_lights = 1; /* the quad and spheres no longer emit */
    lt = build(&s);
    cr_assert_eq(light_idx_of(lt, LIGHT_QUAD, 0), LIGHT_NONE);
    cr_assert_eq(light_idx_of(lt, LIGHT_SPHERE, 1), LIGHT_NONE);
    light_table_free(lt);
}

/* An emitter whose area overflows float has no finite power and cannot be picked by power:
 * a quad of area 4e38 and a triangle with coordinates of 1e20 are bad input (exit status 2),
 * named in the message, not "out of memory"; trace_prepare reports the same error. */
Test(light, nonfinite_power_is_bad_input)
{
    struct scene s = light_scene();
    s.n_lights = 2;
    lt_quads[0] = (struct quad){.corner = d3(v3(1.0f, 2.0f, 3.0f)),
                                .e1 = d3(v3(2e19f, 0.0f, 0.0f)),
                                .e2 = d3(v3(0.0f, 2e19f, 0.0f))};
    struct mcpt_error err;
    cr_assert_null(light_table_build(&s, &err));
    cr_assert_eq(err.kind, MCPT_ERROR_INPUT);
    cr_assert_str_eq(err.msg, "emissive quad 0 (material 'lamp', corner 1,2,3): expected an "
                              "emitter of finite power pi A Le, got an area beyond float range");
    struct trace_scene *ts = trace_prepare(&s, 1, &err);
    cr_assert_null(ts);
    cr_assert_eq(err.kind, MCPT_ERROR_INPUT);
    cr_assert(strstr(err.msg, "emissive quad 0"), "%s", err.msg);

    s = light_scene();
    s.n_lights = 1;
    lt_positions[0] = v3(1e20f, 0.0f, 0.0f);
    lt_positions[1] = v3(0.0f, 1e20f, 0.0f);
    lt_positions[2] = v3(0.0f, 0.0f, 1e20f);
    cr_assert_null(light_table_build(&s, &err));
    cr_assert_eq(err.kind, MCPT_ERROR_INPUT);
    cr_assert_str_eq(err.msg, "emissive triangle 0 (material 'lamp', corner 1e+20,0,0): "
                              "expected an emitter of finite power pi A Le, got an area beyond "
                              "float range");
}
