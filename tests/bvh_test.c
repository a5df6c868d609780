/* bvh_test.c - tests for bvh.c: the binned-SAH BVH (Wald 2007) must return exactly what brute
 * force returns (same t_hit bits, same prim_idx up to exact ties) on random rays through random
 * soups, a closed icosphere, an axis-aligned flat grid (d_a == 0, origins on slab planes, flat
 * boxes), identical centroids and zero-area triangles, through every layout: the binary
 * reference, the 8-wide layout converted from it (Ylitie et al. 2017 collapse, SIMD Woop test)
 * and 8-ray packets.  The triangle test must be watertight (Woop, Benthin, Wald 2013,
 * "Watertight Ray/Triangle Intersection"): rays aimed exactly at shared vertices and edges never
 * escape a closed mesh.  Rays spawned with offset_ray_origin (PBRT 4e, ch. 6, "Robust Spawned Ray
 * Origins") must not re-hit their own triangle, at scales 1e-4 to 1e4.  The tree must not depend
 * on the build's thread count.  Tests of what only the wide layout has (the conversion of
 * oversized leaves, the fused slab test, packets) are in tests/bvh_wide_test.c. */
#include <criterion/criterion.h>
#include <criterion/logging.h>
#include <stdlib.h>

#include "bvh.h"
#include "bvh_test_util.h"
#include "shape.h"
#include "vec.h"

/* ---- helpers --------------------------------------------------------------------------------- */

static vec3 abs3(vec3 a) { return v3(fabsf(a.x), fabsf(a.y), fabsf(a.z)); }

/* PBRT 4e, ch. 6, "Bounding Intersection Point Error": the error of b0 p0 + b1 p1 + b2 p2 is at
 * most gamma(7) (|b0 p0| + |b1 p1| + |b2 p2|) */
static vec3 barycentric_error(vec3 p0, vec3 p1, vec3 p2, float b0, float b1, float b2)
{
    vec3 sum = v3_add(v3_add(v3_scale(abs3(p0), fabsf(b0)), v3_scale(abs3(p1), fabsf(b1))),
                      v3_scale(abs3(p2), fabsf(b2)));
    return v3_scale(sum, mcpt_gamma(7));
}

/* ---- a single triangle ----------------------------------------------------------------------- */

/* Woop et al. 2013: a ray through b0 p0 + b1 p1 + b2 p2 hits with u = b1, v = b2 (the header's
 * vertex order), from every side and for every major axis of d (the kx/ky swap). */
Test(bvh, single_triangle_hit_inside)
{
    struct mesh m = {0};
    mesh_add_tri_pos(&m, v3(0.1f, 0.2f, 0.3f), v3(1.7f, 0.4f, -0.2f), v3(0.5f, 1.9f, 0.8f));
    struct bvh *bvh = build(&m);
    vec3 p0 = tri_vertex(&m, 0, 0);
    vec3 n = v3_normalize(
        v3_cross(v3_sub(tri_vertex(&m, 0, 1), p0), v3_sub(tri_vertex(&m, 0, 2), p0)));
    const vec3 dirs[6] = {v3(1, 0, 0),  v3(-1, 0, 0), v3(0, 1, 0),
                          v3(0, -1, 0), v3(0, 0, 1),  v3(0, 0, -1)};
    const float barys[4][2] = {{0.2f, 0.3f}, {0.7f, 0.1f}, {0.05f, 0.9f}, {1.0f / 3, 1.0f / 3}};
    struct rng r = {1};
    int n_rays = 0;
    for (int i = 0; i < 6 + 200; i++) {
        vec3 d = i < 6 ? dirs[i] : rng_dir(&r);
        if (fabsf(v3_dot(d, n)) < 0.1f)
            continue;
        for (int j = 0; j < 4; j++) {
            vec3 q = tri_point(&m, 0, barys[j][0], barys[j][1]);
            struct ray ray = make_ray(v3_sub(q, v3_scale(d, 3.0f)), d, 0.0f, INFINITY);
            struct bvh_hit hit;
            cr_assert(bvh_intersect(bvh, &ray, &hit));
            cr_assert_eq(hit.prim_idx, 0u);
            cr_assert_float_eq(hit.t, 3.0f, 1e-5f);
            cr_assert_float_eq(hit.u, barys[j][0], 1e-5f);
            cr_assert_float_eq(hit.v, barys[j][1], 1e-5f);
            cr_assert(bvh_occluded(bvh, &ray));
            n_rays++;
        }
    }
    cr_assert_gt(n_rays, 400);
    bvh_free(bvh);
    mesh_free(&m);
}

/* Outside the triangle, behind the origin, parallel to it, or outside (t_min, t_max): no hit. */
Test(bvh, single_triangle_miss_outside)
{
    struct mesh m = {0};
    mesh_add_tri_pos(&m, v3(0.1f, 0.2f, 0.3f), v3(1.7f, 0.4f, -0.2f), v3(0.5f, 1.9f, 0.8f));
    struct bvh *bvh = build(&m);
    vec3 p0 = tri_vertex(&m, 0, 0);
    vec3 e1 = v3_sub(tri_vertex(&m, 0, 1), p0);
    vec3 n = v3_normalize(v3_cross(e1, v3_sub(tri_vertex(&m, 0, 2), p0)));
    const float outside[5][2] = {{-0.05f, 0.5f},
                                 {0.5f, -0.05f},
                                 {0.6f, 0.45f},
                                 {1.1f, 0.1f},
                                 {-0.2f, -0.2f}};
    struct bvh_hit hit;
    for (int j = 0; j < 5; j++) {
        vec3 q = tri_point(&m, 0, outside[j][0], outside[j][1]);
        struct ray ray = make_ray(v3_add(q, n), v3_neg(n), 0.0f, INFINITY);
        cr_assert_not(bvh_intersect(bvh, &ray, &hit));
        cr_assert_not(bvh_intersect_brute(bvh, &ray, &hit));
        cr_assert_not(bvh_occluded(bvh, &ray));
    }
    vec3 q = tri_point(&m, 0, 0.25f, 0.25f);
    struct ray away = make_ray(v3_add(q, n), n, 0.0f, INFINITY); /* hit would be at t = -1 */
    cr_assert_not(bvh_intersect(bvh, &away, &hit));
    struct ray parallel = make_ray(v3_add(q, v3_scale(e1, -2.0f)), e1, 0.0f, INFINITY);
    cr_assert_not(bvh_intersect(bvh, &parallel, &hit)); /* in the plane: det == 0 */
    struct ray short_ray = make_ray(v3_add(q, n), v3_neg(n), 0.0f, 0.9f);
    cr_assert_not(bvh_intersect(bvh, &short_ray, &hit));
    cr_assert_not(bvh_occluded(bvh, &short_ray));
    struct ray late_ray = make_ray(v3_add(q, n), v3_neg(n), 1.1f, INFINITY);
    cr_assert_not(bvh_intersect(bvh, &late_ray, &hit));
    bvh_free(bvh);
    mesh_free(&m);
}

/* Woop et al. 2013, double-precision fallback: with B = (-1, -(1 + e)), C = (1 + e, 1 + 2e),
 * e = 2^-23, seen along +z from the origin, U = Cx By - Cy Bx = -e^2 exactly, but both float
 * products round to -(1 + 2e) and U is 0 in float.  The ray passes e^2-close outside edge BC
 * of triangle (A, B, C): the fallback recovers the sign, so that triangle is missed and its
 * neighbour across BC is the one hit. */
Test(bvh, float_zero_edge_function_falls_back_to_double)
{
    const float e = 0x1p-23f;
    struct mesh m = {0};
    uint32_t a = mesh_add_vertex(&m, v3(1.0f, -1.0f, 1.0f));
    uint32_t b = mesh_add_vertex(&m, v3(-1.0f, -(1.0f + e), 1.0f));
    uint32_t c = mesh_add_vertex(&m, v3(1.0f + e, 1.0f + 2.0f * e, 1.0f));
    uint32_t d = mesh_add_vertex(&m, v3(-1.0f, 1.0f, 1.0f));
    mesh_add_tri(&m, a, b, c);
    mesh_add_tri(&m, c, b, d);
    struct ray ray = make_ray(v3(0, 0, 0), v3(0, 0, 1), 0.0f, INFINITY);
    struct bvh *first = bvh_build(m.positions, m.indices, 1, 1);
    cr_assert_not_null(first);
    struct bvh_hit hit;
    cr_assert_not(bvh_intersect(first, &ray, &hit), "float U == 0 taken as on the edge");
    bvh_free(first);
    struct bvh *both = build(&m);
    cr_assert(bvh_intersect(both, &ray, &hit));
    cr_assert_eq(hit.prim_idx, 1u);
    cr_assert_eq(hit.t, 1.0f);
    bvh_free(both);
    mesh_free(&m);
}

/* bvh.h: a hit needs t strictly inside (t_min, t_max). */
Test(bvh, t_interval_is_open)
{
    struct mesh m = {0};
    mesh_add_tri_pos(&m, v3(-1, -1, 0), v3(1, -1, 0), v3(0, 1, 0));
    struct bvh *bvh = build(&m);
    struct ray ray = make_ray(v3(0.1f, 0.0f, 0.7f), v3(0.2f, -0.1f, -1.0f), 0.0f, INFINITY);
    struct bvh_hit hit;
    cr_assert(bvh_intersect(bvh, &ray, &hit));
    float t_hit = hit.t;
    ray.t_max = t_hit;
    cr_assert_not(bvh_intersect(bvh, &ray, &hit));
    cr_assert_not(bvh_occluded(bvh, &ray));
    ray.t_max = next_float_up(t_hit);
    cr_assert(bvh_intersect(bvh, &ray, &hit));
    cr_assert(same_bits(hit.t, t_hit));
    ray.t_max = INFINITY;
    ray.t_min = t_hit;
    cr_assert_not(bvh_intersect(bvh, &ray, &hit));
    cr_assert_not(bvh_occluded(bvh, &ray));
    ray.t_min = next_float_down(t_hit);
    cr_assert(bvh_intersect(bvh, &ray, &hit));
    bvh_free(bvh);
    mesh_free(&m);
}

/* Woop et al. 2013, watertightness: a ray through the shared edge of a quad's two triangles,
 * or through their shared vertices, or through the centre of a fan of six, hits at least one
 * of them (never zero) and the closest-hit query reports exactly one. */
Test(bvh, shared_edge_and_vertex_never_missed)
{
    struct mesh m = {0};
    uint32_t a = mesh_add_vertex(&m, v3(0, 0, 0));
    uint32_t b = mesh_add_vertex(&m, v3(1, 0, 0));
    uint32_t c = mesh_add_vertex(&m, v3(1, 1, 0));
    uint32_t d = mesh_add_vertex(&m, v3(0, 1, 0));
    mesh_add_tri(&m, a, b, c);
    mesh_add_tri(&m, a, c, d);
    struct bvh *bvh = build(&m);
    struct rng r = {2};
    for (int i = 0; i < 3000; i++) {
        /* a target exactly on the shared diagonal x == y, away from the quad's corners (there a
         * rounded shear may legitimately pass outside the quad) */
        float s = i < 1500 ? rng_range(&r, 1.0f / 64, 63.0f / 64) : (float)(1 + i % 63) / 64.0f;
        vec3 target = v3(s, s, 0.0f);
        vec3 o = v3(rng_range(&r, -2, 3), rng_range(&r, -2, 3), rng_range(&r, 0.01f, 2));
        if (i & 2)
            o.z = -o.z; /* from below too */
        struct ray ray = make_ray(o, v3_sub(target, o), 0.0f, INFINITY);
        int n_tri_hits = 0;
        for (uint32_t k = 0; k < 2; k++) {
            struct bvh *one = bvh_build(m.positions, m.indices + 3 * k, 1, 1);
            cr_assert_not_null(one);
            struct bvh_hit h;
            n_tri_hits += bvh_intersect(one, &ray, &h);
            bvh_free(one);
        }
        cr_assert_geq(n_tri_hits, 1, "ray through (%a, %a, 0) from (%a %a %a) slips through", s, s,
                      o.x, o.y, o.z);
        struct bvh_hit hit;
        cr_assert(bvh_intersect(bvh, &ray, &hit));
        cr_assert_float_eq(hit.t, 1.0f, 1e-5f);
        expect_matches_brute(&m, bvh, &ray);
    }
    /* the two vertices both triangles share, hit along the normal (an exact shear) */
    for (int i = 0; i < 2; i++) {
        struct ray ray = make_ray(v3((float)i, (float)i, 1.0f), v3(0, 0, -1), 0.0f, INFINITY);
        struct bvh_hit hit;
        cr_assert(bvh_intersect(bvh, &ray, &hit));
        cr_assert_eq(hit.t, 1.0f);
    }
    bvh_free(bvh);
    mesh_free(&m);

    /* a fan of six triangles in a tilted plane: rays through the shared centre vertex from
     * either side (not grazing, where the rounded plane may fold) */
    struct mesh fan = {0};
    vec3 fan_n = v3_normalize(v3(0.2f, -0.3f, 1.0f));
    vec3 fan_t;
    vec3 fan_b;
    v3_basis(fan_n, &fan_t, &fan_b);
    vec3 centre_p = v3(0.3f, -0.2f, 0.1f);
    uint32_t centre = mesh_add_vertex(&fan, centre_p);
    uint32_t rim[6];
    for (int k = 0; k < 6; k++) {
        float phi = (float)k * MCPT_PI / 3.0f + 0.1f;
        vec3 offset = v3_add(v3_scale(fan_t, cosf(phi)), v3_scale(fan_b, sinf(phi)));
        rim[k] = mesh_add_vertex(&fan, v3_add(centre_p, offset));
    }
    for (int k = 0; k < 6; k++)
        mesh_add_tri(&fan, centre, rim[k], rim[(k + 1) % 6]);
    struct bvh *fan_bvh = build(&fan);
    for (int i = 0; i < 3000; i++) {
        vec3 w = rng_dir(&r);
        if (fabsf(v3_dot(w, fan_n)) < 0.05f)
            continue;
        vec3 o = v3_add(centre_p, v3_scale(w, rng_range(&r, 0.1f, 10.0f)));
        struct ray ray = make_ray(o, v3_sub(centre_p, o), 0.0f, INFINITY);
        struct bvh_hit hit;
        cr_assert(bvh_intersect(fan_bvh, &ray, &hit), "ray at the fan's centre vertex escaped");
        cr_assert(expect_close_to_brute(&fan, fan_bvh, &ray));
    }
    bvh_free(fan_bvh);
    mesh_free(&fan);
}

/* ---- BVH versus brute force (STYLE.md §6) --------------------------------------------------- */

/* 2000 random triangles: random rays and rays aimed at random points on random triangles. */
Test(bvh, matches_brute_force_random_soup)
{
    struct mesh m = {0};
    make_soup(&m, 2000, 3);
    struct bvh *bvh = build(&m);
    struct rng r = {4};
    int n_hits = 0;
    for (int i = 0; i < 6000; i++) {
        struct ray ray;
        if (i % 2 == 0) {
            ray = make_ray(rng_in_box(&r, -2, 2), rng_dir(&r), 0.0f, INFINITY);
        } else {
            uint32_t prim = (uint32_t)(rng_next(&r) % m.n_tris);
            float b1;
            float b2;
            rng_bary(&r, &b1, &b2);
            vec3 o = rng_in_box(&r, -3, 3);
            ray = make_ray(o, v3_sub(tri_point(&m, prim, b1, b2), o), 0.0f, INFINITY);
        }
        if (i % 3 == 0)
            ray.t_min = rng_range(&r, 0.0f, 0.5f);
        n_hits += expect_matches_brute(&m, bvh, &ray);
    }
    cr_assert_gt(n_hits, 3500); /* the aimed half nearly always hits */
    bvh_free(bvh);
    mesh_free(&m);
}

/* A closed icosphere (5120 triangles): rays from inside always hit; rays from outside. */
Test(bvh, matches_brute_force_icosphere)
{
    struct mesh m = {0};
    make_icosphere(&m, 4, v3(0.2f, -0.1f, 0.3f), 1.5f);
    struct bvh *bvh = build(&m);
    struct rng r = {5};
    for (int i = 0; i < 2000; i++) {
        vec3 o = v3_add(v3(0.2f, -0.1f, 0.3f), v3_scale(rng_dir(&r), 1.5f * 0.9f * rng_float(&r)));
        struct ray ray = make_ray(o, rng_dir(&r), 0.0f, INFINITY);
        cr_assert(expect_matches_brute(&m, bvh, &ray), "ray from inside escaped");
    }
    int n_hits = 0;
    for (int i = 0; i < 2000; i++) {
        vec3 o = v3_scale(rng_dir(&r), 4.0f);
        vec3 target = v3_scale(rng_dir(&r), 2.0f * rng_float(&r));
        struct ray ray = make_ray(o, v3_sub(target, o), 0.0f, INFINITY);
        n_hits += expect_matches_brute(&m, bvh, &ray);
    }
    cr_assert_gt(n_hits, 700);
    bvh_free(bvh);
    mesh_free(&m);
}

/* bvh.h: prim_idx is the caller's index.  From the centre of a convex icosphere the ray to a
 * face's centroid hits that face, with u = v = 1/3. */
Test(bvh, prim_idx_is_callers_index)
{
    struct mesh m = {0};
    make_icosphere(&m, 3, v3(0, 0, 0), 1.0f);
    struct bvh *bvh = build(&m);
    for (uint32_t prim = 0; prim < m.n_tris; prim++) {
        vec3 target = tri_point(&m, prim, 1.0f / 3.0f, 1.0f / 3.0f);
        struct ray ray = make_ray(v3(0, 0, 0), target, 0.0f, INFINITY);
        struct bvh_hit hit;
        cr_assert(bvh_intersect(bvh, &ray, &hit));
        cr_assert_eq(hit.prim_idx, prim);
        cr_assert_float_eq(hit.u, 1.0f / 3.0f, 1e-4f);
        cr_assert_float_eq(hit.v, 1.0f / 3.0f, 1e-4f);
        cr_assert_float_eq(hit.t, 1.0f, 1e-5f);
    }
    bvh_free(bvh);
    mesh_free(&m);
}

/* struct ray: d need not be unit length.  Scaling d by a power of two scales every quantity of
 * the traversal and the triangle test exactly (the shear sx, sy is unchanged; sz, inv_d and t
 * scale), so hit or miss, prim_idx, u, v are identical and t scales exactly; this also checks
 * that the delta_t bound scales like t. */
Test(bvh, direction_length_does_not_matter)
{
    struct mesh m = {0};
    make_soup(&m, 1000, 21);
    struct bvh *bvh = build(&m);
    struct rng r = {22};
    int n_hits = 0;
    for (int i = 0; i < 3000; i++) {
        vec3 o = rng_in_box(&r, -2, 2);
        vec3 d = i % 2 ? rng_dir(&r) : v3_sub(tri_point(&m, (uint32_t)(i % 1000), 0.3f, 0.3f), o);
        struct ray ray = make_ray(o, d, 0.0f, INFINITY);
        struct bvh_hit hit;
        bool is_hit = bvh_intersect(bvh, &ray, &hit);
        n_hits += is_hit;
        for (int e = -17; e <= 17; e += 34) {
            struct ray scaled = make_ray(o, v3_scale(d, ldexpf(1.0f, e)), 0.0f, INFINITY);
            struct bvh_hit hit_scaled;
            cr_assert_eq(bvh_intersect(bvh, &scaled, &hit_scaled), is_hit);
            cr_assert_eq(bvh_occluded(bvh, &scaled), is_hit);
            if (!is_hit)
                continue;
            cr_assert(same_bits(hit_scaled.t, ldexpf(hit.t, -e)));
            cr_assert_eq(hit_scaled.prim_idx, hit.prim_idx);
            cr_assert(same_bits(hit_scaled.u, hit.u) && same_bits(hit_scaled.v, hit.v));
        }
    }
    cr_assert_gt(n_hits, 1500);
    bvh_free(bvh);
    mesh_free(&m);
}

/* ---- degenerate inputs ----------------------------------------------------------------------- */

/* Wald 2007's binning needs a centroid extent; with all centres equal the build cuts the index
 * range in half instead, so the tree stays shallow and leaves bounded: 1000 copies of one
 * triangle, and 1000 tiny (1e-6) triangles at one point with their vertex order rotated. */
Test(bvh, identical_centroids)
{
    for (int variant = 0; variant < 2; variant++) {
        struct mesh m = {0};
        vec3 p[3];
        if (variant == 0) {
            p[0] = v3(0.1f, 0.2f, 0.3f);
            p[1] = v3(1.1f, 0.5f, 0.2f);
            p[2] = v3(0.4f, 1.3f, -0.4f);
        } else {
            vec3 at = v3(0.3f, -0.2f, 0.7f);
            p[0] = at;
            p[1] = v3_add(at, v3(1e-6f, 0.0f, 0.0f));
            p[2] = v3_add(at, v3(0.0f, 1e-6f, 1e-6f));
        }
        uint32_t ia = mesh_add_vertex(&m, p[0]);
        uint32_t ib = mesh_add_vertex(&m, p[1]);
        uint32_t ic = mesh_add_vertex(&m, p[2]);
        for (int i = 0; i < 1000; i++) {
            if (variant == 0 || i % 3 == 0)
                mesh_add_tri(&m, ia, ib, ic);
            else if (i % 3 == 1)
                mesh_add_tri(&m, ib, ic, ia);
            else
                mesh_add_tri(&m, ic, ia, ib);
        }
        struct bvh *bvh = build(&m);
        struct bvh_stats st = bvh_get_stats(bvh);
        cr_assert_eq(st.n_tris, 1000u);
        cr_assert_eq(st.n_nodes, 2 * st.n_leaves - 1);
        cr_assert_geq(st.n_leaves, 2u);   /* 1000 triangles are not one leaf */
        cr_assert_leq(st.max_depth, 12u); /* about log2(1000 / leaf size) */
        struct rng r = {6};
        int n_hits = 0;
        for (int i = 0; i < 500; i++) {
            float b1;
            float b2;
            rng_bary(&r, &b1, &b2);
            vec3 o = v3_add(p[0], v3_scale(rng_dir(&r), variant == 0 ? 3.0f : 1e-5f));
            struct ray ray = make_ray(o, v3_sub(tri_point(&m, 0, b1, b2), o), 0.0f, INFINITY);
            n_hits += expect_matches_brute(&m, bvh, &ray);
        }
        cr_assert_gt(n_hits, 400);
        bvh_free(bvh);
        mesh_free(&m);
    }
}

/* bvh.h: zero-area triangles (repeated vertices, collinear vertices, a point) are kept by the
 * build and never hit, even by rays aimed exactly at them; a proper triangle among them is. */
Test(bvh, zero_area_triangles_never_hit)
{
    struct mesh m = {0};
    mesh_add_tri_pos(&m, v3(0, 0, 0), v3(1, 1, 1), v3(2, 2, 2));             /* collinear */
    mesh_add_tri_pos(&m, v3(0.5f, 0, 0), v3(0.5f, 0, 0), v3(0.5f, 1, 0.5f)); /* repeated */
    mesh_add_tri_pos(&m, v3(1, 0, 1), v3(1, 0, 1), v3(1, 0, 1));             /* a point */
    /* p, 2 p, 4 p: collinear exactly, since scaling by 2 is exact */
    mesh_add_tri_pos(&m, v3(0.1f, 0.3f, 0.7f), v3(0.2f, 0.6f, 1.4f), v3(0.4f, 1.2f, 2.8f));
    mesh_add_tri_pos(&m, v3(3, 0, 0), v3(4, 0, 0), v3(3, 1, 0)); /* the one real triangle */
    struct bvh *bvh = build(&m);
    struct bvh_stats st = bvh_get_stats(bvh);
    cr_assert_eq(st.n_tris, 5u);
    struct rng r = {7};
    for (int i = 0; i < 4000; i++) {
        uint32_t prim = (uint32_t)(i % 4);
        float s = rng_float(&r);
        vec3 p0 = tri_vertex(&m, prim, 0);
        vec3 p2 = tri_vertex(&m, prim, 2);
        vec3 target = i % 8 < 4 ? v3_add(p0, v3_scale(v3_sub(p2, p0), s)) : p0;
        vec3 o = v3_add(target, v3_scale(rng_dir(&r), rng_range(&r, 0.01f, 5.0f)));
        struct ray ray = make_ray(o, v3_sub(target, o), 0.0f, INFINITY);
        struct bvh_hit hit;
        if (bvh_intersect(bvh, &ray, &hit))
            cr_assert_eq(hit.prim_idx, 4u, "zero-area triangle %u was hit", hit.prim_idx);
        if (bvh_intersect_brute(bvh, &ray, &hit))
            cr_assert_eq(hit.prim_idx, 4u);
        expect_matches_brute(&m, bvh, &ray);
    }
    struct ray at_real = make_ray(v3(3.2f, 0.2f, 1.0f), v3(0, 0, -1), 0.0f, INFINITY);
    struct bvh_hit hit;
    cr_assert(bvh_intersect(bvh, &at_real, &hit));
    cr_assert_eq(hit.prim_idx, 4u);
    bvh_free(bvh);

    /* only degenerate triangles: builds, never hits */
    m.n_tris = 4;
    bvh = build(&m);
    for (int i = 0; i < 1000; i++) {
        struct ray ray = make_ray(rng_in_box(&r, -1, 3), rng_dir(&r), 0.0f, INFINITY);
        cr_assert_not(bvh_intersect(bvh, &ray, &hit));
        cr_assert_not(bvh_occluded(bvh, &ray));
    }
    bvh_free(bvh);
    mesh_free(&m);
}

/* ---- an axis-aligned flat grid: flat boxes, d_a == 0, origins on slab planes --------------------
 * PBRT 4e, ch. 6, "Conservative Ray-Bounds Intersections": with d.x == 0 the slab test meets
 * 0 * inf = NaN when o.x lies exactly on a box face; the ray must still find the grid. */

static void make_grid(struct mesh *m, int n_cells)
{
    float step = 2.0f / (float)n_cells; /* exact for powers of two */
    for (int i = 0; i <= n_cells; i++)
        for (int j = 0; j <= n_cells; j++)
            mesh_add_vertex(m, v3(-1.0f + step * (float)i, 0.0f, -1.0f + step * (float)j));
    uint32_t row = (uint32_t)n_cells + 1;
    for (uint32_t i = 0; i < (uint32_t)n_cells; i++) {
        for (uint32_t j = 0; j < (uint32_t)n_cells; j++) {
            uint32_t v00 = i * row + j;
            uint32_t v10 = (i + 1) * row + j;
            mesh_add_tri(m, v00, v10 + 1, v10);
            mesh_add_tri(m, v00, v00 + 1, v10 + 1);
        }
    }
}

Test(bvh, flat_axis_aligned_grid)
{
    struct mesh m = {0};
    make_grid(&m, 32);
    struct bvh *bvh = build(&m);
    struct rng r = {8};
    int n_hits = 0;
    for (int i = 0; i < 6000; i++) {
        /* x, z on grid lines (box faces), on vertices, or anywhere in [-1, 1] */
        float x = (i % 3 == 0) ? -1.0f + (float)(rng_next(&r) % 33) / 16.0f : rng_range(&r, -1, 1);
        float z = (i % 3 != 2) ? -1.0f + (float)(rng_next(&r) % 33) / 16.0f : rng_range(&r, -1, 1);
        struct ray ray;
        struct bvh_hit hit;
        switch (i % 6) {
        case 0: /* straight down: d.x == d.z == 0 */
        case 1: /* straight up from below, d.x == -0 */
            ray = make_ray(v3(x, i % 6 == 0 ? 1.0f : -1.0f, z),
                           v3(i % 6 == 0 ? 0.0f : -0.0f, i % 6 == 0 ? -1.0f : 1.0f, -0.0f), 0.0f,
                           INFINITY);
            cr_assert(bvh_intersect(bvh, &ray, &hit), "vertical ray at x %a z %a missed", x, z);
            cr_assert_float_eq(hit.t, 1.0f, 1e-6f);
            cr_assert(bvh_occluded(bvh, &ray));
            break;
        case 2: /* d.x == 0: oblique in the yz plane */
            ray = make_ray(v3(x, 0.5f, z), v3(0.0f, -0.8f, rng_range(&r, -0.6f, 0.6f)), 0.0f,
                           INFINITY);
            break;
        case 3: /* d.z == 0 */
            ray = make_ray(v3(x, 0.5f, z), v3(rng_range(&r, -0.6f, 0.6f), -0.8f, 0.0f), 0.0f,
                           INFINITY);
            break;
        case 4: /* random from above */
            ray = make_ray(v3(x, rng_range(&r, 0.1f, 2), z), rng_dir(&r), 0.0f, INFINITY);
            break;
        default: /* lying in the plane y = 0: det == 0 for every triangle, no hit */
            ray = make_ray(v3(x, 0.0f, z), i % 12 == 5 ? v3(1, 0, 0) : v3(0.6f, 0, -0.8f), 0.0f,
                           INFINITY);
            cr_assert_not(bvh_intersect(bvh, &ray, &hit));
            break;
        }
        n_hits += expect_matches_brute(&m, bvh, &ray);
    }
    cr_assert_gt(n_hits, 3000);
    bvh_free(bvh);
    mesh_free(&m);
}

/* ---- rays that start on a surface ------------------------------------------------------------
 * Behaviour (documented, not a bug): a ray whose origin lies on a triangle (to rounding) may
 * report that triangle at t ~ 0: the origin can be on either side of the plane, and only
 * t == 0 exactly (cut by t > t_min = 0) or t <= delta_t (PBRT 4e, ch. 6, "Avoiding Intersections
 * Behind Ray Origins") are excluded.  The integrator therefore spawns rays with
 * offset_ray_origin (PBRT 4e, ch. 6, "Robust Spawned Ray Origins"), which the next test checks. */
Test(bvh, ray_from_surface_with_t_min_zero)
{
    /* exactly on the plane y = 0, y the major axis: the computed t is exactly 0, never a hit */
    struct mesh grid = {0};
    make_grid(&grid, 8);
    struct bvh *bvh = build(&grid);
    struct rng r = {9};
    struct bvh_hit hit;
    for (int i = 0; i < 2000; i++) {
        vec3 o = v3(rng_range(&r, -0.99f, 0.99f), 0.0f, rng_range(&r, -0.99f, 0.99f));
        vec3 d = v3(rng_range(&r, -0.5f, 0.5f), i % 2 ? 1.0f : -1.0f, rng_range(&r, -0.5f, 0.5f));
        struct ray ray = make_ray(o, d, 0.0f, INFINITY);
        cr_assert_not(bvh_intersect(bvh, &ray, &hit));
    }
    bvh_free(bvh);
    mesh_free(&grid);

    /* on random triangles: any report of the own triangle is at t ~ 0 */
    struct mesh m = {0};
    make_soup(&m, 200, 10);
    bvh = build(&m);
    int n_self = 0;
    for (int i = 0; i < 20000; i++) {
        uint32_t prim = (uint32_t)(rng_next(&r) % m.n_tris);
        float b1;
        float b2;
        rng_bary(&r, &b1, &b2);
        vec3 p = tri_point(&m, prim, b1, b2);
        vec3 w = rng_dir(&r);
        struct ray ray = make_ray(p, w, 0.0f, INFINITY);
        if (bvh_intersect(bvh, &ray, &hit) && hit.prim_idx == prim) {
            /* the origin is within rounding of the plane: |t (w . n)| is its distance */
            vec3 p0 = tri_vertex(&m, prim, 0);
            vec3 n = v3_normalize(
                v3_cross(v3_sub(tri_vertex(&m, prim, 1), p0), v3_sub(tri_vertex(&m, prim, 2), p0)));
            cr_assert_lt(fabsf(hit.t * v3_dot(w, n)), 1e-6f, "self hit off the plane: t %g", hit.t);
            n_self++;
        }
    }
    cr_log_info("ray_from_surface: %d of 20000 rays re-hit their own triangle at t ~ 0", n_self);
    bvh_free(bvh);
    mesh_free(&m);
}

/* PBRT 4e, ch. 6, "Robust Spawned Ray Origins": p from barycentrics carries the error bound
 * p_error = gamma(7) (|b0 p0| + |b1 p1| + |b2 p2|); offset_ray_origin moves it off the plane by
 * that bound, and with the t > delta_t check of "Avoiding Intersections Behind Ray Origins" the
 * spawned ray does not hit its own triangle: at scales 1e-4 to 1e4, for needles, and for
 * grazing directions down to |w . n| = 1e-5. */
static void check_offset_origins(vec3 location, float size, uint64_t seed)
{
    struct rng r = {seed};
    int n_rays = 0;
    for (int i = 0; i < 4000; i++) {
        struct mesh m = {0};
        vec3 q0 = v3_add(location, v3_scale(rng_in_box(&r, -1, 1), size));
        vec3 q1 = v3_add(location, v3_scale(rng_in_box(&r, -1, 1), size));
        vec3 q2 = v3_add(location, v3_scale(rng_in_box(&r, -1, 1), size));
        if (i % 4 == 0) { /* a needle: q2 near the segment q0 q1, 1e-3 of the size off it */
            q2 = v3_add(q0, v3_scale(v3_sub(q1, q0), rng_float(&r)));
            q2 = v3_add(q2, v3_scale(rng_in_box(&r, -1, 1), 1e-3f * size));
        }
        mesh_add_tri_pos(&m, q0, q1, q2);
        vec3 p0 = tri_vertex(&m, 0, 0);
        vec3 p1 = tri_vertex(&m, 0, 1);
        vec3 p2 = tri_vertex(&m, 0, 2);
        vec3 cross = v3_cross(v3_sub(p1, p0), v3_sub(p2, p0));
        if (v3_is_zero(cross) || !v3_is_finite(cross)) {
            mesh_free(&m);
            continue;
        }
        vec3 n = v3_normalize(cross);
        struct bvh *bvh = build(&m);
        for (int j = 0; j < 8; j++) {
            float b1;
            float b2;
            rng_bary(&r, &b1, &b2);
            float b0 = 1.0f - b1 - b2;
            vec3 p = tri_point(&m, 0, b1, b2);
            vec3 p_error = barycentric_error(p0, p1, p2, b0, b1, b2);
            vec3 w = rng_dir(&r);
            if (j >= 6) { /* grazing: nearly in the plane */
                vec3 tangent = v3_normalize(v3_cross(n, w));
                w = v3_normalize(v3_add(tangent, v3_scale(n, rng_range(&r, -1e-3f, 1e-3f))));
            }
            if (fabsf(v3_dot(w, n)) < 1e-5f)
                continue; /* below the angular error of the computed normal itself */
            vec3 o = offset_ray_origin(p, p_error, n, w);
            struct ray ray = make_ray(o, w, 0.0f, INFINITY);
            struct bvh_hit hit;
            cr_assert_not(bvh_intersect(bvh, &ray, &hit),
                          "self hit at t %g: size %g at (%g %g %g), w.n %g", hit.t, size,
                          location.x, location.y, location.z, v3_dot(w, n));
            cr_assert_not(bvh_occluded(bvh, &ray));
            n_rays++;
        }
        bvh_free(bvh);
        mesh_free(&m);
    }
    cr_assert_gt(n_rays, 30000);
}

Test(bvh, offset_origin_does_not_rehit_own_triangle)
{
    check_offset_origins(v3(0, 0, 0), 1.0f, 11);
    check_offset_origins(v3(1e4f, -1e4f, 1e4f), 1.0f, 12);
    check_offset_origins(v3(1e4f, 1e4f, -1e4f), 1e4f, 13);
    check_offset_origins(v3(1e-4f, 1e-4f, 1e-4f), 1e-4f, 14);
    check_offset_origins(v3(0, 0, 0), 1e-4f, 15);
    check_offset_origins(v3(-1e4f, 0, 3e3f), 1e-2f, 16);
}

/* The same on a closed mesh far from the origin: a ray spawned outward or inward from a point of
 * one face never reports that face. */
Test(bvh, offset_origin_on_mesh)
{
    struct mesh m = {0};
    make_icosphere(&m, 3, v3(1e4f, -2e3f, 5e3f), 2.0f);
    struct bvh *bvh = build(&m);
    struct rng r = {17};
    int n_hits = 0;
    for (int i = 0; i < 20000; i++) {
        uint32_t prim = (uint32_t)(rng_next(&r) % m.n_tris);
        float b1;
        float b2;
        rng_bary(&r, &b1, &b2);
        float b0 = 1.0f - b1 - b2;
        vec3 p0 = tri_vertex(&m, prim, 0);
        vec3 p1 = tri_vertex(&m, prim, 1);
        vec3 p2 = tri_vertex(&m, prim, 2);
        vec3 p = tri_point(&m, prim, b1, b2);
        vec3 n = v3_normalize(v3_cross(v3_sub(p1, p0), v3_sub(p2, p0)));
        vec3 w = rng_dir(&r);
        if (v3_dot(w, n) == 0.0f)
            continue;
        vec3 o = offset_ray_origin(p, barycentric_error(p0, p1, p2, b0, b1, b2), n, w);
        struct ray ray = make_ray(o, w, 0.0f, INFINITY);
        struct bvh_hit hit;
        bool is_hit = bvh_intersect(bvh, &ray, &hit);
        if (is_hit)
            cr_assert_neq(hit.prim_idx, prim, "ray re-hit its own face at t %g", hit.t);
        /* inward rays (n points out) must hit the far side: the mesh is closed */
        if (v3_dot(w, n) < 0.0f)
            cr_assert(is_hit, "inward ray escaped the closed mesh");
        n_hits += is_hit;
    }
    cr_assert_gt(n_hits, 8000);
    bvh_free(bvh);
    mesh_free(&m);
}

/* ---- PBRT's Reintersect test, through the whole pipeline --------------------------------------
 * pbrt-v3/v4, tests/shapes.cpp, "Triangle, Reintersect": triangles whose coordinates are spread
 * log-uniformly over 1e-8 .. 1e8 (here with random signs), a ray from a point spread the same way
 * aimed at a point of the triangle, then rays spawned from the hit in every direction must not
 * hit the triangle again.  Here the hit point is mcpt's (shape_triangle_surface: the point in
 * double, its error its rounding) and the origin offset_ray_origin's; the BVH decides undecided
 * hits in double (bvh.c, "Watertight ray-triangle test").
 * Aimed rays: 4 per triangle, at b = 0.05 + 0.85 w (w uniform on the simplex) rounded to float.
 * The float ray (o, d = target - o) need not pass through that point, so "interior" is decided
 * on the ray itself: in double, it meets the plane at barycentrics each >= 0.05.  Every such ray
 * that passes its triangle's edges at least 2^-20 M inside, measured across the ray (M the
 * largest coordinate of the origin and vertices: the float inside test resolves about 2^-18 M),
 * must find its triangle, with t within 2^-10 of the exact one (the float test's accepted bound,
 * docs/theory.md); closer to an edge float may miss, and the count is logged (the float test
 * alone, rejecting t <= delta_t, found 544 of pbrt's 1000).  Spawned rays: 2000 per triangle
 * from the first aimed hit, 1000 into each hemisphere of its normal: no self-hit. */
static float log_uniform_signed(struct rng *r)
{
    float v = powf(10.0f, rng_range(r, -8.0f, 8.0f));
    return rng_float(r) < 0.5f ? -v : v;
}

static void cross_d(const double a[3], const double b[3], double c[3])
{
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
}

static double dot_d(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* In double: where the ray meets the plane of q (t, barycentrics b), and how far inside the
 * triangle's three edges it passes, measured across the ray, over the largest coordinate. */
static void ray_crossing(const vec3 q[3], const struct ray *ray, double *t, double b[3],
                         double *margin_rel)
{
    double p[3][3], o[3] = {ray->o.x, ray->o.y, ray->o.z}, d[3] = {ray->d.x, ray->d.y, ray->d.z};
    double m = fmax(fabs(o[0]), fmax(fabs(o[1]), fabs(o[2])));
    for (int k = 0; k < 3; k++)
        for (int a = 0; a < 3; a++) {
            p[k][a] = v3_get(q[k], a);
            m = fmax(m, fabs(p[k][a]));
        }
    double e1[3], e2[3], n[3], po[3];
    for (int a = 0; a < 3; a++) {
        e1[a] = p[1][a] - p[0][a];
        e2[a] = p[2][a] - p[0][a];
        po[a] = p[0][a] - o[a];
    }
    cross_d(e1, e2, n);
    *t = dot_d(n, po) / dot_d(n, d);
    double x[3], c1[3], c2[3];
    for (int a = 0; a < 3; a++)
        x[a] = o[a] + *t * d[a] - p[0][a];
    cross_d(x, e2, c1);
    cross_d(e1, x, c2);
    b[1] = dot_d(c1, n) / dot_d(n, n);
    b[2] = dot_d(c2, n) / dot_d(n, n);
    b[0] = 1.0 - b[1] - b[2];
    /* the vertices projected on a frame (ex, ey) across the unit ray direction u */
    double len = sqrt(dot_d(d, d)), u[3] = {d[0] / len, d[1] / len, d[2] / len};
    double axis[3] = {fabs(u[0]) > 0.9 ? 0.0 : 1.0, fabs(u[0]) > 0.9 ? 1.0 : 0.0, 0.0};
    double ex[3], ey[3], px[3], py[3];
    cross_d(u, axis, ex);
    double ex_len = sqrt(dot_d(ex, ex));
    for (int a = 0; a < 3; a++)
        ex[a] /= ex_len;
    cross_d(u, ex, ey);
    for (int k = 0; k < 3; k++) {
        double w[3] = {p[k][0] - o[0], p[k][1] - o[1], p[k][2] - o[2]};
        px[k] = dot_d(w, ex);
        py[k] = dot_d(w, ey);
    }
    double margin = INFINITY;
    for (int k = 0; k < 3; k++) {
        int k1 = (k + 1) % 3;
        double dx = px[k1] - px[k], dy = py[k1] - py[k];
        margin = fmin(margin, fabs(dx * py[k] - dy * px[k]) / sqrt(dx * dx + dy * dy));
    }
    *margin_rel = margin / m;
}

Test(bvh, reintersect_pbrt)
{
    struct rng r = {2024};
    int n_tris = 0, n_interior = 0, n_clear = 0, n_found = 0, n_spawned = 0;
    for (int i = 0; i < 1000; i++) {
        vec3 q[3];
        for (int k = 0; k < 3; k++)
            q[k] = v3(log_uniform_signed(&r), log_uniform_signed(&r), log_uniform_signed(&r));
        double e1[3], e2[3], n[3];
        for (int a = 0; a < 3; a++) {
            e1[a] = (double)v3_get(q[1], a) - v3_get(q[0], a);
            e2[a] = (double)v3_get(q[2], a) - v3_get(q[0], a);
        }
        cross_d(e1, e2, n);
        if (dot_d(n, n) == 0.0)
            continue; /* no area */
        struct mesh m = {0};
        mesh_add_tri_pos(&m, q[0], q[1], q[2]);
        struct bvh *bvh = build(&m);
        n_tris++;
        for (int j = 0; j < 4; j++) {
            float w1 = rng_float(&r), w2 = rng_float(&r);
            if (w1 + w2 > 1.0f) {
                w1 = 1.0f - w1;
                w2 = 1.0f - w2;
            }
            double b1 = 0.05 + 0.85 * w1, b2 = 0.05 + 0.85 * w2;
            float target[3];
            for (int a = 0; a < 3; a++)
                target[a] = (float)((1.0 - b1 - b2) * v3_get(q[0], a) + b1 * v3_get(q[1], a) +
                                    b2 * v3_get(q[2], a));
            vec3 o = v3(log_uniform_signed(&r), log_uniform_signed(&r), log_uniform_signed(&r));
            struct ray ray = make_ray(o, v3_sub(v3(target[0], target[1], target[2]), o), 0.0f,
                                      INFINITY);
            double t_exact, b[3], margin_rel;
            ray_crossing(q, &ray, &t_exact, b, &margin_rel);
            if (!(b[0] >= 0.05 && b[1] >= 0.05 && b[2] >= 0.05))
                continue;
            n_interior++;
            struct bvh_hit hit;
            bool is_hit = bvh_intersect(bvh, &ray, &hit);
            n_found += is_hit;
            if (margin_rel >= 0x1p-20) {
                n_clear++;
                cr_assert(is_hit, "triangle %d: a ray %g M inside its edges missed", i, margin_rel);
            }
            if (is_hit)
                cr_assert(fabs(hit.t - t_exact) <= 0x1p-10 * t_exact, "triangle %d: t %g, not %g",
                          i, hit.t, t_exact);
            if (!is_hit || j > 0)
                continue;
            /* rays leaving the hit, 1000 into each hemisphere of the geometric normal */
            struct surface sf = shape_triangle_surface(q, NULL, NULL, NULL, &ray, hit.t, hit.u,
                                                       hit.v, 0);
            for (int k = 0; k < 2000; k++) {
                vec3 w = rng_dir(&r);
                if ((v3_dot(w, sf.ng) < 0.0f) != (k % 2 == 1))
                    w = v3_neg(w);
                struct ray out = make_ray(offset_ray_origin(sf.p, sf.p_error, sf.ng, w), w, 0.0f,
                                          INFINITY);
                cr_assert_not(bvh_intersect(bvh, &out, &hit),
                              "triangle %d: self hit at t %g, w . ng %g", i, hit.t,
                              v3_dot(w, sf.ng));
                cr_assert_not(bvh_occluded(bvh, &out));
                n_spawned++;
            }
        }
        bvh_free(bvh);
        mesh_free(&m);
    }
    cr_log_info("reintersect: %d triangles; %d aimed rays cross an interior, %d of them found "
                "(all %d at least 2^-20 M inside); %d spawned rays, no self-hit",
                n_tris, n_interior, n_found, n_clear, n_spawned);
    cr_assert_gt(n_tris, 990);
    cr_assert_gt(n_clear, 1000);
    cr_assert_gt(n_spawned, 1900000);
}

/* ---- rays that leave a triangle (bvh_intersect_from) --------------------------------------------
 * A ray spawned from triangle `from` never reports it: every traversal (wide, binary, brute
 * force) skips it, and for rays spawned as the renderer spawns them (offset_ray_origin) that
 * changes nothing, since such a ray cannot meet its own flat triangle at t > 0.  Triangle soup
 * (crossing and touching triangles) plus an icosphere: points at random barycentrics, rays into
 * both hemispheres, unbounded and shadow-like (t_max = 0.5).  Rays aimed at a triangle from
 * outside with that triangle as `from` show that the skip is real: they find another triangle
 * or none, in every traversal alike. */
static bool same_hit(bool a, const struct bvh_hit *ha, bool b, const struct bvh_hit *hb)
{
    return a == b && (!a || (ha->prim_idx == hb->prim_idx && same_bits(ha->t, hb->t) &&
                             same_bits(ha->u, hb->u) && same_bits(ha->v, hb->v)));
}

Test(bvh, spawned_rays_skip_their_triangle)
{
    struct mesh m = {0};
    make_icosphere(&m, 3, v3(0.2f, -0.1f, 0.3f), 0.6f); /* first: it subdivides all of m */
    make_soup(&m, 3000, 77);
    struct bvh *both = build(&m);
    /* one layout each: bvh_intersect_from takes the wide one where there is one */
    struct bvh_build_options opt = {1, BVH_LAYOUT_WIDE, BVH_QUALITY_DEFAULT};
    struct bvh *wide = bvh_build_with(m.positions, m.indices, m.n_tris, &opt);
    opt.layouts = BVH_LAYOUT_BINARY;
    struct bvh *binary = bvh_build_with(m.positions, m.indices, m.n_tris, &opt);
    cr_assert(wide && binary);
    struct rng r = {91};
    int n_rays = 0, n_hits = 0, n_own_first = 0;
    for (uint32_t prim = 0; prim < m.n_tris; prim += 3) {
        struct surface sf = random_surface(&m, prim, &r);
        for (int k = 0; k < 4; k++) {
            vec3 w = rng_dir(&r);
            if ((v3_dot(w, sf.ng) < 0.0f) != (k % 2 == 1))
                w = v3_neg(w);
            struct ray out = make_ray(offset_ray_origin(sf.p, sf.p_error, sf.ng, w), w, 0.0f,
                                      k < 2 ? INFINITY : 0.5f);
            struct bvh_hit h_plain, h_from, h_bin, h_brute, h_wide_brute;
            bool plain = bvh_intersect(both, &out, &h_plain);
            bool from = bvh_intersect_from(both, &out, prim, &h_from);
            bool bin = bvh_intersect_from(binary, &out, prim, &h_bin);
            cr_assert(same_hit(from, &h_from, bin, &h_bin), "triangle %u: wide vs binary", prim);
            bool brute = bvh_intersect_brute_from(both, &out, prim, &h_brute);
            bool wide_brute = bvh_intersect_brute_from(wide, &out, prim, &h_wide_brute);
            cr_assert(same_hit(plain, &h_plain, from, &h_from),
                      "triangle %u: spawned ray differs with from (%d %d)", prim, plain, from);
            cr_assert(same_hit(from, &h_from, brute, &h_brute), "triangle %u: wide vs brute", prim);
            cr_assert(same_hit(from, &h_from, wide_brute, &h_wide_brute),
                      "triangle %u: wide vs brute over the wide leaves", prim);
            cr_assert(!from || h_from.prim_idx != prim);
            bool occ = bvh_occluded_from(both, &out, prim);
            cr_assert_eq(occ, bvh_occluded(both, &out), "triangle %u: occlusion", prim);
            cr_assert_eq(occ, from, "triangle %u: occluded %d, hit %d", prim, occ, from);
            cr_assert_eq(bvh_occluded_from(binary, &out, prim), occ);
            n_rays++;
            n_hits += from;
        }
        /* aimed at the triangle from outside, the triangle being `from`: it is skipped */
        vec3 o = v3_add(sf.p, v3_scale(sf.ng, 0.01f));
        struct ray in = make_ray(o, v3_sub(sf.p, o), 0.0f, INFINITY);
        struct bvh_hit h_plain, h_from, h_bin, h_brute;
        bool plain = bvh_intersect(both, &in, &h_plain);
        bool from = bvh_intersect_from(both, &in, prim, &h_from);
        bool bin = bvh_intersect_from(binary, &in, prim, &h_bin);
        bool brute = bvh_intersect_brute_from(both, &in, prim, &h_brute);
        cr_assert(same_hit(from, &h_from, brute, &h_brute), "triangle %u: aimed, wide vs brute",
                  prim);
        cr_assert(same_hit(from, &h_from, bin, &h_bin), "triangle %u: aimed, wide vs binary", prim);
        cr_assert_eq(bvh_occluded_from(both, &in, prim), from);
        cr_assert_eq(bvh_occluded_from(binary, &in, prim), from);
        cr_assert(!from || h_from.prim_idx != prim);
        if (plain && h_plain.prim_idx == prim) {
            n_own_first++;
            cr_assert(!from || h_from.t >= h_plain.t);
        }
    }
    cr_log_info("spawned rays: %d, %d of them hit another triangle; %d aimed rays found their "
                "triangle first, and skipped it with from",
                n_rays, n_hits, n_own_first);
    cr_assert_gt(n_hits, n_rays / 10);
    cr_assert_gt(n_own_first, 500);
    bvh_free(binary);
    bvh_free(wide);
    bvh_free(both);
    mesh_free(&m);
}

/* ---- watertightness on a closed mesh ----------------------------------------------------------
 * Woop et al. 2013: rays aimed exactly at the mesh's vertices and edge midpoints, from the
 * centre, from off-centre points inside and from outside, never escape. */
static void probe_watertight_mesh(const struct mesh *mesh, vec3 centre, float radius)
{
    struct mesh m = *mesh;
    check_closed(&m);
    struct bvh *bvh = build(&m);
    /* targets: every vertex once, every edge midpoint once (edge a-b with a < b) */
    uint32_t n_targets = 0;
    vec3 *targets = malloc((m.n_positions + 3 * (size_t)m.n_tris) * sizeof *targets);
    cr_assert_not_null(targets);
    for (uint32_t i = 0; i < m.n_positions; i++)
        targets[n_targets++] = m.positions[i];
    for (uint32_t i = 0; i < 3 * m.n_tris; i++) {
        uint32_t a = m.indices[i];
        uint32_t b = m.indices[i % 3 == 2 ? i - 2 : i + 1];
        if (a < b)
            targets[n_targets++] = v3_scale(v3_add(m.positions[a], m.positions[b]), 0.5f);
    }
    const vec3 offsets[5] = {v3(0, 0, 0), v3(0.1f, -0.2f, 0.05f), v3(-0.3f, 0.25f, 0.4f),
                             v3(0.0f, 0.0f, 0.85f), v3(0.55f, -0.55f, -0.3f)};
    int n_rays = 0;
    for (int k = 0; k < 6; k++) {
        vec3 o = k < 5 ? v3_add(centre, v3_scale(offsets[k], radius))
                       : v3_add(centre, v3(3.0f * radius, 2.0f * radius, -2.5f * radius));
        for (uint32_t i = 0; i < n_targets; i++) {
            struct ray ray = make_ray(o, v3_sub(targets[i], o), 0.0f, INFINITY);
            struct bvh_hit hit;
            bool is_hit = bvh_intersect(bvh, &ray, &hit);
            if (k == 5 && !is_hit)
                continue; /* from outside, a target on the silhouette is only grazed */
            cr_assert(is_hit, "ray to %s %u escaped (origin %d)",
                      i < m.n_positions ? "vertex" : "edge midpoint", i, k);
            expect_close_to_brute(&m, bvh, &ray);
            if (k < 5) /* from inside, the first hit is the target itself: t = 1 */
                cr_assert_float_eq(hit.t, 1.0f, 1e-4f);
            n_rays++;
        }
    }
    cr_assert_eq(n_targets, m.n_positions + 3 * m.n_tris / 2);
    cr_assert_gt(n_rays, 5 * (int)n_targets);
    free(targets);
    bvh_free(bvh);
}

/* The icosphere of `levels` subdivisions, centre and radius: convex, so a ray from inside first
 * meets the target it is aimed at. */
static void probe_watertight(vec3 centre, float radius, int levels)
{
    struct mesh m = {0};
    make_icosphere(&m, levels, centre, radius);
    probe_watertight_mesh(&m, centre, radius);
    mesh_free(&m);
}

Test(bvh, watertight_closed_mesh)
{
    probe_watertight(v3(0, 0, 0), 1.0f, 3);
    probe_watertight(v3(100.0f, -200.0f, 50.0f), 10.0f, 2);
    probe_watertight(v3(0.001f, 0.002f, -0.001f), 1e-3f, 2);
}

/* ---- occlusion, empty BVH, stats ------------------------------------------------------------- */

/* bvh.h: bvh_occluded reports a hit in (t_min, t_max) exactly when bvh_intersect finds one. */
Test(bvh, occluded_agrees_with_intersect)
{
    struct mesh m = {0};
    make_soup(&m, 2000, 18);
    struct bvh *bvh = build(&m);
    struct rng r = {19};
    int n_occluded = 0;
    for (int i = 0; i < 6000; i++) {
        float t_max = i % 5 == 0 ? INFINITY : rng_range(&r, 0.0f, 3.0f);
        struct ray ray = make_ray(rng_in_box(&r, -2, 2), rng_dir(&r), 0.0f, t_max);
        struct bvh_hit hit;
        bool is_hit = bvh_intersect(bvh, &ray, &hit);
        bool occluded = bvh_occluded(bvh, &ray);
        cr_assert_eq(occluded, is_hit);
        n_occluded += occluded;
    }
    cr_assert_gt(n_occluded, 1000);
    cr_assert_lt(n_occluded, 5500);
    bvh_free(bvh);
    mesh_free(&m);
}

/* bvh.h: n_tris == 0 gives a valid BVH that nothing hits. */
Test(bvh, empty_bvh)
{
    struct bvh *bvh = bvh_build(NULL, NULL, 0, 1);
    cr_assert_not_null(bvh);
    struct ray ray = make_ray(v3(0, 0, 0), v3(0, 0, 1), 0.0f, INFINITY);
    struct bvh_hit hit;
    cr_assert_not(bvh_intersect(bvh, &ray, &hit));
    cr_assert_not(bvh_intersect_brute(bvh, &ray, &hit));
    cr_assert_not(bvh_occluded(bvh, &ray));
    struct bvh_packet p;
    struct bvh_packet_hit ph;
    packet_of(&p, &ray, -1);
    cr_assert_eq(bvh_intersect_packet(bvh, &p, 0xFFu, &ph), 0u);
    cr_assert_eq(bvh_occluded_packet(bvh, &p, 0xFFu), 0u);
    cr_assert_eq(bvh_layouts(bvh), 0u);
    struct bvh_stats st = bvh_get_stats(bvh);
    cr_assert_eq(st.n_tris, 0u);
    cr_assert_eq(st.n_nodes, 0u);
    cr_assert_eq(st.n_leaves, 0u);
    cr_assert_eq(st.n_wide_nodes, 0u);
    cr_assert_eq(st.sah_cost, 0.0);
    bvh_free(bvh);
    bvh_free(NULL);
}

/* Stats: a binary tree has 2 L - 1 nodes; depth within bounds; the root-normalised SAH cost
 * (Wald 2007's cost model over the whole tree) is below that of one big leaf (n C_isect) and
 * at least one triangle test; one triangle is one leaf.  bytes counts what each layout keeps:
 * bvh_build keeps only the wide one (nodes of 256 bytes, 9 floats and an index per triangle). */
Test(bvh, stats_are_consistent)
{
    struct mesh m = {0};
    make_soup(&m, 2000, 20);
    struct bvh *bvh = build(&m);
    struct bvh_stats st = bvh_get_stats(bvh);
    cr_assert_eq(st.n_tris, 2000u);
    cr_assert_eq(st.n_nodes, 2 * st.n_leaves - 1);
    cr_assert_geq(st.max_depth, 8u); /* at least log2(n_leaves) with n_leaves >= 2000 / 8 */
    cr_assert_leq(st.max_depth, 64u);
    cr_assert_gt(st.sah_cost, 1.0);
    cr_assert_lt(st.sah_cost, 200.0);
    cr_assert_geq(st.binary_bytes,
                  st.n_nodes * sizeof(struct bvh_node) + 2000 * (9 * sizeof(float)));
    cr_assert_eq(st.bytes, st.binary_bytes + st.wide_bytes);
    cr_assert_geq(st.build_ms, st.convert_ms);
    /* a wide node holds up to 8 children, so a tree of L leaves has at least (L - 1) / 7 */
    cr_assert_geq(st.n_wide_nodes, (st.n_wide_leaves - 1) / 7);
    cr_assert_leq(st.n_wide_leaves, st.n_leaves); /* leaves merge, never split (leaves <= 8) */
    cr_assert_geq(st.n_wide_leaves, 2000u / 8);
    bvh_free(bvh);

    bvh = bvh_build(m.positions, m.indices, m.n_tris, 1);
    st = bvh_get_stats(bvh);
    cr_assert_eq(bvh_layouts(bvh), (unsigned)BVH_LAYOUT_WIDE);
    cr_assert_eq(st.binary_bytes, 0u);
    cr_assert_eq(st.bytes, st.wide_bytes);
    cr_assert_geq(st.bytes, st.n_wide_nodes * 256 + 2000 * (9 * sizeof(float) + 4));
    cr_assert_lt(st.bytes, 2000u * 100u);
    bvh_free(bvh);

    m.n_tris = 1;
    bvh = build(&m);
    st = bvh_get_stats(bvh);
    cr_assert_eq(st.n_nodes, 1u);
    cr_assert_eq(st.n_leaves, 1u);
    cr_assert_eq(st.max_depth, 0u);
    cr_assert_gt(st.sah_cost, 0.0);
    cr_assert_eq(st.n_wide_nodes, 1u);
    cr_assert_eq(st.n_wide_leaves, 1u);
    bvh_free(bvh);
    mesh_free(&m);
}

/* ---- the build ------------------------------------------------------------------------------- */

/* bvh.c's BVH_UNBINNED_LEAF_TRIS: a node of at most 6 triangles is a leaf, even where the SAH
 * would split it (tiny triangles far apart: two children cost far less than their parent); one
 * of 7 such triangles is split.  Every triangle is still found by a ray aimed at its centre. */
Test(bvh, small_nodes_are_leaves)
{
    for (uint32_t n = 1; n <= 8; n++) {
        struct mesh m = {0};
        for (uint32_t i = 0; i < n; i++) {
            vec3 c = v3((float)(i % 2) * 100.0f, (float)(i / 2 % 2) * 100.0f,
                        (float)(i / 4) * 100.0f);
            mesh_add_tri_pos(&m, c, v3_add(c, v3(0.1f, 0.0f, 0.0f)),
                             v3_add(c, v3(0.0f, 0.1f, 0.0f)));
        }
        struct bvh *bvh = build(&m);
        struct bvh_stats st = bvh_get_stats(bvh);
        if (n <= 6)
            cr_assert_eq(st.n_nodes, 1u, "%u triangles: one leaf, got %u nodes", n, st.n_nodes);
        else
            cr_assert_gt(st.n_nodes, 1u, "%u triangles far apart are split", n);
        for (uint32_t i = 0; i < n; i++) {
            vec3 p = tri_point(&m, i, 1.0f / 3.0f, 1.0f / 3.0f);
            struct ray ray = make_ray(v3_add(p, v3(0.0f, 0.0f, 1.0f)), v3(0.0f, 0.0f, -1.0f), 0.0f,
                                      INFINITY);
            for (int layout = 0; layout < 2; layout++) {
                struct bvh_hit hit;
                enum bvh_layout l = layout ? BVH_LAYOUT_BINARY : BVH_LAYOUT_WIDE;
                cr_assert(bvh_intersect_layout(bvh, l, &ray, &hit), "n %u, triangle %u missed", n,
                          i);
                cr_assert_eq(hit.prim_idx, i);
            }
        }
        bvh_free(bvh);
        mesh_free(&m);
    }
}

/* bvh.h: the tree is the same for every thread count (each node's split depends only on its own
 * refs; parallel binning merges exact box unions and counts): same stats to the bit and the
 * same hit, t and prim_idx for every ray.  70000 triangles, above the parallel threshold. */
Test(bvh, build_is_independent_of_thread_count)
{
    struct mesh m = {0};
    make_soup(&m, 70000, 40);
    struct bvh *ref = build(&m);
    struct bvh_stats st_ref = bvh_get_stats(ref);
    struct rng r = {41};
    struct ray rays[2000];
    for (int i = 0; i < 2000; i++)
        rays[i] = make_ray(rng_in_box(&r, -2, 2), rng_dir(&r), 0.0f, INFINITY);
    /* 2, 3: the top nodes' waves share an odd count of threads; 5, 8: waves of several nodes,
     * each with a share of the threads (bvh.c, build_tree) */
    static const int thread_counts[] = {2, 3, 5, 8};
    for (size_t c = 0; c < sizeof thread_counts / sizeof thread_counts[0]; c++) {
        int n_threads = thread_counts[c];
        struct bvh_build_options opt = {n_threads, BVH_LAYOUT_BINARY | BVH_LAYOUT_WIDE,
                                        BVH_QUALITY_DEFAULT};
        struct bvh *bvh = bvh_build_with(m.positions, m.indices, m.n_tris, &opt);
        cr_assert_not_null(bvh);
        struct bvh_stats st = bvh_get_stats(bvh);
        cr_assert_eq(st.n_threads, n_threads);
        cr_assert_eq(st.n_nodes, st_ref.n_nodes);
        cr_assert_eq(st.n_leaves, st_ref.n_leaves);
        cr_assert_eq(st.max_depth, st_ref.max_depth);
        cr_assert_eq(st.sah_cost, st_ref.sah_cost);
        cr_assert_eq(st.n_refs, st_ref.n_refs);
        cr_assert_eq(st.n_wide_nodes, st_ref.n_wide_nodes);
        cr_assert_eq(st.n_wide_leaves, st_ref.n_wide_leaves);
        cr_assert_eq(st.bytes, st_ref.bytes);
        cr_assert_eq(bvh_layout_hash(bvh), bvh_layout_hash(ref), "%d threads: every byte",
                     n_threads);
        /* rays aimed at every 5th triangle: the wide layout, which the threads write by
         * subtrees, gives the same hits as the one written by one thread */
        for (uint32_t k = 0; k < m.n_tris; k += 5) {
            vec3 p = tri_point(&m, k, 1.0f / 3.0f, 1.0f / 3.0f);
            struct ray ray = make_ray(v3_add(p, v3(0.0f, 0.0f, 3.0f)), v3(0.0f, 0.0f, -1.0f), 0.0f,
                                      INFINITY);
            struct bvh_hit a;
            struct bvh_hit b;
            bool hit_a = bvh_intersect(ref, &ray, &a);
            cr_assert(hit_a, "triangle %u: its ray hits something", k);
            cr_assert(bvh_intersect(bvh, &ray, &b) && same_bits(a.t, b.t) &&
                          a.prim_idx == b.prim_idx,
                      "%d threads, triangle %u", n_threads, k);
        }
        for (int i = 0; i < 2000; i++) {
            struct bvh_hit a;
            struct bvh_hit b;
            bool hit_a = bvh_intersect(ref, &rays[i], &a);
            cr_assert_eq(bvh_intersect(bvh, &rays[i], &b), hit_a);
            if (hit_a)
                cr_assert(same_bits(a.t, b.t) && a.prim_idx == b.prim_idx);
            hit_a = bvh_intersect_layout(ref, BVH_LAYOUT_BINARY, &rays[i], &a);
            cr_assert_eq(bvh_intersect_layout(bvh, BVH_LAYOUT_BINARY, &rays[i], &b), hit_a);
            if (hit_a)
                cr_assert(same_bits(a.t, b.t) && a.prim_idx == b.prim_idx);
        }
        bvh_free(bvh);
    }
    bvh_free(ref);
    mesh_free(&m);
}

/* bvh_layout_hash, which the test above and bench/raybench rely on to say two builds made the
 * same trees: the same build gives the same hash, and a BVH without the binary layout, or a wide
 * layout that differs by one vertex, another. */
Test(bvh, layout_hash_tells_trees_apart)
{
    struct mesh m = {0};
    make_soup(&m, 3000, 7);
    struct bvh *a = build(&m);
    struct bvh *b = build(&m);
    cr_assert_eq(bvh_layout_hash(a), bvh_layout_hash(b));
    struct bvh_build_options wide_only = {1, BVH_LAYOUT_WIDE, BVH_QUALITY_DEFAULT};
    struct bvh *c = bvh_build_with(m.positions, m.indices, m.n_tris, &wide_only);
    cr_assert_not_null(c);
    cr_assert_neq(bvh_layout_hash(c), bvh_layout_hash(a));
    m.positions[m.indices[0]].x = nextafterf(m.positions[m.indices[0]].x, INFINITY);
    struct bvh *d = bvh_build_with(m.positions, m.indices, m.n_tris, &wide_only);
    cr_assert_not_null(d);
    cr_assert_neq(bvh_layout_hash(d), bvh_layout_hash(c), "one vertex moved by one float step");
    bvh_free(a);
    bvh_free(b);
    bvh_free(c);
    bvh_free(d);
    mesh_free(&m);
}

/* bvh.c: a node's box is the union of its bins' boxes, and the partition must send every ref to
 * the side whose bins hold it (the one bin formula, centre_bins); a ref on the wrong side would
 * lie outside its node's box.  So a ray aimed at each triangle from 1e-3 above its centre finds
 * it (or a triangle nearer still), in both layouts, for the binned build on one thread and on
 * two (70000 triangles: the top nodes' binning is shared and merged) and the spatial build.
 * Fails when a side's box takes one bin too few (bins 0..bin - 1). */
Test(bvh, every_triangle_is_found_by_a_ray_aimed_at_it)
{
    struct mesh m = {0};
    make_soup(&m, 70000, 43);
    const enum bvh_quality qualities[2] = {BVH_QUALITY_BINNED, BVH_QUALITY_SPATIAL};
    for (int q = 0; q < 2; q++) {
        for (int n_threads = 1; n_threads <= 2 - q; n_threads++) { /* spatial: one thread */
            struct bvh_build_options opt = {n_threads, BVH_LAYOUT_BINARY | BVH_LAYOUT_WIDE,
                                            qualities[q]};
            struct bvh *bvh = bvh_build_with(m.positions, m.indices, m.n_tris, &opt);
            cr_assert_not_null(bvh);
            uint32_t n_aimed = 0;
            for (uint32_t i = 0; i < m.n_tris; i++) {
                vec3 p[3];
                for (int k = 0; k < 3; k++)
                    p[k] = m.positions[m.indices[3 * i + (uint32_t)k]];
                vec3 n = v3_cross(v3_sub(p[1], p[0]), v3_sub(p[2], p[0]));
                float len = v3_length(n);
                if (!(len > 1e-6f))
                    continue; /* a sliver: its normal is not worth aiming along */
                n = v3_scale(n, 1.0f / len);
                vec3 c = v3_scale(v3_add(v3_add(p[0], p[1]), p[2]), 1.0f / 3.0f);
                struct ray ray = make_ray(v3_add(c, v3_scale(n, 1e-3f)), v3_neg(n), 0.0f, INFINITY);
                /* the binary reference, slower, on every fourth triangle */
                for (int how = WIDE; how <= (i % 4 == 0 ? BINARY : WIDE); how++) {
                    struct bvh_hit hit;
                    bool is_hit = trace_with(bvh, (enum traversal)how, &ray, &hit);
                    cr_assert(is_hit && (hit.prim_idx == i || hit.t <= 1.001e-3f),
                              "%s build, %d thread(s), %s traversal: triangle %u not found "
                              "(hit %d, prim %u, t %g)",
                              q == 0 ? "binned" : "spatial", n_threads, traversal_names[how], i,
                              is_hit, hit.prim_idx, (double)hit.t);
                }
                n_aimed++;
            }
            cr_assert_gt(n_aimed, 69000u);
            bvh_free(bvh);
        }
    }
    mesh_free(&m);
}

/* ---- spatial splits (Stich, Friedrich, Dietrich 2009) ----------------------------------------
 * A spatial split cuts triangles: each part keeps the triangle, with a box that must contain the
 * part of it on its side of the plane (bvh.c, "Spatial splits").  A box that lost a sliver of
 * its triangle would let rays through that part; these tests aim rays at the long triangles
 * such splits cut. */

/* n long thin triangles ("sticks", length 1.5, width 0.02, random directions) in [-1, 1]^3:
 * object splits leave their boxes overlapping, so spatial splits cut them. */
static void make_sticks(struct mesh *m, uint32_t n, uint64_t seed)
{
    struct rng r = {seed};
    for (uint32_t i = 0; i < n; i++) {
        vec3 c = rng_in_box(&r, -1.0f, 1.0f);
        vec3 d = v3_scale(rng_dir(&r), 0.75f);
        vec3 w = v3_scale(rng_dir(&r), 0.02f);
        mesh_add_tri_pos(m, v3_sub(c, d), v3_add(c, d), v3_add(v3_sub(c, d), w));
    }
}

/* bvh.h: BVH_QUALITY_SPATIAL (the default) gives the same hits as brute force and as a binned
 * build, with copies of cut triangles (n_refs > n_tris) within the 25% budget. */
Test(bvh, spatial_splits_keep_every_hit)
{
    struct mesh m = {0};
    make_sticks(&m, 600, 60);
    make_soup(&m, 3000, 61);
    struct bvh *bvh = build(&m);
    struct bvh_stats st = bvh_get_stats(bvh);
    cr_assert_gt(st.n_refs, st.n_tris, "no triangle was cut");
    cr_assert_leq(st.n_refs, st.n_tris + st.n_tris / 4);
    struct bvh_build_options opt = {1, BVH_LAYOUT_WIDE, BVH_QUALITY_BINNED};
    struct bvh *binned = bvh_build_with(m.positions, m.indices, m.n_tris, &opt);
    cr_assert_not_null(binned);
    cr_assert_eq(bvh_get_stats(binned).n_refs, m.n_tris);
    struct rng r = {62};
    int n_hits = 0;
    for (int i = 0; i < 6000; i++) {
        struct ray ray;
        if (i % 3 == 0) {
            ray = make_ray(rng_in_box(&r, -2, 2), rng_dir(&r), 0.0f, INFINITY);
        } else { /* aimed at a stick: its middle is where planes cut it */
            uint32_t prim = (uint32_t)(rng_next(&r) % 600);
            float b1;
            float b2;
            rng_bary(&r, &b1, &b2);
            vec3 o = rng_in_box(&r, -3, 3);
            ray = make_ray(o, v3_sub(tri_point(&m, prim, b1, b2), o), 0.0f, INFINITY);
        }
        bool is_hit = expect_matches_brute(&m, bvh, &ray);
        n_hits += is_hit;
        struct bvh_hit a;
        struct bvh_hit b;
        cr_assert_eq(bvh_intersect(binned, &ray, &b), is_hit, "binned build disagrees, ray %d", i);
        if (is_hit) {
            bvh_intersect(bvh, &ray, &a);
            cr_assert(same_bits(a.t, b.t), "ray %d: t %a (spatial) vs %a (binned)", i, a.t, b.t);
        }
    }
    cr_assert_gt(n_hits, 3500);
    bvh_free(binned);
    bvh_free(bvh);
    mesh_free(&m);
}

/* A closed tube of long thin side triangles (length 20, radius 0.5, 48 sides, fan caps) along
 * the diagonal (1, 1, 1), centred at the origin: the side triangles' boxes are long cubes that
 * all overlap, and spatial splits cut them many times.  Rays aimed exactly at every vertex and
 * edge midpoint, from inside and outside, never escape (Woop et al. 2013's watertightness
 * survives the cut boxes). */
static vec3 tube_point(float x, float y, float z)
{
    vec3 a = v3_normalize(v3(1, 1, 1));
    vec3 u = v3_normalize(v3(1, -1, 0));
    vec3 w = v3_cross(a, u);
    return v3_add(v3_add(v3_scale(a, x), v3_scale(u, y)), v3_scale(w, z));
}

Test(bvh, spatial_splits_stay_watertight)
{
    enum { SIDES = 48 };
    struct mesh m = {0};
    uint32_t ring[2][SIDES];
    for (int end = 0; end < 2; end++) {
        for (int i = 0; i < SIDES; i++) {
            float phi = 2.0f * MCPT_PI * (float)i / (float)SIDES;
            ring[end][i] = mesh_add_vertex(&m, tube_point(end ? 10.0f : -10.0f, 0.5f * cosf(phi),
                                                          0.5f * sinf(phi)));
        }
    }
    uint32_t cap[2] = {mesh_add_vertex(&m, tube_point(-10.0f, 0, 0)),
                       mesh_add_vertex(&m, tube_point(10.0f, 0, 0))};
    for (int i = 0; i < SIDES; i++) {
        int j = (i + 1) % SIDES;
        mesh_add_tri(&m, ring[0][i], ring[0][j], ring[1][j]);
        mesh_add_tri(&m, ring[0][i], ring[1][j], ring[1][i]);
        mesh_add_tri(&m, cap[0], ring[0][j], ring[0][i]);
        mesh_add_tri(&m, cap[1], ring[1][i], ring[1][j]);
    }
    struct bvh *bvh = build(&m);
    cr_assert_gt(bvh_get_stats(bvh).n_refs, m.n_tris, "no triangle was cut");
    bvh_free(bvh);
    probe_watertight_mesh(&m, v3(0, 0, 0), 0.5f);
    mesh_free(&m);
}

/* ---- the tree over boxes (bvh_boxes_build) ---- */

struct sphere_visit {
    const struct sphere *spheres;
    uint32_t hit; /* closest so far, or UINT32_MAX */
    uint32_t visits;
};

static bool visit_closest(void *ctx, uint32_t i, struct ray *ray)
{
    struct sphere_visit *v = ctx;
    float t;
    v->visits++;
    if (shape_sphere_intersect(&v->spheres[i], ray, &t)) {
        ray->t_max = t;
        v->hit = i;
    }
    return false;
}

static bool visit_any(void *ctx, uint32_t i, struct ray *ray)
{
    struct sphere_visit *v = ctx;
    float t;
    v->visits++;
    return shape_sphere_intersect(&v->spheres[i], ray, &t);
}

/* 2000 spheres of radius 10^-3 .. 10^-1 in a unit box (some overlapping, some nested), each in a
 * box one float step wider than its extent: for 20000 rays from inside and outside the box, the
 * tree's closest hit is the sphere and t a loop over all of them finds, its any hit the same
 * answer, and a ray visits far fewer boxes than there are spheres.  Rays that are not finite
 * visit none. */
Test(bvh, boxes_tree_finds_what_a_loop_finds)
{
    enum { N = 2000, RAYS = 20000 };
    struct rng r = {77};
    struct sphere *sp = malloc(N * sizeof *sp);
    float(*boxes)[2][3] = malloc(N * sizeof *boxes);
    cr_assert(sp && boxes);
    for (uint32_t i = 0; i < N; i++) {
        sp[i] = (struct sphere){rng_in_box(&r, -1.0f, 1.0f), powf(10.0f, rng_range(&r, -3, -1)), 0};
        const float c[3] = {sp[i].center.x, sp[i].center.y, sp[i].center.z};
        for (int a = 0; a < 3; a++) {
            boxes[i][0][a] = nextafterf(c[a] - sp[i].radius, -INFINITY);
            boxes[i][1][a] = nextafterf(c[a] + sp[i].radius, INFINITY);
        }
    }
    struct bvh_boxes *tree = bvh_boxes_build((const float(*)[2][3])boxes, N);
    cr_assert_not_null(tree);
    uint64_t visits = 0;
    uint32_t n_hits = 0;
    for (int k = 0; k < RAYS; k++) {
        vec3 o = rng_in_box(&r, k % 2 ? -1.2f : -4.0f, k % 2 ? 1.2f : 4.0f);
        vec3 d = v3_sub(rng_in_box(&r, -1.0f, 1.0f), o);
        struct ray ray = {.o = o, .t_min = 0.0f, .d = d, .t_max = INFINITY};
        float t_loop = INFINITY, t;
        uint32_t hit_loop = UINT32_MAX;
        struct ray probe = ray;
        for (uint32_t i = 0; i < N; i++)
            if (shape_sphere_intersect(&sp[i], &probe, &t)) {
                probe.t_max = t_loop = t;
                hit_loop = i;
            }
        struct sphere_visit v = {sp, UINT32_MAX, 0};
        struct ray tr = ray;
        cr_assert_not(bvh_boxes_traverse(tree, &tr, visit_closest, &v));
        visits += v.visits;
        cr_assert_eq(v.hit, hit_loop, "ray %d: sphere %u, the loop's %u", k, v.hit, hit_loop);
        if (hit_loop != UINT32_MAX) {
            n_hits++;
            cr_assert_eq(tr.t_max, t_loop, "ray %d", k);
        }
        struct sphere_visit va = {sp, UINT32_MAX, 0};
        struct ray ta = ray;
        cr_assert_eq(bvh_boxes_traverse(tree, &ta, visit_any, &va), hit_loop != UINT32_MAX,
                     "ray %d", k);
    }
    cr_assert_gt(n_hits, RAYS / 4, "most rays meet a sphere: %u", n_hits);
    cr_assert_lt(visits, (uint64_t)RAYS * N / 20, "%llu visits", (unsigned long long)visits);
    struct ray bad = {.o = v3(NAN, 0.0f, 0.0f), .d = v3(1.0f, 0.0f, 0.0f), .t_max = INFINITY};
    struct sphere_visit vb = {sp, UINT32_MAX, 0};
    cr_assert_not(bvh_boxes_traverse(tree, &bad, visit_closest, &vb));
    cr_assert_eq(vb.visits, 0);
    bvh_boxes_free(tree);
    free(sp);
    free(boxes);
}
