/* bvh_internal.h - private to bvh.c (the binary reference) and bvh_wide.c (the 8-wide layout
 * converted from it); nothing else includes it, the API is bvh.h.  It holds what both layouts
 * share: struct bvh, the stored triangle, boxes, the per-ray constants, the reference slab test
 * (PBRT 4e, ch. 6, "Conservative Ray-Bounds Intersections", used by both for the first test
 * against the whole tree), and the functions each file lends the other.  The small helpers are
 * static inline here so that the hot paths of both files inline them. */
#ifndef MCPT_BVH_INTERNAL_H
#define MCPT_BVH_INTERNAL_H

#include "bvh.h"

/* The watertight test needs a * b - c * d rounded as two products and a difference, never fused
 * into an FMA (bvh.c, "Watertight ray-triangle test").  gcc does not contract under -std=c11;
 * clang does unless told.  The pragma holds to the end of each file that includes this one. */
#if defined(__clang__)
#pragma STDC FP_CONTRACT OFF
#endif

/* The deepest binary node (root = 0); bounds the build and traversal stacks of both layouts. */
#define BVH_MAX_DEPTH 64
/* The wide layout's size limit: a leaf reference keeps its first triangle in 28 bits. */
#define BVH_WIDE_MAX_TRIS (1u << 28)

/* One triangle in BVH order.  Woop's test translates the vertices themselves to the ray origin;
 * storing v0, e1 = v1 - v0, e2 = v2 - v0 instead would hand it v0 + e1, which is not v1 bit for
 * bit, and two triangles sharing an edge would then disagree on where the edge is: the test
 * would no longer be watertight.  A degenerate triangle is stored collapsed to p0 (bvh.c,
 * collapse_if_degenerate), which the test rejects exactly. */
struct bvh_tri {
    float p0[3]; /* vertex 0, scene units */
    float p1[3]; /* vertex 1 */
    float p2[3]; /* vertex 2 */
};               /* 36 bytes */

struct wide_node; /* bvh_wide.c */

struct bvh {
    /* binary reference (BVH_LAYOUT_BINARY), bvh.c */
    struct bvh_node *nodes; /* n_nodes nodes, 64-byte aligned; root at 0, nodes[1] unused */
    struct bvh_tri *tris;   /* n_tris triangles in BVH order */
    uint32_t *prim_idx;     /* prim_idx[i]: the caller's index of tris[i] */
    uint32_t n_refs;        /* length of tris and prim_idx: triangles plus spatial splits' copies */
    uint32_t n_nodes;       /* length of nodes, the unused nodes[1] included; 0 when empty */
    /* wide (BVH_LAYOUT_WIDE), bvh_wide.c */
    struct wide_node *wide;  /* n_wide nodes, root at 0 */
    float *leaf_tris;        /* 9 floats per wide triangle, SoA per leaf, plus 8 padding */
    uint32_t *wide_prim_idx; /* the caller's index of each wide triangle */
    struct bvh_node bounds;  /* the whole tree's box (the binary root's), for a first test */
    uint32_t n_wide;         /* wide nodes */
    uint32_t n_wide_tris;    /* triangles in the wide leaves (the non-degenerate ones) */
    uint32_t n_tris;         /* triangles given to the build */
    unsigned layouts;        /* OR of enum bvh_layout */
    struct bvh_stats stats;  /* filled once by the build */
};

/* ---- Boxes ----------------------------------------------------------------------------------- */

struct box {
    float min[4]; /* lower corner; +inf when empty; [3] is padding for 4-lane SIMD (kept 0) */
    float max[4]; /* upper corner; -inf when empty; [3] likewise */
};                /* 32 bytes */

static const struct box empty_box = {{INFINITY, INFINITY, INFINITY, 0.0f},
                                     {-INFINITY, -INFINITY, -INFINITY, 0.0f}};

static inline void box_grow(struct box *b, const float min[3], const float max[3])
{
    for (int a = 0; a < 3; a++) {
        b->min[a] = min[a] < b->min[a] ? min[a] : b->min[a];
        b->max[a] = max[a] > b->max[a] ? max[a] : b->max[a];
    }
}

/* Half the surface area: the SAH uses only ratios of areas, so the factor 2 cancels. */
static inline float box_half_area(const struct box *b)
{
    float dx = b->max[0] - b->min[0];
    float dy = b->max[1] - b->min[1];
    float dz = b->max[2] - b->min[2];
    return dx * dy + dy * dz + dz * dx;
}

/* A node's box as a struct box. */
static inline struct box node_box(const struct bvh_node *node)
{
    return (struct box){{node->min[0], node->min[1], node->min[2], 0.0f},
                        {node->max[0], node->max[1], node->max[2], 0.0f}};
}

static inline float node_half_area(const struct bvh_node *node)
{
    struct box b = node_box(node);
    return box_half_area(&b);
}

/* ---- Per-ray constants and the reference slab test ------------------------------------------- */

/* Per-ray constants, computed once per ray and shared by every box and triangle test. */
struct ray_pre {
    float o[3];       /* origin */
    float d[3];       /* direction */
    float inv_d[3];   /* 1 / d per axis; +-inf where d is +-0 */
    int is_neg[3];    /* inv_d[a] < 0: the slab's near plane is max[a], the far plane min[a] */
    float far_scale;  /* 1 + 2 gamma(3), PBRT 4e, ch. 6, "Conservative Ray-Bounds Intersections" */
    int kx, ky, kz;   /* Woop et al. 2013: kz = argmax |d|, (kx, ky) swapped when d[kz] < 0 */
    float sx, sy, sz; /* shear: sx = d[kx] / d[kz], sy = d[ky] / d[kz], sz = 1 / d[kz] */
    float o_scale;    /* max |o_a| |sz|: the origin's magnitude in units of t (t's precision) */
};                    /* 76 bytes */

/* max(running, candidate) and min(...) where a NaN candidate leaves running unchanged: fmaxf /
 * fminf semantics for the one operand that can be NaN, written as a comparison so that gcc
 * emits maxss/minss instead of a libm call. */
static inline float max_num(float running, float candidate)
{
    return candidate > running ? candidate : running;
}
static inline float min_num(float running, float candidate)
{
    return candidate < running ? candidate : running;
}

/* The slab test's constants. */
static inline void ray_setup_box(const struct ray *ray, struct ray_pre *rp)
{
    float o[3] = {ray->o.x, ray->o.y, ray->o.z};
    float d[3] = {ray->d.x, ray->d.y, ray->d.z};
    for (int a = 0; a < 3; a++) {
        rp->o[a] = o[a];
        rp->d[a] = d[a];
        rp->inv_d[a] = 1.0f / d[a]; /* +-inf for d = +-0 (IEEE 754) */
        rp->is_neg[a] = rp->inv_d[a] < 0.0f;
    }
    rp->far_scale = 1.0f + 2.0f * mcpt_gamma(3);
}

/* Woop et al. 2013, ray preparation: the dimension where |d| is largest becomes z; kx, ky are
 * swapped when d[kz] < 0 to keep the triangles' winding; then the shear constants.
 * branch_free makes the choices arithmetic: an incoherent ray's largest axis and sign are coin
 * tosses, which a branch mispredicts, while branches let a predictor that guesses right (rays
 * of one direction: packets, streams) start the divisions at once instead of after the
 * selection (docs/bvh.md, "Branches").  Both give the same constants. */
static ALWAYS_INLINE void ray_setup_woop_as(struct ray_pre *rp, const bool branch_free)
{
    const float *d = rp->d;
    float ad[3] = {fabsf(d[0]), fabsf(d[1]), fabsf(d[2])};
    int kx, ky, kz;
    if (branch_free) {
        int x_first = ad[0] >= ad[1];
        int is_x = x_first & (ad[0] >= ad[2]);
        int is_y = (x_first ^ 1) & (ad[1] >= ad[2]);
        kz = 2 - 2 * is_x - is_y; /* as the comparisons below */
        kx = 0x9 >> 2 * kz & 3;   /* (kz + 1) mod 3: the 2-bit entries 1, 2, 0 */
        ky = 0x12 >> 2 * kz & 3;  /* (kz + 2) mod 3: 2, 0, 1 */
        int swap = (kx ^ ky) & -(int)(d[kz] < 0.0f);
        kx ^= swap;
        ky ^= swap;
    } else {
        kz = ad[0] >= ad[1] ? (ad[0] >= ad[2] ? 0 : 2) : (ad[1] >= ad[2] ? 1 : 2);
        kx = kz == 2 ? 0 : kz + 1;
        ky = kx == 2 ? 0 : kx + 1;
        if (d[kz] < 0.0f) {
            int tmp = kx;
            kx = ky;
            ky = tmp;
        }
    }
    rp->kx = kx;
    rp->ky = ky;
    rp->kz = kz;
    rp->sx = d[kx] / d[kz];
    rp->sy = d[ky] / d[kz];
    rp->sz = 1.0f / d[kz];
    rp->o_scale = max_f(fabsf(rp->o[0]), max_f(fabsf(rp->o[1]), fabsf(rp->o[2]))) * fabsf(rp->sz);
}
static inline void ray_setup_woop(struct ray_pre *rp) { ray_setup_woop_as(rp, false); }

/* Slab test (Kay, Kajiya 1986, "Ray Tracing Complex Scenes") in the (min - o) * inv_d form of
 * PBRT 4e, ch. 6, "Conservative Ray-Bounds Intersections":
 *   t_near_a = (near_a - o_a) * inv_d_a
 *   t_far_a  = (far_a - o_a) * inv_d_a * (1 + 2 gamma(3))   (covers the rounding of both ops)
 *   hit  iff  max(t_min, t_near_x, t_near_y, t_near_z) <= min(t_max, t_far_x, t_far_y, t_far_z)
 * The near plane is min_a for inv_d_a >= 0 and max_a otherwise, chosen by sign, never by
 * comparing the two t values.  With d_a == +-0, inv_d_a = +-inf: an origin outside the slab
 * gives the same infinity on both planes (miss), one strictly inside gives -inf for the near
 * and +inf for the far plane (no constraint), and an origin exactly on a plane gives
 * 0 * inf = NaN for that plane, which max_num/min_num ignore: the ray lies in the face of a
 * closed box and is treated as inside.  A flat box (min_a == max_a) is therefore hit both by
 * rays crossing it and by rays lying in it.  *t_entry gets the entry distance. */
static inline bool box_hit(const struct bvh_node *node, const struct ray_pre *rp, float t_min,
                           float t_max, float *t_entry)
{
    float t0 = t_min;
    float t1 = t_max;
    for (int a = 0; a < 3; a++) {
        float near_plane = rp->is_neg[a] ? node->max[a] : node->min[a];
        float far_plane = rp->is_neg[a] ? node->min[a] : node->max[a];
        float t_near = (near_plane - rp->o[a]) * rp->inv_d[a];
        float t_far = (far_plane - rp->o[a]) * rp->inv_d[a] * rp->far_scale;
        t0 = max_num(t0, t_near);
        t1 = min_num(t1, t_far);
    }
    *t_entry = t0;
    return t0 <= t1;
}

/* A ray the traversals accept: finite origin and direction, direction not zero.  Any other ray
 * hits nothing (a NaN ray would pass every slab test, the empty lanes of wide nodes included). */
static inline bool ray_is_valid(const struct ray *ray)
{
    return v3_is_finite(ray->o) && v3_is_finite(ray->d) && !v3_is_zero(ray->d);
}

/* A traversal stack entry of the closest-hit loops. */
struct stack_entry {
    uint32_t node_idx; /* node still to visit (binary index or wide reference) */
    float t_entry;     /* where the ray enters its box */
};                     /* 8 bytes */

/* ---- What bvh.c lends bvh_wide.c ------------------------------------------------------------- */

/* n elements of size bytes on a 64-byte boundary / with malloc; NULL on overflow or when out
 * of memory.  The caller frees. */
void *bvh_alloc_aligned(size_t n, size_t size);
void *bvh_alloc_array(size_t n, size_t size);

/* Triangle prim of the caller's mesh as stored: its three vertices, collapsed onto p0 when it
 * has no area. */
void bvh_load_tri(struct bvh_tri *tri, const vec3 *positions, const uint32_t *indices,
                  uint32_t prim);

/* Woop et al. 2013's double-precision fallback: the three edge functions U, V, W of the sheared
 * 2D vertices A, B, C, each from two exact double products and one rounding. */
void bvh_edge_functions_double(float Ax, float Ay, float Bx, float By, float Cx, float Cy, float *U,
                               float *V, float *W);

/* Woop's test in double for a (ray, triangle) pair whose float test (tri_hit, woop8) found
 * inside but could not decide on which side of the origin the hit lies; edge[] are the float
 * edge functions U, V, W (after Woop's fallback).  True with t in (t_min, t_max), u and v when
 * the hit is certainly in front (bvh.c, "Watertight ray-triangle test").  rp needs Woop's
 * constants (ray_setup_woop). */
bool bvh_tri_hit_double(const struct bvh_tri *tri, const struct ray_pre *rp, const float edge[3],
                        float t_min, float t_max, float *t_out, float *u_out, float *v_out);

/* Brute force's step: tests tri (the caller's triangle prim) with the scalar watertight test and
 * keeps it in *best when it is hit before best->t (prim_idx UINT32_MAX while nothing is hit). */
void bvh_brute_step(const struct bvh_tri *tri, uint32_t prim, const struct ray_pre *rp, float t_min,
                    struct bvh_hit *best);

/* Fork-join on n_jobs (at most 64) threads: fn(args + i * arg_bytes) for i in [0, n_jobs),
 * job 0 on the calling thread.  A thread that cannot be started runs its job inline. */
void bvh_run_jobs(int n_jobs, void *(*fn)(void *), void *args, size_t arg_bytes);

/* ---- What bvh_wide.c lends bvh.c ------------------------------------------------------------- */

/* Converts the binary tree of bvh (nodes, prim_idx; degenerate[i] flags the zero-area triangle
 * at binary position i) into the wide layout, reading the vertices from the caller's mesh.
 * Fills the wide fields of bvh and of bvh->stats; false when out of memory (bvh_free frees
 * whatever was allocated). */
bool bvh_wide_convert(struct bvh *bvh, const vec3 *positions, const uint32_t *indices,
                      const uint8_t *degenerate, int n_threads);

/* bvh_intersect / bvh_occluded through the wide layout, which bvh must carry. */
bool bvh_wide_intersect(const struct bvh *bvh, const struct ray *ray, uint32_t from,
                        struct bvh_hit *hit);
bool bvh_wide_occluded(const struct bvh *bvh, const struct ray *ray, uint32_t from);
/* bvh_intersect_stream and bvh_occluded_stream through the wide layout. */
void bvh_wide_intersect_stream(const struct bvh *bvh, const struct ray *rays, const uint32_t *from,
                               size_t n, struct bvh_hit *out, bool *is_hit);
void bvh_wide_occluded_stream(const struct bvh *bvh, const struct ray *rays, const uint32_t *from,
                              size_t n, bool *occluded);

/* h with n bytes of p mixed in, 8 at a time (the last word zero-padded), for bvh_layout_hash. */
uint64_t bvh_hash_bytes(uint64_t h, const void *p, size_t n);
/* h with the wide layout mixed in (bvh_layout_hash): nodes, leaf rows and indices. */
uint64_t bvh_wide_hash(const struct bvh *bvh, uint64_t h);

/* Brute force over the wide leaves (bvh_brute_step on each triangle, in stored order), for a
 * BVH that did not keep the binary layout. */
void bvh_wide_brute(const struct bvh *bvh, const struct ray_pre *rp, float t_min, uint32_t from,
                    struct bvh_hit *best);

#endif
