/* tests/shape_test.c - shape.c: ray-sphere, ray-quad and ray-plane intersection, including
 * edge and corner hits, rays from inside and far-away rays (Haines et al. 2019, RTG ch. 7), and
 * the error bounds of hit points (PBRT 4e, ch. 6, "Managing Rounding Error"). */
#include <criterion/criterion.h>

#include "shape.h"

static struct ray mkray(vec3 o, vec3 d)
{
    return (struct ray){.o = o, .d = d, .t_min = 0.0f, .t_max = INFINITY};
}

/* A ray through the centre hits the near side at t = |o - c| - r. */
Test(shape, sphere_from_outside)
{
    struct sphere s = {.center = v3(1, 2, 3), .radius = 0.5f};
    struct ray r = mkray(v3(1, 2, -2), v3(0, 0, 1));
    float t;
    cr_assert(shape_sphere_intersect(&s, &r, &t));
    cr_assert_float_eq(t, 4.5f, 1e-6f);
    struct surface sf = shape_sphere_surface(&s, &r, t);
    cr_assert_float_eq(sf.ng.z, -1.0f, 1e-6f);
}

/* From the centre, the hit is at t = r and the normal points outwards (along the ray). */
Test(shape, sphere_from_inside)
{
    struct sphere s = {.center = v3(0, 0, 0), .radius = 2.0f};
    struct ray r = mkray(v3(0, 0, 0), v3(0, 1, 0));
    float t;
    cr_assert(shape_sphere_intersect(&s, &r, &t));
    cr_assert_float_eq(t, 2.0f, 1e-6f);
    struct surface sf = shape_sphere_surface(&s, &r, t);
    cr_assert_float_eq(sf.ng.y, 1.0f, 1e-6f);
}

/* Misses, and t_max/t_min clipping. */
Test(shape, sphere_miss_and_range)
{
    struct sphere s = {.center = v3(0, 0, 0), .radius = 1.0f};
    float t;
    struct ray r = mkray(v3(0, 1.001f, -5), v3(0, 0, 1));
    cr_assert_not(shape_sphere_intersect(&s, &r, &t));
    r = mkray(v3(0, 0, -5), v3(0, 0, 1));
    r.t_max = 3.9f;
    cr_assert_not(shape_sphere_intersect(&s, &r, &t));
    r = mkray(v3(0, 0, -5), v3(0, 0, -1));
    cr_assert_not(shape_sphere_intersect(&s, &r, &t), "sphere behind the ray");
}

/* A smallpt wall: radius 1e5 sphere, ray from 50 units away.  The naive discriminant loses all
 * precision here (RTG ch. 7); the hit must land on the surface within its error bound. */
Test(shape, huge_sphere_precision)
{
    struct sphere s = {.center = v3(1e5f + 1.0f, 40.8f, 81.6f), .radius = 1e5f};
    struct ray r = mkray(v3(50, 40.8f, 81.6f), v3(-1, 0, 0));
    float t;
    cr_assert(shape_sphere_intersect(&s, &r, &t));
    cr_assert_float_eq(t, 49.0f, 0.02f);
    struct surface sf = shape_sphere_surface(&s, &r, t);
    float dist = v3_length(v3_sub(sf.p, s.center));
    cr_assert(fabsf(dist - s.radius) <= 4.0f * v3_max_comp(sf.p_error) + 1e-2f,
              "reprojected point is on the sphere: |p-c| = %.6f", dist);
}

/* Quad hits inside, on an edge (alpha = 0) and at a corner count; just outside does not. */
Test(shape, quad_edges_and_corners)
{
    struct quad q = {.corner = v3(0, 0, 0), .e1 = v3(1, 0, 0), .e2 = v3(0, 1, 0)};
    float t;
    struct ray r = mkray(v3(0.5f, 0.5f, 1), v3(0, 0, -1));
    cr_assert(shape_quad_intersect(&q, &r, &t));
    cr_assert_float_eq(t, 1.0f, 1e-6f);
    r = mkray(v3(0.0f, 0.5f, 1), v3(0, 0, -1));
    cr_assert(shape_quad_intersect(&q, &r, &t), "edge");
    r = mkray(v3(1.0f, 1.0f, 1), v3(0, 0, -1));
    cr_assert(shape_quad_intersect(&q, &r, &t), "corner");
    r = mkray(v3(1.0001f, 0.5f, 1), v3(0, 0, -1));
    cr_assert_not(shape_quad_intersect(&q, &r, &t), "outside");
    r = mkray(v3(0.5f, 0.5f, 1), v3(1, 0, 0));
    cr_assert_not(shape_quad_intersect(&q, &r, &t), "parallel");
    struct surface sf = shape_quad_surface(&q, &(struct ray){v3(0.25f, 0.75f, 1), 0,
                                                             v3(0, 0, -1), INFINITY}, 1.0f);
    cr_assert_float_eq(sf.ng.z, 1.0f, 1e-6f);
    cr_assert_float_eq(sf.uv.x, 0.25f, 1e-6f);
    cr_assert_float_eq(sf.uv.y, 0.75f, 1e-6f);
}

/* Planes: hit from either side, parallel rays miss, the point lies on the plane. */
Test(shape, plane)
{
    struct plane pl = {.point = v3(0, -1, 0), .n = v3(0, 1, 0)};
    float t;
    struct ray r = mkray(v3(3, 2, 7), v3(0, -1, 0));
    cr_assert(shape_plane_intersect(&pl, &r, &t));
    cr_assert_float_eq(t, 3.0f, 1e-6f);
    r = mkray(v3(3, -4, 7), v3(0, 1, 0));
    cr_assert(shape_plane_intersect(&pl, &r, &t), "from behind");
    struct surface sf = shape_plane_surface(&pl, &r, t);
    cr_assert_float_eq(sf.p.y, -1.0f, 1e-6f);
    r = mkray(v3(3, 2, 7), v3(1, 0, 0));
    cr_assert_not(shape_plane_intersect(&pl, &r, &t), "parallel");
}

/* A ray leaving a sphere's surface, offset by its error bound, never re-hits the surface at
 * t ~ 0 (PBRT 4e, ch. 6, "Robust Spawned Ray Origins"), at radii from 1e-4 to 1e4. */
Test(shape, sphere_offset_no_self_hit)
{
    float radii[] = {1e-4f, 1.0f, 1e4f};
    for (int k = 0; k < 3; k++) {
        struct sphere s = {.center = v3(radii[k] * 3, -radii[k], radii[k] * 0.5f),
                           .radius = radii[k]};
        for (int i = 0; i < 500; i++) {
            float th = 0.0123f * (float)i, ph = 0.731f * (float)i;
            vec3 dir = v3(sinf(th) * cosf(ph), cosf(th), sinf(th) * sinf(ph));
            struct ray in = mkray(v3_add(s.center, v3_scale(dir, 5 * radii[k])), v3_neg(dir));
            float t;
            cr_assert(shape_sphere_intersect(&s, &in, &t));
            struct surface sf = shape_sphere_surface(&s, &in, t);
            /* leave outwards, tangent-ish */
            vec3 w = v3_normalize(v3_add(sf.ng, v3_scale(v3(dir.y, -dir.x, 0.3f), 3.0f)));
            struct ray out = mkray(offset_ray_origin(sf.p, sf.p_error, sf.ng, w), w);
            float t2;
            bool hit = shape_sphere_intersect(&s, &out, &t2);
            cr_assert(!hit || t2 > 1e-3f * radii[k], "radius %g: self hit at t = %g", radii[k],
                      t2);
        }
    }
}
