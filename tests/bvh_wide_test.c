/* bvh_wide_test.c - tests for bvh_wide.c: the 8-wide layout converted from the binary reference
 * by the SAH-optimal collapse (Ylitie, Karras, Laine 2017, sec. 4.1), traversed one ray at a time
 * with the fused slab test and in 8-ray packets (Benthin et al. 2012), must return what the
 * scalar reference returns: the same t_hit bits and prim_idx as brute force (Woop, Benthin, Wald
 * 2013's test, which woop8 repeats on eight lanes).  Oversized binary leaves become small wide
 * subtrees; brute force over the wide leaves equals brute force over the binary triangles; tiny
 * triangles far from the origin check the biased constants of the fused slab test.  Every test
 * in tests/bvh_test.c runs the wide layout and packets too (bvh_test_util.h).  Ray streams
 * (bvh_occluded_stream) give each ray what bvh_occluded_from gives it. */
#include <criterion/criterion.h>
#include <criterion/logging.h>
#include <stdlib.h>
#include <string.h>

#include "bvh.h"
#include "bvh_test_util.h"
#include "shape.h"
#include "vec.h"

/* ---- brute force over the wide leaves ----------------------------------------------------------- */

/* bvh.h: without the binary layout (bvh_build keeps only the wide one) bvh_intersect_brute walks
 * the wide leaves.  They hold the binary triangles in BVH order minus the degenerate ones, so it
 * must report exactly what brute force over the binary triangles reports: hit flag, t, u, v and
 * prim_idx, ties included (both keep the first of equal t in the same order). */
Test(bvh_wide, brute_force_over_wide_leaves_matches_binary)
{
    struct mesh m = {0};
    make_soup(&m, 3000, 50);
    struct rng r = {51};
    for (int i = 0; i < 30; i++) { /* zero-area triangles, dropped from the wide leaves */
        vec3 p = rng_in_box(&r, -1, 1);
        mesh_add_tri_pos(&m, p, v3_add(p, v3(0.1f, 0.1f, 0.1f)), v3_add(p, v3(0.2f, 0.2f, 0.2f)));
    }
    struct bvh *both = build(&m);
    struct bvh *wide = bvh_build(m.positions, m.indices, m.n_tris, 1);
    cr_assert_not_null(wide);
    cr_assert_eq(bvh_layouts(wide), (unsigned)BVH_LAYOUT_WIDE);
    int n_hits = 0;
    for (int i = 0; i < 4000; i++) {
        struct ray ray;
        if (i % 2) {
            ray = make_ray(rng_in_box(&r, -2, 2), rng_dir(&r), 0.0f, INFINITY);
        } else {
            float b1;
            float b2;
            rng_bary(&r, &b1, &b2);
            vec3 target = tri_point(&m, (uint32_t)(rng_next(&r) % m.n_tris), b1, b2);
            vec3 o = rng_in_box(&r, -2, 2);
            ray = make_ray(o, v3_sub(target, o), 0.0f, INFINITY);
        }
        struct bvh_hit a;
        struct bvh_hit b;
        bool hit_a = bvh_intersect_brute(both, &ray, &a);
        cr_assert_eq(bvh_intersect_brute(wide, &ray, &b), hit_a, "ray %d", i);
        if (!hit_a)
            continue;
        n_hits++;
        cr_assert(same_bits(a.t, b.t) && same_bits(a.u, b.u) && same_bits(a.v, b.v),
                  "ray %d: t %a vs %a", i, b.t, a.t);
        cr_assert_eq(b.prim_idx, a.prim_idx, "ray %d", i);
    }
    cr_assert_gt(n_hits, 2000); /* the aimed half hits, and some random rays */
    bvh_free(wide);
    bvh_free(both);
    mesh_free(&m);
}

/* ---- packets ------------------------------------------------------------------------------------
 * bvh.h: each lane of a packet gets what bvh_intersect / bvh_occluded report for its ray (t to
 * the bit, prim_idx up to exact ties); inactive lanes are untouched and may hold garbage. */

/* Lane by lane against single rays. */
static void expect_packet_matches(const struct mesh *m, const struct bvh *bvh,
                                  const struct ray rays[BVH_PACKET_SIZE], uint32_t active)
{
    struct bvh_packet p;
    memset(&p, 0xFF, sizeof p); /* inactive lanes: NaN garbage */
    for (int lane = 0; lane < BVH_PACKET_SIZE; lane++)
        if (active >> lane & 1u)
            bvh_packet_set(&p, lane, &rays[lane]);
    struct bvh_packet_hit ph;
    uint32_t hits = bvh_intersect_packet(bvh, &p, active, &ph);
    uint32_t occluded = bvh_occluded_packet(bvh, &p, active);
    cr_assert_eq(hits & ~active, 0u);
    cr_assert_eq(occluded & ~active, 0u);
    for (int lane = 0; lane < BVH_PACKET_SIZE; lane++) {
        if (!(active >> lane & 1u))
            continue;
        struct bvh_hit hit;
        bool is_hit = bvh_intersect(bvh, &rays[lane], &hit);
        cr_assert_eq((hits >> lane & 1u) != 0, is_hit, "lane %d", lane);
        cr_assert_eq((occluded >> lane & 1u) != 0, is_hit, "lane %d any-hit", lane);
        if (!is_hit)
            continue;
        cr_assert(same_bits(ph.t[lane], hit.t), "lane %d t %a vs %a", lane, ph.t[lane], hit.t);
        if (ph.prim_idx[lane] == hit.prim_idx)
            cr_assert(same_bits(ph.u[lane], hit.u) && same_bits(ph.v[lane], hit.v));
        else
            cr_assert(single_tri_hits_at(m, ph.prim_idx[lane], &rays[lane], ph.t[lane]));
    }
}

/* Coherent packets (a camera's 4 x 2 pixel blocks, shadow rays from a patch toward an area
 * light), incoherent ones (random origins and directions), with every kind of active mask, and
 * mixed-sign directions with zero components (lanes whose slab planes and Woop axes differ). */
Test(bvh_wide, packets_match_single_rays)
{
    struct mesh m = {0};
    make_icosphere(&m, 4, v3(0.1f, 0.0f, -0.2f), 1.0f);
    make_soup(&m, 1500, 30);
    struct bvh *bvh = build(&m);
    struct rng r = {31};
    int n_packets = 0;
    for (int i = 0; i < 1500; i++) {
        struct ray rays[BVH_PACKET_SIZE];
        int kind = i % 4;
        vec3 eye = v3(0.3f, 0.5f, 4.0f);
        float px = rng_range(&r, -1.2f, 1.2f);
        float py = rng_range(&r, -1.2f, 1.2f);
        vec3 light = v3(0.0f, 3.0f, 0.0f);
        vec3 patch = v3_scale(rng_dir(&r), 1.0f);
        for (int lane = 0; lane < BVH_PACKET_SIZE; lane++) {
            if (kind == 0) { /* a 4 x 2 block of camera rays */
                vec3 target = v3(px + 0.01f * (float)(lane % 4), py + 0.01f * (float)(lane / 4), 0);
                rays[lane] = make_ray(eye, v3_normalize(v3_sub(target, eye)), 0.0f, INFINITY);
            } else if (kind == 1) { /* shadow rays from a small patch to an area light */
                vec3 o = v3_add(patch, v3_scale(rng_in_box(&r, -1, 1), 0.02f));
                vec3 to = v3_sub(v3_add(light, v3(rng_range(&r, -0.5f, 0.5f), 0,
                                                  rng_range(&r, -0.5f, 0.5f))),
                                 o);
                float dist = v3_length(to);
                rays[lane] = make_ray(o, v3_scale(to, 1.0f / dist), 0.0f, 0.999f * dist);
            } else if (kind == 2) { /* incoherent */
                rays[lane] = make_ray(rng_in_box(&r, -2, 2), rng_dir(&r), 0.0f,
                                      lane % 3 ? INFINITY : rng_range(&r, 0.5f, 3.0f));
            } else { /* axis directions and zero components, both signs */
                vec3 d = rng_dir(&r);
                if (lane % 2)
                    d.x = lane % 4 == 1 ? 0.0f : -0.0f;
                if (lane % 3 == 0)
                    d.y = 0.0f;
                if (v3_is_zero(d))
                    d.z = 1.0f;
                rays[lane] = make_ray(rng_in_box(&r, -2, 2), d, 0.0f, INFINITY);
            }
        }
        uint32_t active = i % 5 == 0 ? (uint32_t)(rng_next(&r) & 0xFFu) : 0xFFu;
        expect_packet_matches(&m, bvh, rays, active);
        n_packets++;
    }
    cr_assert_eq(n_packets, 1500);
    bvh_free(bvh);
    mesh_free(&m);
}

/* ---- streams -------------------------------------------------------------------------------------
 * bvh.h: bvh_intersect_stream and bvh_occluded_stream give ray i what bvh_intersect_from and
 * bvh_occluded_from(bvh, &rays[i], from[i]) give it (t to the bit, the triangle up to exact ties). */

/* Shadow rays spawned from the mesh's triangles toward an area light (with the triangle they
 * leave, in the order of their points, as a renderer makes them), the same rays without it,
 * rays aimed at the triangle they name (which the name skips),
 * random rays with finite and infinite t_max, rays whose direction lies in an axis plane (the
 * single ray's safe path), rays that miss the tree's box, and invalid rays (NaN origin, zero
 * direction), in streams of 1 to 100 rays, on the wide layout and on the binary one. */
Test(bvh_wide, streams_match_single_rays)
{
    struct mesh m = {0};
    make_icosphere(&m, 3, v3(0.1f, 0.0f, -0.2f), 1.0f); /* first: it subdivides all of m */
    make_soup(&m, 2000, 41);
    struct bvh *wide = build(&m);
    struct bvh_build_options opt = {1, BVH_LAYOUT_BINARY, BVH_QUALITY_DEFAULT};
    struct bvh *binary = bvh_build_with(m.positions, m.indices, m.n_tris, &opt);
    cr_assert(wide && binary);
    enum { N = 6000 };
    struct ray *rays = malloc(N * sizeof *rays);
    uint32_t *from = malloc(N * sizeof *from);
    bool *occluded = malloc(N * sizeof *occluded);
    bool *is_hit = malloc(N * sizeof *is_hit);
    struct bvh_hit *hits = malloc(N * sizeof *hits);
    cr_assert(rays && from && occluded && is_hit && hits);
    struct rng r = {43};
    vec3 light = v3(0.0f, 3.0f, 0.0f);
    for (uint32_t i = 0; i < N; i++) {
        from[i] = BVH_NO_PRIM;
        int kind = (int)(i / 500) % 6;
        if (kind <= 1) { /* spawned shadow rays, triangle by triangle */
            uint32_t prim = (i * 7u) % m.n_tris;
            struct surface sf = random_surface(&m, prim, &r);
            vec3 target = v3_add(light,
                                 v3(rng_range(&r, -0.5f, 0.5f), 0.0f, rng_range(&r, -0.5f, 0.5f)));
            vec3 w = v3_normalize(v3_sub(target, sf.p));
            vec3 o = offset_ray_origin(sf.p, sf.p_error, sf.ng, w);
            rays[i] = make_ray(o, w, 0.0f, 0.999f * v3_length(v3_sub(target, o)));
            if (kind == 0)
                from[i] = prim;
            if (kind == 1 && i % 2) { /* aimed at its own triangle, which `from` skips */
                vec3 above = v3_add(sf.p, v3_scale(sf.ng, 0.01f));
                rays[i] = make_ray(above, v3_sub(sf.p, above), 0.0f, INFINITY);
                from[i] = prim;
            }
        } else if (kind == 2) { /* random, finite and infinite */
            rays[i] = make_ray(rng_in_box(&r, -2, 2), rng_dir(&r), 0.0f,
                               i % 3 ? INFINITY : rng_range(&r, 0.2f, 3.0f));
        } else if (kind == 3) { /* a zero component, both signs: the safe path */
            vec3 d = rng_dir(&r);
            if (i % 2)
                d.x = i % 4 == 1 ? 0.0f : -0.0f;
            else
                d.y = 0.0f;
            rays[i] = make_ray(rng_in_box(&r, -2, 2), v3_normalize(d), 0.0f, INFINITY);
        } else if (kind == 4) { /* from far away: most miss the tree's box */
            vec3 o = v3_scale(rng_dir(&r), 20.0f);
            vec3 to = v3_sub(rng_in_box(&r, -3, 3), o);
            rays[i] = make_ray(o, v3_normalize(to), 0.0f, INFINITY);
        } else { /* some invalid among valid ones */
            rays[i] = make_ray(rng_in_box(&r, -2, 2), rng_dir(&r), 0.0f, INFINITY);
            if (i % 7 == 0)
                rays[i].o.y = NAN;
            if (i % 11 == 0)
                rays[i].d = v3(0.0f, 0.0f, 0.0f);
        }
    }
    const struct bvh *trees[2] = {wide, binary};
    int n_occluded = 0;
    for (int t = 0; t < 2; t++) {
        size_t lengths[] = {1, 7, 32, 33, 64, 100};
        size_t begin = 0;
        for (int k = 0; begin < N; k++) {
            size_t n = lengths[k % 6];
            if (n > N - begin)
                n = N - begin;
            bool use_from = k % 5 != 4; /* and now and then from = NULL */
            bvh_occluded_stream(trees[t], rays + begin, use_from ? from + begin : NULL, n,
                                occluded + begin);
            bvh_intersect_stream(trees[t], rays + begin, use_from ? from + begin : NULL, n,
                                 hits + begin, is_hit + begin);
            for (size_t i = begin; i < begin + n; i++) {
                uint32_t f = use_from ? from[i] : BVH_NO_PRIM;
                bool single = bvh_occluded_from(trees[t], &rays[i], f);
                cr_assert_eq(occluded[i], single, "%s, ray %zu (stream of %zu at %zu)",
                             t ? "binary" : "wide", i, n, begin);
                n_occluded += t == 0 && single;
                struct bvh_hit h;
                bool hit = bvh_intersect_from(trees[t], &rays[i], f, &h);
                cr_assert_eq(is_hit[i], hit, "%s, ray %zu: closest", t ? "binary" : "wide", i);
                if (!hit)
                    continue;
                cr_assert(same_bits(hits[i].t, h.t), "ray %zu: t %a vs %a", i, hits[i].t, h.t);
                if (hits[i].prim_idx == h.prim_idx)
                    cr_assert(same_bits(hits[i].u, h.u) && same_bits(hits[i].v, h.v));
                else
                    cr_assert(single_tri_hits_at(&m, hits[i].prim_idx, &rays[i], hits[i].t));
            }
            begin += n;
        }
    }
    cr_log_info("streams: %d of %d rays occluded", n_occluded, N);
    cr_assert_gt(n_occluded, N / 10);
    cr_assert_lt(n_occluded, N - N / 10);
    free(rays);
    free(from);
    free(occluded);
    free(is_hit);
    free(hits);
    bvh_free(wide);
    bvh_free(binary);
    mesh_free(&m);
}

/* ---- the conversion and the fused slab test ------------------------------------------------------ */

/* Wald 2007's binning peels a geometric sequence one bin at a time: three chains of 126
 * triangles at 2^-k along x, y and z reach the depth cap (BVH_MAX_DEPTH = 64), where a leaf
 * takes whatever is left (65 triangles here).  The wide layout splits such a leaf into a small
 * subtree of 8-triangle leaves; every traversal must still agree with brute force on rays aimed
 * at each triangle, down to the tiniest (2^-125, with subnormal vertex offsets), and rays at
 * the triangles down to 2^-40 hit. */
Test(bvh_wide, depth_cap_keeps_oversized_leaves)
{
    struct mesh m = {0};
    for (int chain = 0; chain < 3; chain++) {
        for (int k = 0; k < 126; k++) {
            float x = ldexpf(1.0f, -k);
            float s = x / 8.0f;
            vec3 c = v3(chain == 0 ? x : 0.0f, chain == 1 ? x : 0.0f, chain == 2 ? x : 0.0f);
            mesh_add_tri_pos(&m, v3_add(c, v3(-s, -s, s)), v3_add(c, v3(s, -s, -s)),
                             v3_add(c, v3(-s, s, -s)));
        }
    }
    struct bvh *bvh = build(&m);
    struct bvh_stats st = bvh_get_stats(bvh);
    cr_assert_eq(st.max_depth, 64u, "depth %u: the cap was not reached", st.max_depth);
    struct rng r = {42};
    /* below about 2^-60 the edge functions' products (coordinates squared) underflow and rays
     * may miss; both brute force and the BVH see the same float results */
    int n_misses = 0;
    for (uint32_t prim = 0; prim < m.n_tris; prim++) {
        int k = (int)(prim % 126);
        float x = ldexpf(1.0f, -k);
        vec3 target = tri_point(&m, prim, 1.0f / 3.0f, 1.0f / 3.0f);
        for (int j = 0; j < 4; j++) {
            vec3 o = v3_add(target, v3_scale(rng_dir(&r), 3.0f * x));
            struct ray ray = make_ray(o, v3_sub(target, o), 0.0f, INFINITY);
            bool is_hit = expect_matches_brute(&m, bvh, &ray);
            n_misses += k < 40 && !is_hit;
        }
    }
    cr_assert_eq(n_misses, 0);
    for (int i = 0; i < 2000; i++) {
        struct ray ray = make_ray(rng_in_box(&r, -0.2f, 1.2f), rng_dir(&r), 0.0f, INFINITY);
        expect_matches_brute(&m, bvh, &ray);
    }
    bvh_free(bvh);
    mesh_free(&m);
}

/* bvh_wide.c, "Wide traversal, one ray": the fused slab test b inv_d - c biases c by the rounding
 * error of o inv_d, which is large when the origin is far from the coordinate origin and the
 * boxes close to it.  Small triangles (0.02, ten float spacings at this magnitude) around
 * (3e4, -2e4, 1e4), rays from within 0.3 of them: every traversal matches brute force, so no
 * box was culled by that rounding. */
Test(bvh_wide, far_from_origin_small_mesh)
{
    struct mesh m = {0};
    struct rng r = {43};
    vec3 centre = v3(3e4f, -2e4f, 1e4f);
    for (int i = 0; i < 3000; i++) {
        vec3 c = v3_add(centre, v3_scale(rng_in_box(&r, -1, 1), 0.5f));
        mesh_add_tri_pos(&m, v3_add(c, v3_scale(rng_in_box(&r, -1, 1), 0.02f)),
                         v3_add(c, v3_scale(rng_in_box(&r, -1, 1), 0.02f)),
                         v3_add(c, v3_scale(rng_in_box(&r, -1, 1), 0.02f)));
    }
    struct bvh *bvh = build(&m);
    int n_hits = 0;
    for (int i = 0; i < 4000; i++) {
        uint32_t prim = (uint32_t)(rng_next(&r) % m.n_tris);
        float b1;
        float b2;
        rng_bary(&r, &b1, &b2);
        vec3 target = tri_point(&m, prim, b1, b2);
        vec3 o = v3_add(target, v3_scale(rng_dir(&r), rng_range(&r, 0.01f, 0.3f)));
        struct ray ray = make_ray(o, v3_sub(target, o), 0.0f, INFINITY);
        n_hits += expect_matches_brute(&m, bvh, &ray);
    }
    cr_log_info("far_from_origin: %d of 4000 aimed rays hit", n_hits);
    cr_assert_gt(n_hits, 3000);
    bvh_free(bvh);
    mesh_free(&m);
}

/* ---- floating-point assists ------------------------------------------------------------------------ */

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define MXCSR_FLAGS 0x3Fu  /* the sticky exception flags */
#define MXCSR_DENORMAL 0x02u /* DE: an operand was subnormal */
#define MXCSR_UNDERFLOW 0x10u /* UE: a result was tiny */
#endif

/* bvh_wide.c, wide_ray8_fast: on an ordinary scene no operation of the traversal may see a
 * subnormal operand or make a tiny result.  Intel cores finish such an operation in a microcode
 * assist; the fused setup once read the root's left_first and n_tris into the unused lane of
 * an FMA (small integers: subnormal floats), which cost every single ray an assist: single
 * camera rays ran 1.9x faster without it (docs/bvh.md, "Subnormal operands").  The flags are the
 * hardware's own record: cleared before each call, read after.  Unit-scale geometry (an
 * icosphere and a soup), camera, incoherent, shadow and spawned rays (bvh_intersect_from and
 * bvh_occluded_from) and packets of each, some partly active with subnormal bits in their idle
 * lanes. */
Test(bvh_wide, ordinary_rays_raise_no_subnormal_flags)
{
#if defined(__x86_64__) || defined(__i386__)
    struct mesh m = {0};
    make_icosphere(&m, 4, v3(0.1f, 0.0f, -0.2f), 1.0f);
    make_soup(&m, 1500, 61);
    struct bvh *bvh = build(&m);
    struct rng r = {62};
    unsigned flags = 0;
    int n_calls = 0;
    int n_hits = 0;
    for (int i = 0; i < 800; i++) {
        struct ray rays[BVH_PACKET_SIZE];
        vec3 eye = v3(0.3f, 0.5f, 4.0f);
        for (int lane = 0; lane < BVH_PACKET_SIZE; lane++) {
            if (i % 3 == 0) {
                vec3 target = v3(rng_range(&r, -1.2f, 1.2f), rng_range(&r, -1.2f, 1.2f), 0.0f);
                rays[lane] = make_ray(eye, v3_normalize(v3_sub(target, eye)), 0.0f, INFINITY);
            } else if (i % 3 == 1) {
                rays[lane] = make_ray(rng_in_box(&r, -2, 2), rng_dir(&r), 0.0f, INFINITY);
            } else {
                vec3 o = rng_in_box(&r, -1, 1);
                vec3 to = v3_sub(v3(rng_range(&r, -0.5f, 0.5f), 3.0f, rng_range(&r, -0.5f, 0.5f)), o);
                float dist = v3_length(to);
                rays[lane] = make_ray(o, v3_scale(to, 1.0f / dist), 0.0f, 0.999f * dist);
            }
        }
        for (int lane = 0; lane < BVH_PACKET_SIZE; lane++) {
            struct bvh_hit hit;
            _mm_setcsr(_mm_getcsr() & ~MXCSR_FLAGS);
            bool is_hit = bvh_intersect(bvh, &rays[lane], &hit);
            bvh_occluded(bvh, &rays[lane]);
            flags |= _mm_getcsr();
            n_calls += 2;
            if (!is_hit)
                continue;
            n_hits++;
            /* a ray leaving the hit triangle, in a random direction */
            vec3 p = v3_add(rays[lane].o, v3_scale(rays[lane].d, hit.t));
            struct ray out = make_ray(p, rng_dir(&r), 0.0f, INFINITY);
            struct bvh_hit next;
            _mm_setcsr(_mm_getcsr() & ~MXCSR_FLAGS);
            bvh_intersect_from(bvh, &out, hit.prim_idx, &next);
            bvh_occluded_from(bvh, &out, hit.prim_idx);
            flags |= _mm_getcsr();
            n_calls += 2;
        }
        /* every fifth packet partly active, its idle lanes holding the bits of 1 (a subnormal
         * float), which the packet setup must replace before any arithmetic */
        struct bvh_packet packet;
        uint32_t active = i % 5 == 0 ? (uint32_t)(rng_next(&r) & 0xFFu) | 1u : 0xFFu;
        for (int lane = 0; lane < BVH_PACKET_SIZE; lane++) {
            bvh_packet_set(&packet, lane, &rays[lane]);
            if (!(active >> lane & 1u)) {
                const uint32_t one = 1;
                for (int a = 0; a < 3; a++) {
                    memcpy(&packet.o[a][lane], &one, sizeof one);
                    memcpy(&packet.d[a][lane], &one, sizeof one);
                }
                memcpy(&packet.t_min[lane], &one, sizeof one);
                memcpy(&packet.t_max[lane], &one, sizeof one);
            }
        }
        struct bvh_packet_hit packet_hit;
        _mm_setcsr(_mm_getcsr() & ~MXCSR_FLAGS);
        bvh_intersect_packet(bvh, &packet, active, &packet_hit);
        bvh_occluded_packet(bvh, &packet, active);
        flags |= _mm_getcsr();
        n_calls += 2;
    }
    cr_log_info("subnormal flags: %d calls, %d hits, MXCSR flags seen %#x", n_calls, n_hits,
                flags & MXCSR_FLAGS);
    cr_assert_gt(n_hits, 2000);
    cr_assert_eq(flags & MXCSR_DENORMAL, 0u, "a traversal saw a subnormal operand");
    cr_assert_eq(flags & MXCSR_UNDERFLOW, 0u, "a traversal made a tiny result");
    bvh_free(bvh);
    mesh_free(&m);
#else
    cr_skip_test("MXCSR is x86's");
#endif
}
