/* tests/shape_test.c - shape.c: ray-sphere, ray-quad and ray-plane intersection, including
 * edge and corner hits, rays from inside and far-away rays (Haines et al. 2019, RTG ch. 7), and
 * the error bounds of hit points (PBRT 4e, ch. 6, "Managing Rounding Error"); triangle surfaces;
 * sampled points on their shape, with the density shape_*_pdf gives (PBRT 4e, ch. 6, "Shape
 * Interface").  The distributions of the samples are tested in light_test.c (chi-square). */
#include <criterion/criterion.h>
#include <string.h>

#include "bvh_test_util.h"
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

/* Rays that pass a sphere's surface closely, at every scale: where the sign of the
 * discriminant is certain in long double (64-bit mantissa: the float inputs' products are exact
 * there), the double test must agree with it, hit for a ray whose closest approach lies inside
 * by more than 1e-9 a S2 (S2 = 2 (|f|^2 + r^2)), miss for one outside by as much.  The closest
 * approach r (1 + delta), |delta| from 1e-12 to 1e-2, puts rays on both sides of the quick
 * rejection's margin (2^-40 a S2) and of the near-tangent fallback's. */
Test(shape, sphere_near_tangent_rays_agree_with_long_double)
{
    struct rng rng = {12345};
    int n_hit = 0, n_miss = 0;
    for (int i = 0; i < 200000; i++) {
        /* scales 1e-6 .. 1e6, a closest approach of r (1 + delta), delta in +-[1e-12, 1e-2] */
        double scale = pow(10.0, 12.0 * rng_float(&rng) - 6.0);
        double delta = (rng_float(&rng) < 0.5f ? -1.0 : 1.0) *
                       pow(10.0, 10.0 * rng_float(&rng) - 12.0);
        vec3 c = rng_in_box(&rng, -1.0f, 1.0f);
        struct sphere s = {.center = v3_scale(c, (float)scale), .radius = (float)(0.5 * scale)};
        vec3 d = rng_dir(&rng);
        vec3 e = v3_normalize(v3_cross(d, fabsf(d.x) < 0.9f ? v3(1, 0, 0) : v3(0, 1, 0)));
        double dist = (double)s.radius * (1.0 + delta);
        double back = 4.0 * (double)s.radius;
        vec3 o = v3((float)(s.center.x + dist * e.x - back * d.x),
                    (float)(s.center.y + dist * e.y - back * d.y),
                    (float)(s.center.z + dist * e.z - back * d.z));
        struct ray r = mkray(o, d);
        /* the reference, from the float inputs as they are */
        long double f[3] = {(long double)o.x - s.center.x, (long double)o.y - s.center.y,
                            (long double)o.z - s.center.z};
        long double dd[3] = {d.x, d.y, d.z};
        long double a = 0, b = 0, ff = 0, rr = (long double)s.radius * s.radius;
        for (int k = 0; k < 3; k++) {
            a += dd[k] * dd[k];
            b += f[k] * dd[k];
            ff += f[k] * f[k];
        }
        long double disc = b * b - a * (ff - rr); /* the root's sign: hit where > 0 */
        long double s2 = 2.0L * (ff + rr);
        float t;
        bool hit = shape_sphere_intersect(&s, &r, &t);
        if (disc > 1e-9L * a * s2) {
            cr_assert(hit, "ray %d: inside by %Lg of a S2 (scale %g), missed", i, disc / (a * s2),
                      scale);
            n_hit++;
        } else if (disc < -1e-9L * a * s2) {
            cr_assert_not(hit, "ray %d: outside by %Lg of a S2 (scale %g), hit", i,
                          -disc / (a * s2), scale);
            n_miss++;
        }
    }
    cr_assert(n_hit > 10000 && n_miss > 10000, "decisive rays: %d hits, %d misses", n_hit, n_miss);
}

/* Quad hits inside, on an edge (alpha = 0) and at a corner count; just outside does not. */
Test(shape, quad_edges_and_corners)
{
    struct quad q = {.corner = d3(v3(0, 0, 0)), .e1 = d3(v3(1, 0, 0)), .e2 = d3(v3(0, 1, 0))};
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
    struct surface sf =
        shape_quad_surface(&q, &(struct ray){v3(0.25f, 0.75f, 1), 0, v3(0, 0, -1), INFINITY}, 1.0f);
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
            cr_assert(!hit || t2 > 1e-3f * radii[k], "radius %g: self hit at t = %g", radii[k], t2);
        }
    }
}

/* pbrt-v4's sphere Reintersect test (tests/shapes.cpp), both ways and far from the origin:
 * spheres of radius 10^-8 .. 10^8 moved up to 2^20 radii (half of them along an axis, where one
 * coordinate's rounding is large and the others' small), a hit point from a random ray, then
 * rays spawned from it (offset_ray_origin) in random directions: one leaving outwards never
 * meets the sphere again, and one leaving inwards always meets it (its origin is inside: no
 * path escapes a closed sphere).  Before the sagitta (shape.c, sphere_point) an inward ray from a
 * point off sideways could start outside the curved surface and miss it. */
Test(shape, sphere_reintersect_both_ways)
{
    struct rng rng = {7};
    int n_in = 0, n_out = 0;
    for (int k = 0; k < 200; k++) {
        float r = powf(10.0f, rng_range(&rng, -8.0f, 8.0f));
        vec3 axis = rng_dir(&rng);
        if (k % 2) {
            int a = (int)(rng_float(&rng) * 3.0f);
            axis = v3(a == 0, a == 1, a == 2);
        }
        struct sphere s = {.center = v3_scale(axis, r * exp2f(rng_range(&rng, 0.0f, 20.0f))),
                           .radius = r};
        for (int i = 0; i < 50; i++) {
            vec3 dir = rng_dir(&rng);
            struct ray in = mkray(v3_add(s.center, v3_scale(dir, 3.0f * r)),
                                  v3_neg(v3_normalize(v3_add(dir, v3_scale(rng_dir(&rng), 0.3f)))));
            float t;
            if (!shape_sphere_intersect(&s, &in, &t))
                continue;
            struct surface sf = shape_sphere_surface(&s, &in, t);
            for (int j = 0; j < 20; j++) {
                vec3 w = rng_dir(&rng);
                float c = v3_dot(w, sf.ng);
                if (c == 0.0f)
                    continue;
                struct ray out = mkray(offset_ray_origin(sf.p, sf.p_error, sf.ng, w), w);
                float t2;
                bool hit = shape_sphere_intersect(&s, &out, &t2);
                if (c > 0.0f) {
                    n_out++;
                    cr_assert(!hit,
                              "radius %g at %g,%g,%g: an outward ray meets the sphere at "
                              "t = %g",
                              r, s.center.x, s.center.y, s.center.z, t2);
                } else {
                    n_in++;
                    cr_assert(hit,
                              "radius %g at %g,%g,%g: an inward ray (cos %g) leaves the "
                              "sphere",
                              r, s.center.x, s.center.y, s.center.z, c);
                }
            }
        }
    }
    cr_assert_gt(n_in, 50000);
    cr_assert_gt(n_out, 50000);
}

/* A triangle's surface at barycentrics (b0, b1, b2): p lies on the triangle's plane within its
 * error bound projected on the normal (PBRT 4e, ch. 6, "Robust Spawned Ray Origins"), the bound
 * is the rounding to float, a few 2^-24 |p|, not gamma(7) sum |b_i p_i| (docs/theory.md,
 * "Self-intersection"), and p is the point sum b_i p_i moved inside the triangle by a few of
 * its error bounds; the shading normal and uv interpolated (the normal renormalised and turned
 * to the side of ng), and without per-corner normals ns = ng. */
Test(shape, triangle_surface_interpolates)
{
    const vec3 p[3] = {{1e3f, 2.0f, -3.0f}, {1e3f + 1.5f, 2.25f, -3.0f}, {1e3f, 3.0f, -1.0f}};
    const vec3 ns[3] = {{0, 0, 1}, {0, 1, 0}, {1, 0, 0}};
    const vec2 uv[3] = {{0, 0}, {1, 0}, {0, 1}};
    const float b1 = 0.3f, b2 = 0.45f;
    const double b[3] = {1.0 - b1 - b2, b1, b2};
    struct surface sf = shape_triangle_surface(p, NULL, ns, uv, NULL, 0.0f, b1, b2, 7);
    double e1[3], e2[3], q[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = (double)v3_get(p[1], k) - v3_get(p[0], k);
        e2[k] = (double)v3_get(p[2], k) - v3_get(p[0], k);
        q[k] = (double)v3_get(sf.p, k) - v3_get(p[0], k);
    }
    double nx = e1[1] * e2[2] - e1[2] * e2[1], ny = e1[2] * e2[0] - e1[0] * e2[2],
           nz = e1[0] * e2[1] - e1[1] * e2[0];
    double len = sqrt(nx * nx + ny * ny + nz * nz);
    double dist = fabs(nx * q[0] + ny * q[1] + nz * q[2]) / len;
    double bound = (fabs(nx) * sf.p_error.x + fabs(ny) * sf.p_error.y + fabs(nz) * sf.p_error.z) /
                   len;
    cr_assert(dist <= bound, "off the plane by %g, bound %g", dist, bound);
    float p_max = fmaxf(fabsf(sf.p.x), fmaxf(fabsf(sf.p.y), fabsf(sf.p.z)));
    for (int k = 0; k < 3; k++) {
        double exact = b[0] * v3_get(p[0], k) + b[1] * v3_get(p[1], k) + b[2] * v3_get(p[2], k);
        cr_assert(fabs(v3_get(sf.p, k) - exact) <= 16.0f * v3_max_comp(sf.p_error), "axis %d", k);
        cr_assert(v3_get(sf.p_error, k) > 0.0f);
        cr_assert(v3_get(sf.p_error, k) <= 4.0f * 0x1p-24f * p_max, "axis %d: bound %g", k,
                  v3_get(sf.p_error, k));
    }
    vec3 n = v3_normalize(
        v3_add(v3_add(v3_scale(ns[0], (float)b[0]), v3_scale(ns[1], b1)), v3_scale(ns[2], b2)));
    float side = v3_dot(n, sf.ng) < 0.0f ? -1.0f : 1.0f;
    cr_assert(v3_length(v3_sub(sf.ns, v3_scale(n, side))) < 1e-6f);
    cr_assert_float_eq(sf.uv.x, b1, 1e-6f);
    cr_assert_float_eq(sf.uv.y, b2, 1e-6f);
    cr_assert_eq(sf.mat_idx, 7u);
    struct surface flat = shape_triangle_surface(p, NULL, NULL, NULL, NULL, 0.0f, b1, b2, 0);
    cr_assert(v3_length(v3_sub(flat.ns, flat.ng)) == 0.0f);
    vec3 ng;
    float area = shape_triangle_area(p, &ng);
    cr_assert(v3_length(v3_sub(ng, sf.ng)) < 1e-6f);
    cr_assert_float_eq(area, 0.5f * v3_length(v3_cross(v3_sub(p[1], p[0]), v3_sub(p[2], p[0]))),
                       1e-6f);
}

/* A hit's surface from the triangle's kept plane (shape_triangle_plane, out of line, as trace.c
 * keeps it for a small scene's triangles) is that of shape_triangle_surface, which computes the
 * plane inline, to the bit: the two must not round differently (contracted multiply-adds, say),
 * or a small scene's image would change.  Random triangles from 1e-6 to 1e6 units, hit from
 * nearby and from far (the point rebuilt from the barycentrics, or projected from the ray where
 * the triangle is 2^8 times larger than the hit distance), with and without shading normals and
 * uvs, and without a ray. */
Test(shape, triangle_plane_surface_equals_triangle_surface)
{
    struct rng rng = {777};
    const vec3 ns[3] = {{0, 0, 1}, {0, 1, 0}, {1, 0, 0}};
    const vec2 uv[3] = {{0, 0}, {1, 0}, {0, 1}};
    int n_projected = 0, n_rebuilt = 0;
    for (int i = 0; i < 20000; i++) {
        /* the hit point x 4 sizes from the world's origin, or within 1e-3 of a size (half the
         * triangles), and the ray's origin 1e-4 to 10 sizes before it: the point is projected
         * from the ray where the triangle is 2^8 times larger than the distance plus |o| */
        float scale = (float)pow(10.0, 12.0 * rng_float(&rng) - 6.0);
        float far = i % 2 ? 4.0f : 1e-3f;
        vec3 x = v3_scale(rng_in_box(&rng, -1.0f, 1.0f), scale * far);
        vec3 e1 = v3_scale(rng_in_box(&rng, -1.0f, 1.0f), scale);
        vec3 e2 = v3_scale(rng_in_box(&rng, -1.0f, 1.0f), scale);
        float b1 = rng_float(&rng), b2 = rng_float(&rng);
        if (b1 + b2 > 1.0f) {
            b1 = 1.0f - b1;
            b2 = 1.0f - b2;
        }
        vec3 p0 = v3_sub(x, v3_add(v3_scale(e1, b1), v3_scale(e2, b2)));
        const vec3 p[3] = {p0, v3_add(p0, e1), v3_add(p0, e2)};
        float dist = scale * (float)pow(10.0, 5.0 * rng_float(&rng) - 4.0);
        vec3 d = rng_dir(&rng);
        struct ray r = mkray(v3_sub(x, v3_scale(d, dist)), d);
        double near = 256.0 * ((double)dist + fmax(fabsf(r.o.x), fmax(fabsf(r.o.y), fabsf(r.o.z))));
        if (fmax(v3_dot(e1, e1), v3_dot(e2, e2)) > near * near * 1.01)
            n_projected++;
        else
            n_rebuilt++;
        struct triangle_plane tp;
        shape_triangle_plane(p, NULL, &tp);
        for (int variant = 0; variant < 3; variant++) {
            const struct ray *ray = variant == 2 ? NULL : &r;
            const vec3 *n = variant == 1 ? ns : NULL;
            const vec2 *t = variant == 1 ? uv : NULL;
            struct surface a = shape_triangle_surface(p, NULL, n, t, ray, ray ? dist : 0.0f, b1, b2,
                                                      3);
            struct surface b = shape_triangle_plane_surface(&tp, n, t, ray, ray ? dist : 0.0f, b1,
                                                            b2, 3);
            cr_assert(memcmp(&a.p, &b.p, sizeof a.p) == 0 &&
                          memcmp(&a.p_error, &b.p_error, sizeof a.p_error) == 0 &&
                          memcmp(&a.ng, &b.ng, sizeof a.ng) == 0 &&
                          memcmp(&a.ns, &b.ns, sizeof a.ns) == 0 &&
                          memcmp(&a.uv, &b.uv, sizeof a.uv) == 0 && a.mat_idx == b.mat_idx,
                      "triangle %d, variant %d (scale %g, distance %g): the surfaces differ", i,
                      variant, scale, dist);
        }
    }
    cr_assert(n_projected > 1000 && n_rebuilt > 1000, "projected %d, rebuilt %d", n_projected,
              n_rebuilt);
}

/* Sampled points lie on their shape to within their error bound: on the plane of a triangle
 * or quad (|(p - p0) . n| <= |n| . p_error) and at distance r from a sphere's centre (seen from
 * outside, cone sampling, and from inside, by a cosine-weighted direction; | |p - c| - r | <=
 * |p_error|); wi is the unit direction to p; shape_*_pdf at p is the density the sample
 * returned: exactly for the spheres, whose two computations are the same formula, to 1e-5 by
 * area (the sample measures to its exact point, the pdf to where the ray along the rounded wi
 * meets the plane), to 1e-4 by solid angle (the triangle and the rectangle, whose density reads
 * the bilinear warp's at the inverse of the spherical map, which rounds). */
Test(shape, samples_lie_on_the_shape)
{
    const vec3 tri[3] = {{-1, -1, 2}, {2, -1, 2.5f}, {-1, 2, 2}};
    struct quad q = {.corner = d3(v3(-0.5f, -2, 0.3f)),
                     .e1 = d3(v3(1, 0, 0.2f)),
                     .e2 = d3(v3(0, 0.3f, 1))};
    struct quad rect = {.corner = d3(v3(-1, -1.5f, 0.2f)),
                        .e1 = d3(v3(2, 0, 0.4f)),
                        .e2 = d3(v3(0.12f, 0.9f, -0.6f))};
    struct sphere far = {.center = v3(0.5f, 0.3f, 2.5f), .radius = 0.7f};
    struct sphere around = {.center = v3(0.1f, -0.2f, 0.2f), .radius = 1.0f};
    struct surface ref = {.p = v3(0, 0, 0), .ng = v3(0, 0, 1), .ns = v3(0, 0, 1)};
    for (int i = 0; i < 1000; i++) {
        vec2 u = {((float)i + 0.5f) / 1000.0f, (float)((i * 389) % 1000) / 1000.0f};
        struct shape_sample ss[6];
        bool ok[6] = {shape_triangle_sample(tri, &ref, u, &ss[0]),
                      shape_quad_sample(&q, &ref, u, &ss[1]),
                      shape_sphere_sample(&far, &ref, ref.ns, u, &ss[2]),
                      shape_sphere_sample(&around, &ref, ref.ns, u, &ss[3]),
                      shape_triangle_sample_solid_angle(tri, &ref, u, &ss[4]),
                      shape_quad_sample_solid_angle(&rect, &ref, u, &ss[5])};
        for (int k = 0; k < 6; k++) {
            if (!ok[k])
                continue;
            const struct shape_sample *s = &ss[k];
            vec3 n_abs = v3(fabsf(s->n.x), fabsf(s->n.y), fabsf(s->n.z));
            double off;
            if (k < 2 || k >= 4) {
                vec3 p0 = k == 0 || k == 4 ? tri[0]
                          : k == 1         ? d3_to_float(q.corner)
                                           : d3_to_float(rect.corner);
                vec3 d = v3_sub(s->p, p0);
                off = fabs((double)d.x * s->n.x + (double)d.y * s->n.y + (double)d.z * s->n.z);
                cr_assert(off <= 1.01 * v3_dot(n_abs, s->p_error) + 1e-7, "shape %d: %g", k, off);
            } else {
                const struct sphere *sp = k == 2 ? &far : &around;
                double dx = (double)s->p.x - sp->center.x, dy = (double)s->p.y - sp->center.y,
                       dz = (double)s->p.z - sp->center.z;
                off = fabs(sqrt(dx * dx + dy * dy + dz * dz) - sp->radius);
                cr_assert(off <= v3_length(s->p_error), "sphere %d: %g", k, off);
            }
            cr_assert(fabsf(v3_length(s->n) - 1.0f) < 1e-5f);
            vec3 w = v3_normalize(v3_sub(s->p, ref.p));
            cr_assert(v3_length(v3_sub(w, s->wi)) < 1e-6f, "shape %d: wi", k);
            struct surface on = {.p = s->p, .ng = s->n};
            float pdf = k == 0   ? shape_triangle_pdf(tri, &ref, &on, s->wi)
                        : k == 1 ? shape_quad_pdf(&q, &ref, &on, s->wi)
                        : k == 2 ? shape_sphere_pdf(&far, &ref, ref.ns, s->wi)
                        : k == 3 ? shape_sphere_pdf(&around, &ref, ref.ns, s->wi)
                        : k == 4 ? shape_triangle_pdf_solid_angle(tri, &ref, &on, s->wi)
                                 : shape_quad_pdf_solid_angle(&rect, &ref, &on, s->wi);
            if (k >= 4 || k < 2)
                cr_assert(fabsf(pdf / s->pdf_sa - 1.0f) < (k >= 4 ? 1e-4f : 1e-5f),
                          "shape %d: %g vs %g", k, pdf, s->pdf_sa);
            else
                cr_assert_eq(pdf, s->pdf_sa, "shape %d", k);
        }
    }
}

/* Spawned origins from n_points points on an edge of quad q (edge 0: alpha = 1, edge 1:
 * beta = 1) and, for edge 0, of the float triangle corner, corner + e1, corner + e1 + e2 (whose
 * edge b0 = 0 it is), each in 8 directions: how many lie on or past the plane through that edge
 * at a right angle to the face, the side decided in long double. */
static int origins_past_right_angled_neighbour(const struct quad *q, int edge, int n_points)
{
    const struct dvec3 *e_along = edge == 0 ? &q->e2 : &q->e1,
                       *e_across = edge == 0 ? &q->e1 : &q->e2;
    long double c[3] = {q->corner.x, q->corner.y, q->corner.z},
                a[3] = {e_across->x, e_across->y, e_across->z},
                e[3] = {e_along->x, e_along->y, e_along->z};
    vec3 tri[3];
    for (int v = 0; v < 3; v++)
        tri[v] = v3((float)(c[0] + (v > 0) * a[0] + (v > 1) * e[0]),
                    (float)(c[1] + (v > 0) * a[1] + (v > 1) * e[1]),
                    (float)(c[2] + (v > 0) * a[2] + (v > 1) * e[2]));
    /* per face (0 the quad, 1 the triangle): a point on the edge, the face's other side, the
     * edge's direction, a vector across the face */
    long double on[2][3], inner[2][3], along[2][3], across[2][3];
    for (int k = 0; k < 3; k++) {
        on[0][k] = c[k] + a[k];
        inner[0][k] = c[k];
        along[0][k] = e[k];
        across[0][k] = a[k];
        on[1][k] = (&tri[1].x)[k];
        inner[1][k] = (&tri[0].x)[k];
        along[1][k] = (long double)(&tri[2].x)[k] - (&tri[1].x)[k];
        across[1][k] = (long double)(&tri[1].x)[k] - (&tri[0].x)[k];
    }
    long double nb[2][3]; /* the neighbour's normal, pointing away from the face */
    for (int f = 0; f < 2; f++) {
        const long double *u = across[f], *v = along[f];
        long double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                            u[0] * v[1] - u[1] * v[0]};
        long double m[3] = {v[1] * n[2] - v[2] * n[1], v[2] * n[0] - v[0] * n[2],
                            v[0] * n[1] - v[1] * n[0]};
        long double in = 0.0L;
        for (int k = 0; k < 3; k++)
            in += m[k] * (inner[f][k] - on[f][k]);
        for (int k = 0; k < 3; k++)
            nb[f][k] = in < 0.0L ? m[k] : -m[k];
    }
    struct surface ref = {.p = v3(0, 0, 0), .ng = v3(0, 0, 1), .ns = v3(0, 0, 1)};
    uint32_t rng = 12345u;
    int n_out = 0;
    for (int i = 0; i < n_points; i++) {
        float t = ((float)i + 0.5f) / (float)n_points;
        struct shape_sample ss;
        cr_assert(shape_quad_sample(q, &ref, edge == 0 ? (vec2){1.0f, t} : (vec2){t, 1.0f}, &ss));
        struct surface faces[2] = {{.p = ss.p, .p_error = ss.p_error, .ng = ss.n},
                                   shape_triangle_surface(tri, NULL, NULL, NULL, NULL, 0.0f,
                                                          1.0f - t, t, 0)};
        for (int f = 0; f < (edge == 0 ? 2 : 1); f++)
            for (int d = 0; d < 8; d++) {
                vec3 dir;
                do {
                    for (int k = 0; k < 3; k++) {
                        rng = rng * 1664525u + 1013904223u;
                        (&dir.x)[k] = (float)(rng >> 8) * 0x1p-23f - 1.0f;
                    }
                } while (v3_dot(dir, dir) > 1.0f || v3_dot(dir, dir) < 1e-4f);
                vec3 o = offset_ray_origin(faces[f].p, faces[f].p_error, faces[f].ng,
                                           v3_normalize(dir));
                long double side = 0.0L;
                for (int k = 0; k < 3; k++)
                    side += nb[f][k] * ((long double)(&o.x)[k] - on[f][k]);
                n_out += !(side < 0.0L);
            }
    }
    return n_out;
}

/* A point on the edge of a face, pulled inside by shape.c's margin (EDGE_MARGIN_E times its
 * error projected on the edge's normal in the plane, edge_margin_groove), spawns rays whose origins lie
 * strictly in front of a neighbouring face at a right angle across that edge, whatever the
 * direction: the push along the face's normal is parallel to the neighbour, and only roundings
 * move the origin towards it, by less than the margin.  First the
 * face of a rotated box of quads at size 1e-12 and offset 1e-9 that let sky in (tests/extremes,
 * moved_quad_box_sees_no_sky): with twice the error as the margin, 4.7% of its origins crossed.
 * Then quads and triangles of a box turned 16 ways at sizes and offsets where float resolves
 * the face to 1 part in 10^3 to 10^7. */
Test(shape, edge_points_spawn_in_front_of_a_right_angled_neighbour)
{
    struct quad leaked = {
        .corner = {9.983635021393847e-10, 5.356659133986832e-13, 1.8691383422365932e-13},
        .e1 = {9.447165533382443e-13, -1.2729957212306679e-12, 1.2194230306079677e-12},
        .e2 = {1.6097115153039838e-12, 1.1869138342236594e-12, -8.024190067805304e-15}};
    int n_out = origins_past_right_angled_neighbour(&leaked, 1, 20000);
    cr_assert_eq(n_out, 0, "the quad that leaked: %d of 160000 origins past the neighbour", n_out);
    static const double cases[][2] = {{1e-12, 1e-9}, {1.0, 1e3}, {1.0, 1e5},
                                      {1e-6, 0.3},   {1e3, 1e6}, {1e6, 0.0}};
    for (int turn = 0; turn < 16; turn++) {
        /* turned by 0.4 + 0.37 turn radians about an axis that changes with turn */
        const double ang = 0.4 + 0.37 * turn, c = cos(ang), s = sin(ang);
        double ax[3] = {1.0 + turn % 3, 2.0 - turn % 5, 3.0 + (turn % 2 ? -turn : turn)};
        double len = sqrt(ax[0] * ax[0] + ax[1] * ax[1] + ax[2] * ax[2]);
        const double k[3] = {ax[0] / len, ax[1] / len, ax[2] / len};
        const double K[3][3] = {{0, -k[2], k[1]}, {k[2], 0, -k[0]}, {-k[1], k[0], 0}};
        double R[3][3];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                R[i][j] = (i == j ? c : 0.0) + s * K[i][j] + (1.0 - c) * k[i] * k[j];
        for (size_t ci = 0; ci < sizeof cases / sizeof cases[0]; ci++) {
            double size = cases[ci][0], off = cases[ci][1];
            /* the face corner (-1, -1, -1), e1 = (2, 0, 0), e2 = (0, 2, 0) in the box's frame */
            const double local[3][3] = {{-1, -1, -1}, {2, 0, 0}, {0, 2, 0}};
            double w[3][3];
            for (int v = 0; v < 3; v++)
                for (int i = 0; i < 3; i++)
                    w[v][i] = (v == 0 ? off : 0.0) +
                              size * (R[i][0] * local[v][0] + R[i][1] * local[v][1] +
                                      R[i][2] * local[v][2]);
            struct quad q = {.corner = {w[0][0], w[0][1], w[0][2]},
                             .e1 = {w[1][0], w[1][1], w[1][2]},
                             .e2 = {w[2][0], w[2][1], w[2][2]}};
            for (int edge = 0; edge < 2; edge++) {
                n_out = origins_past_right_angled_neighbour(&q, edge, 2000);
                cr_assert_eq(n_out, 0, "turn %d, size %g at %g, edge %d: %d origins past it", turn,
                             size, off, edge, n_out);
            }
        }
    }
}
