/* bvh.h - bounding volume hierarchy over triangles: binned SAH build (Wald 2007), flattened
 * nodes, triangles stored in BVH order, watertight ray-triangle test (Woop, Benthin, Wald 2013).
 * Analytic shapes (spheres, quads, planes) are not in the BVH; trace.c tests them directly. */
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
}; /* 32 bytes */
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
    uint32_t n_nodes;
    uint32_t n_leaves;
    uint32_t max_depth;
    double sah_cost;     /* SAH cost of the tree, in units of one node traversal */
    double build_ms;     /* wall-clock build time */
    size_t bytes;        /* nodes + triangle data */
};

/* Builds a BVH over n_tris triangles whose vertex indices are indices[3i .. 3i+2] into
 * positions.  n_threads <= 1 builds on the calling thread.  Degenerate (zero-area) triangles
 * are kept (they never report a hit).  Returns NULL only when out of memory.  n_tris may be 0. */
struct bvh *bvh_build(const vec3 *positions, const uint32_t *indices, uint32_t n_tris,
                      int n_threads);

/* Closest hit with t in (ray->t_min, ray->t_max).  On a hit fills *hit and returns true. */
bool bvh_intersect(const struct bvh *bvh, const struct ray *ray, struct bvh_hit *hit);

/* Any hit with t in (ray->t_min, ray->t_max): shadow rays.  Returns true when occluded. */
bool bvh_occluded(const struct bvh *bvh, const struct ray *ray);

/* Brute-force reference: tests every triangle (the teaching O(n) baseline and test oracle). */
bool bvh_intersect_brute(const struct bvh *bvh, const struct ray *ray, struct bvh_hit *hit);

struct bvh_stats bvh_get_stats(const struct bvh *bvh);

void bvh_free(struct bvh *bvh);

#endif
