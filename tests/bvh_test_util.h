/* tests/bvh_test_util.h - what tests/bvh_test.c (the binary reference, bvh.c) and
 * tests/bvh_wide_test.c (the 8-wide layout, bvh_wide.c) share: a deterministic random stream,
 * small meshes (random soups, closed icospheres), and the checks that run every traversal (the
 * wide layout, the binary reference, 8-ray packets) against brute force on the same ray.
 * Header-only: static inline, so a test file that uses some of them compiles warning-free. */
#ifndef MCPT_BVH_TEST_UTIL_H
#define MCPT_BVH_TEST_UTIL_H

#include <criterion/criterion.h>
#include <stdlib.h>
#include <string.h>

#include "bvh.h"
#include "shape.h"
#include "vec.h"

/* splitmix64: a small deterministic stream for test inputs */
struct rng {
    uint64_t state;
};

static inline uint64_t rng_next(struct rng *r)
{
    uint64_t z = (r->state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

/* uniform in [0, 1) */
static inline float rng_float(struct rng *r) { return (float)(rng_next(r) >> 40) * 0x1p-24f; }

static inline float rng_range(struct rng *r, float lo, float hi) { return lo + (hi - lo) * rng_float(r); }

static inline vec3 rng_in_box(struct rng *r, float lo, float hi)
{
    float x = rng_range(r, lo, hi);
    float y = rng_range(r, lo, hi);
    float z = rng_range(r, lo, hi);
    return v3(x, y, z);
}

/* uniform direction on the unit sphere */
static inline vec3 rng_dir(struct rng *r)
{
    float z = 1.0f - 2.0f * rng_float(r);
    float phi = 2.0f * MCPT_PI * rng_float(r);
    float s = sqrtf(fmaxf(0.0f, 1.0f - z * z));
    return v3(s * cosf(phi), s * sinf(phi), z);
}

struct mesh {
    vec3 *positions;
    uint32_t n_positions;
    uint32_t cap_positions;
    uint32_t *indices; /* 3 per triangle */
    uint32_t n_tris;
    uint32_t cap_tris;
};

static inline uint32_t mesh_add_vertex(struct mesh *m, vec3 p)
{
    if (m->n_positions == m->cap_positions) {
        m->cap_positions = m->cap_positions ? 2 * m->cap_positions : 64;
        m->positions = realloc(m->positions, m->cap_positions * sizeof *m->positions);
        cr_assert_not_null(m->positions);
    }
    m->positions[m->n_positions] = p;
    return m->n_positions++;
}

static inline void mesh_add_tri(struct mesh *m, uint32_t a, uint32_t b, uint32_t c)
{
    if (m->n_tris == m->cap_tris) {
        m->cap_tris = m->cap_tris ? 2 * m->cap_tris : 64;
        m->indices = realloc(m->indices, 3 * (size_t)m->cap_tris * sizeof *m->indices);
        cr_assert_not_null(m->indices);
    }
    m->indices[3 * m->n_tris + 0] = a;
    m->indices[3 * m->n_tris + 1] = b;
    m->indices[3 * m->n_tris + 2] = c;
    m->n_tris++;
}

static inline void mesh_add_tri_pos(struct mesh *m, vec3 a, vec3 b, vec3 c)
{
    uint32_t ia = mesh_add_vertex(m, a);
    uint32_t ib = mesh_add_vertex(m, b);
    uint32_t ic = mesh_add_vertex(m, c);
    mesh_add_tri(m, ia, ib, ic);
}

static inline void mesh_free(struct mesh *m)
{
    free(m->positions);
    free(m->indices);
    *m = (struct mesh){0};
}

static inline vec3 tri_vertex(const struct mesh *m, uint32_t prim, int k)
{
    return m->positions[m->indices[3 * prim + (uint32_t)k]];
}

/* b0 p0 + b1 p1 + b2 p2 */
static inline vec3 tri_point(const struct mesh *m, uint32_t prim, float b1, float b2)
{
    float b0 = 1.0f - b1 - b2;
    vec3 p0 = tri_vertex(m, prim, 0);
    vec3 p1 = tri_vertex(m, prim, 1);
    vec3 p2 = tri_vertex(m, prim, 2);
    return v3_add(v3_add(v3_scale(p0, b0), v3_scale(p1, b1)), v3_scale(p2, b2));
}

/* random barycentrics, uniform over the triangle */
static inline void rng_bary(struct rng *r, float *b1, float *b2)
{
    float u = rng_float(r);
    float v = rng_float(r);
    if (u + v > 1.0f) {
        u = 1.0f - u;
        v = 1.0f - v;
    }
    *b1 = u;
    *b2 = v;
}

/* A random point of triangle prim (rng_bary) as the renderer forms it: position, error bound and
 * normal for offset_ray_origin. */
static inline struct surface random_surface(const struct mesh *m, uint32_t prim, struct rng *r)
{
    vec3 q[3];
    for (int k = 0; k < 3; k++)
        q[k] = m->positions[m->indices[3 * prim + (uint32_t)k]];
    float b1, b2;
    rng_bary(r, &b1, &b2);
    return shape_triangle_surface(q, NULL, NULL, NULL, NULL, 0.0f, b1, b2, 0);
}

/* n random triangles in [-1, 1]^3, edge lengths from about 0.01 to 0.6 */
static inline void make_soup(struct mesh *m, uint32_t n, uint64_t seed)
{
    struct rng r = {seed};
    for (uint32_t i = 0; i < n; i++) {
        vec3 c = rng_in_box(&r, -1.0f, 1.0f);
        float size = 0.01f * exp2f(6.0f * rng_float(&r));
        vec3 a = v3_add(c, v3_scale(rng_in_box(&r, -1.0f, 1.0f), size));
        vec3 b = v3_add(c, v3_scale(rng_in_box(&r, -1.0f, 1.0f), size));
        vec3 d = v3_add(c, v3_scale(rng_in_box(&r, -1.0f, 1.0f), size));
        mesh_add_tri_pos(m, a, b, d);
    }
}

/* Icosphere: the icosahedron, each triangle split in four `levels` times with the edge
 * midpoints shared between neighbours (pushed to the unit sphere), then scaled and moved.
 * Closed: every edge belongs to exactly two triangles (checked). */
struct edge_map {
    uint64_t *keys;
    uint32_t *vals;
    uint32_t cap; /* power of two */
};

static inline uint32_t edge_midpoint(struct mesh *m, struct edge_map *map, uint32_t a, uint32_t b)
{
    uint64_t key = a < b ? ((uint64_t)a << 32 | b) : ((uint64_t)b << 32 | a);
    uint32_t h = (uint32_t)((key * 0x9E3779B97F4A7C15ull) >> 32) & (map->cap - 1);
    while (map->keys[h] != UINT64_MAX) {
        if (map->keys[h] == key)
            return map->vals[h];
        h = (h + 1) & (map->cap - 1);
    }
    vec3 mid = v3_normalize(v3_scale(v3_add(m->positions[a], m->positions[b]), 0.5f));
    uint32_t idx = mesh_add_vertex(m, mid);
    map->keys[h] = key;
    map->vals[h] = idx;
    return idx;
}

static inline int compare_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a;
    uint64_t y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

static inline void check_closed(const struct mesh *m)
{
    /* every directed edge (a, b) must have its reverse (b, a) exactly once: closed, oriented */
    size_t n_edges = 3 * (size_t)m->n_tris;
    uint64_t *edges = malloc(n_edges * sizeof *edges);
    cr_assert_not_null(edges);
    for (size_t i = 0; i < n_edges; i++) {
        uint64_t a = m->indices[i];
        uint64_t b = m->indices[i % 3 == 2 ? i - 2 : i + 1];
        edges[i] = a << 32 | b;
    }
    qsort(edges, n_edges, sizeof *edges, compare_u64);
    for (size_t i = 0; i < n_edges; i++) {
        uint64_t reverse = (edges[i] & 0xffffffffu) << 32 | edges[i] >> 32;
        int n_reverse = 0;
        uint64_t *found = bsearch(&reverse, edges, n_edges, sizeof *edges, compare_u64);
        if (found) { /* count equal neighbours around the match */
            uint64_t *lo = found;
            while (lo > edges && lo[-1] == reverse)
                lo--;
            while (lo < edges + n_edges && *lo == reverse) {
                n_reverse++;
                lo++;
            }
        }
        cr_assert_eq(n_reverse, 1, "icosphere edge %llx has %d twins",
                     (unsigned long long)edges[i], n_reverse);
    }
    free(edges);
}

static inline void make_icosphere(struct mesh *m, int levels, vec3 centre, float radius)
{
    const float t = 1.61803398874989484820f; /* golden ratio */
    const float base[12][3] = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                               {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                               {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
    const uint32_t faces[20][3] = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                   {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                   {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                   {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
    for (int i = 0; i < 12; i++)
        mesh_add_vertex(m, v3_normalize(v3(base[i][0], base[i][1], base[i][2])));
    for (int i = 0; i < 20; i++)
        mesh_add_tri(m, faces[i][0], faces[i][1], faces[i][2]);
    for (int level = 0; level < levels; level++) {
        uint32_t n_old = m->n_tris;
        uint32_t *old = malloc(3 * (size_t)n_old * sizeof *old);
        cr_assert_not_null(old);
        memcpy(old, m->indices, 3 * (size_t)n_old * sizeof *old);
        m->n_tris = 0;
        struct edge_map map = {NULL, NULL, 1};
        while (map.cap < 4 * 3 * n_old)
            map.cap *= 2;
        map.keys = malloc(map.cap * sizeof *map.keys);
        map.vals = malloc(map.cap * sizeof *map.vals);
        cr_assert(map.keys && map.vals);
        memset(map.keys, 0xff, map.cap * sizeof *map.keys);
        for (uint32_t i = 0; i < n_old; i++) {
            uint32_t a = old[3 * i];
            uint32_t b = old[3 * i + 1];
            uint32_t c = old[3 * i + 2];
            uint32_t ab = edge_midpoint(m, &map, a, b);
            uint32_t bc = edge_midpoint(m, &map, b, c);
            uint32_t ca = edge_midpoint(m, &map, c, a);
            mesh_add_tri(m, a, ab, ca);
            mesh_add_tri(m, b, bc, ab);
            mesh_add_tri(m, c, ca, bc);
            mesh_add_tri(m, ab, bc, ca);
        }
        free(map.keys);
        free(map.vals);
        free(old);
    }
    for (uint32_t i = 0; i < m->n_positions; i++)
        m->positions[i] = v3_add(centre, v3_scale(m->positions[i], radius));
}

/* Both layouts, so that every test below checks the reference and the fast one. */
static inline struct bvh *build(const struct mesh *m)
{
    struct bvh_build_options opt = {1, BVH_LAYOUT_BINARY | BVH_LAYOUT_WIDE, BVH_QUALITY_DEFAULT};
    struct bvh *bvh = bvh_build_with(m->positions, m->indices, m->n_tris, &opt);
    cr_assert_not_null(bvh);
    cr_assert_eq(bvh_layouts(bvh), m->n_tris ? BVH_LAYOUT_BINARY | BVH_LAYOUT_WIDE : 0u);
    return bvh;
}

/* The same ray in all eight lanes of a packet (so the packet traversal, not its one-ray
 * fallback, runs), or in lane `lane` alone. */
static inline void packet_of(struct bvh_packet *p, const struct ray *ray, int lane)
{
    memset(p, 0, sizeof *p);
    for (int i = 0; i < BVH_PACKET_SIZE; i++)
        if (lane < 0 || i == lane)
            bvh_packet_set(p, i, ray);
}

static inline struct ray make_ray(vec3 o, vec3 d, float t_min, float t_max)
{
    return (struct ray){o, t_min, d, t_max};
}

static inline bool same_bits(float a, float b) { return memcmp(&a, &b, sizeof a) == 0; }

/* Does triangle prim of m alone report a hit at exactly t_hit for this ray? */
static inline bool single_tri_hits_at(const struct mesh *m, uint32_t prim, const struct ray *ray,
                               float t_hit)
{
    struct bvh *one = bvh_build(m->positions, m->indices + 3 * prim, 1, 1);
    cr_assert_not_null(one);
    struct bvh_hit hit;
    bool is_hit = bvh_intersect(one, ray, &hit);
    bvh_free(one);
    return is_hit && same_bits(hit.t, t_hit);
}

/* Each traversal: the wide layout (bvh_intersect), the binary reference, and the packet
 * traversal with the ray in all eight lanes. */
enum traversal { WIDE, BINARY, PACKET, N_TRAVERSALS };
static const char *const traversal_names[N_TRAVERSALS] = {"wide", "binary", "packet"};

static inline bool trace_with(const struct bvh *bvh, enum traversal how, const struct ray *ray,
                       struct bvh_hit *hit)
{
    if (how == WIDE)
        return bvh_intersect(bvh, ray, hit);
    if (how == BINARY)
        return bvh_intersect_layout(bvh, BVH_LAYOUT_BINARY, ray, hit);
    struct bvh_packet p;
    struct bvh_packet_hit ph;
    packet_of(&p, ray, -1);
    uint32_t hits = bvh_intersect_packet(bvh, &p, 0xFFu, &ph);
    cr_assert(hits == 0 || hits == 0xFFu, "identical lanes disagree: %x", hits);
    for (int lane = 1; lane < BVH_PACKET_SIZE && hits; lane++)
        cr_assert(same_bits(ph.t[lane], ph.t[0]) && ph.prim_idx[lane] == ph.prim_idx[0]);
    *hit = (struct bvh_hit){ph.t[0], ph.u[0], ph.v[0], ph.prim_idx[0]};
    return hits != 0;
}

static inline bool occluded_with(const struct bvh *bvh, enum traversal how, const struct ray *ray)
{
    if (how == WIDE)
        return bvh_occluded(bvh, ray);
    if (how == BINARY)
        return bvh_occluded_layout(bvh, BVH_LAYOUT_BINARY, ray);
    struct bvh_packet p;
    packet_of(&p, ray, -1);
    uint32_t occluded = bvh_occluded_packet(bvh, &p, 0xFFu);
    cr_assert(occluded == 0 || occluded == 0xFFu);
    return occluded != 0;
}

/* Every traversal and brute force must agree: same hit flag, same t bits, and the same
 * prim_idx, u, v; where two triangles are hit at exactly the same t either may be reported, so a
 * different prim_idx must itself be hit at that t.  Any-hit agrees with the hit flag.  Returns
 * whether the ray hit. */
static inline bool expect_matches_brute(const struct mesh *m, const struct bvh *bvh,
                                 const struct ray *ray)
{
    struct bvh_hit slow;
    bool hit_slow = bvh_intersect_brute(bvh, ray, &slow);
    for (int how = 0; how < N_TRAVERSALS; how++) {
        struct bvh_hit fast;
        bool hit_fast = trace_with(bvh, (enum traversal)how, ray, &fast);
        cr_assert_eq(hit_fast, hit_slow, "%s %d vs brute %d for o (%a %a %a) d (%a %a %a)",
                     traversal_names[how], hit_fast, hit_slow, ray->o.x, ray->o.y, ray->o.z,
                     ray->d.x, ray->d.y, ray->d.z);
        cr_assert_eq(occluded_with(bvh, (enum traversal)how, ray), hit_slow,
                     "%s any-hit disagrees", traversal_names[how]);
        if (!hit_fast)
            continue;
        cr_assert(same_bits(fast.t, slow.t), "%s t %a vs brute %a (prim %u vs %u)",
                  traversal_names[how], fast.t, slow.t, fast.prim_idx, slow.prim_idx);
        cr_assert_lt(fast.prim_idx, m->n_tris);
        if (fast.prim_idx == slow.prim_idx) {
            cr_assert(same_bits(fast.u, slow.u) && same_bits(fast.v, slow.v));
        } else {
            cr_assert(single_tri_hits_at(m, fast.prim_idx, ray, fast.t),
                      "%s tie: prim %u not hit at t %a", traversal_names[how], fast.prim_idx,
                      fast.t);
        }
    }
    return hit_slow;
}

/* For rays aimed exactly at shared vertices and edges, where several triangles are hit within a
 * few ulps of each other: a traversal may cull the box of the marginally nearer one (bvh.c,
 * "Reference traversal"), so require the same hit flag, t within 1e-6 relative, and that the
 * reported triangle itself is hit at the reported t. */
static inline bool expect_close_to_brute(const struct mesh *m, const struct bvh *bvh,
                                  const struct ray *ray)
{
    struct bvh_hit slow;
    bool hit_slow = bvh_intersect_brute(bvh, ray, &slow);
    for (int how = 0; how < N_TRAVERSALS; how++) {
        struct bvh_hit fast;
        bool hit_fast = trace_with(bvh, (enum traversal)how, ray, &fast);
        cr_assert_eq(hit_fast, hit_slow, "%s", traversal_names[how]);
        if (!hit_fast)
            continue;
        if (fast.prim_idx == slow.prim_idx) {
            cr_assert(same_bits(fast.t, slow.t));
        } else {
            cr_assert_float_eq(fast.t, slow.t, 1e-6f * fabsf(slow.t));
            cr_assert(single_tri_hits_at(m, fast.prim_idx, ray, fast.t));
        }
    }
    return hit_slow;
}

#endif
