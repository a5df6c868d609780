/* bvh.c - the scalar reference BVH over triangles: 32-byte nodes in one flat array, triangles
 * permuted into BVH order, a binned-SAH build (Wald 2007, "On fast Construction of SAH-based
 * Bounding Volume Hierarchies"), ordered traversal with a fixed stack and a conservative slab
 * test (PBRT 4e, ch. 6, "Conservative Ray-Bounds Intersections"), and the watertight
 * ray-triangle test of Woop, Benthin, Wald 2013, "Watertight Ray/Triangle Intersection"
 * (JCGT 2(1)), which PBRT 4e, ch. 6, "Triangle Meshes" also uses.  Wide SIMD layouts are to be
 * converted from this one and checked against it.  Reading order: layout and invariants, the
 * build, traversal, the triangle test, brute force, stats. */
#include "bvh.h"

#include <assert.h>
#include <stdlib.h>
#include <time.h>

/* The watertight test needs a * b - c * d rounded as two products and a difference, never fused
 * into an FMA (see tri_hit).  gcc does not contract under -std=c11; clang does unless told. */
#if defined(__clang__)
#pragma STDC FP_CONTRACT OFF
#endif

/* ---- Layout and invariants ------------------------------------------------------------------
 * struct bvh_node (bvh.h): 32 bytes, box min/max plus left_first and n_tris.
 * nodes[0] is the root; an empty BVH (n_tris == 0) has no nodes at all.  nodes[1] is unused, so
 *   that every sibling pair starts at an even index: in the 64-byte aligned array the two
 *   children of a node share one cache line.  Nodes are numbered in depth-first build order.
 * Interior node (n_tris == 0): children nodes[left_first] and nodes[left_first + 1].
 * Leaf (n_tris > 0): triangles tris[left_first .. left_first + n_tris) and their input indices
 *   prim_idx[left_first ..].  The leaves' ranges tile [0, n_tris) exactly once.
 * Every box is the exact float min/max of the vertices below it (no padding); the traversal,
 *   not the box, carries the rounding allowance.
 * Depth (root = 0) is at most BVH_MAX_DEPTH, so the traversal stack of BVH_MAX_DEPTH entries
 *   cannot overflow: it holds at most one pending sibling per level.
 * Triangles keep their three vertices exactly as given, in input order (struct bvh_tri), so the
 *   hit point is (1 - u - v) p0 + u p1 + v p2 of the caller's triangle prim_idx. */

/* One triangle in BVH order.  Woop's test translates the vertices themselves to the ray origin;
 * storing v0, e1 = v1 - v0, e2 = v2 - v0 instead would hand it v0 + e1, which is not v1 bit for
 * bit, and two triangles sharing an edge would then disagree on where the edge is: the test
 * would no longer be watertight.  A degenerate triangle is stored collapsed to p0 (see
 * collapse_if_degenerate), which the test rejects exactly. */
struct bvh_tri {
    float p0[3]; /* vertex 0, scene units */
    float p1[3]; /* vertex 1 */
    float p2[3]; /* vertex 2 */
}; /* 36 bytes */

struct bvh {
    struct bvh_node *nodes; /* n_nodes nodes, 64-byte aligned; root at 0, nodes[1] unused */
    struct bvh_tri *tris;   /* n_tris triangles in BVH order */
    uint32_t *prim_idx;     /* prim_idx[i]: the caller's index of tris[i] */
    uint32_t n_nodes;       /* length of nodes, the unused nodes[1] included; 0 when empty */
    uint32_t n_tris;        /* triangles */
    struct bvh_stats stats; /* filled once by bvh_build */
};

/* ---- Build: binned SAH, Wald 2007 ------------------------------------------------------------
 * The build sees only one box and one centre per triangle (the centre of its box).  At each
 * node the centres' bounds are cut into BVH_N_BINS equal bins on each axis; every plane between
 * two bins is a candidate, and the cheapest by the surface area heuristic wins:
 *   C_split = C_trav + (A_L / A) * N_L * C_isect + (A_R / A) * N_R * C_isect
 *   C_leaf  = N * C_isect
 * with A the surface area of the node's box, A_L/A_R those of the children's boxes and N_L/N_R
 * their triangle counts.  A node becomes a leaf when C_leaf <= C_split and N <= BVH_MAX_LEAF_TRIS,
 * when N == 1, or at depth BVH_MAX_DEPTH (any size).  When all centres coincide no plane
 * separates them: a node of more than BVH_MAX_LEAF_TRIS triangles is then cut in the middle of
 * its index range, so leaves stay bounded and depth grows only as log2(N).
 * The build runs on the calling thread whatever n_threads says (a later task parallelises it). */

/* The constants were chosen by measurement on the 100k-triangle Stanford dragon (single thread,
 * best of 30 runs, incoherent and camera rays): C_isect = 0.5 traced 15-25% faster than 1.0 and
 * used 61 instead of 75 bytes per triangle; 0.75 was within noise of 0.5; 32 bins instead of 16
 * cut node visits by 1.5% but built 28% slower; 8 bins visited 1.5% more nodes. */
#define BVH_COST_TRAVERSAL 1.0f /* C_trav: visiting one interior node (two box tests); the unit */
#define BVH_COST_INTERSECT 0.5f /* C_isect: one triangle test, in units of C_trav */
#define BVH_N_BINS 16           /* bins per axis */
#define BVH_MAX_LEAF_TRIS 8     /* a larger node is split even when the SAH prefers a leaf */
#define BVH_MAX_DEPTH 64        /* deepest node; bounds the build and traversal stacks */

/* What the build knows of one triangle: its box (the centre is derived from it). */
struct prim_ref {
    float min[3];      /* lower corner of the box of the stored vertices */
    float max[3];      /* upper corner */
    uint32_t prim_idx; /* the caller's index of the triangle */
}; /* 28 bytes */

struct box {
    float min[3]; /* lower corner; +inf when empty */
    float max[3]; /* upper corner; -inf when empty */
}; /* 24 bytes */

struct bin {
    struct box box; /* union of the boxes of the triangles whose centre falls in the bin */
    uint32_t n;     /* number of those triangles */
}; /* 28 bytes */

/* A node waiting to be built: refs[begin, end) at depth. */
struct build_task {
    uint32_t node_idx; /* node to fill */
    uint32_t begin;    /* first ref */
    uint32_t end;      /* one past the last */
    uint32_t depth;    /* root = 0 */
}; /* 16 bytes */

/* A split candidate: sah_sum = A_L N_L + A_R N_R (half areas), the part of C_split that varies. */
struct split {
    int axis;      /* 0, 1, 2; -1 when no candidate separates the centres */
    int bin;       /* the left child takes bins 0..bin */
    float sah_sum; /* A_L * N_L + A_R * N_R */
}; /* 12 bytes */

static const struct box empty_box = {{INFINITY, INFINITY, INFINITY},
                                     {-INFINITY, -INFINITY, -INFINITY}};

static void box_grow(struct box *b, const float min[3], const float max[3])
{
    for (int a = 0; a < 3; a++) {
        b->min[a] = min[a] < b->min[a] ? min[a] : b->min[a];
        b->max[a] = max[a] > b->max[a] ? max[a] : b->max[a];
    }
}

/* Half the surface area: the SAH uses only ratios of areas, so the factor 2 cancels. */
static float box_half_area(const struct box *b)
{
    float dx = b->max[0] - b->min[0];
    float dy = b->max[1] - b->min[1];
    float dz = b->max[2] - b->min[2];
    return dx * dy + dy * dz + dz * dx;
}

static float ref_centre(const struct prim_ref *r, int axis)
{
    return 0.5f * (r->min[axis] + r->max[axis]);
}

/* Bin of a centre coordinate c in [c_min, c_max], scale = BVH_N_BINS / (c_max - c_min). */
static int bin_index(float c, float c_min, float scale)
{
    int k = (int)((c - c_min) * scale);
    return k < BVH_N_BINS ? k : BVH_N_BINS - 1;
}

/* Bin scale of an axis, or 0 where all centres share the coordinate (or their extent is too
 * small to divide): every centre then falls in bin 0 and the axis offers no split. */
static float bin_scale(const struct box *centre_bounds, int axis)
{
    float extent = centre_bounds->max[axis] - centre_bounds->min[axis];
    float scale = (float)BVH_N_BINS / extent;
    return extent > 0.0f && isfinite(scale) ? scale : 0.0f;
}

/* The cheapest binned split of refs[begin, end) (Wald 2007): one pass fills the bins of all
 * three axes, then per axis a sweep from the right gathers the right children's areas and one
 * from the left evaluates every plane. */
static struct split find_split(const struct prim_ref *refs, uint32_t begin, uint32_t end,
                               const struct box *centre_bounds)
{
    struct bin bins[3][BVH_N_BINS];
    float scale[3];
    for (int axis = 0; axis < 3; axis++) {
        scale[axis] = bin_scale(centre_bounds, axis);
        for (int k = 0; k < BVH_N_BINS; k++)
            bins[axis][k] = (struct bin){empty_box, 0};
    }
    for (uint32_t i = begin; i < end; i++) {
        const struct prim_ref *r = &refs[i];
        for (int axis = 0; axis < 3; axis++) {
            int k = bin_index(ref_centre(r, axis), centre_bounds->min[axis], scale[axis]);
            box_grow(&bins[axis][k].box, r->min, r->max);
            bins[axis][k].n++;
        }
    }
    struct split best = {-1, 0, INFINITY};
    uint32_t n = end - begin;
    for (int axis = 0; axis < 3; axis++) {
        /* right sweep: right_area[k], right_n[k] describe bins k .. BVH_N_BINS - 1 */
        float right_area[BVH_N_BINS];
        uint32_t right_n[BVH_N_BINS];
        struct box acc = empty_box;
        uint32_t acc_n = 0;
        for (int k = BVH_N_BINS - 1; k > 0; k--) {
            box_grow(&acc, bins[axis][k].box.min, bins[axis][k].box.max);
            acc_n += bins[axis][k].n;
            right_area[k] = acc_n > 0 ? box_half_area(&acc) : 0.0f;
            right_n[k] = acc_n;
        }
        /* left sweep: the plane after bin k puts bins 0..k left, k+1.. right */
        acc = empty_box;
        acc_n = 0;
        for (int k = 0; k < BVH_N_BINS - 1; k++) {
            box_grow(&acc, bins[axis][k].box.min, bins[axis][k].box.max);
            acc_n += bins[axis][k].n;
            if (acc_n == 0 || acc_n == n)
                continue; /* one side would be empty */
            float sah_sum = box_half_area(&acc) * (float)acc_n +
                            right_area[k + 1] * (float)right_n[k + 1];
            if (sah_sum < best.sah_sum)
                best = (struct split){axis, k, sah_sum};
        }
    }
    return best;
}

/* Decides node refs[begin, end) and partitions refs in place.  Returns the first index of the
 * right child, or begin when the node is to be a leaf. */
static uint32_t split_node(struct prim_ref *refs, uint32_t begin, uint32_t end, uint32_t depth,
                           const struct box *bounds, const struct box *centre_bounds)
{
    uint32_t n = end - begin;
    if (n <= 1 || depth >= BVH_MAX_DEPTH)
        return begin;
    struct split best = find_split(refs, begin, end, centre_bounds);
    if (best.axis < 0) /* all centres coincide: halve the range, or stop when small */
        return n <= BVH_MAX_LEAF_TRIS ? begin : begin + n / 2;
    /* C_split < C_leaf, both multiplied by A so that a zero-area box (a point) needs no division:
     * C_trav A + C_isect (A_L N_L + A_R N_R) < C_isect N A */
    float area = box_half_area(bounds);
    float split_cost = BVH_COST_TRAVERSAL * area + BVH_COST_INTERSECT * best.sah_sum;
    float leaf_cost = BVH_COST_INTERSECT * (float)n * area;
    if (split_cost >= leaf_cost && n <= BVH_MAX_LEAF_TRIS)
        return begin;
    int axis = best.axis;
    float c_min = centre_bounds->min[axis];
    float scale = bin_scale(centre_bounds, axis);
    uint32_t i = begin;
    uint32_t j = end;
    while (i < j) { /* left takes bins 0..best.bin */
        if (bin_index(ref_centre(&refs[i], axis), c_min, scale) <= best.bin) {
            i++;
        } else {
            struct prim_ref tmp = refs[i];
            refs[i] = refs[--j];
            refs[j] = tmp;
        }
    }
    assert(i > begin && i < end); /* find_split only offers planes with both sides non-empty */
    return i;
}

/* Builds nodes[] depth first from an explicit stack; returns the deepest depth reached.  The
 * root is nodes[0], nodes[1] is left unused and every sibling pair starts at an even index, so
 * with a 64-byte aligned array the two children of a node share one cache line. */
static uint32_t build_nodes(struct bvh *bvh, struct prim_ref *refs)
{
    struct build_task stack[BVH_MAX_DEPTH + 2]; /* one pending right child per level + current */
    int n_stack = 0;
    uint32_t max_depth = 0;
    bvh->nodes[1] = (struct bvh_node){{0}, 0, {0}, 0};
    bvh->n_nodes = 2;
    stack[n_stack++] = (struct build_task){0, 0, bvh->n_tris, 0};
    while (n_stack > 0) {
        struct build_task task = stack[--n_stack];
        struct box bounds = empty_box;
        struct box centre_bounds = empty_box;
        for (uint32_t i = task.begin; i < task.end; i++) {
            const struct prim_ref *r = &refs[i];
            float centre[3] = {ref_centre(r, 0), ref_centre(r, 1), ref_centre(r, 2)};
            box_grow(&bounds, r->min, r->max);
            box_grow(&centre_bounds, centre, centre);
        }
        struct bvh_node *node = &bvh->nodes[task.node_idx];
        memcpy(node->min, bounds.min, sizeof node->min);
        memcpy(node->max, bounds.max, sizeof node->max);
        if (task.depth > max_depth)
            max_depth = task.depth;
        uint32_t mid = split_node(refs, task.begin, task.end, task.depth, &bounds, &centre_bounds);
        if (mid == task.begin) {
            node->left_first = task.begin;
            node->n_tris = task.end - task.begin;
            continue;
        }
        uint32_t left_idx = bvh->n_nodes;
        bvh->n_nodes += 2;
        node->left_first = left_idx;
        node->n_tris = 0;
        assert(n_stack + 2 <= (int)(sizeof stack / sizeof stack[0]));
        stack[n_stack++] = (struct build_task){left_idx + 1, mid, task.end, task.depth + 1};
        stack[n_stack++] = (struct build_task){left_idx, task.begin, mid, task.depth + 1};
    }
    return max_depth;
}

/* A triangle whose edge cross product, evaluated in double (exact for all but extreme exponent
 * ranges), is zero has no area: repeated or collinear vertices.  Its edge functions in Woop's
 * test are rounding noise and could all share a sign, so it is collapsed onto p0: then
 * U = V = W = 0 exactly and the test rejects it with det == 0. */
static void collapse_if_degenerate(struct bvh_tri *tri)
{
    double e1[3];
    double e2[3];
    for (int a = 0; a < 3; a++) {
        e1[a] = (double)tri->p1[a] - (double)tri->p0[a];
        e2[a] = (double)tri->p2[a] - (double)tri->p0[a];
    }
    double nx = e1[1] * e2[2] - e1[2] * e2[1];
    double ny = e1[2] * e2[0] - e1[0] * e2[2];
    double nz = e1[0] * e2[1] - e1[1] * e2[0];
    if (nx == 0.0 && ny == 0.0 && nz == 0.0) {
        memcpy(tri->p1, tri->p0, sizeof tri->p0);
        memcpy(tri->p2, tri->p0, sizeof tri->p0);
    }
}

static void load_tri(struct bvh_tri *tri, const vec3 *positions, const uint32_t *indices,
                     uint32_t prim)
{
    vec3 p[3];
    for (int k = 0; k < 3; k++) {
        p[k] = positions[indices[3 * (size_t)prim + (size_t)k]];
        assert(v3_is_finite(p[k])); /* parsers reject NaN/Inf */
    }
    *tri = (struct bvh_tri){{p[0].x, p[0].y, p[0].z},
                            {p[1].x, p[1].y, p[1].z},
                            {p[2].x, p[2].y, p[2].z}};
    collapse_if_degenerate(tri);
}

static double now_ms(void)
{
    struct timespec ts;
    timespec_get(&ts, TIME_UTC);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* malloc of n elements of size bytes, NULL on overflow. */
static void *alloc_array(size_t n, size_t size)
{
    if (size != 0 && n > SIZE_MAX / size)
        return NULL;
    return malloc(n * size == 0 ? 1 : n * size);
}

/* n nodes on a 64-byte boundary (aligned_alloc wants a multiple of 64 bytes), NULL on overflow. */
static struct bvh_node *alloc_nodes(size_t n)
{
    if (n > (SIZE_MAX - 64) / sizeof(struct bvh_node))
        return NULL;
    size_t bytes = (n * sizeof(struct bvh_node) + 63) / 64 * 64;
    return aligned_alloc(64, bytes == 0 ? 64 : bytes);
}

static void compute_stats(struct bvh *bvh);

struct bvh *bvh_build(const vec3 *positions, const uint32_t *indices, uint32_t n_tris,
                      int n_threads)
{
    (void)n_threads; /* single-threaded for now, see the build comment above */
    double t_start_ms = now_ms();
    struct prim_ref *refs = NULL;
    struct bvh_node *nodes_worst = NULL;
    struct bvh *bvh = calloc(1, sizeof *bvh);
    if (!bvh)
        goto fail;
    bvh->n_tris = n_tris;
    if (n_tris > 0) {
        if (n_tris > UINT32_MAX / 2)
            goto fail; /* 2 n nodes (2 n - 1 and the unused nodes[1]) must fit in uint32_t */
        refs = alloc_array(n_tris, sizeof *refs);
        nodes_worst = alloc_nodes(2 * (size_t)n_tris);
        bvh->tris = alloc_array(n_tris, sizeof *bvh->tris);
        bvh->prim_idx = alloc_array(n_tris, sizeof *bvh->prim_idx);
        if (!refs || !nodes_worst || !bvh->tris || !bvh->prim_idx)
            goto fail;
        /* the build sees only boxes (of the stored, possibly collapsed, vertices) */
        for (uint32_t i = 0; i < n_tris; i++) {
            struct bvh_tri tri;
            load_tri(&tri, positions, indices, i);
            struct prim_ref *r = &refs[i];
            for (int a = 0; a < 3; a++) {
                r->min[a] = fminf(tri.p0[a], fminf(tri.p1[a], tri.p2[a]));
                r->max[a] = fmaxf(tri.p0[a], fmaxf(tri.p1[a], tri.p2[a]));
            }
            r->prim_idx = i;
        }
        bvh->nodes = nodes_worst;
        bvh->stats.max_depth = build_nodes(bvh, refs);
        /* move the nodes into an array of the final size */
        bvh->nodes = alloc_nodes(bvh->n_nodes);
        if (!bvh->nodes)
            goto fail;
        memcpy(bvh->nodes, nodes_worst, bvh->n_nodes * sizeof *bvh->nodes);
        free(nodes_worst);
        nodes_worst = NULL;
        for (uint32_t i = 0; i < n_tris; i++) {
            load_tri(&bvh->tris[i], positions, indices, refs[i].prim_idx);
            bvh->prim_idx[i] = refs[i].prim_idx;
        }
    }
    free(refs);
    compute_stats(bvh);
    bvh->stats.build_ms = now_ms() - t_start_ms;
    return bvh;
fail:
    free(refs);
    free(nodes_worst);
    bvh_free(bvh);
    return NULL;
}

/* ---- Traversal --------------------------------------------------------------------------------
 * Closest hit: iterative, depth first, nearer child first.  At an interior node both children's
 * boxes are tested against [t_min, t_hit] (t_hit = the closest hit so far, initially t_max); if
 * both are hit the farther one is pushed with its entry distance and the nearer one visited.
 * A popped node whose entry distance now lies beyond t_hit is skipped.  No allocation.
 * The result is bit for bit that of bvh_intersect_brute (same t, u, v, prim_idx; among exactly
 * equal t either triangle), with one exception: where several triangles are hit within a few
 * ulps of each other (a ray through a shared vertex or edge), the box of the marginally nearer
 * one can start a few ulps beyond t_hit and be culled.  The reported hit is then one of those
 * triangles, at the same point to within rounding.
 * A ray starting on a surface (t_min = 0) may report that surface at t ~ 0 when rounding puts
 * its origin behind the plane; tri_hit only rejects t <= delta_t.  Spawned rays must start at
 * offset_ray_origin (vec.h), which puts the origin on the correct side by the error bound. */

/* Per-ray constants, computed once per ray and shared by every box and triangle test. */
struct ray_pre {
    float o[3];        /* origin */
    float inv_d[3];    /* 1 / d per axis; +-inf where d is +-0 */
    int is_neg[3];     /* inv_d[a] < 0: the slab's near plane is max[a], the far plane min[a] */
    float far_scale;   /* 1 + 2 gamma(3), PBRT 4e, ch. 6, "Conservative Ray-Bounds Intersections" */
    int kx, ky, kz;    /* Woop et al. 2013: kz = argmax |d|, (kx, ky) swapped when d[kz] < 0 */
    float sx, sy, sz;  /* shear: sx = d[kx] / d[kz], sy = d[ky] / d[kz], sz = 1 / d[kz] */
}; /* 60 bytes */

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

static void ray_setup(const struct ray *ray, struct ray_pre *rp)
{
    float o[3] = {ray->o.x, ray->o.y, ray->o.z};
    float d[3] = {ray->d.x, ray->d.y, ray->d.z};
    for (int a = 0; a < 3; a++) {
        rp->o[a] = o[a];
        rp->inv_d[a] = 1.0f / d[a]; /* +-inf for d = +-0 (IEEE 754) */
        rp->is_neg[a] = rp->inv_d[a] < 0.0f;
    }
    rp->far_scale = 1.0f + 2.0f * mcpt_gamma(3);
    /* Woop et al. 2013, ray preparation: the dimension where |d| is largest becomes z; kx, ky
     * are swapped when d[kz] < 0 to keep the triangles' winding; then the shear constants. */
    float ad[3] = {fabsf(d[0]), fabsf(d[1]), fabsf(d[2])};
    int kz = ad[0] >= ad[1] ? (ad[0] >= ad[2] ? 0 : 2) : (ad[1] >= ad[2] ? 1 : 2);
    int kx = kz == 2 ? 0 : kz + 1;
    int ky = kx == 2 ? 0 : kx + 1;
    if (d[kz] < 0.0f) {
        int tmp = kx;
        kx = ky;
        ky = tmp;
    }
    rp->kx = kx;
    rp->ky = ky;
    rp->kz = kz;
    rp->sx = d[kx] / d[kz];
    rp->sy = d[ky] / d[kz];
    rp->sz = 1.0f / d[kz];
}

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

static bool tri_hit(const struct bvh_tri *tri, const struct ray_pre *rp, float t_min, float t_max,
                    float *t_out, float *u_out, float *v_out);

struct stack_entry {
    uint32_t node_idx; /* node still to visit */
    float t_entry;     /* where the ray enters its box */
}; /* 8 bytes */

bool bvh_intersect(const struct bvh *bvh, const struct ray *ray, struct bvh_hit *hit)
{
    if (bvh->n_nodes == 0)
        return false;
    struct ray_pre rp;
    ray_setup(ray, &rp);
    const struct bvh_node *nodes = bvh->nodes;
    const float t_min = ray->t_min;
    float t_hit = ray->t_max; /* closest hit so far; shrinks */
    float u_hit = 0.0f;
    float v_hit = 0.0f;
    uint32_t tri_idx = UINT32_MAX;
    float t_entry;
    if (!box_hit(&nodes[0], &rp, t_min, t_hit, &t_entry))
        return false;
    struct stack_entry stack[BVH_MAX_DEPTH];
    uint32_t n_stack = 0;
    uint32_t node_idx = 0;
    for (;;) {
        const struct bvh_node *node = &nodes[node_idx];
        if (node->n_tris > 0) {
            uint32_t end = node->left_first + node->n_tris;
            for (uint32_t i = node->left_first; i < end; i++) {
                float t;
                float u;
                float v;
                if (tri_hit(&bvh->tris[i], &rp, t_min, t_hit, &t, &u, &v)) {
                    t_hit = t;
                    u_hit = u;
                    v_hit = v;
                    tri_idx = i;
                }
            }
        } else {
            uint32_t near_idx = node->left_first;
            uint32_t far_idx = near_idx + 1;
            float t_near;
            float t_far;
            bool hit_near = box_hit(&nodes[near_idx], &rp, t_min, t_hit, &t_near);
            bool hit_far = box_hit(&nodes[far_idx], &rp, t_min, t_hit, &t_far);
            if (hit_near && hit_far) {
                if (t_far < t_near) {
                    uint32_t tmp_idx = near_idx;
                    near_idx = far_idx;
                    far_idx = tmp_idx;
                    float tmp_t = t_near;
                    t_near = t_far;
                    t_far = tmp_t;
                }
                assert(n_stack < BVH_MAX_DEPTH);
                stack[n_stack++] = (struct stack_entry){far_idx, t_far};
                node_idx = near_idx;
                continue;
            }
            if (hit_near || hit_far) {
                node_idx = hit_near ? near_idx : far_idx;
                continue;
            }
        }
        /* pop the next pending node that still starts before the closest hit */
        do {
            if (n_stack == 0)
                goto done;
            n_stack--;
        } while (stack[n_stack].t_entry > t_hit);
        node_idx = stack[n_stack].node_idx;
    }
done:
    if (tri_idx == UINT32_MAX)
        return false;
    *hit = (struct bvh_hit){t_hit, u_hit, v_hit, bvh->prim_idx[tri_idx]};
    return true;
}

/* Any hit: the same boxes against the fixed [t_min, t_max], children in stored order, and the
 * first triangle hit ends the search.  It reports a hit exactly when bvh_intersect does. */
bool bvh_occluded(const struct bvh *bvh, const struct ray *ray)
{
    if (bvh->n_nodes == 0)
        return false;
    struct ray_pre rp;
    ray_setup(ray, &rp);
    const struct bvh_node *nodes = bvh->nodes;
    const float t_min = ray->t_min;
    const float t_max = ray->t_max;
    float t_entry;
    if (!box_hit(&nodes[0], &rp, t_min, t_max, &t_entry))
        return false;
    uint32_t stack[BVH_MAX_DEPTH];
    uint32_t n_stack = 0;
    uint32_t node_idx = 0;
    for (;;) {
        const struct bvh_node *node = &nodes[node_idx];
        if (node->n_tris > 0) {
            uint32_t end = node->left_first + node->n_tris;
            for (uint32_t i = node->left_first; i < end; i++) {
                float t;
                float u;
                float v;
                if (tri_hit(&bvh->tris[i], &rp, t_min, t_max, &t, &u, &v))
                    return true;
            }
        } else {
            uint32_t left_idx = node->left_first;
            bool hit_left = box_hit(&nodes[left_idx], &rp, t_min, t_max, &t_entry);
            bool hit_right = box_hit(&nodes[left_idx + 1], &rp, t_min, t_max, &t_entry);
            if (hit_left && hit_right) {
                assert(n_stack < BVH_MAX_DEPTH);
                stack[n_stack++] = left_idx + 1;
                node_idx = left_idx;
                continue;
            }
            if (hit_left || hit_right) {
                node_idx = hit_left ? left_idx : left_idx + 1;
                continue;
            }
        }
        if (n_stack == 0)
            return false;
        node_idx = stack[--n_stack];
    }
}

/* ---- Watertight ray-triangle test: Woop, Benthin, Wald 2013 -----------------------------------
 * Translate the vertices to the ray origin, shear so the ray runs along +z from the origin, and
 * the question becomes 2D: does (0, 0) lie inside the projected triangle A, B, C?  The scaled
 * barycentric coordinates are the 2D edge functions
 *   U = Cx By - Cy Bx   (weight of A = p0),  V = Ax Cy - Ay Cx  (p1),  W = Bx Ay - By Ax  (p2)
 * Two triangles sharing an edge evaluate that edge's function on the same sheared endpoints with
 * the operands swapped, and fl(a b - c d) = -fl(c d - a b), so no ray can slip between them
 * (watertight along edges and at vertices).  This needs the products not to be contracted into
 * FMAs (see the pragma at the top of the file).  Where a float edge function is exactly 0 the
 * sign is unreliable and all three are recomputed in double (the paper's double-precision
 * fallback; the products of floats are exact in double).  Both signs are accepted (no culling).
 *   det = U + V + W,  T = U Az + V Bz + W Cz,  t = T / det,  u = V / det,  v = W / det
 * A hit needs t_min < t < t_max and t > delta_t, PBRT's bound on the rounding error of t (a hit
 * that close may lie behind the origin, so a negative t_min finds nothing behind it either);
 * det == 0 (ray parallel to, or in, the plane) is a miss. */
static inline float max_abs3(float a, float b, float c)
{
    float m = fabsf(a) > fabsf(b) ? fabsf(a) : fabsf(b);
    return fabsf(c) > m ? fabsf(c) : m;
}

static bool tri_hit(const struct bvh_tri *tri, const struct ray_pre *rp, float t_min, float t_max,
                    float *t_out, float *u_out, float *v_out)
{
    const int kx = rp->kx;
    const int ky = rp->ky;
    const int kz = rp->kz;
    /* vertices relative to the ray origin */
    float a_x = tri->p0[kx] - rp->o[kx];
    float a_y = tri->p0[ky] - rp->o[ky];
    float a_z = tri->p0[kz] - rp->o[kz];
    float b_x = tri->p1[kx] - rp->o[kx];
    float b_y = tri->p1[ky] - rp->o[ky];
    float b_z = tri->p1[kz] - rp->o[kz];
    float c_x = tri->p2[kx] - rp->o[kx];
    float c_y = tri->p2[ky] - rp->o[ky];
    float c_z = tri->p2[kz] - rp->o[kz];
    /* shear so the ray direction becomes (0, 0, 1) */
    float Ax = a_x - rp->sx * a_z;
    float Ay = a_y - rp->sy * a_z;
    float Bx = b_x - rp->sx * b_z;
    float By = b_y - rp->sy * b_z;
    float Cx = c_x - rp->sx * c_z;
    float Cy = c_y - rp->sy * c_z;
    /* scaled barycentric coordinates */
    float U = Cx * By - Cy * Bx;
    float V = Ax * Cy - Ay * Cx;
    float W = Bx * Ay - By * Ax;
    if (U == 0.0f || V == 0.0f || W == 0.0f) {
        double CxBy = (double)Cx * (double)By;
        double CyBx = (double)Cy * (double)Bx;
        U = (float)(CxBy - CyBx);
        double AxCy = (double)Ax * (double)Cy;
        double AyCx = (double)Ay * (double)Cx;
        V = (float)(AxCy - AyCx);
        double BxAy = (double)Bx * (double)Ay;
        double ByAx = (double)By * (double)Ax;
        W = (float)(BxAy - ByAx);
    }
    /* (0, 0) is outside when the edge functions disagree in sign */
    if ((U < 0.0f || V < 0.0f || W < 0.0f) && (U > 0.0f || V > 0.0f || W > 0.0f))
        return false;
    float det = U + V + W;
    if (det == 0.0f)
        return false;
    /* scaled hit distance: the sheared z of the vertices, weighted */
    float Az = rp->sz * a_z;
    float Bz = rp->sz * b_z;
    float Cz = rp->sz * c_z;
    float T = U * Az + V * Bz + W * Cz;
    float inv_det = 1.0f / det;
    float t = T * inv_det;
    if (!(t > t_min && t < t_max)) /* written so that a NaN t is a miss */
        return false;
    /* PBRT 4e, ch. 6, "Avoiding Intersections Behind Ray Origins": the rounding error of t is at
     * most delta_t; a hit with t <= delta_t may lie behind the origin and is rejected.  With
     * offset_ray_origin this keeps spawned rays off their own triangle even for slivers. */
    float max_xt = max_abs3(Ax, Bx, Cx);
    float max_yt = max_abs3(Ay, By, Cy);
    float max_zt = max_abs3(Az, Bz, Cz);
    float max_e = max_abs3(U, V, W);
    /* the shear's error scales with the unscaled z (|sx|, |sy| <= 1); PBRT writes max_zt, the
     * same only for |d[kz]| = 1, and a ray's d need not be unit length here */
    float max_z = max_abs3(a_z, b_z, c_z);
    float delta_x = mcpt_gamma(5) * (max_xt + max_z);
    float delta_y = mcpt_gamma(5) * (max_yt + max_z);
    float delta_z = mcpt_gamma(3) * max_zt;
    float delta_e = 2.0f * (mcpt_gamma(2) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
    float delta_t = 3.0f * (mcpt_gamma(3) * max_e * max_zt + delta_e * max_zt + delta_z * max_e) *
                    fabsf(inv_det);
    if (!(t > delta_t))
        return false;
    *t_out = t;
    *u_out = V * inv_det;
    *v_out = W * inv_det;
    return true;
}

/* ---- Brute force: every triangle, the same test ----------------------------------------------
 * O(n) per ray, the baseline of the BVH-versus-naive table and the oracle of the tests.  It
 * tests the BVH-ordered triangles with tri_hit, so a triangle's t, u, v are bit-identical to
 * what bvh_intersect computes for it; among exactly equal t the lowest BVH position wins. */
bool bvh_intersect_brute(const struct bvh *bvh, const struct ray *ray, struct bvh_hit *hit)
{
    struct ray_pre rp;
    ray_setup(ray, &rp);
    float t_hit = ray->t_max;
    float u_hit = 0.0f;
    float v_hit = 0.0f;
    uint32_t tri_idx = UINT32_MAX;
    for (uint32_t i = 0; i < bvh->n_tris; i++) {
        float t;
        float u;
        float v;
        if (tri_hit(&bvh->tris[i], &rp, ray->t_min, t_hit, &t, &u, &v)) {
            t_hit = t;
            u_hit = u;
            v_hit = v;
            tri_idx = i;
        }
    }
    if (tri_idx == UINT32_MAX)
        return false;
    *hit = (struct bvh_hit){t_hit, u_hit, v_hit, bvh->prim_idx[tri_idx]};
    return true;
}

/* ---- Stats ------------------------------------------------------------------------------------
 * SAH cost of the finished tree, normalised by the root's area (Wald 2007's cost model summed
 * over the tree; A(n) / A(root) is the probability that a ray hitting the root hits node n):
 *   C = sum_interior C_trav A(n) / A(root) + sum_leaves C_isect N(n) A(n) / A(root)
 * When the root has zero area (every triangle at one point) all ratios are taken as 1. */
static float node_half_area(const struct bvh_node *node)
{
    struct box b = {{node->min[0], node->min[1], node->min[2]},
                    {node->max[0], node->max[1], node->max[2]}};
    return box_half_area(&b);
}

static void compute_stats(struct bvh *bvh)
{
    struct bvh_stats *st = &bvh->stats;
    st->n_tris = bvh->n_tris;
    st->n_nodes = bvh->n_nodes > 0 ? bvh->n_nodes - 1 : 0; /* without the unused nodes[1] */
    st->n_leaves = 0;
    st->sah_cost = 0.0;
    double root_area = bvh->n_nodes > 0 ? (double)node_half_area(&bvh->nodes[0]) : 0.0;
    for (uint32_t i = 0; i < bvh->n_nodes; i++) {
        if (i == 1)
            continue;
        const struct bvh_node *node = &bvh->nodes[i];
        double ratio = root_area > 0.0 ? (double)node_half_area(node) / root_area : 1.0;
        if (node->n_tris > 0) {
            st->n_leaves++;
            st->sah_cost += BVH_COST_INTERSECT * (double)node->n_tris * ratio;
        } else {
            st->sah_cost += BVH_COST_TRAVERSAL * ratio;
        }
    }
    st->bytes = (size_t)bvh->n_nodes * sizeof(struct bvh_node) +
                (size_t)bvh->n_tris * (sizeof(struct bvh_tri) + sizeof(uint32_t));
}

struct bvh_stats bvh_get_stats(const struct bvh *bvh) { return bvh->stats; }

void bvh_free(struct bvh *bvh)
{
    if (!bvh)
        return;
    free(bvh->nodes);
    free(bvh->tris);
    free(bvh->prim_idx);
    free(bvh);
}
