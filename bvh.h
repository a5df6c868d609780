/* bvh.h - bounding volume hierarchy over triangles: binned SAH build (Wald 2007) with spatial
 * splits (Stich et al. 2009), flattened nodes, triangles stored in BVH order (a triangle cut by
 * a spatial split in each leaf it reaches), watertight ray-triangle test (Woop et al. 2013).
 * Two traversal layouts: the scalar binary reference (bvh.c), and an 8-wide layout (SoA child
 * boxes, SoA leaves, SIMD; bvh_wide.c) converted from it, which the renderer uses.  Analytic
 * shapes (spheres, quads, planes) are not in the BVH; trace.c tests them directly. */
#ifndef MCPT_BVH_H
#define MCPT_BVH_H

#include <stddef.h>

#include "vec.h"

/* The scalar reference node: two to a 64-byte cache line.  An interior node's children are
 * nodes left_first and left_first + 1; a leaf holds triangles [left_first, left_first + n_tris)
 * of the BVH-ordered triangle array.  n_tris == 0 marks an interior node. */
struct bvh_node {
    float min[3];
    uint32_t left_first; /* first child node index (interior) or first triangle (leaf) */
    float max[3];
    uint32_t n_tris; /* triangles in this leaf; 0 for an interior node */
};                   /* 32 bytes */
_Static_assert(sizeof(struct bvh_node) == 32, "bvh_node must be 32 bytes");

struct bvh; /* opaque */

/* Closest hit: the hit point is (1 - u - v) p0 + u p1 + v p2 of triangle prim_idx. */
struct bvh_hit {
    float t;           /* ray parameter of the hit */
    float u;           /* barycentric weight of vertex 1 */
    float v;           /* barycentric weight of vertex 2 */
    uint32_t prim_idx; /* index of the triangle in the caller's input order */
};

struct bvh_stats {
    uint32_t n_tris;
    uint32_t n_refs;    /* triangle references in the leaves: n_tris plus spatial splits' copies */
    uint32_t n_nodes;   /* binary nodes (the tree every layout is converted from) */
    uint32_t n_leaves;  /* binary leaves */
    uint32_t max_depth; /* of the binary tree, root = 0 */
    double sah_cost;    /* SAH cost of the binary tree, in units of one node traversal */
    double build_ms;    /* wall-clock build time, conversion to the wide layout included */
    size_t bytes;       /* what the BVH keeps: nodes + triangle data of every layout it carries */
    /* the 8-wide layout (0 when the BVH carries none) */
    uint32_t n_wide_nodes;  /* 8-wide nodes */
    uint32_t n_wide_leaves; /* leaves of the wide tree (non-empty binary leaves) */
    size_t wide_bytes;      /* wide nodes + SoA leaf triangles + their prim_idx */
    size_t binary_bytes;    /* binary nodes + triangles + prim_idx, 0 when not kept */
    double convert_ms;      /* converting the binary tree into the wide layout (in build_ms) */
    int n_threads;          /* threads the build used */
};

/* Traversal layouts.  A BVH carries one or both; bvh_intersect uses the wide one if present. */
enum bvh_layout {
    BVH_LAYOUT_BINARY = 1, /* the scalar reference: binary tree of struct bvh_node */
    BVH_LAYOUT_WIDE = 2,   /* 8-wide nodes, SoA boxes and leaves, converted from the binary tree */
};

/* How the binary tree is split (docs/bvh.md, "Build"). */
enum bvh_quality {
    BVH_QUALITY_DEFAULT = 0, /* what bvh_build uses: BVH_QUALITY_SPATIAL */
    BVH_QUALITY_BINNED = 1,  /* object splits only: binned SAH (Wald 2007) */
    BVH_QUALITY_SPATIAL = 2, /* object and spatial splits (Stich, Friedrich, Dietrich 2009) */
};

struct bvh_build_options {
    int n_threads;            /* <= 1: build on the calling thread; the tree is the same for any */
    unsigned layouts;         /* OR of enum bvh_layout; 0 means BVH_LAYOUT_WIDE */
    enum bvh_quality quality; /* 0: the default */
};

/* Builds a BVH over n_tris triangles whose vertex indices are indices[3i .. 3i+2] into
 * positions, with the wide layout only (bvh_build_with, default options).  Degenerate
 * (zero-area) triangles are kept in the binary layout and dropped from the wide one (they never
 * report a hit in either).  Returns NULL only when out of memory.  n_tris may be 0.  The tree
 * is identical for every n_threads. */
struct bvh *bvh_build(const vec3 *positions, const uint32_t *indices, uint32_t n_tris,
                      int n_threads);

/* The same with explicit options (opt NULL: the defaults).  The wide layout needs
 * n_tris < 2^28; beyond that only the binary layout is built, whatever opt asks. */
struct bvh *bvh_build_with(const vec3 *positions, const uint32_t *indices, uint32_t n_tris,
                           const struct bvh_build_options *opt);

/* Which layouts the BVH carries (OR of enum bvh_layout; 0 for an empty BVH that has none). */
unsigned bvh_layouts(const struct bvh *bvh);

/* Closest hit with t in (ray->t_min, ray->t_max).  On a hit fills *hit and returns true. */
bool bvh_intersect(const struct bvh *bvh, const struct ray *ray, struct bvh_hit *hit);

/* Any hit with t in (ray->t_min, ray->t_max): shadow rays.  Returns true when occluded. */
bool bvh_occluded(const struct bvh *bvh, const struct ray *ray);

/* The prim_idx of no triangle: what rays that leave no triangle pass as `from`. */
#define BVH_NO_PRIM UINT32_MAX

/* bvh_intersect and bvh_occluded for a ray spawned from the surface of triangle `from` (its
 * prim_idx, or BVH_NO_PRIM), which is never reported.  A ray leaving a flat triangle, its origin
 * offset to the side of its direction (offset_ray_origin), cannot meet that triangle at t > 0,
 * so the result is what bvh_intersect / bvh_occluded give; but the origin's own triangle is the
 * one whose test float cannot decide (t ~ 0), and the traversals skip its double-precision
 * test (docs/theory.md, "Self-intersection"). */
bool bvh_intersect_from(const struct bvh *bvh, const struct ray *ray, uint32_t from,
                        struct bvh_hit *hit);
bool bvh_occluded_from(const struct bvh *bvh, const struct ray *ray, uint32_t from);

/* The same through one given layout, which the BVH must carry (see bvh_layouts): the tests and
 * the benchmark compare the layouts on the same rays. */
bool bvh_intersect_layout(const struct bvh *bvh, enum bvh_layout layout, const struct ray *ray,
                          struct bvh_hit *hit);
bool bvh_occluded_layout(const struct bvh *bvh, enum bvh_layout layout, const struct ray *ray);

/* Brute-force reference: tests every triangle (the teaching O(n) baseline and test oracle). */
bool bvh_intersect_brute(const struct bvh *bvh, const struct ray *ray, struct bvh_hit *hit);
bool bvh_intersect_brute_from(const struct bvh *bvh, const struct ray *ray, uint32_t from,
                              struct bvh_hit *hit);

/* Ray packets: BVH_PACKET_SIZE rays in SoA form, traversed together through the wide layout
 * (each node's boxes are tested against all active rays at once).  They pay for coherent rays
 * (primary rays of a tile, shadow rays toward one light); see docs/bvh.md for the measured
 * choice.  Every ray gets exactly what bvh_intersect / bvh_occluded would report (up to which
 * of several triangles hit at the same t).  Lane i is active when bit i of `active` is set. */
#define BVH_PACKET_SIZE 8

struct bvh_packet {
    _Alignas(32) float o[3][BVH_PACKET_SIZE]; /* origins, o[axis][lane] */
    _Alignas(32) float d[3][BVH_PACKET_SIZE]; /* directions */
    _Alignas(32) float t_min[BVH_PACKET_SIZE];
    _Alignas(32) float t_max[BVH_PACKET_SIZE];
}; /* 256 bytes */

struct bvh_packet_hit {
    _Alignas(32) float t[BVH_PACKET_SIZE];
    _Alignas(32) float u[BVH_PACKET_SIZE];
    _Alignas(32) float v[BVH_PACKET_SIZE];
    _Alignas(32) uint32_t prim_idx[BVH_PACKET_SIZE];
}; /* 128 bytes */

/* Closest hit for each active lane; returns the mask of lanes that hit (their hit fields are
 * filled; the others are left unspecified). */
uint32_t bvh_intersect_packet(const struct bvh *bvh, const struct bvh_packet *packet,
                              uint32_t active, struct bvh_packet_hit *hit);

/* Any hit for each active lane; returns the mask of occluded lanes. */
uint32_t bvh_occluded_packet(const struct bvh *bvh, const struct bvh_packet *packet,
                             uint32_t active);

/* Fills lane i of *packet with ray (for building packets from struct ray). */
void bvh_packet_set(struct bvh_packet *packet, int lane, const struct ray *ray);

/* Ray streams: closest hit or any hit for n rays in one call, traversed BVH_STREAM_RAYS at a
 * time (each node visited once for the rays of the stream that entered it; docs/bvh.md,
 * "Streams").  They pay where neighbouring rays take the same way: camera rays in pixel order,
 * shadow rays toward one light in the order of the points they leave.  Ray i gets what
 * bvh_intersect_from / bvh_occluded_from(bvh, &rays[i], from[i]) give it (the triangle up to
 * exact ties); from may be NULL (no ray leaves a triangle); out[i] is filled where is_hit[i]. */
#define BVH_STREAM_RAYS 32
void bvh_intersect_stream(const struct bvh *bvh, const struct ray *rays, const uint32_t *from,
                          size_t n, struct bvh_hit *out, bool *is_hit);
void bvh_occluded_stream(const struct bvh *bvh, const struct ray *rays, const uint32_t *from,
                         size_t n, bool *occluded);

struct bvh_stats bvh_get_stats(const struct bvh *bvh);

/* A 64-bit hash of every byte of the layouts the BVH carries (nodes, triangles, indices), which
 * two builds share only when they made the same trees: how a change to the build shows it kept
 * them (bench/raybench --build-only prints it).  Not a checksum against corruption. */
uint64_t bvh_layout_hash(const struct bvh *bvh);

/* "avx2" or "scalar": the kernels bvh_wide.c was compiled with. */
const char *bvh_simd_name(void);

void bvh_free(struct bvh *bvh);

/* A tree over n axis-aligned boxes (boxes[i][0] the lower corner, [1] the upper), for primitives
 * the caller tests itself: trace.c's spheres and quads.  The triangles' binned SAH build without
 * spatial splits, the binary layout.  NULL where n is 0 or out of memory. */
struct bvh_boxes;
struct bvh_boxes *bvh_boxes_build(const float (*boxes)[2][3], uint32_t n);

/* Called with each box i that the ray's [t_min, t_max] may cross (the conservative slab test of
 * the triangles' traversal), nearer subtrees first: it tests primitive i, may lower ray->t_max
 * to a hit's t (so farther subtrees are skipped: a closest hit), and returns true to end the
 * traversal (an any hit). */
typedef bool (*bvh_box_visit)(void *ctx, uint32_t i, struct ray *ray);

/* Visits the boxes the ray may cross; true where a visit ended it.  A ray that is not finite
 * visits none. */
bool bvh_boxes_traverse(const struct bvh_boxes *tree, struct ray *ray, bvh_box_visit visit,
                        void *ctx);
void bvh_boxes_free(struct bvh_boxes *tree);

#endif
