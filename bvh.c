/* bvh.c - BVH over triangles.  The scalar reference: 32-byte binary nodes in one flat array,
 * triangles permuted into BVH order, a binned-SAH build (Wald 2007, "On fast Construction of
 * SAH-based Bounding Volume Hierarchies") on several threads for large meshes, ordered
 * traversal with a conservative slab test (PBRT 4e, ch. 6, "Conservative Ray-Bounds
 * Intersections") and the watertight test of Woop, Benthin, Wald 2013, "Watertight Ray/Triangle
 * Intersection".  The fast layout is converted from it by the SAH-optimal collapse of Ylitie,
 * Karras, Laine 2017: 8-wide nodes with SoA child boxes (Wald et al. 2008, "Getting Rid of
 * Packets"), SoA leaves tested 8 at a time with the same watertight test, single rays and 8-ray
 * packets.  Reading order: layouts, build, conversion, reference traversal, the triangle test,
 * the SIMD lanes, wide traversal, packets, brute force, stats.  Measurements: docs/bvh.md. */
#include "bvh.h"

#include <assert.h>
#include <float.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <time.h>

/* The watertight test needs a * b - c * d rounded as two products and a difference, never fused
 * into an FMA (see tri_hit).  gcc does not contract under -std=c11; clang does unless told. */
#if defined(__clang__)
#pragma STDC FP_CONTRACT OFF
#endif

/* ---- The binary reference layout --------------------------------------------------------------
 * struct bvh_node (bvh.h): 32 bytes, box min/max plus left_first and n_tris.
 * nodes[0] is the root; an empty BVH (n_tris == 0) has no nodes at all.  nodes[1] is unused, so
 *   that every sibling pair starts at an even index: in the 64-byte aligned array the two
 *   children of a node share one cache line.  Nodes are numbered in depth-first build order
 *   (a node's child pair is allocated when the node is split, left subtree first).
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

/* ---- The 8-wide layout --------------------------------------------------------------------------
 * Converted from the binary tree (convert_wide, "Conversion" below): each wide node gathers up
 * to BVH_WIDTH binary descendants as children, and small subtrees become single leaves, as the
 * SAH decides.  The child boxes are stored SoA, bounds[2 a][lane] = min along axis a and
 * bounds[2 a + 1][lane] = max, so one ray meets all eight boxes in one SIMD slab test.
 * A child reference is a wide node index, or WIDE_LEAF | first << 3 | (n - 1) for a leaf of
 * n in 1..8 triangles starting at wide triangle `first`.  An unused lane has the empty box
 * (min +inf, max -inf), which no ray hits, whatever the signs of its direction.
 * A leaf holds the triangles of one binary subtree (at most 8) minus the degenerate ones (a
 * binary leaf of more than 8, which only the depth cap makes, becomes a small wide subtree of
 * 8-triangle leaves).  A leaf's triangles
 * are SoA: leaf_tris[9 first + (3 k + a) n + i] is coordinate a of vertex k of its triangle i
 * (the same three vertices as struct bvh_tri, so the test stays watertight), and
 * wide_prim_idx[first + i] is the caller's index.  The array has 8 floats of padding at its end
 * so that an 8-lane load of any leaf row stays inside it; lanes i >= n are masked.
 * Wide nodes are numbered in depth-first order, root = 0; leaves' triangles in the same order. */
#define BVH_WIDTH 8
#define WIDE_LEAF 0x80000000u
#define WIDE_MAX_TRIS (1u << 28) /* first must fit in 28 bits */

struct wide_node {
    _Alignas(64) float bounds[6][BVH_WIDTH]; /* SoA child boxes: min x, max x, min y, ... */
    uint32_t child[BVH_WIDTH];               /* child references */
    uint32_t n_children;                     /* lanes in use: 0 .. n_children - 1 */
    uint32_t pad[7];
}; /* 256 bytes: four cache lines */
_Static_assert(sizeof(struct wide_node) == 256, "wide_node must be 256 bytes");

struct bvh {
    /* binary reference (BVH_LAYOUT_BINARY) */
    struct bvh_node *nodes; /* n_nodes nodes, 64-byte aligned; root at 0, nodes[1] unused */
    struct bvh_tri *tris;   /* n_tris triangles in BVH order */
    uint32_t *prim_idx;     /* prim_idx[i]: the caller's index of tris[i] */
    uint32_t n_nodes;       /* length of nodes, the unused nodes[1] included; 0 when empty */
    /* wide (BVH_LAYOUT_WIDE) */
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
 * Threads: every node's split depends only on its own range of refs, so the tree is the same
 * for any thread count.  With several threads the top nodes are split first, their binning
 * shared by all threads (each fills private bins over a slice, then they are merged: box
 * unions and counts are exact), until there are BVH_SUBTREES_PER_THREAD subtrees per thread;
 * those are built in parallel into reserved node ranges and renumbered into the order above. */

/* The constants were chosen by measurement (docs/bvh.md, "Build constants"): for the binary
 * reference on the 100k-triangle dragon, C_isect = 0.5 traced 15-25% faster than 1.0 and 0.75
 * was within noise; 32 bins cut node visits by 1.5% but built 28% slower, 8 bins visited 1.5%
 * more.  For the wide layout, converted from this tree, C_isect = 0.15 and 0.3 (larger binary
 * leaves) made the wide traversal test 3-11% more triangles per ray at the same node visits on
 * the bunny, dragon and Sponza, and 1.0 gave the same as 0.5. */
#define BVH_COST_TRAVERSAL 1.0f /* C_trav: visiting one interior node (two box tests); the unit */
#define BVH_COST_INTERSECT 0.5f /* C_isect: one triangle test, in units of C_trav */
#define BVH_N_BINS 16           /* bins per axis */
#define BVH_MAX_LEAF_TRIS 8     /* a larger node is split even when the SAH prefers a leaf */
#define BVH_MAX_DEPTH 64        /* deepest node; bounds the build and traversal stacks */
#define BVH_PARALLEL_MIN_TRIS 65536 /* fewer: build on one thread (the threads cost more) */
#define BVH_PARALLEL_BIN_MIN 16384  /* top nodes with more refs share their binning */
#define BVH_SUBTREES_PER_THREAD 4   /* subtrees handed to the threads, per thread */
#define BVH_MAX_THREADS 64

/* What the build knows of one triangle: its box (the centre is derived from it). */
struct prim_ref {
    float min[3];      /* lower corner of the box of the stored vertices */
    uint32_t prim_idx; /* the caller's index of the triangle */
    float max[3];      /* upper corner */
    uint32_t is_degenerate; /* 1 for a zero-area triangle (dropped from the wide layout) */
}; /* 32 bytes */

struct box {
    float min[4]; /* lower corner; +inf when empty; [3] is padding for 4-lane SIMD (kept 0) */
    float max[4]; /* upper corner; -inf when empty; [3] likewise */
}; /* 32 bytes */

struct bin {
    struct box box; /* union of the boxes of the triangles whose centre falls in the bin */
    uint32_t n;     /* number of those triangles */
}; /* 36 bytes */

struct bins {
    struct bin b[3][BVH_N_BINS]; /* per axis */
}; /* 1728 bytes */

/* A node waiting to be built: refs[begin, end) at depth, with the bounds of the refs' boxes
 * and of their centres (computed while the parent partitioned them). */
struct build_task {
    uint32_t node_idx;        /* node to fill */
    uint32_t begin;           /* first ref */
    uint32_t end;             /* one past the last */
    uint32_t depth;           /* root = 0 */
    uint32_t node_base;       /* parallel subtrees: first node index of its reserved range */
    struct box bounds;        /* of the refs' boxes */
    struct box centre_bounds; /* of their centres */
}; /* 84 bytes */

/* A split candidate: sah_sum = A_L N_L + A_R N_R (half areas), the part of C_split that varies. */
struct split {
    int axis;      /* 0, 1, 2; -1 when no candidate separates the centres */
    int bin;       /* the left child takes bins 0..bin */
    float sah_sum; /* A_L * N_L + A_R * N_R */
}; /* 12 bytes */

struct build_ctx {
    struct prim_ref *refs;  /* n_tris refs, permuted into BVH order by the build */
    struct bvh_node *nodes; /* node array being written */
    int n_threads;          /* 1 .. BVH_MAX_THREADS */
};

static const struct box empty_box = {{INFINITY, INFINITY, INFINITY, 0.0f},
                                     {-INFINITY, -INFINITY, -INFINITY, 0.0f}};

static void box_grow(struct box *b, const float min[3], const float max[3])
{
    for (int a = 0; a < 3; a++) {
        b->min[a] = min[a] < b->min[a] ? min[a] : b->min[a];
        b->max[a] = max[a] > b->max[a] ? max[a] : b->max[a];
    }
}

/* b grows to contain c: all four lanes (the padding lanes stay 0), which the compiler turns into
 * one minps and one maxps. */
static inline void box_union(struct box *b, const struct box *c)
{
    for (int a = 0; a < 4; a++) {
        b->min[a] = c->min[a] < b->min[a] ? c->min[a] : b->min[a];
        b->max[a] = c->max[a] > b->max[a] ? c->max[a] : b->max[a];
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

static void ref_centre(const struct prim_ref *r, float c[3])
{
    for (int a = 0; a < 3; a++)
        c[a] = 0.5f * (r->min[a] + r->max[a]);
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

static void bins_clear(struct bins *bins)
{
    for (int axis = 0; axis < 3; axis++)
        for (int k = 0; k < BVH_N_BINS; k++)
            bins->b[axis][k] = (struct bin){empty_box, 0};
}

/* One pass fills the bins of all three axes (Wald 2007, sec. 3.2).  With SSE2 one ref's box,
 * centre and three bin indices are each one 4-lane operation (lane 3 is zeroed padding); the
 * scalar loop below is the same arithmetic lane by lane, so both give the same bins. */
#if defined(__SSE2__) && !defined(BVH_NO_SIMD)
#include <emmintrin.h>

static inline __m128 box_lane_mask(void)
{
    return _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0));
}

static void bins_fill(struct bins *bins, const struct prim_ref *refs, uint32_t begin,
                      uint32_t end, const struct box *centre_bounds)
{
    const __m128 xyz = box_lane_mask();
    const __m128 c_min = _mm_and_ps(_mm_loadu_ps(centre_bounds->min), xyz);
    const __m128 scale = _mm_setr_ps(bin_scale(centre_bounds, 0), bin_scale(centre_bounds, 1),
                                     bin_scale(centre_bounds, 2), 0.0f);
    const __m128 half = _mm_set1_ps(0.5f);
    const __m128 last = _mm_set1_ps((float)(BVH_N_BINS - 1));
    for (uint32_t i = begin; i < end; i++) {
        const struct prim_ref *r = &refs[i];
        __m128 lo = _mm_and_ps(_mm_loadu_ps(r->min), xyz); /* lane 3 held prim_idx */
        __m128 hi = _mm_and_ps(_mm_loadu_ps(r->max), xyz);
        __m128 c = _mm_mul_ps(half, _mm_add_ps(lo, hi));
        /* bin_index: (int) min((c - c_min) scale, N - 1), which equals min((int) ..., N - 1) */
        __m128i k = _mm_cvttps_epi32(_mm_min_ps(_mm_mul_ps(_mm_sub_ps(c, c_min), scale), last));
        int idx[4];
        _mm_storeu_si128((__m128i *)idx, k);
        for (int axis = 0; axis < 3; axis++) {
            struct bin *b = &bins->b[axis][idx[axis]];
            _mm_storeu_ps(b->box.min, _mm_min_ps(lo, _mm_loadu_ps(b->box.min)));
            _mm_storeu_ps(b->box.max, _mm_max_ps(hi, _mm_loadu_ps(b->box.max)));
            b->n++;
        }
    }
}
#else
static void bins_fill(struct bins *bins, const struct prim_ref *refs, uint32_t begin,
                      uint32_t end, const struct box *centre_bounds)
{
    float scale[3];
    for (int axis = 0; axis < 3; axis++)
        scale[axis] = bin_scale(centre_bounds, axis);
    for (uint32_t i = begin; i < end; i++) {
        const struct prim_ref *r = &refs[i];
        float c[3];
        ref_centre(r, c);
        for (int axis = 0; axis < 3; axis++) {
            struct bin *b = &bins->b[axis][bin_index(c[axis], centre_bounds->min[axis],
                                                     scale[axis])];
            box_grow(&b->box, r->min, r->max);
            b->n++;
        }
    }
}
#endif

static void bins_merge(struct bins *into, const struct bins *from)
{
    for (int axis = 0; axis < 3; axis++) {
        for (int k = 0; k < BVH_N_BINS; k++) {
            box_union(&into->b[axis][k].box, &from->b[axis][k].box);
            into->b[axis][k].n += from->b[axis][k].n;
        }
    }
}

/* The cheapest plane of n binned refs: per axis a sweep from the right gathers the right
 * children's areas and one from the left evaluates every plane.  With SSE2 the running box is
 * one register and its half area dx dy + dy dz + dz dx is formed from one shuffled product,
 * added in the same order as box_half_area, so both paths give the same split. */
#if defined(__SSE2__) && !defined(BVH_NO_SIMD)
static inline float half_area_sse(__m128 lo, __m128 hi)
{
    __m128 d = _mm_sub_ps(hi, lo);
    __m128 d_yzx = _mm_shuffle_ps(d, d, _MM_SHUFFLE(3, 0, 2, 1));
    __m128 p = _mm_mul_ps(d, d_yzx); /* dx dy, dy dz, dz dx */
    float q[4];
    _mm_storeu_ps(q, p);
    return q[0] + q[1] + q[2];
}

static struct split bins_best_split(const struct bins *bins, uint32_t n)
{
    struct split best = {-1, 0, INFINITY};
    const __m128 empty_lo = _mm_loadu_ps(empty_box.min);
    const __m128 empty_hi = _mm_loadu_ps(empty_box.max);
    for (int axis = 0; axis < 3; axis++) {
        const struct bin *b = bins->b[axis];
        float right_area[BVH_N_BINS];
        uint32_t right_n[BVH_N_BINS];
        __m128 lo = empty_lo;
        __m128 hi = empty_hi;
        uint32_t acc_n = 0;
        for (int k = BVH_N_BINS - 1; k > 0; k--) {
            lo = _mm_min_ps(_mm_loadu_ps(b[k].box.min), lo);
            hi = _mm_max_ps(_mm_loadu_ps(b[k].box.max), hi);
            acc_n += b[k].n;
            right_area[k] = acc_n > 0 ? half_area_sse(lo, hi) : 0.0f;
            right_n[k] = acc_n;
        }
        lo = empty_lo;
        hi = empty_hi;
        acc_n = 0;
        for (int k = 0; k < BVH_N_BINS - 1; k++) {
            lo = _mm_min_ps(_mm_loadu_ps(b[k].box.min), lo);
            hi = _mm_max_ps(_mm_loadu_ps(b[k].box.max), hi);
            acc_n += b[k].n;
            if (acc_n == 0 || acc_n == n)
                continue;
            float sah_sum = half_area_sse(lo, hi) * (float)acc_n +
                            right_area[k + 1] * (float)right_n[k + 1];
            if (sah_sum < best.sah_sum)
                best = (struct split){axis, k, sah_sum};
        }
    }
    return best;
}
#else
static struct split bins_best_split(const struct bins *bins, uint32_t n)
{
    struct split best = {-1, 0, INFINITY};
    for (int axis = 0; axis < 3; axis++) {
        const struct bin *b = bins->b[axis];
        /* right sweep: right_area[k], right_n[k] describe bins k .. BVH_N_BINS - 1 */
        float right_area[BVH_N_BINS];
        uint32_t right_n[BVH_N_BINS];
        struct box acc = empty_box;
        uint32_t acc_n = 0;
        for (int k = BVH_N_BINS - 1; k > 0; k--) {
            box_union(&acc, &b[k].box);
            acc_n += b[k].n;
            right_area[k] = acc_n > 0 ? box_half_area(&acc) : 0.0f;
            right_n[k] = acc_n;
        }
        /* left sweep: the plane after bin k puts bins 0..k left, k+1.. right */
        acc = empty_box;
        acc_n = 0;
        for (int k = 0; k < BVH_N_BINS - 1; k++) {
            box_union(&acc, &b[k].box);
            acc_n += b[k].n;
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
#endif

/* Fork-join on up to n_threads threads: fn(arg + i * arg_bytes) for i in [0, n_jobs), job 0 on
 * the calling thread.  A thread that cannot be started runs its job inline. */
static void run_jobs(int n_jobs, void *(*fn)(void *), void *args, size_t arg_bytes)
{
    pthread_t threads[BVH_MAX_THREADS];
    bool started[BVH_MAX_THREADS] = {false};
    assert(n_jobs <= BVH_MAX_THREADS);
    for (int i = 1; i < n_jobs; i++) {
        void *arg = (char *)args + (size_t)i * arg_bytes;
        started[i] = pthread_create(&threads[i], NULL, fn, arg) == 0;
    }
    fn(args);
    for (int i = 1; i < n_jobs; i++) {
        if (started[i])
            pthread_join(threads[i], NULL);
        else
            fn((char *)args + (size_t)i * arg_bytes);
    }
}

struct bin_job {
    const struct prim_ref *refs;
    uint32_t begin;
    uint32_t end;
    const struct box *centre_bounds;
    struct bins bins;
};

static void *bin_job_run(void *arg)
{
    struct bin_job *job = arg;
    bins_clear(&job->bins);
    bins_fill(&job->bins, job->refs, job->begin, job->end, job->centre_bounds);
    return NULL;
}

/* Bins refs[begin, end) on n_threads threads (private bins per slice, merged in slice order). */
static void bins_fill_parallel(struct bins *bins, const struct prim_ref *refs, uint32_t begin,
                               uint32_t end, const struct box *centre_bounds, int n_threads)
{
    struct bin_job *jobs = malloc((size_t)n_threads * sizeof *jobs);
    if (!jobs) {
        bins_clear(bins);
        bins_fill(bins, refs, begin, end, centre_bounds);
        return;
    }
    uint32_t n = end - begin;
    for (int i = 0; i < n_threads; i++) {
        jobs[i].refs = refs;
        jobs[i].begin = begin + (uint32_t)((uint64_t)n * (uint64_t)i / (uint64_t)n_threads);
        jobs[i].end = begin + (uint32_t)((uint64_t)n * (uint64_t)(i + 1) / (uint64_t)n_threads);
        jobs[i].centre_bounds = centre_bounds;
    }
    run_jobs(n_threads, bin_job_run, jobs, sizeof *jobs);
    *bins = jobs[0].bins;
    for (int i = 1; i < n_threads; i++)
        bins_merge(bins, &jobs[i].bins);
    free(jobs);
}

/* Bounds of the boxes and of the centres of refs[begin, end). */
static void range_bounds(const struct prim_ref *refs, uint32_t begin, uint32_t end,
                         struct box *bounds, struct box *centre_bounds)
{
    *bounds = empty_box;
    *centre_bounds = empty_box;
    for (uint32_t i = begin; i < end; i++) {
        float c[3];
        ref_centre(&refs[i], c);
        box_grow(bounds, refs[i].min, refs[i].max);
        box_grow(centre_bounds, c, c);
    }
}

/* Decides task's node and partitions its refs in place.  Returns the first index of the right
 * child, or task->begin when the node is to be a leaf; fills the children's bounds. */
static uint32_t split_task(const struct build_ctx *ctx, const struct build_task *task,
                           int n_threads, struct box child_bounds[2], struct box child_centres[2])
{
    struct prim_ref *refs = ctx->refs;
    uint32_t begin = task->begin;
    uint32_t end = task->end;
    uint32_t n = end - begin;
    /* C_split >= C_trav A (children's areas are >= 0) while C_leaf = C_isect N A: for
     * N <= C_trav / C_isect (= 2) the leaf always wins, and binning is skipped */
    if (n * BVH_COST_INTERSECT <= BVH_COST_TRAVERSAL || task->depth >= BVH_MAX_DEPTH)
        return begin;
    struct bins bins;
    if (n_threads > 1 && n >= BVH_PARALLEL_BIN_MIN) {
        bins_fill_parallel(&bins, refs, begin, end, &task->centre_bounds, n_threads);
    } else {
        bins_clear(&bins);
        bins_fill(&bins, refs, begin, end, &task->centre_bounds);
    }
    struct split best = bins_best_split(&bins, n);
    if (best.axis < 0) { /* all centres coincide: halve the range, or stop when small */
        if (n <= BVH_MAX_LEAF_TRIS)
            return begin;
        uint32_t mid = begin + n / 2;
        range_bounds(refs, begin, mid, &child_bounds[0], &child_centres[0]);
        range_bounds(refs, mid, end, &child_bounds[1], &child_centres[1]);
        return mid;
    }
    /* C_split < C_leaf, both multiplied by A so that a zero-area box (a point) needs no division:
     * C_trav A + C_isect (A_L N_L + A_R N_R) < C_isect N A */
    float area = box_half_area(&task->bounds);
    float split_cost = BVH_COST_TRAVERSAL * area + BVH_COST_INTERSECT * best.sah_sum;
    float leaf_cost = BVH_COST_INTERSECT * (float)n * area;
    if (split_cost >= leaf_cost && n <= BVH_MAX_LEAF_TRIS)
        return begin;
    int axis = best.axis;
    float c_min = task->centre_bounds.min[axis];
    float scale = bin_scale(&task->centre_bounds, axis);
    for (int side = 0; side < 2; side++) {
        child_bounds[side] = empty_box;
        child_centres[side] = empty_box;
    }
    uint32_t i = begin;
    uint32_t j = end;
#if defined(__SSE2__) && !defined(BVH_NO_SIMD)
    /* the scalar loop below, four lanes at a time: the side's box and centre bounds grow */
    const __m128 xyz = box_lane_mask();
    const __m128 half = _mm_set1_ps(0.5f);
    __m128 side_lo[2] = {_mm_loadu_ps(empty_box.min), _mm_loadu_ps(empty_box.min)};
    __m128 side_hi[2] = {_mm_loadu_ps(empty_box.max), _mm_loadu_ps(empty_box.max)};
    __m128 side_c_lo[2] = {side_lo[0], side_lo[0]};
    __m128 side_c_hi[2] = {side_hi[0], side_hi[0]};
    while (i < j) {
        __m128 lo = _mm_and_ps(_mm_loadu_ps(refs[i].min), xyz);
        __m128 hi = _mm_and_ps(_mm_loadu_ps(refs[i].max), xyz);
        __m128 c = _mm_mul_ps(half, _mm_add_ps(lo, hi));
        float c_axis[4];
        _mm_storeu_ps(c_axis, c);
        int side = bin_index(c_axis[axis], c_min, scale) <= best.bin ? 0 : 1;
        side_lo[side] = _mm_min_ps(lo, side_lo[side]);
        side_hi[side] = _mm_max_ps(hi, side_hi[side]);
        side_c_lo[side] = _mm_min_ps(c, side_c_lo[side]);
        side_c_hi[side] = _mm_max_ps(c, side_c_hi[side]);
        if (side == 0) {
            i++;
        } else {
            struct prim_ref tmp = refs[i];
            refs[i] = refs[--j];
            refs[j] = tmp;
        }
    }
    for (int side = 0; side < 2; side++) {
        _mm_storeu_ps(child_bounds[side].min, side_lo[side]);
        _mm_storeu_ps(child_bounds[side].max, side_hi[side]);
        _mm_storeu_ps(child_centres[side].min, side_c_lo[side]);
        _mm_storeu_ps(child_centres[side].max, side_c_hi[side]);
    }
#else
    while (i < j) { /* left takes bins 0..best.bin; each ref's side grows that side's bounds */
        float c[3];
        ref_centre(&refs[i], c);
        if (bin_index(c[axis], c_min, scale) <= best.bin) {
            box_grow(&child_bounds[0], refs[i].min, refs[i].max);
            box_grow(&child_centres[0], c, c);
            i++;
        } else {
            box_grow(&child_bounds[1], refs[i].min, refs[i].max);
            box_grow(&child_centres[1], c, c);
            struct prim_ref tmp = refs[i];
            refs[i] = refs[--j];
            refs[j] = tmp;
        }
    }
#endif
    assert(i > begin && i < end); /* bins_best_split only offers planes with both sides used */
    return i;
}

static void node_set_box(struct bvh_node *node, const struct box *b)
{
    memcpy(node->min, b->min, sizeof node->min);
    memcpy(node->max, b->max, sizeof node->max);
}

/* Builds the subtree of root depth first from an explicit stack, allocating child pairs from
 * root.node_base on.  Returns the deepest depth reached; *n_next is one past the last node
 * used.  Started at the root with node_base 2, this numbers nodes in the canonical order. */
static uint32_t build_subtree(const struct build_ctx *ctx, struct build_task root,
                              uint32_t *n_next)
{
    struct build_task stack[BVH_MAX_DEPTH + 2]; /* one pending right child per level + current */
    int n_stack = 0;
    uint32_t max_depth = 0;
    uint32_t next = root.node_base;
    stack[n_stack++] = root;
    while (n_stack > 0) {
        struct build_task task = stack[--n_stack];
        struct bvh_node *node = &ctx->nodes[task.node_idx];
        node_set_box(node, &task.bounds);
        if (task.depth > max_depth)
            max_depth = task.depth;
        struct box child_bounds[2];
        struct box child_centres[2];
        uint32_t mid = split_task(ctx, &task, 1, child_bounds, child_centres);
        if (mid == task.begin) {
            node->left_first = task.begin;
            node->n_tris = task.end - task.begin;
            continue;
        }
        uint32_t left_idx = next;
        next += 2;
        node->left_first = left_idx;
        node->n_tris = 0;
        assert(n_stack + 2 <= (int)(sizeof stack / sizeof stack[0]));
        stack[n_stack++] = (struct build_task){left_idx + 1, mid,          task.end,
                                               task.depth + 1, 0,          child_bounds[1],
                                               child_centres[1]};
        stack[n_stack++] = (struct build_task){left_idx,       task.begin,      mid,
                                               task.depth + 1, 0,               child_bounds[0],
                                               child_centres[0]};
    }
    *n_next = next;
    return max_depth;
}

/* Parallel subtrees: the threads take tasks from a shared counter, largest first. */
struct subtree_pool {
    const struct build_ctx *ctx;
    struct build_task *tasks;
    uint32_t n_tasks;
    atomic_uint next_task;
    atomic_uint max_depth;
};

static void *subtree_worker(void *arg)
{
    struct subtree_pool *pool = *(struct subtree_pool **)arg;
    for (;;) {
        uint32_t i = atomic_fetch_add(&pool->next_task, 1u);
        if (i >= pool->n_tasks)
            break;
        uint32_t n_next;
        uint32_t depth = build_subtree(pool->ctx, pool->tasks[i], &n_next);
        uint32_t seen = atomic_load(&pool->max_depth);
        while (depth > seen && !atomic_compare_exchange_weak(&pool->max_depth, &seen, depth)) {
        }
    }
    return NULL;
}

static int compare_task_size(const void *a, const void *b)
{
    const struct build_task *x = a;
    const struct build_task *y = b;
    uint32_t nx = x->end - x->begin;
    uint32_t ny = y->end - y->begin;
    return (nx < ny) - (nx > ny); /* largest first */
}

/* Copies the tree under old[old_root] into out[] in the canonical depth-first numbering of
 * build_subtree (root 0, nodes[1] unused, a node's pair allocated when it is visited). */
static uint32_t renumber(const struct bvh_node *old, struct bvh_node *out)
{
    uint32_t stack[2 * (BVH_MAX_DEPTH + 4)];
    int n_stack = 0;
    uint32_t next = 2;
    out[1] = (struct bvh_node){{0}, 0, {0}, 0};
    stack[n_stack++] = 0; /* old index */
    stack[n_stack++] = 0; /* new index */
    while (n_stack > 0) {
        uint32_t new_idx = stack[--n_stack];
        uint32_t old_idx = stack[--n_stack];
        out[new_idx] = old[old_idx];
        if (old[old_idx].n_tris > 0)
            continue;
        uint32_t left = next;
        next += 2;
        out[new_idx].left_first = left;
        assert(n_stack + 4 <= (int)(sizeof stack / sizeof stack[0]));
        stack[n_stack++] = old[old_idx].left_first + 1;
        stack[n_stack++] = left + 1;
        stack[n_stack++] = old[old_idx].left_first;
        stack[n_stack++] = left;
    }
    return next;
}

static uint32_t count_nodes(const struct bvh_node *nodes)
{
    uint32_t stack[BVH_MAX_DEPTH + 2];
    int n_stack = 0;
    uint32_t n = 2; /* the root and the unused slot */
    stack[n_stack++] = 0;
    while (n_stack > 0) {
        const struct bvh_node *node = &nodes[stack[--n_stack]];
        if (node->n_tris > 0)
            continue;
        n += 2;
        stack[n_stack++] = node->left_first + 1;
        stack[n_stack++] = node->left_first;
    }
    return n;
}

/* n nodes on a 64-byte boundary (aligned_alloc wants a multiple of 64 bytes), NULL on overflow. */
static void *alloc_aligned(size_t n, size_t size)
{
    if (size != 0 && n > (SIZE_MAX - 64) / size)
        return NULL;
    size_t bytes = (n * size + 63) / 64 * 64;
    return aligned_alloc(64, bytes == 0 ? 64 : bytes);
}

/* malloc of n elements of size bytes, NULL on overflow. */
static void *alloc_array(size_t n, size_t size)
{
    if (size != 0 && n > SIZE_MAX / size)
        return NULL;
    return malloc(n * size == 0 ? 1 : n * size);
}

/* Builds the binary tree over ctx->refs[0, n) into a fresh exact-size node array (*out_nodes,
 * *out_n_nodes).  Returns the maximum depth, or UINT32_MAX when out of memory. */
static uint32_t build_tree(struct build_ctx *ctx, uint32_t n, const struct box *root_bounds,
                           const struct box *root_centres, struct bvh_node **out_nodes,
                           uint32_t *out_n_nodes)
{
    struct bvh_node *work = alloc_aligned(2 * (size_t)n, sizeof *work);
    struct build_task *pending = NULL;
    if (!work)
        return UINT32_MAX;
    ctx->nodes = work;
    work[1] = (struct bvh_node){{0}, 0, {0}, 0};
    struct build_task root = {0, 0, n, 0, 2, *root_bounds, *root_centres};
    uint32_t max_depth = 0;
    uint32_t n_used = 0;
    bool renumbered = false;
    if (ctx->n_threads <= 1 || n < BVH_PARALLEL_MIN_TRIS) {
        max_depth = build_subtree(ctx, root, &n_used);
    } else {
        /* top nodes, largest first, until every thread has BVH_SUBTREES_PER_THREAD subtrees */
        uint32_t target = (uint32_t)ctx->n_threads * BVH_SUBTREES_PER_THREAD;
        uint32_t cap = 2 * target + 2;
        pending = malloc(cap * sizeof *pending);
        if (!pending) {
            free(work);
            return UINT32_MAX;
        }
        uint32_t n_pending = 0;
        pending[n_pending++] = root;
        uint32_t next = 2;
        while (n_pending < target) {
            uint32_t largest = 0;
            for (uint32_t i = 1; i < n_pending; i++)
                if (pending[i].end - pending[i].begin >
                    pending[largest].end - pending[largest].begin)
                    largest = i;
            struct build_task task = pending[largest];
            if (task.end - task.begin < BVH_PARALLEL_BIN_MIN)
                break; /* the rest is small: leave it to the subtree threads */
            pending[largest] = pending[--n_pending];
            struct bvh_node *node = &work[task.node_idx];
            node_set_box(node, &task.bounds);
            if (task.depth > max_depth)
                max_depth = task.depth;
            struct box child_bounds[2];
            struct box child_centres[2];
            uint32_t mid = split_task(ctx, &task, ctx->n_threads, child_bounds, child_centres);
            if (mid == task.begin) {
                node->left_first = task.begin;
                node->n_tris = task.end - task.begin;
                continue;
            }
            uint32_t left_idx = next;
            next += 2;
            node->left_first = left_idx;
            node->n_tris = 0;
            pending[n_pending++] = (struct build_task){
                left_idx, task.begin, mid, task.depth + 1, 0, child_bounds[0], child_centres[0]};
            pending[n_pending++] = (struct build_task){
                left_idx + 1, mid, task.end, task.depth + 1, 0, child_bounds[1], child_centres[1]};
        }
        /* a subtree of m refs has at most 2 (m - 1) nodes below its root */
        qsort(pending, n_pending, sizeof *pending, compare_task_size);
        for (uint32_t i = 0; i < n_pending; i++) {
            pending[i].node_base = next;
            next += 2 * (pending[i].end - pending[i].begin - 1);
        }
        assert(next <= 2 * n);
        struct subtree_pool pool = {ctx, pending, n_pending, 0, max_depth};
        struct subtree_pool *handles[BVH_MAX_THREADS];
        for (int i = 0; i < ctx->n_threads; i++)
            handles[i] = &pool;
        run_jobs(ctx->n_threads, subtree_worker, handles, sizeof handles[0]);
        max_depth = atomic_load(&pool.max_depth);
        free(pending);
        n_used = count_nodes(work);
        renumbered = true;
    }
    struct bvh_node *nodes = alloc_aligned(n_used, sizeof *nodes);
    if (!nodes) {
        free(work);
        return UINT32_MAX;
    }
    if (renumbered) {
        uint32_t n_check = renumber(work, nodes);
        assert(n_check == n_used);
        (void)n_check;
    } else {
        memcpy(nodes, work, n_used * sizeof *nodes);
    }
    free(work);
    ctx->nodes = NULL;
    *out_nodes = nodes;
    *out_n_nodes = n_used;
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

static bool tri_is_collapsed(const struct bvh_tri *tri)
{
    return memcmp(tri->p0, tri->p1, sizeof tri->p0) == 0 &&
           memcmp(tri->p0, tri->p2, sizeof tri->p0) == 0;
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

/* Refs of triangles [begin, end), in parallel slices. */
struct ref_job {
    struct prim_ref *refs;
    const vec3 *positions;
    const uint32_t *indices;
    uint32_t begin;
    uint32_t end;
    struct box bounds;
    struct box centres;
};

static void *ref_job_run(void *arg)
{
    struct ref_job *job = arg;
    job->bounds = empty_box;
    job->centres = empty_box;
    for (uint32_t i = job->begin; i < job->end; i++) {
        struct bvh_tri tri;
        load_tri(&tri, job->positions, job->indices, i);
        struct prim_ref *r = &job->refs[i];
        for (int a = 0; a < 3; a++) {
            float lo = tri.p0[a] < tri.p1[a] ? tri.p0[a] : tri.p1[a];
            float hi = tri.p0[a] > tri.p1[a] ? tri.p0[a] : tri.p1[a];
            r->min[a] = tri.p2[a] < lo ? tri.p2[a] : lo; /* finite: no NaN rules needed */
            r->max[a] = tri.p2[a] > hi ? tri.p2[a] : hi;
        }
        r->prim_idx = i;
        r->is_degenerate = tri_is_collapsed(&tri) ? 1u : 0u;
        float c[3];
        ref_centre(r, c);
        box_grow(&job->bounds, r->min, r->max);
        box_grow(&job->centres, c, c);
    }
    return NULL;
}

static double now_ms(void)
{
    struct timespec ts;
    timespec_get(&ts, TIME_UTC);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static bool convert_wide(struct bvh *bvh, const vec3 *positions, const uint32_t *indices,
                         const uint8_t *degenerate);
static void compute_stats(struct bvh *bvh);

struct bvh *bvh_build(const vec3 *positions, const uint32_t *indices, uint32_t n_tris,
                      int n_threads)
{
    struct bvh_build_options opt = {n_threads, BVH_LAYOUT_WIDE};
    return bvh_build_with(positions, indices, n_tris, &opt);
}

struct bvh *bvh_build_with(const vec3 *positions, const uint32_t *indices, uint32_t n_tris,
                           const struct bvh_build_options *opt)
{
    double t_start_ms = now_ms();
    struct bvh_build_options o = opt ? *opt : (struct bvh_build_options){1, BVH_LAYOUT_WIDE};
    unsigned layouts = o.layouts ? o.layouts : BVH_LAYOUT_WIDE;
    if (n_tris >= WIDE_MAX_TRIS)
        layouts = BVH_LAYOUT_BINARY;
    int n_threads = o.n_threads < 1 ? 1 : o.n_threads > BVH_MAX_THREADS ? BVH_MAX_THREADS
                                                                          : o.n_threads;
    struct build_ctx ctx = {NULL, NULL, n_threads};
    uint8_t *degenerate = NULL; /* per binary triangle position, for the conversion */
    struct bvh *bvh = calloc(1, sizeof *bvh);
    if (!bvh)
        goto fail;
    bvh->n_tris = n_tris;
    bvh->stats.n_threads = n_threads;
    if (n_tris > 0) {
        if (n_tris > UINT32_MAX / 2)
            goto fail; /* 2 n nodes (2 n - 1 and the unused nodes[1]) must fit in uint32_t */
        ctx.refs = alloc_aligned(n_tris, sizeof *ctx.refs);
        bvh->prim_idx = alloc_array(n_tris, sizeof *bvh->prim_idx);
        if (!ctx.refs || !bvh->prim_idx)
            goto fail;
        /* the build sees only boxes (of the stored, possibly collapsed, vertices) */
        int n_jobs = n_tris >= BVH_PARALLEL_MIN_TRIS ? n_threads : 1;
        struct ref_job jobs[BVH_MAX_THREADS];
        for (int i = 0; i < n_jobs; i++) {
            uint32_t begin = (uint32_t)((uint64_t)n_tris * (uint64_t)i / (uint64_t)n_jobs);
            uint32_t end = (uint32_t)((uint64_t)n_tris * (uint64_t)(i + 1) / (uint64_t)n_jobs);
            jobs[i] = (struct ref_job){ctx.refs, positions, indices, begin, end, empty_box,
                                       empty_box};
        }
        run_jobs(n_jobs, ref_job_run, jobs, sizeof jobs[0]);
        struct box bounds = empty_box;
        struct box centres = empty_box;
        for (int i = 0; i < n_jobs; i++) {
            box_grow(&bounds, jobs[i].bounds.min, jobs[i].bounds.max);
            box_grow(&centres, jobs[i].centres.min, jobs[i].centres.max);
        }
        uint32_t depth = build_tree(&ctx, n_tris, &bounds, &centres, &bvh->nodes, &bvh->n_nodes);
        if (depth == UINT32_MAX)
            goto fail;
        bvh->stats.max_depth = depth;
        /* the refs are in BVH order now; keep what the conversion needs of them */
        degenerate = alloc_array(n_tris, sizeof *degenerate);
        if (!degenerate)
            goto fail;
        for (uint32_t i = 0; i < n_tris; i++) {
            bvh->prim_idx[i] = ctx.refs[i].prim_idx;
            degenerate[i] = (uint8_t)ctx.refs[i].is_degenerate;
        }
        free(ctx.refs);
        ctx.refs = NULL;
        compute_stats(bvh); /* of the binary tree, before it may be dropped */
        if (layouts & BVH_LAYOUT_WIDE) {
            double t_convert_ms = now_ms();
            if (!convert_wide(bvh, positions, indices, degenerate))
                goto fail;
            bvh->stats.convert_ms = now_ms() - t_convert_ms;
        }
        free(degenerate);
        degenerate = NULL;
        if (layouts & BVH_LAYOUT_BINARY) {
            bvh->tris = alloc_array(n_tris, sizeof *bvh->tris);
            if (!bvh->tris)
                goto fail;
            for (uint32_t i = 0; i < n_tris; i++)
                load_tri(&bvh->tris[i], positions, indices, bvh->prim_idx[i]);
        } else {
            free(bvh->nodes);
            free(bvh->prim_idx);
            bvh->nodes = NULL;
            bvh->prim_idx = NULL;
            bvh->n_nodes = 0;
        }
        bvh->layouts = layouts;
    } else {
        compute_stats(bvh);
    }
    bvh->stats.binary_bytes = bvh->layouts & BVH_LAYOUT_BINARY
                                  ? (size_t)bvh->n_nodes * sizeof(struct bvh_node) +
                                        (size_t)n_tris * (sizeof(struct bvh_tri) + sizeof(uint32_t))
                                  : 0;
    bvh->stats.wide_bytes = bvh->layouts & BVH_LAYOUT_WIDE
                                ? (size_t)bvh->n_wide * sizeof(struct wide_node) +
                                      ((size_t)bvh->n_wide_tris * 9 + 8) * sizeof(float) +
                                      (size_t)bvh->n_wide_tris * sizeof(uint32_t)
                                : 0;
    bvh->stats.bytes = bvh->stats.binary_bytes + bvh->stats.wide_bytes;
    bvh->stats.n_wide_nodes = bvh->n_wide;
    bvh->stats.build_ms = now_ms() - t_start_ms;
    return bvh;
fail:
    free(ctx.refs);
    free(degenerate);
    bvh_free(bvh);
    return NULL;
}

unsigned bvh_layouts(const struct bvh *bvh) { return bvh->layouts; }

/* ---- Conversion to the wide layout ----------------------------------------------------------
 * The binary tree is collapsed into 8-wide nodes by the SAH-optimal dynamic programme of
 * Ylitie, Karras, Laine 2017, "Efficient Incoherent Ray Traversal on GPUs Through Compressed
 * Wide BVHs", sec. 4.1.  For each binary node n and i = 1..8 slots of a wide parent, C(n, i) is
 * the least SAH cost of representing n's subtree by at most i children:
 *   C(n, 1)  = min(C_leaf(n), C_node(n))
 *   C(n, i)  = min(C(n, i - 1), C_split(n, i))                          for i > 1
 *   C_split(n, j) = min over 0 < k < j of C(left, k) + C(right, j - k)
 *   C_node(n) = A(n) c_node + C_split(n, 8)       (n becomes a wide node)
 *   C_leaf(n) = A(n) c_leaf if n's subtree has at most 8 triangles, else infinite
 * with A(n) the surface area of n's box.  A leaf costs the same for 1..8 triangles (one woop8
 * call tests them all), so small subtrees merge into one leaf.  Costs are filled bottom up (a
 * node's children have larger indices), then the wide tree is emitted top down following the
 * recorded choices.  A binary leaf of more than 8 triangles (only the depth cap makes one)
 * becomes a small wide subtree of 8-triangle parts.  A first pass counts nodes and triangles so
 * that the arrays are allocated once at their exact size. */
#define WIDE_COST_NODE 1.0f /* c_node: one wide node visit (eight box tests) */
#define WIDE_COST_LEAF 1.0f /* c_leaf: one leaf (woop8), in units of c_node; 1.5 and 2.0 gave
                               the same visits per ray within 1% (docs/bvh.md) */

#define CHOICE_FEWER 0   /* C(n, i) = C(n, i - 1) */
#define CHOICE_LEAF 0xFE /* C(n, 1): n's subtree is one leaf */
#define CHOICE_NODE 0xFF /* C(n, 1): n is a wide node */

struct collapse_entry {
    float cost[BVH_WIDTH];     /* C(n, i), i = 1..8 */
    uint8_t choice[BVH_WIDTH]; /* i = 1: LEAF or NODE; i > 1: FEWER or k, the left's slots */
    uint8_t node_k;            /* C_node: the left child's share of the 8 slots */
    uint32_t first;            /* the subtree's triangles: [first, first + n_tris) */
    uint32_t n_tris;
}; /* 52 bytes */

struct convert {
    const struct bvh *bvh;       /* binary tree: nodes, prim_idx */
    const uint8_t *degenerate;   /* per binary triangle position: zero area, dropped */
    const struct collapse_entry *dp; /* per binary node */
    const vec3 *positions;       /* the caller's mesh, read again for the leaves */
    const uint32_t *indices;     /* (the wide leaves keep the same vertices as struct bvh_tri) */
    struct wide_node *wide;      /* NULL in the counting pass */
    float *leaf_tris;            /* SoA leaves */
    uint32_t *prim_idx;          /* of the wide triangles */
    uint32_t *scratch;           /* valid triangles of one leaf */
    uint32_t n_wide;             /* nodes allocated so far */
    uint32_t n_wide_tris;        /* triangles written so far */
    uint32_t n_leaves;           /* wide leaves */
    uint32_t depth;              /* current wide depth, root = 0 */
    uint32_t max_depth;          /* deepest wide node */
};

/* Wide depth stays below the binary depth cap plus the levels of one oversized leaf
 * (8-way splits of at most 2^28 triangles). */
#define WIDE_MAX_DEPTH (BVH_MAX_DEPTH + 10)
#define WIDE_STACK_SIZE (7 * WIDE_MAX_DEPTH + 8)

static float node_half_area(const struct bvh_node *node)
{
    struct box b = {{node->min[0], node->min[1], node->min[2]},
                    {node->max[0], node->max[1], node->max[2]}};
    return box_half_area(&b);
}

/* Fills the cost table bottom up; children always have larger indices than their parent. */
static void collapse_costs(const struct bvh *bvh, struct collapse_entry *dp)
{
    const struct bvh_node *nodes = bvh->nodes;
    for (uint32_t idx = bvh->n_nodes; idx-- > 0;) {
        if (idx == 1)
            continue;
        const struct bvh_node *node = &nodes[idx];
        struct collapse_entry *e = &dp[idx];
        float area = node_half_area(node);
        if (node->n_tris > 0) {
            e->first = node->left_first;
            e->n_tris = node->n_tris;
            /* an oversized leaf is emitted in 8-triangle parts */
            float n_parts = (float)((node->n_tris + BVH_WIDTH - 1) / BVH_WIDTH);
            for (int i = 0; i < BVH_WIDTH; i++) {
                e->cost[i] = area * WIDE_COST_LEAF * n_parts;
                e->choice[i] = i == 0 ? CHOICE_LEAF : CHOICE_FEWER;
            }
            e->node_k = 0;
            continue;
        }
        const struct collapse_entry *l = &dp[node->left_first];
        const struct collapse_entry *r = &dp[node->left_first + 1];
        e->first = l->first;
        e->n_tris = l->n_tris + r->n_tris;
        float split[BVH_WIDTH + 1];
        uint8_t split_k[BVH_WIDTH + 1];
        for (int j = 2; j <= BVH_WIDTH; j++) {
            split[j] = INFINITY;
            split_k[j] = 1;
            for (int k = 1; k < j; k++) {
                float c = l->cost[k - 1] + r->cost[j - k - 1];
                if (c < split[j]) {
                    split[j] = c;
                    split_k[j] = (uint8_t)k;
                }
            }
        }
        float c_node = area * WIDE_COST_NODE + split[BVH_WIDTH];
        float c_leaf = e->n_tris <= BVH_WIDTH ? area * WIDE_COST_LEAF : INFINITY;
        e->node_k = split_k[BVH_WIDTH];
        e->cost[0] = c_leaf <= c_node ? c_leaf : c_node;
        e->choice[0] = c_leaf <= c_node ? CHOICE_LEAF : CHOICE_NODE;
        for (int i = 2; i <= BVH_WIDTH; i++) {
            bool fewer = e->cost[i - 2] <= split[i];
            e->cost[i - 1] = fewer ? e->cost[i - 2] : split[i];
            e->choice[i - 1] = fewer ? CHOICE_FEWER : split_k[i];
        }
    }
}

static void wide_node_init(struct wide_node *w)
{
    for (int lane = 0; lane < BVH_WIDTH; lane++) {
        for (int a = 0; a < 3; a++) {
            w->bounds[2 * a][lane] = INFINITY;
            w->bounds[2 * a + 1][lane] = -INFINITY;
        }
        w->child[lane] = 0;
    }
    w->n_children = 0;
    memset(w->pad, 0, sizeof w->pad);
}

static void wide_node_add(struct wide_node *w, const struct box *b, uint32_t ref)
{
    uint32_t lane = w->n_children++;
    assert(lane < BVH_WIDTH);
    for (int a = 0; a < 3; a++) {
        w->bounds[2 * a][lane] = b->min[a];
        w->bounds[2 * a + 1][lane] = b->max[a];
    }
    w->child[lane] = ref;
}

/* Writes one wide leaf of the n (1..8) triangles tris[] (binary positions) and returns its
 * reference; grows *box by their vertices. */
static uint32_t emit_leaf(struct convert *cv, const uint32_t *tris, uint32_t n, struct box *box)
{
    assert(n >= 1 && n <= BVH_WIDTH);
    uint32_t first = cv->n_wide_tris;
    cv->n_wide_tris += n;
    cv->n_leaves++;
    if (!cv->wide) /* counting pass */
        return WIDE_LEAF | first << 3 | (n - 1);
    for (uint32_t i = 0; i < n; i++) {
        struct bvh_tri tri;
        uint32_t prim = cv->bvh->prim_idx[tris[i]];
        load_tri(&tri, cv->positions, cv->indices, prim);
        box_grow(box, tri.p0, tri.p0);
        box_grow(box, tri.p1, tri.p1);
        box_grow(box, tri.p2, tri.p2);
        float *base = cv->leaf_tris + 9 * (size_t)first;
        const float *p[3] = {tri.p0, tri.p1, tri.p2};
        for (int k = 0; k < 3; k++)
            for (int a = 0; a < 3; a++)
                base[(size_t)(3 * k + a) * n + i] = p[k][a];
        cv->prim_idx[first + i] = prim;
    }
    return WIDE_LEAF | first << 3 | (n - 1);
}

/* Triangles tris[0, n) as one leaf (n <= 8) or, for more, a wide node of up to eight parts. */
static uint32_t emit_triangles(struct convert *cv, const uint32_t *tris, uint32_t n,
                               struct box *box)
{
    if (n <= BVH_WIDTH)
        return emit_leaf(cv, tris, n, box);
    uint32_t w = cv->n_wide++;
    if (cv->wide)
        wide_node_init(&cv->wide[w]);
    cv->depth++;
    if (cv->depth > cv->max_depth)
        cv->max_depth = cv->depth;
    uint32_t n_parts = (n + BVH_WIDTH - 1) / BVH_WIDTH < BVH_WIDTH ? (n + BVH_WIDTH - 1) / BVH_WIDTH
                                                                   : BVH_WIDTH;
    for (uint32_t part = 0; part < n_parts; part++) {
        uint32_t begin = (uint32_t)((uint64_t)n * part / n_parts);
        uint32_t end = (uint32_t)((uint64_t)n * (part + 1) / n_parts);
        struct box part_box = empty_box;
        uint32_t ref = emit_triangles(cv, tris + begin, end - begin, &part_box);
        box_grow(box, part_box.min, part_box.max);
        if (cv->wide)
            wide_node_add(&cv->wide[w], &part_box, ref);
    }
    cv->depth--;
    return w;
}

/* The wide leaf of binary subtree idx without its degenerate triangles; false when none is
 * left (the leaf is dropped). */
static bool emit_subtree_leaf(struct convert *cv, uint32_t idx, uint32_t *ref)
{
    const struct collapse_entry *e = &cv->dp[idx];
    uint32_t n = 0;
    for (uint32_t i = e->first; i < e->first + e->n_tris; i++)
        if (!cv->degenerate[i])
            cv->scratch[n++] = i;
    if (n == 0)
        return false;
    struct box unused = empty_box;
    *ref = emit_triangles(cv, cv->scratch, n, &unused);
    return true;
}

static uint32_t emit_wide(struct convert *cv, uint32_t idx);

/* Binary node idx given i slots: appends its children (binary indices) to slots[]. */
static void gather_slots(const struct convert *cv, uint32_t idx, int i, uint32_t *slots,
                         int *n_slots)
{
    const struct collapse_entry *e = &cv->dp[idx];
    while (i > 1 && e->choice[i - 1] == CHOICE_FEWER)
        i--;
    if (i == 1) {
        slots[(*n_slots)++] = idx;
        return;
    }
    uint32_t left = cv->bvh->nodes[idx].left_first;
    int k = e->choice[i - 1];
    gather_slots(cv, left, k, slots, n_slots);
    gather_slots(cv, left + 1, i - k, slots, n_slots);
}

/* One slot: binary node idx as a leaf or as a wide node, by C(idx, 1)'s choice. */
static bool emit_slot(struct convert *cv, uint32_t idx, uint32_t *ref)
{
    if (cv->dp[idx].choice[0] == CHOICE_LEAF)
        return emit_subtree_leaf(cv, idx, ref);
    *ref = emit_wide(cv, idx);
    return true;
}

/* A wide node for binary interior node idx (C_node's split of its 8 slots); returns its index. */
static uint32_t emit_wide(struct convert *cv, uint32_t idx)
{
    const struct bvh_node *nodes = cv->bvh->nodes;
    uint32_t slots[BVH_WIDTH];
    int n_slots = 0;
    uint32_t left = nodes[idx].left_first;
    int k = cv->dp[idx].node_k;
    gather_slots(cv, left, k, slots, &n_slots);
    gather_slots(cv, left + 1, BVH_WIDTH - k, slots, &n_slots);
    uint32_t w = cv->n_wide++;
    if (cv->wide)
        wide_node_init(&cv->wide[w]);
    cv->depth++;
    if (cv->depth > cv->max_depth)
        cv->max_depth = cv->depth;
    for (int i = 0; i < n_slots; i++) {
        const struct bvh_node *c = &nodes[slots[i]];
        struct box b = {{c->min[0], c->min[1], c->min[2]}, {c->max[0], c->max[1], c->max[2]}};
        uint32_t ref;
        if (emit_slot(cv, slots[i], &ref) && cv->wide)
            wide_node_add(&cv->wide[w], &b, ref);
    }
    cv->depth--;
    return w;
}

/* The whole tree: the root is always a wide node (with one leaf child when the binary root
 * is best as a leaf). */
static void emit_root(struct convert *cv)
{
    if (cv->dp[0].choice[0] == CHOICE_NODE) {
        emit_wide(cv, 0);
        return;
    }
    uint32_t w = cv->n_wide++;
    if (cv->wide)
        wide_node_init(&cv->wide[w]);
    uint32_t ref;
    const struct bvh_node *root = &cv->bvh->nodes[0];
    struct box b = {{root->min[0], root->min[1], root->min[2]},
                    {root->max[0], root->max[1], root->max[2]}};
    if (emit_subtree_leaf(cv, 0, &ref) && cv->wide)
        wide_node_add(&cv->wide[w], &b, ref);
}

static bool convert_wide(struct bvh *bvh, const vec3 *positions, const uint32_t *indices,
                         const uint8_t *degenerate)
{
    bool ok = false;
    struct collapse_entry *dp = alloc_array(bvh->n_nodes, sizeof *dp);
    uint32_t *scratch = alloc_array(bvh->n_tris, sizeof *scratch);
    if (!dp || !scratch)
        goto done;
    collapse_costs(bvh, dp);
    /* pass 1: count */
    struct convert cv = {bvh,  degenerate, dp, positions, indices, NULL, NULL, NULL, scratch, 0, 0,
                         0,    0,          0};
    emit_root(&cv);
    assert(cv.max_depth <= WIDE_MAX_DEPTH);
    uint32_t n_wide = cv.n_wide;
    uint32_t n_wide_tris = cv.n_wide_tris;
    /* pass 2: write */
    bvh->wide = alloc_aligned(n_wide, sizeof *bvh->wide);
    bvh->leaf_tris = alloc_aligned(9 * (size_t)n_wide_tris + 8, sizeof(float));
    bvh->wide_prim_idx = alloc_array(n_wide_tris, sizeof(uint32_t));
    if (!bvh->wide || !bvh->leaf_tris || !bvh->wide_prim_idx)
        goto done;
    memset(bvh->leaf_tris + 9 * (size_t)n_wide_tris, 0, 8 * sizeof(float));
    cv = (struct convert){bvh,       degenerate,     dp,
                          positions, indices,        bvh->wide,
                          bvh->leaf_tris, bvh->wide_prim_idx, scratch,
                          0,         0,              0,
                          0,         0};
    emit_root(&cv);
    assert(cv.n_wide == n_wide && cv.n_wide_tris == n_wide_tris);
    bvh->n_wide = n_wide;
    bvh->n_wide_tris = n_wide_tris;
    bvh->bounds = bvh->nodes[0];
    bvh->stats.n_wide_leaves = cv.n_leaves;
    ok = true;
done:
    free(dp);
    free(scratch);
    return ok;
}

/* ---- Reference traversal ----------------------------------------------------------------------
 * Closest hit: iterative, depth first, nearer child first.  At an interior node both children's
 * boxes are tested against [t_min, t_hit] (t_hit = the closest hit so far, initially t_max); if
 * both are hit the farther one is pushed with its entry distance and the nearer one visited.
 * A popped node whose entry distance now lies beyond t_hit is skipped.  No allocation.
 * The result is bit for bit that of bvh_intersect_brute (same t, u, v, prim_idx; among exactly
 * equal t either triangle), with one exception: where several triangles are hit within a few
 * ulps of each other (a ray through a shared vertex or edge), the box of the marginally nearer
 * one can start a few ulps beyond t_hit and be culled.  The reported hit is then one of those
 * triangles, at the same point to within rounding.  The wide traversal below has the same
 * contract.
 * A ray starting on a surface (t_min = 0) may report that surface at t ~ 0 when rounding puts
 * its origin behind the plane; tri_hit only rejects t <= delta_t.  Spawned rays must start at
 * offset_ray_origin (vec.h), which puts the origin on the correct side by the error bound. */

/* Per-ray constants, computed once per ray and shared by every box and triangle test. */
struct ray_pre {
    float o[3];        /* origin */
    float d[3];        /* direction */
    float inv_d[3];    /* 1 / d per axis; +-inf where d is +-0 */
    int is_neg[3];     /* inv_d[a] < 0: the slab's near plane is max[a], the far plane min[a] */
    float far_scale;   /* 1 + 2 gamma(3), PBRT 4e, ch. 6, "Conservative Ray-Bounds Intersections" */
    int kx, ky, kz;    /* Woop et al. 2013: kz = argmax |d|, (kx, ky) swapped when d[kz] < 0 */
    float sx, sy, sz;  /* shear: sx = d[kx] / d[kz], sy = d[ky] / d[kz], sz = 1 / d[kz] */
}; /* 72 bytes */

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
 * swapped when d[kz] < 0 to keep the triangles' winding; then the shear constants. */
static inline void ray_setup_woop(struct ray_pre *rp)
{
    const float *d = rp->d;
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

static void ray_setup(const struct ray *ray, struct ray_pre *rp)
{
    ray_setup_box(ray, rp);
    ray_setup_woop(rp);
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
    uint32_t node_idx; /* node still to visit (binary index or wide reference) */
    float t_entry;     /* where the ray enters its box */
}; /* 8 bytes */

static bool binary_intersect(const struct bvh *bvh, const struct ray *ray, struct bvh_hit *hit)
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
 * first triangle hit ends the search.  It reports a hit exactly when binary_intersect does. */
static bool binary_occluded(const struct bvh *bvh, const struct ray *ray)
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
 * det == 0 (ray parallel to, or in, the plane) is a miss.  The SIMD kernel woop8 below performs
 * exactly these operations in the same order on eight lanes, so its t, u, v are the same bits. */
static inline float max_abs3(float a, float b, float c)
{
    float m = fabsf(a) > fabsf(b) ? fabsf(a) : fabsf(b);
    return fabsf(c) > m ? fabsf(c) : m;
}

/* The double-precision fallback for one triangle's sheared 2D vertices. */
static void edge_functions_double(float Ax, float Ay, float Bx, float By, float Cx, float Cy,
                                  float *U, float *V, float *W)
{
    double CxBy = (double)Cx * (double)By;
    double CyBx = (double)Cy * (double)Bx;
    *U = (float)(CxBy - CyBx);
    double AxCy = (double)Ax * (double)Cy;
    double AyCx = (double)Ay * (double)Cx;
    *V = (float)(AxCy - AyCx);
    double BxAy = (double)Bx * (double)Ay;
    double ByAx = (double)By * (double)Ax;
    *W = (float)(BxAy - ByAx);
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
    if (U == 0.0f || V == 0.0f || W == 0.0f)
        edge_functions_double(Ax, Ay, Bx, By, Cx, Cy, &U, &V, &W);
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

/* ---- Eight SIMD lanes -----------------------------------------------------------------------
 * struct f8 holds eight floats, struct m8 eight lane masks (all ones or all zeros).  With AVX2
 * each operation is one instruction on a 256-bit register; otherwise it is the loop written
 * beside it, which is also the definition of what the AVX2 instruction computes.  max_num and
 * min_num keep the running value when the candidate is NaN, as the scalar ones above do. */
#if defined(__AVX2__) && !defined(BVH_NO_SIMD)
#include <immintrin.h>

struct f8 {
    __m256 v;
};
struct m8 {
    __m256 v;
};

const char *bvh_simd_name(void) { return "avx2"; }

static inline struct f8 f8_set1(float s) { return (struct f8){_mm256_set1_ps(s)}; }
static inline struct f8 f8_load(const float *p) { return (struct f8){_mm256_load_ps(p)}; }
static inline struct f8 f8_loadu(const float *p) { return (struct f8){_mm256_loadu_ps(p)}; }
static inline void f8_store(float *p, struct f8 a) { _mm256_storeu_ps(p, a.v); }
static inline struct f8 f8_add(struct f8 a, struct f8 b)
{
    return (struct f8){_mm256_add_ps(a.v, b.v)};
}
static inline struct f8 f8_sub(struct f8 a, struct f8 b)
{
    return (struct f8){_mm256_sub_ps(a.v, b.v)};
}
static inline struct f8 f8_mul(struct f8 a, struct f8 b)
{
    return (struct f8){_mm256_mul_ps(a.v, b.v)};
}
static inline struct f8 f8_div(struct f8 a, struct f8 b)
{
    return (struct f8){_mm256_div_ps(a.v, b.v)};
}
#if defined(__FMA__)
#define BVH_FUSED_SLABS 1
/* a b - c rounded once (vfmsub); only the slab test's fast path uses it */
static inline struct f8 f8_fmsub(struct f8 a, struct f8 b, struct f8 c)
{
    return (struct f8){_mm256_fmsub_ps(a.v, b.v, c.v)};
}
#else
#define BVH_FUSED_SLABS 0
static inline struct f8 f8_fmsub(struct f8 a, struct f8 b, struct f8 c)
{
    return (struct f8){_mm256_sub_ps(_mm256_mul_ps(a.v, b.v), c.v)}; /* never called */
}
#endif
/* candidate > running ? candidate : running (vmaxps returns its second operand on NaN) */
static inline struct f8 f8_max_num(struct f8 running, struct f8 candidate)
{
    return (struct f8){_mm256_max_ps(candidate.v, running.v)};
}
static inline struct f8 f8_min_num(struct f8 running, struct f8 candidate)
{
    return (struct f8){_mm256_min_ps(candidate.v, running.v)};
}
static inline struct f8 f8_abs(struct f8 a)
{
    return (struct f8){_mm256_andnot_ps(_mm256_set1_ps(-0.0f), a.v)};
}
static inline struct m8 f8_lt(struct f8 a, struct f8 b)
{
    return (struct m8){_mm256_cmp_ps(a.v, b.v, _CMP_LT_OQ)};
}
static inline struct m8 f8_le(struct f8 a, struct f8 b)
{
    return (struct m8){_mm256_cmp_ps(a.v, b.v, _CMP_LE_OQ)};
}
static inline struct m8 f8_gt(struct f8 a, struct f8 b)
{
    return (struct m8){_mm256_cmp_ps(a.v, b.v, _CMP_GT_OQ)};
}
static inline struct m8 f8_eq(struct f8 a, struct f8 b)
{
    return (struct m8){_mm256_cmp_ps(a.v, b.v, _CMP_EQ_OQ)};
}
static inline struct m8 m8_or(struct m8 a, struct m8 b)
{
    return (struct m8){_mm256_or_ps(a.v, b.v)};
}
static inline struct m8 m8_and(struct m8 a, struct m8 b)
{
    return (struct m8){_mm256_and_ps(a.v, b.v)};
}
/* a and not b */
static inline struct m8 m8_andnot(struct m8 a, struct m8 b)
{
    return (struct m8){_mm256_andnot_ps(b.v, a.v)};
}
static inline uint32_t m8_bits(struct m8 m) { return (uint32_t)_mm256_movemask_ps(m.v); }
/* lane i set when bit i of bits is */
static inline struct m8 m8_from_bits(uint32_t bits)
{
    const __m256i lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    __m256i b = _mm256_and_si256(_mm256_set1_epi32((int)bits), lane_bit);
    return (struct m8){_mm256_castsi256_ps(_mm256_cmpeq_epi32(b, lane_bit))};
}
/* m ? a : b per lane */
static inline struct f8 f8_select(struct m8 m, struct f8 a, struct f8 b)
{
    return (struct f8){_mm256_blendv_ps(b.v, a.v, m.v)};
}
/* smallest lane */
static inline float f8_hmin(struct f8 a)
{
    __m256 m = _mm256_min_ps(a.v, _mm256_permute2f128_ps(a.v, a.v, 1));
    m = _mm256_min_ps(m, _mm256_shuffle_ps(m, m, _MM_SHUFFLE(1, 0, 3, 2)));
    m = _mm256_min_ps(m, _mm256_shuffle_ps(m, m, _MM_SHUFFLE(2, 3, 0, 1)));
    return _mm256_cvtss_f32(m);
}
#else
struct f8 {
    float v[8];
};
struct m8 {
    int32_t v[8]; /* 0 or -1 */
};

const char *bvh_simd_name(void) { return "scalar"; }

#define F8_MAP(expr)                                                                              \
    struct f8 r;                                                                                  \
    for (int i = 0; i < 8; i++)                                                                   \
        r.v[i] = (expr);                                                                          \
    return r
#define M8_MAP(expr)                                                                              \
    struct m8 r;                                                                                  \
    for (int i = 0; i < 8; i++)                                                                   \
        r.v[i] = (expr) ? -1 : 0;                                                                 \
    return r

static inline struct f8 f8_set1(float s) { F8_MAP(s); }
static inline struct f8 f8_load(const float *p) { F8_MAP(p[i]); }
static inline struct f8 f8_loadu(const float *p) { F8_MAP(p[i]); }
static inline void f8_store(float *p, struct f8 a) { memcpy(p, a.v, sizeof a.v); }
static inline struct f8 f8_add(struct f8 a, struct f8 b) { F8_MAP(a.v[i] + b.v[i]); }
static inline struct f8 f8_sub(struct f8 a, struct f8 b) { F8_MAP(a.v[i] - b.v[i]); }
static inline struct f8 f8_mul(struct f8 a, struct f8 b) { F8_MAP(a.v[i] * b.v[i]); }
static inline struct f8 f8_div(struct f8 a, struct f8 b) { F8_MAP(a.v[i] / b.v[i]); }
/* fmaf is a slow library call without FMA hardware: the portable build keeps the
 * sub-and-multiply slab test (this is never called there) */
#define BVH_FUSED_SLABS 0
static inline struct f8 f8_fmsub(struct f8 a, struct f8 b, struct f8 c)
{
    F8_MAP(fmaf(a.v[i], b.v[i], -c.v[i]));
}
static inline struct f8 f8_max_num(struct f8 running, struct f8 candidate)
{
    F8_MAP(max_num(running.v[i], candidate.v[i]));
}
static inline struct f8 f8_min_num(struct f8 running, struct f8 candidate)
{
    F8_MAP(min_num(running.v[i], candidate.v[i]));
}
static inline struct f8 f8_abs(struct f8 a) { F8_MAP(fabsf(a.v[i])); }
static inline struct m8 f8_lt(struct f8 a, struct f8 b) { M8_MAP(a.v[i] < b.v[i]); }
static inline struct m8 f8_le(struct f8 a, struct f8 b) { M8_MAP(a.v[i] <= b.v[i]); }
static inline struct m8 f8_gt(struct f8 a, struct f8 b) { M8_MAP(a.v[i] > b.v[i]); }
static inline struct m8 f8_eq(struct f8 a, struct f8 b) { M8_MAP(a.v[i] == b.v[i]); }
static inline struct m8 m8_or(struct m8 a, struct m8 b) { M8_MAP(a.v[i] | b.v[i]); }
static inline struct m8 m8_and(struct m8 a, struct m8 b) { M8_MAP(a.v[i] & b.v[i]); }
static inline struct m8 m8_andnot(struct m8 a, struct m8 b) { M8_MAP(a.v[i] & ~b.v[i]); }
static inline uint32_t m8_bits(struct m8 m)
{
    uint32_t bits = 0;
    for (int i = 0; i < 8; i++)
        bits |= (m.v[i] ? 1u : 0u) << i;
    return bits;
}
static inline struct m8 m8_from_bits(uint32_t bits) { M8_MAP((bits >> i) & 1u); }
static inline struct f8 f8_select(struct m8 m, struct f8 a, struct f8 b)
{
    F8_MAP(m.v[i] ? a.v[i] : b.v[i]);
}
static inline float f8_hmin(struct f8 a)
{
    float m = a.v[0];
    for (int i = 1; i < 8; i++)
        m = a.v[i] < m ? a.v[i] : m;
    return m;
}
#undef F8_MAP
#undef M8_MAP
#endif

/* The traversal loops take `fast` as a constant argument; inlining them at each call gives
 * one specialised copy per slab-test form instead of a branch per node. */
#if defined(__GNUC__)
#define ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define ALWAYS_INLINE inline
#endif

static inline int lowest_bit(uint32_t bits)
{
    assert(bits != 0);
    return __builtin_ctz(bits);
}

/* ---- Woop's test on eight lanes ----------------------------------------------------------------
 * A lane is one (ray, triangle) pair: eight triangles against one ray in a leaf, or one
 * triangle against eight rays in a packet.  The inputs are the vertices relative to the ray
 * origin, components already permuted to (kx, ky, kz) of the lane's ray.  Every operation is
 * tri_hit's, in the same order, so a lane's t, u, v equal tri_hit's to the bit.  Lanes outside
 * `valid` are ignored (their inputs may be garbage).  Returns the mask of lanes that hit. */
struct woop8_in {
    struct f8 a[3]; /* p0 - o: (kx, ky, kz) components */
    struct f8 b[3]; /* p1 - o */
    struct f8 c[3]; /* p2 - o */
    struct f8 sx;   /* shear constants of each lane's ray */
    struct f8 sy;
    struct f8 sz;
    struct f8 t_min; /* hit interval (t_min, t_max) */
    struct f8 t_max;
};

struct woop8_out {
    struct f8 t;
    struct f8 u; /* V / det */
    struct f8 v; /* W / det */
};

static void woop8_fallback(uint32_t lanes, struct f8 Ax, struct f8 Ay, struct f8 Bx,
                               struct f8 By, struct f8 Cx, struct f8 Cy, struct f8 *U,
                               struct f8 *V, struct f8 *W)
{
    float ax[8], ay[8], bx[8], by[8], cx[8], cy[8], u[8], v[8], w[8];
    f8_store(ax, Ax);
    f8_store(ay, Ay);
    f8_store(bx, Bx);
    f8_store(by, By);
    f8_store(cx, Cx);
    f8_store(cy, Cy);
    f8_store(u, *U);
    f8_store(v, *V);
    f8_store(w, *W);
    for (uint32_t bits = lanes; bits; bits &= bits - 1) {
        int i = lowest_bit(bits);
        edge_functions_double(ax[i], ay[i], bx[i], by[i], cx[i], cy[i], &u[i], &v[i], &w[i]);
    }
    *U = f8_loadu(u);
    *V = f8_loadu(v);
    *W = f8_loadu(w);
}

static inline uint32_t woop8(const struct woop8_in *in, uint32_t valid, struct woop8_out *out)
{
    const struct f8 zero = f8_set1(0.0f);
    /* shear so each lane's ray direction becomes (0, 0, 1) */
    struct f8 Ax = f8_sub(in->a[0], f8_mul(in->sx, in->a[2]));
    struct f8 Ay = f8_sub(in->a[1], f8_mul(in->sy, in->a[2]));
    struct f8 Bx = f8_sub(in->b[0], f8_mul(in->sx, in->b[2]));
    struct f8 By = f8_sub(in->b[1], f8_mul(in->sy, in->b[2]));
    struct f8 Cx = f8_sub(in->c[0], f8_mul(in->sx, in->c[2]));
    struct f8 Cy = f8_sub(in->c[1], f8_mul(in->sy, in->c[2]));
    /* scaled barycentric coordinates (edge functions) */
    struct f8 U = f8_sub(f8_mul(Cx, By), f8_mul(Cy, Bx));
    struct f8 V = f8_sub(f8_mul(Ax, Cy), f8_mul(Ay, Cx));
    struct f8 W = f8_sub(f8_mul(Bx, Ay), f8_mul(By, Ax));
    uint32_t on_edge = m8_bits(m8_or(m8_or(f8_eq(U, zero), f8_eq(V, zero)), f8_eq(W, zero)));
    if (on_edge & valid)
        woop8_fallback(on_edge & valid, Ax, Ay, Bx, By, Cx, Cy, &U, &V, &W);
    /* outside when the edge functions disagree in sign */
    struct m8 any_neg = m8_or(m8_or(f8_lt(U, zero), f8_lt(V, zero)), f8_lt(W, zero));
    struct m8 any_pos = m8_or(m8_or(f8_gt(U, zero), f8_gt(V, zero)), f8_gt(W, zero));
    uint32_t hit = valid & ~m8_bits(m8_and(any_neg, any_pos));
    if (!hit)
        return 0;
    struct f8 det = f8_add(f8_add(U, V), W);
    hit &= ~m8_bits(f8_eq(det, zero));
    if (!hit)
        return 0;
    struct f8 Az = f8_mul(in->sz, in->a[2]);
    struct f8 Bz = f8_mul(in->sz, in->b[2]);
    struct f8 Cz = f8_mul(in->sz, in->c[2]);
    struct f8 T = f8_add(f8_add(f8_mul(U, Az), f8_mul(V, Bz)), f8_mul(W, Cz));
    struct f8 inv_det = f8_div(f8_set1(1.0f), det);
    struct f8 t = f8_mul(T, inv_det);
    hit &= m8_bits(m8_and(f8_gt(t, in->t_min), f8_lt(t, in->t_max)));
    if (!hit)
        return 0;
    /* PBRT 4e, ch. 6, "Avoiding Intersections Behind Ray Origins", as in tri_hit */
    struct f8 max_xt = f8_max_num(f8_max_num(f8_abs(Ax), f8_abs(Bx)), f8_abs(Cx));
    struct f8 max_yt = f8_max_num(f8_max_num(f8_abs(Ay), f8_abs(By)), f8_abs(Cy));
    struct f8 max_zt = f8_max_num(f8_max_num(f8_abs(Az), f8_abs(Bz)), f8_abs(Cz));
    struct f8 max_e = f8_max_num(f8_max_num(f8_abs(U), f8_abs(V)), f8_abs(W));
    struct f8 max_z = f8_max_num(f8_max_num(f8_abs(in->a[2]), f8_abs(in->b[2])), f8_abs(in->c[2]));
    struct f8 delta_x = f8_mul(f8_set1(mcpt_gamma(5)), f8_add(max_xt, max_z));
    struct f8 delta_y = f8_mul(f8_set1(mcpt_gamma(5)), f8_add(max_yt, max_z));
    struct f8 delta_z = f8_mul(f8_set1(mcpt_gamma(3)), max_zt);
    struct f8 delta_e = f8_mul(
        f8_set1(2.0f), f8_add(f8_add(f8_mul(f8_mul(f8_set1(mcpt_gamma(2)), max_xt), max_yt),
                                     f8_mul(delta_y, max_xt)),
                              f8_mul(delta_x, max_yt)));
    struct f8 delta_t = f8_mul(
        f8_mul(f8_set1(3.0f), f8_add(f8_add(f8_mul(f8_mul(f8_set1(mcpt_gamma(3)), max_e), max_zt),
                                            f8_mul(delta_e, max_zt)),
                                     f8_mul(delta_z, max_e))),
        f8_abs(inv_det));
    hit &= m8_bits(f8_gt(t, delta_t));
    out->t = t;
    out->u = f8_mul(V, inv_det);
    out->v = f8_mul(W, inv_det);
    return hit;
}

/* ---- Wide traversal, one ray --------------------------------------------------------------------
 * The eight child boxes of a node are slab-tested at once (the box_hit formulas, one lane per
 * child; the far-plane allowance is folded into inv_d_far = inv_d (1 + 4 gamma(3)), twice
 * PBRT's, which also covers the rounding of that product).  The children hit are visited
 * nearest first: one hit child is taken directly, two are ordered by one comparison, more are
 * pushed and insertion-sorted on the stack (nearest on top) (Wald et al. 2008, sec. 4).
 * A stack entry keeps its entry distance, and an entry beyond the closest hit is dropped when
 * popped.  A leaf's triangles are tested by woop8, eight lanes at once.  Rays with finite
 * constants use the fused slab form (one FMA per plane, wide_ray_setup); the traversal loops
 * are compiled once for each form. */

/* Per-ray constants of the wide traversal, scalars; the traversal broadcasts them into
 * registers (struct wide_ray8).  The slab axes are in slab order (see slab_order). */
struct wide_ray {
    float o[3];         /* origin, slab order */
    float inv_d[3];     /* 1 / d */
    float inv_d_far[3]; /* inv_d (1 + 4 gamma(3)): the conservative far plane */
    int near_row[3];    /* bounds row of the near plane: 2 a + is_neg */
    int far_row[3];     /* and of the far plane: 2 a + 1 - is_neg */
    float c_near[3];    /* fused form: o inv_d rounded up by its error bound */
    float c_far[3];     /* o inv_d_far rounded down by its error bound */
    bool fast;          /* the fused form applies (every constant finite) */
    float t_min;
    struct ray_pre *rp; /* for Woop's constants, computed at the first leaf */
}; /* 104 bytes */

/* struct wide_ray broadcast to eight lanes, a local of the traversal loop. */
struct wide_ray8 {
    struct f8 o[3];               /* origin, slab order */
    struct f8 inv_d[3];           /* 1 / d */
    struct f8 inv_d_far[3];       /* the conservative far-plane factor */
    struct f8 c_near[3];          /* fused form constants */
    struct f8 c_far[3];
    struct f8 t_min;
    struct f8 o_k[3];             /* Woop: o[kx], o[ky], o[kz] (set at the first leaf) */
    struct f8 sx;                 /* Woop's shear constants */
    struct f8 sy;
    struct f8 sz;
    int k[3];                     /* kx, ky, kz */
    size_t near_off[3];           /* byte offsets of the near and far bounds rows in a node */
    size_t far_off[3];
    const struct wide_node *wide; /* the node array */
}; /* 640 bytes with AVX2 */

/* The slab test takes max(max(t_0, t_1), max(t_2, t_min)) as a tree, which shortens the chain
 * of dependent instructions per node.  A slab distance is NaN only where inv_d is infinite
 * (d_a = 0, or subnormal) and the origin lies on that plane; max_num drops a NaN candidate but
 * not a NaN running value, so such axes take slots 0 and 2 (candidates) and slot 1 (a running
 * value) gets an axis with finite inv_d.  With at most two infinite axes (a valid direction)
 * this gives the sequential chain's result bit for bit.  Row: bit a set when inv_d[a] is
 * infinite. */
static const int8_t slab_order[8][3] = {
    {0, 1, 2}, {0, 1, 2}, {1, 0, 2}, {0, 2, 1}, {2, 0, 1}, {0, 1, 2}, {1, 0, 2}, {0, 1, 2},
};

/* The fused slab distances (fast path).  PBRT's form (b - o) inv_d costs a subtraction and a
 * product; b inv_d - o inv_d is one fused multiply-add (Embree's form), but the rounding of
 * o inv_d is an absolute error that can exceed the distance itself.  So the constant is
 * biased by its error bound: c_near >= o inv_d and c_far <= o inv_d_far exactly, hence
 *   t_near = fl(b inv_d - c_near) <= fl((b - o) inv_d),  t_far = fl(b inv_d_far - c_far)
 *   >= fl((b - o) inv_d_far)
 * (rounding is monotone, and the fused product is exact), and the test is at least as
 * conservative as the sub-and-multiply one.  fl(x y) is within 2^-24 |x y| of x y in the normal
 * range (and within 2^-150 below it), so a bias of 2^-21 |c| + FLT_MIN covers it and the
 * rounding of the bias's own addition.  Rays with an infinite inv_d (d_a = 0) or an infinite
 * constant take the sub-and-multiply path, whose NaN rules give flat boxes and origins on a
 * face their meaning. */
#define SLAB_BIAS 0x1p-21f

static inline void wide_ray_setup(struct ray_pre *rp, float t_min, struct wide_ray *wr)
{
    const float far_scale = 1.0f + 4.0f * mcpt_gamma(3);
    unsigned inf_bits = (fabsf(rp->inv_d[0]) > FLT_MAX ? 1u : 0u) |
                        (fabsf(rp->inv_d[1]) > FLT_MAX ? 2u : 0u) |
                        (fabsf(rp->inv_d[2]) > FLT_MAX ? 4u : 0u);
    const int8_t *order = slab_order[inf_bits];
    float magnitude = 0.0f; /* infinite or NaN when some constant is: then the safe path */
    for (int j = 0; j < 3; j++) {
        int a = order[j];
        float o = rp->o[a];
        float inv_d = rp->inv_d[a];
        float inv_d_far = inv_d * far_scale;
        wr->o[j] = o;
        wr->inv_d[j] = inv_d;
        wr->inv_d_far[j] = inv_d_far;
        wr->near_row[j] = 2 * a + rp->is_neg[a];
        wr->far_row[j] = 2 * a + 1 - rp->is_neg[a];
        float on = o * inv_d;
        float of = o * inv_d_far;
        wr->c_near[j] = on + (SLAB_BIAS * fabsf(on) + FLT_MIN);
        wr->c_far[j] = of - (SLAB_BIAS * fabsf(of) + FLT_MIN);
        magnitude += fabsf(inv_d_far) + fabsf(wr->c_near[j]) + fabsf(wr->c_far[j]);
    }
    /* a sum that overflows only sends a valid ray down the safe path */
    wr->fast = BVH_FUSED_SLABS && inf_bits == 0 && magnitude <= FLT_MAX;
    wr->t_min = t_min;
    wr->rp = rp;
}

static inline void wide_ray8_box(const struct bvh *bvh, const struct wide_ray *wr,
                                 struct wide_ray8 *v)
{
    v->wide = bvh->wide;
    for (int j = 0; j < 3; j++) {
        v->near_off[j] = (size_t)wr->near_row[j] * sizeof(float) * BVH_WIDTH;
        v->far_off[j] = (size_t)wr->far_row[j] * sizeof(float) * BVH_WIDTH;
        v->o[j] = f8_set1(wr->o[j]);
        v->inv_d[j] = f8_set1(wr->inv_d[j]);
        v->inv_d_far[j] = f8_set1(wr->inv_d_far[j]);
        v->c_near[j] = f8_set1(wr->c_near[j]);
        v->c_far[j] = f8_set1(wr->c_far[j]);
    }
    v->t_min = f8_set1(wr->t_min);
}

/* Woop's constants: computed into *rp (which the caller owns) on the first leaf. */
static inline void wide_ray8_woop(const struct wide_ray *wr, struct wide_ray8 *v)
{
    struct ray_pre *rp = wr->rp;
    ray_setup_woop(rp);
    v->k[0] = rp->kx;
    v->k[1] = rp->ky;
    v->k[2] = rp->kz;
    for (int j = 0; j < 3; j++)
        v->o_k[j] = f8_set1(rp->o[v->k[j]]);
    v->sx = f8_set1(rp->sx);
    v->sy = f8_set1(rp->sy);
    v->sz = f8_set1(rp->sz);
}

/* Slab test of one ray against a wide node's children; returns the mask of children hit in
 * [t_min, t_max] and their entry distances. */
static inline uint32_t wide_box_hit(const struct wide_node *node, const struct wide_ray8 *v,
                                    const bool fast, float t_max, struct f8 *t_entry)
{
    struct f8 t_near[3];
    struct f8 t_far[3];
    const char *base = (const char *)node->bounds;
    for (int j = 0; j < 3; j++) {
        struct f8 near = f8_load((const float *)(base + v->near_off[j]));
        struct f8 far = f8_load((const float *)(base + v->far_off[j]));
        if (fast) {
            t_near[j] = f8_fmsub(near, v->inv_d[j], v->c_near[j]);
            t_far[j] = f8_fmsub(far, v->inv_d_far[j], v->c_far[j]);
        } else {
            t_near[j] = f8_mul(f8_sub(near, v->o[j]), v->inv_d[j]);
            t_far[j] = f8_mul(f8_sub(far, v->o[j]), v->inv_d_far[j]);
        }
    }
    struct f8 t0 = f8_max_num(f8_max_num(v->t_min, t_near[2]), f8_max_num(t_near[1], t_near[0]));
    struct f8 t1 = f8_min_num(f8_min_num(f8_set1(t_max), t_far[2]), f8_min_num(t_far[1], t_far[0]));
    *t_entry = t0;
    return m8_bits(f8_le(t0, t1));
}

/* woop8 of one ray against the n (1..8) triangles of the leaf at wide triangle `first`. */
static inline uint32_t wide_leaf_hit(const struct bvh *bvh, uint32_t first, uint32_t n,
                                     const struct wide_ray8 *v, float t_max,
                                     struct woop8_out *out)
{
    const float *base = bvh->leaf_tris + 9 * (size_t)first;
    struct woop8_in in;
    for (int j = 0; j < 3; j++) {
        size_t row = (size_t)v->k[j] * n;
        in.a[j] = f8_sub(f8_loadu(base + row), v->o_k[j]);
        in.b[j] = f8_sub(f8_loadu(base + 3 * (size_t)n + row), v->o_k[j]);
        in.c[j] = f8_sub(f8_loadu(base + 6 * (size_t)n + row), v->o_k[j]);
    }
    in.sx = v->sx;
    in.sy = v->sy;
    in.sz = v->sz;
    in.t_min = v->t_min;
    in.t_max = f8_set1(t_max);
    return woop8(&in, (1u << n) - 1u, out);
}

/* The closest hit so far. */
struct wide_hit {
    float t;      /* t_hit, initially the ray's t_max */
    float u;
    float v;
    uint32_t tri; /* wide triangle index, UINT32_MAX while none */
};

/* Pushes the children in mask (at least three) and sorts them so the nearest is on top. */
static inline void push_sorted(struct stack_entry *stack, uint32_t *n_stack,
                               const struct wide_node *node, uint32_t mask, const float *dist)
{
    uint32_t base = *n_stack;
    uint32_t n = base;
    for (; mask; mask &= mask - 1) {
        int c = lowest_bit(mask);
        struct stack_entry e = {node->child[c], dist[c]};
        /* insertion: farther entries sink below nearer ones */
        uint32_t i = n++;
        while (i > base && stack[i - 1].t_entry < e.t_entry) {
            stack[i] = stack[i - 1];
            i--;
        }
        stack[i] = e;
    }
    *n_stack = n;
}

/* Closest hit below wide reference `root` (a node or a leaf) for t in (t_min, hit->t). */
static ALWAYS_INLINE void wide_closest(const struct bvh *bvh, uint32_t root,
                                       const struct wide_ray *wr, struct wide_hit *hit,
                                       const bool fast)
{
    struct wide_ray8 v;
    wide_ray8_box(bvh, wr, &v);
    bool woop_ready = false;
    struct stack_entry stack[WIDE_STACK_SIZE];
    uint32_t n_stack = 0;
    uint32_t ref = root;
    for (;;) {
        if (!(ref & WIDE_LEAF)) {
            const struct wide_node *node = &v.wide[ref];
            struct f8 t_entry;
            uint32_t mask = wide_box_hit(node, &v, fast, hit->t, &t_entry);
            if (mask) {
                int c0 = lowest_bit(mask);
                uint32_t rest = mask & (mask - 1);
                if (!rest) {
                    ref = node->child[c0];
                    continue;
                }
                float dist[8];
                f8_store(dist, t_entry);
                int c1 = lowest_bit(rest);
                if (!(rest & (rest - 1))) {
                    if (dist[c1] < dist[c0]) {
                        int tmp = c0;
                        c0 = c1;
                        c1 = tmp;
                    }
                    stack[n_stack++] = (struct stack_entry){node->child[c1], dist[c1]};
                    ref = node->child[c0];
                    continue;
                }
                assert(n_stack + 8 <= WIDE_STACK_SIZE);
                push_sorted(stack, &n_stack, node, mask, dist);
                ref = stack[--n_stack].node_idx;
                continue;
            }
        } else {
            if (!woop_ready) {
                wide_ray8_woop(wr, &v);
                woop_ready = true;
            }
            uint32_t first = (ref & ~WIDE_LEAF) >> 3;
            uint32_t n = (ref & 7u) + 1;
            struct woop8_out out;
            uint32_t hits = wide_leaf_hit(bvh, first, n, &v, hit->t, &out);
            if (hits) {
                struct f8 t_hits = f8_select(m8_from_bits(hits), out.t, f8_set1(INFINITY));
                float t_best = f8_hmin(t_hits);
                /* among equal t the lowest lane: the first in BVH order, as brute force */
                int lane = lowest_bit(hits & m8_bits(f8_eq(t_hits, f8_set1(t_best))));
                float u[8];
                float uv_v[8];
                f8_store(u, out.u);
                f8_store(uv_v, out.v);
                *hit = (struct wide_hit){t_best, u[lane], uv_v[lane], first + (uint32_t)lane};
            }
        }
        /* pop the next pending node that still starts before the closest hit */
        do {
            if (n_stack == 0)
                return;
            n_stack--;
        } while (stack[n_stack].t_entry > hit->t);
        ref = stack[n_stack].node_idx;
    }
}

/* Any hit below `root` for t in (t_min, t_max): children in any order, the first hit ends it
 * (nearest-first order measured no faster for shadow rays, docs/bvh.md). */
static ALWAYS_INLINE bool wide_any(const struct bvh *bvh, uint32_t root,
                                   const struct wide_ray *wr, float t_max, const bool fast)
{
    struct wide_ray8 v;
    wide_ray8_box(bvh, wr, &v);
    bool woop_ready = false;
    uint32_t stack[WIDE_STACK_SIZE];
    uint32_t n_stack = 0;
    uint32_t ref = root;
    for (;;) {
        if (!(ref & WIDE_LEAF)) {
            const struct wide_node *node = &v.wide[ref];
            struct f8 t_entry;
            uint32_t mask = wide_box_hit(node, &v, fast, t_max, &t_entry);
            if (mask) {
                ref = node->child[lowest_bit(mask)];
                assert(n_stack + 8 <= WIDE_STACK_SIZE);
                for (mask &= mask - 1; mask; mask &= mask - 1)
                    stack[n_stack++] = node->child[lowest_bit(mask)];
                continue;
            }
        } else {
            if (!woop_ready) {
                wide_ray8_woop(wr, &v);
                woop_ready = true;
            }
            struct woop8_out out;
            if (wide_leaf_hit(bvh, (ref & ~WIDE_LEAF) >> 3, (ref & 7u) + 1, &v, t_max, &out))
                return true;
        }
        if (n_stack == 0)
            return false;
        ref = stack[--n_stack];
    }
}

static void wide_closest_fast(const struct bvh *bvh, uint32_t root, const struct wide_ray *wr,
                              struct wide_hit *hit)
{
    wide_closest(bvh, root, wr, hit, true);
}

static void wide_closest_safe(const struct bvh *bvh, uint32_t root, const struct wide_ray *wr,
                              struct wide_hit *hit)
{
    wide_closest(bvh, root, wr, hit, false);
}

static bool wide_any_fast(const struct bvh *bvh, uint32_t root, const struct wide_ray *wr,
                          float t_max)
{
    return wide_any(bvh, root, wr, t_max, true);
}

static bool wide_any_safe(const struct bvh *bvh, uint32_t root, const struct wide_ray *wr,
                          float t_max)
{
    return wide_any(bvh, root, wr, t_max, false);
}

/* Most camera rays of a small object miss it altogether: a scalar test against the tree's box
 * (box_hit, the reference form) lets them return before any SIMD setup. */
static bool wide_intersect(const struct bvh *bvh, const struct ray *ray, struct bvh_hit *out)
{
    if (bvh->n_wide == 0)
        return false;
    struct ray_pre rp;
    ray_setup_box(ray, &rp);
    float t_entry;
    if (!box_hit(&bvh->bounds, &rp, ray->t_min, ray->t_max, &t_entry))
        return false;
    struct wide_ray wr;
    wide_ray_setup(&rp, ray->t_min, &wr);
    struct wide_hit hit = {ray->t_max, 0.0f, 0.0f, UINT32_MAX};
    if (wr.fast)
        wide_closest_fast(bvh, 0, &wr, &hit);
    else
        wide_closest_safe(bvh, 0, &wr, &hit);
    if (hit.tri == UINT32_MAX)
        return false;
    *out = (struct bvh_hit){hit.t, hit.u, hit.v, bvh->wide_prim_idx[hit.tri]};
    return true;
}

static bool wide_occluded(const struct bvh *bvh, const struct ray *ray)
{
    if (bvh->n_wide == 0)
        return false;
    struct ray_pre rp;
    ray_setup_box(ray, &rp);
    float t_entry;
    if (!box_hit(&bvh->bounds, &rp, ray->t_min, ray->t_max, &t_entry))
        return false;
    struct wide_ray wr;
    wide_ray_setup(&rp, ray->t_min, &wr);
    return wr.fast ? wide_any_fast(bvh, 0, &wr, ray->t_max)
                   : wide_any_safe(bvh, 0, &wr, ray->t_max);
}

bool bvh_intersect(const struct bvh *bvh, const struct ray *ray, struct bvh_hit *hit)
{
    if (bvh->layouts & BVH_LAYOUT_WIDE)
        return wide_intersect(bvh, ray, hit);
    return binary_intersect(bvh, ray, hit);
}

bool bvh_occluded(const struct bvh *bvh, const struct ray *ray)
{
    if (bvh->layouts & BVH_LAYOUT_WIDE)
        return wide_occluded(bvh, ray);
    return binary_occluded(bvh, ray);
}

bool bvh_intersect_layout(const struct bvh *bvh, enum bvh_layout layout, const struct ray *ray,
                          struct bvh_hit *hit)
{
    assert(bvh->n_tris == 0 || (bvh->layouts & (unsigned)layout));
    return layout == BVH_LAYOUT_WIDE ? wide_intersect(bvh, ray, hit)
                                     : binary_intersect(bvh, ray, hit);
}

bool bvh_occluded_layout(const struct bvh *bvh, enum bvh_layout layout, const struct ray *ray)
{
    assert(bvh->n_tris == 0 || (bvh->layouts & (unsigned)layout));
    return layout == BVH_LAYOUT_WIDE ? wide_occluded(bvh, ray) : binary_occluded(bvh, ray);
}

/* ---- Packets: eight rays through the wide layout ------------------------------------------------
 * Lanes are rays.  At a node each child box is slab-tested against all active rays (one lane
 * per ray, near and far planes picked per lane by the sign of d), giving the child's ray mask;
 * children hit by some ray are pushed with that mask and the smallest entry distance among
 * them, nearest on top.  A leaf's triangles are tested one at a time against the node's rays by
 * woop8, each lane with its own permutation (kx, ky, kz) and shear.  When few rays remain
 * active in a node (BVH_PACKET_MIN_ACTIVE), they continue one by one through the single-ray
 * traversal from that node (Benthin et al. 2012, "Combining Single and Packet-Ray Tracing for
 * Arbitrary Ray Distributions on the Intel MIC Architecture").  A packet whose rays share
 * their direction signs takes the coherent form (broadcast planes, fused slabs), and one whose
 * rays share Woop's permutation broadcasts the triangles' coordinates.  A lane's triangle tests
 * give the single-ray t, u, v to the bit (same constants, same woop8), and its box tests are
 * conservative in the same way, so it reports what bvh_intersect reports (up to exact ties). */
#define BVH_PACKET_MIN_ACTIVE 3 /* fewer active rays in a node: finish them one by one */

struct packet_pre {
    struct f8 o[3];
    struct f8 inv_d[3];
    struct f8 inv_d_far[3];
    struct f8 c_near[3];  /* the fused slab constants of wide_ray_setup, per lane */
    struct f8 c_far[3];
    struct m8 is_neg[3];  /* near plane is max */
    struct m8 k_is[3][2]; /* k_is[j][m]: lane's k[j] == m (m = 0, 1; else 2) */
    struct f8 o_k[3];     /* o[k[j]] per lane */
    struct f8 sx;
    struct f8 sy;
    struct f8 sz;
    struct f8 t_min;
    bool coherent;   /* every lane: same direction signs, fused constants finite */
    int near_row[3]; /* when coherent: bounds rows of the near and far planes */
    int far_row[3];
    bool uniform_k;  /* every lane has the same (kx, ky, kz) */
    int k[3];        /* when uniform_k */
};

/* m ? x : (n ? y : z) per lane */
static inline struct f8 select3(struct m8 m, struct m8 n, struct f8 x, struct f8 y, struct f8 z)
{
    return f8_select(m, x, f8_select(n, y, z));
}

/* Per-lane constants, computed on all eight lanes at once: the operations of ray_setup and
 * wide_ray_setup lane by lane, so every value equals the single-ray one to the bit.  An
 * inactive lane (whose fields may be uninitialised) gets the first active ray with an empty
 * interval, t_max[lane] = -inf, so that it never hits and never spoils the packet's coherence. */
static void packet_setup(const struct bvh_packet *p, uint32_t active, struct packet_pre *pp,
                         float t_max[BVH_PACKET_SIZE])
{
    const struct f8 zero = f8_set1(0.0f);
    const float far_scale = 1.0f + 4.0f * mcpt_gamma(3);
    int first = active ? lowest_bit(active) : 0;
    struct m8 on = m8_from_bits(active);
    struct f8 d[3];
    for (int a = 0; a < 3; a++) {
        pp->o[a] = f8_select(on, f8_loadu(p->o[a]), f8_set1(active ? p->o[a][first] : 0.0f));
        d[a] = f8_select(on, f8_loadu(p->d[a]), f8_set1(active ? p->d[a][first] : 1.0f));
    }
    pp->t_min = f8_select(on, f8_loadu(p->t_min), f8_set1(active ? p->t_min[first] : 0.0f));
    f8_store(t_max, f8_select(on, f8_loadu(p->t_max), f8_set1(-INFINITY)));
    /* slabs (ray_setup_box, wide_ray_setup) */
    uint32_t all = (1u << BVH_PACKET_SIZE) - 1u;
    bool coherent = true;
    struct f8 magnitude = zero;
    for (int a = 0; a < 3; a++) {
        pp->inv_d[a] = f8_div(f8_set1(1.0f), d[a]);
        pp->inv_d_far[a] = f8_mul(pp->inv_d[a], f8_set1(far_scale));
        pp->is_neg[a] = f8_lt(pp->inv_d[a], zero);
        struct f8 o_inv = f8_mul(pp->o[a], pp->inv_d[a]);
        struct f8 o_inv_far = f8_mul(pp->o[a], pp->inv_d_far[a]);
        pp->c_near[a] = f8_add(o_inv, f8_add(f8_mul(f8_set1(SLAB_BIAS), f8_abs(o_inv)),
                                             f8_set1(FLT_MIN)));
        pp->c_far[a] = f8_sub(o_inv_far, f8_add(f8_mul(f8_set1(SLAB_BIAS), f8_abs(o_inv_far)),
                                                f8_set1(FLT_MIN)));
        magnitude = f8_add(magnitude, f8_add(f8_add(f8_abs(pp->inv_d[a]), f8_abs(pp->inv_d_far[a])),
                                             f8_add(f8_abs(pp->c_near[a]), f8_abs(pp->c_far[a]))));
        uint32_t neg = m8_bits(pp->is_neg[a]);
        coherent = coherent && (neg == 0 || neg == all);
        pp->near_row[a] = 2 * a + (neg ? 1 : 0);
        pp->far_row[a] = 2 * a + 1 - (neg ? 1 : 0);
    }
    coherent = coherent && m8_bits(f8_le(magnitude, f8_set1(FLT_MAX))) == all;
    pp->coherent = BVH_FUSED_SLABS && coherent;
    /* Woop's permutation (ray_setup_woop): kz = argmax |d|, kx, ky the next two, swapped when
     * d[kz] < 0 */
    struct f8 ad0 = f8_abs(d[0]);
    struct f8 ad1 = f8_abs(d[1]);
    struct f8 ad2 = f8_abs(d[2]);
    struct m8 ge01 = m8_or(f8_gt(ad0, ad1), f8_eq(ad0, ad1));
    struct m8 ge02 = m8_or(f8_gt(ad0, ad2), f8_eq(ad0, ad2));
    struct m8 ge12 = m8_or(f8_gt(ad1, ad2), f8_eq(ad1, ad2));
    struct m8 kz0 = m8_and(ge01, ge02);
    struct m8 kz1 = m8_andnot(ge12, ge01);
    struct f8 d_kz = select3(kz0, kz1, d[0], d[1], d[2]);
    struct m8 swap = f8_lt(d_kz, zero);
    struct m8 kz2 = m8_andnot(m8_andnot(f8_eq(zero, zero), kz0), kz1);
    /* unswapped (kx, ky) = (1, 2) for kz 0, (2, 0) for kz 1, (0, 1) for kz 2 */
    pp->k_is[0][0] = m8_or(m8_andnot(kz2, swap), m8_and(kz1, swap));
    pp->k_is[0][1] = m8_or(m8_andnot(kz0, swap), m8_and(kz2, swap));
    pp->k_is[1][0] = m8_or(m8_andnot(kz1, swap), m8_and(kz2, swap));
    pp->k_is[1][1] = m8_or(m8_andnot(kz2, swap), m8_and(kz0, swap));
    pp->k_is[2][0] = kz0;
    pp->k_is[2][1] = kz1;
    struct f8 d_k[3];
    for (int j = 0; j < 3; j++) {
        d_k[j] = select3(pp->k_is[j][0], pp->k_is[j][1], d[0], d[1], d[2]);
        pp->o_k[j] = select3(pp->k_is[j][0], pp->k_is[j][1], pp->o[0], pp->o[1], pp->o[2]);
    }
    pp->sx = f8_div(d_k[0], d_k[2]);
    pp->sy = f8_div(d_k[1], d_k[2]);
    pp->sz = f8_div(f8_set1(1.0f), d_k[2]);
    uint32_t b0 = m8_bits(kz0);
    uint32_t b1 = m8_bits(kz1);
    uint32_t bs = m8_bits(swap);
    pp->uniform_k = (b0 == 0 || b0 == all) && (b1 == 0 || b1 == all) && (bs == 0 || bs == all);
    int kz = b0 ? 0 : b1 ? 1 : 2;
    int kx = kz == 2 ? 0 : kz + 1;
    int ky = kx == 2 ? 0 : kx + 1;
    pp->k[0] = bs ? ky : kx;
    pp->k[1] = bs ? kx : ky;
    pp->k[2] = kz;
}

/* The single-ray constants of lane `lane`, for the rays that leave the packet. */
static void packet_lane_ray(const struct bvh_packet *p, int lane, struct ray_pre *rp)
{
    struct ray r = {{p->o[0][lane], p->o[1][lane], p->o[2][lane]}, p->t_min[lane],
                    {p->d[0][lane], p->d[1][lane], p->d[2][lane]}, p->t_max[lane]};
    ray_setup_box(&r, rp);
}

/* Slab test of child `lane` of node against every ray; returns the mask of rays hitting it.
 * Coherent packets (coherent == true, the caller checked pp->coherent) share the near and far
 * rows and use the fused form of the single-ray fast path, no NaN can arise, and the maxima are
 * a tree; otherwise each lane picks its planes by its signs and the NaN-aware chain is used. */
static ALWAYS_INLINE uint32_t packet_box_hit(const struct wide_node *node, int lane,
                                             const struct packet_pre *pp, struct f8 t_max,
                                             struct f8 *t_entry, const bool coherent)
{
    if (coherent) {
        struct f8 tn[3];
        struct f8 tf[3];
        for (int a = 0; a < 3; a++) {
            struct f8 near = f8_set1(node->bounds[pp->near_row[a]][lane]);
            struct f8 far = f8_set1(node->bounds[pp->far_row[a]][lane]);
            tn[a] = f8_fmsub(near, pp->inv_d[a], pp->c_near[a]);
            tf[a] = f8_fmsub(far, pp->inv_d_far[a], pp->c_far[a]);
        }
        struct f8 t0 = f8_max_num(f8_max_num(pp->t_min, tn[2]), f8_max_num(tn[1], tn[0]));
        struct f8 t1 = f8_min_num(f8_min_num(t_max, tf[2]), f8_min_num(tf[1], tf[0]));
        *t_entry = t0;
        return m8_bits(f8_le(t0, t1));
    }
    struct f8 t0 = pp->t_min;
    struct f8 t1 = t_max;
    for (int a = 0; a < 3; a++) {
        struct f8 lo = f8_set1(node->bounds[2 * a][lane]);
        struct f8 hi = f8_set1(node->bounds[2 * a + 1][lane]);
        struct f8 near = f8_select(pp->is_neg[a], hi, lo);
        struct f8 far = f8_select(pp->is_neg[a], lo, hi);
        t0 = f8_max_num(t0, f8_mul(f8_sub(near, pp->o[a]), pp->inv_d[a]));
        t1 = f8_min_num(t1, f8_mul(f8_sub(far, pp->o[a]), pp->inv_d_far[a]));
    }
    *t_entry = t0;
    return m8_bits(f8_le(t0, t1));
}

/* coordinate k[j] of (x, y, z) per lane */
static inline struct f8 pick_k(const struct packet_pre *pp, int j, struct f8 x, struct f8 y,
                               struct f8 z)
{
    return f8_select(pp->k_is[j][0], x, f8_select(pp->k_is[j][1], y, z));
}

/* woop8 of triangle i of the leaf at `first` (n triangles) against the rays in mask. */
static inline uint32_t packet_tri_hit(const struct bvh *bvh, uint32_t first, uint32_t n,
                                      uint32_t i, const struct packet_pre *pp, struct f8 t_max,
                                      uint32_t mask, struct woop8_out *out)
{
    const float *base = bvh->leaf_tris + 9 * (size_t)first;
    struct woop8_in in;
    struct f8 *dst[3] = {in.a, in.b, in.c};
    for (int k = 0; k < 3; k++) {
        if (pp->uniform_k) { /* every lane permutes alike: broadcast the permuted coordinate */
            for (int j = 0; j < 3; j++)
                dst[k][j] = f8_sub(f8_set1(base[(size_t)(3 * k + pp->k[j]) * n + i]), pp->o_k[j]);
            continue;
        }
        struct f8 x = f8_set1(base[(size_t)(3 * k) * n + i]);
        struct f8 y = f8_set1(base[(size_t)(3 * k + 1) * n + i]);
        struct f8 z = f8_set1(base[(size_t)(3 * k + 2) * n + i]);
        for (int j = 0; j < 3; j++)
            dst[k][j] = f8_sub(pick_k(pp, j, x, y, z), pp->o_k[j]);
    }
    in.sx = pp->sx;
    in.sy = pp->sy;
    in.sz = pp->sz;
    in.t_min = pp->t_min;
    in.t_max = t_max;
    return woop8(&in, mask, out);
}

struct packet_entry {
    uint32_t ref;  /* wide reference */
    uint32_t mask; /* rays that hit its box */
    float t_entry; /* smallest entry distance among them */
}; /* 12 bytes */

/* The closest-hit packet loop; `coherent` selects packet_box_hit's form (a constant at each
 * call, so there are two specialised copies). */
static ALWAYS_INLINE uint32_t packet_closest(const struct bvh *bvh,
                                             const struct bvh_packet *packet, uint32_t active,
                                             struct packet_pre *pp, float t_hit[8],
                                             struct bvh_packet_hit *hit, const bool coherent)
{
    float u_hit[8];
    float v_hit[8];
    uint32_t tri_hit_idx[8];
    for (int lane = 0; lane < 8; lane++) {
        tri_hit_idx[lane] = UINT32_MAX;
        u_hit[lane] = 0.0f;
        v_hit[lane] = 0.0f;
    }
    struct f8 t_hit8 = f8_loadu(t_hit);
    /* a node's entry is pushed at most once per visit of its parent: 7 per level */
    struct packet_entry stack[WIDE_STACK_SIZE];
    uint32_t n_stack = 0;
    struct packet_entry cur = {0, active, -INFINITY};
    for (;;) {
        if (__builtin_popcount(cur.mask) < BVH_PACKET_MIN_ACTIVE) {
            /* few rays left here: finish them one by one from this node */
            f8_store(t_hit, t_hit8);
            for (uint32_t bits = cur.mask; bits; bits &= bits - 1) {
                int lane = lowest_bit(bits);
                struct ray_pre rp;
                packet_lane_ray(packet, lane, &rp);
                struct wide_ray wr;
                wide_ray_setup(&rp, packet->t_min[lane], &wr);
                struct wide_hit h = {t_hit[lane], u_hit[lane], v_hit[lane], tri_hit_idx[lane]};
                if (wr.fast)
                    wide_closest_fast(bvh, cur.ref, &wr, &h);
                else
                    wide_closest_safe(bvh, cur.ref, &wr, &h);
                t_hit[lane] = h.t;
                u_hit[lane] = h.u;
                v_hit[lane] = h.v;
                tri_hit_idx[lane] = h.tri;
            }
            t_hit8 = f8_loadu(t_hit);
        } else if (!(cur.ref & WIDE_LEAF)) {
            const struct wide_node *node = &bvh->wide[cur.ref];
            const uint32_t base = n_stack;
            for (uint32_t c = 0; c < node->n_children; c++) {
                struct f8 t_entry;
                uint32_t mask =
                    packet_box_hit(node, (int)c, pp, t_hit8, &t_entry, coherent) & cur.mask;
                if (!mask)
                    continue;
                struct f8 t_in = f8_select(m8_from_bits(mask), t_entry, f8_set1(INFINITY));
                struct packet_entry e = {node->child[c], mask, f8_hmin(t_in)};
                /* insertion among this node's children only: nearest on top */
                uint32_t i = n_stack++;
                while (i > base && stack[i - 1].t_entry < e.t_entry) {
                    stack[i] = stack[i - 1];
                    i--;
                }
                stack[i] = e;
            }
        } else {
            uint32_t first = (cur.ref & ~WIDE_LEAF) >> 3;
            uint32_t n = (cur.ref & 7u) + 1;
            for (uint32_t i = 0; i < n; i++) {
                struct woop8_out out;
                uint32_t hits = packet_tri_hit(bvh, first, n, i, pp, t_hit8, cur.mask, &out);
                if (!hits)
                    continue;
                /* a lane's later triangle is tested against the t_hit its earlier one set, as
                 * in the single-ray loop, so the first of equal t stays */
                struct m8 m = m8_from_bits(hits);
                t_hit8 = f8_select(m, out.t, t_hit8);
                float u[8];
                float v[8];
                f8_store(u, out.u);
                f8_store(v, out.v);
                for (uint32_t bits = hits; bits; bits &= bits - 1) {
                    int lane = lowest_bit(bits);
                    u_hit[lane] = u[lane];
                    v_hit[lane] = v[lane];
                    tri_hit_idx[lane] = first + i;
                }
            }
        }
        /* pop the next entry that some of its rays may still need */
        for (;;) {
            if (n_stack == 0)
                goto done;
            cur = stack[--n_stack];
            struct f8 t_in = f8_set1(cur.t_entry);
            cur.mask &= m8_bits(f8_le(t_in, t_hit8));
            if (cur.mask)
                break;
        }
    }
done:
    f8_store(t_hit, t_hit8);
    uint32_t hits = 0;
    for (uint32_t bits = active; bits; bits &= bits - 1) {
        int lane = lowest_bit(bits);
        if (tri_hit_idx[lane] == UINT32_MAX)
            continue;
        hits |= 1u << lane;
        hit->t[lane] = t_hit[lane];
        hit->u[lane] = u_hit[lane];
        hit->v[lane] = v_hit[lane];
        hit->prim_idx[lane] = bvh->wide_prim_idx[tri_hit_idx[lane]];
    }
    return hits;
}

static uint32_t packet_closest_coherent(const struct bvh *bvh, const struct bvh_packet *packet,
                                        uint32_t active, struct packet_pre *pp, float t_hit[8],
                                        struct bvh_packet_hit *hit)
{
    return packet_closest(bvh, packet, active, pp, t_hit, hit, true);
}

static uint32_t packet_closest_general(const struct bvh *bvh, const struct bvh_packet *packet,
                                       uint32_t active, struct packet_pre *pp, float t_hit[8],
                                       struct bvh_packet_hit *hit)
{
    return packet_closest(bvh, packet, active, pp, t_hit, hit, false);
}

uint32_t bvh_intersect_packet(const struct bvh *bvh, const struct bvh_packet *packet,
                              uint32_t active, struct bvh_packet_hit *hit)
{
    active &= (1u << BVH_PACKET_SIZE) - 1u;
    if (!(bvh->layouts & BVH_LAYOUT_WIDE) || bvh->n_wide == 0) {
        uint32_t hits = 0;
        for (uint32_t bits = active; bits; bits &= bits - 1) {
            int lane = lowest_bit(bits);
            struct ray r = {{packet->o[0][lane], packet->o[1][lane], packet->o[2][lane]},
                            packet->t_min[lane],
                            {packet->d[0][lane], packet->d[1][lane], packet->d[2][lane]},
                            packet->t_max[lane]};
            struct bvh_hit h;
            if (bvh_intersect(bvh, &r, &h)) {
                hits |= 1u << lane;
                hit->t[lane] = h.t;
                hit->u[lane] = h.u;
                hit->v[lane] = h.v;
                hit->prim_idx[lane] = h.prim_idx;
            }
        }
        return hits;
    }
    struct packet_pre pp;
    float t_hit[8];
    packet_setup(packet, active, &pp, t_hit);
    return pp.coherent ? packet_closest_coherent(bvh, packet, active, &pp, t_hit, hit)
                       : packet_closest_general(bvh, packet, active, &pp, t_hit, hit);
}

/* The any-hit packet loop: children in stored order, a lane leaves the packet when occluded. */
static ALWAYS_INLINE uint32_t packet_any(const struct bvh *bvh, const struct bvh_packet *packet,
                                         uint32_t active, struct packet_pre *pp,
                                         const float t_max[8], const bool coherent)
{
    const struct f8 t_max8 = f8_loadu(t_max);
    uint32_t occluded = 0;
    struct packet_entry stack[WIDE_STACK_SIZE];
    uint32_t n_stack = 0;
    struct packet_entry cur = {0, active, -INFINITY};
    for (;;) {
        cur.mask &= ~occluded;
        if (!cur.mask) {
            /* nothing left to do here */
        } else if (__builtin_popcount(cur.mask) < BVH_PACKET_MIN_ACTIVE) {
            for (uint32_t bits = cur.mask; bits; bits &= bits - 1) {
                int lane = lowest_bit(bits);
                struct ray_pre rp;
                packet_lane_ray(packet, lane, &rp);
                struct wide_ray wr;
                wide_ray_setup(&rp, packet->t_min[lane], &wr);
                if (wr.fast ? wide_any_fast(bvh, cur.ref, &wr, packet->t_max[lane])
                            : wide_any_safe(bvh, cur.ref, &wr, packet->t_max[lane]))
                    occluded |= 1u << lane;
            }
        } else if (!(cur.ref & WIDE_LEAF)) {
            const struct wide_node *node = &bvh->wide[cur.ref];
            for (uint32_t c = 0; c < node->n_children; c++) {
                struct f8 t_entry;
                uint32_t mask =
                    packet_box_hit(node, (int)c, pp, t_max8, &t_entry, coherent) & cur.mask;
                if (mask)
                    stack[n_stack++] = (struct packet_entry){node->child[c], mask, 0.0f};
            }
        } else {
            uint32_t first = (cur.ref & ~WIDE_LEAF) >> 3;
            uint32_t n = (cur.ref & 7u) + 1;
            for (uint32_t i = 0; i < n && (cur.mask & ~occluded); i++) {
                struct woop8_out out;
                occluded |= packet_tri_hit(bvh, first, n, i, pp, t_max8, cur.mask & ~occluded,
                                           &out);
            }
        }
        if (occluded == active || n_stack == 0)
            return occluded;
        cur = stack[--n_stack];
    }
}

static uint32_t packet_any_coherent(const struct bvh *bvh, const struct bvh_packet *packet,
                                    uint32_t active, struct packet_pre *pp, const float t_max[8])
{
    return packet_any(bvh, packet, active, pp, t_max, true);
}

static uint32_t packet_any_general(const struct bvh *bvh, const struct bvh_packet *packet,
                                   uint32_t active, struct packet_pre *pp, const float t_max[8])
{
    return packet_any(bvh, packet, active, pp, t_max, false);
}

uint32_t bvh_occluded_packet(const struct bvh *bvh, const struct bvh_packet *packet,
                             uint32_t active)
{
    active &= (1u << BVH_PACKET_SIZE) - 1u;
    if (!(bvh->layouts & BVH_LAYOUT_WIDE) || bvh->n_wide == 0) {
        uint32_t occluded = 0;
        for (uint32_t bits = active; bits; bits &= bits - 1) {
            int lane = lowest_bit(bits);
            struct ray r = {{packet->o[0][lane], packet->o[1][lane], packet->o[2][lane]},
                            packet->t_min[lane],
                            {packet->d[0][lane], packet->d[1][lane], packet->d[2][lane]},
                            packet->t_max[lane]};
            if (bvh_occluded(bvh, &r))
                occluded |= 1u << lane;
        }
        return occluded;
    }
    struct packet_pre pp;
    float t_max[8];
    packet_setup(packet, active, &pp, t_max);
    return pp.coherent ? packet_any_coherent(bvh, packet, active, &pp, t_max)
                       : packet_any_general(bvh, packet, active, &pp, t_max);
}

void bvh_packet_set(struct bvh_packet *packet, int lane, const struct ray *ray)
{
    assert(lane >= 0 && lane < BVH_PACKET_SIZE);
    packet->o[0][lane] = ray->o.x;
    packet->o[1][lane] = ray->o.y;
    packet->o[2][lane] = ray->o.z;
    packet->d[0][lane] = ray->d.x;
    packet->d[1][lane] = ray->d.y;
    packet->d[2][lane] = ray->d.z;
    packet->t_min[lane] = ray->t_min;
    packet->t_max[lane] = ray->t_max;
}

/* ---- Brute force: every triangle, the same test ----------------------------------------------
 * O(n) per ray, the baseline of the BVH-versus-naive table and the oracle of the tests.  It
 * tests the BVH-ordered triangles with the scalar tri_hit, so a triangle's t, u, v are
 * bit-identical to what the traversals compute for it; among exactly equal t the lowest BVH
 * position wins.  Without the binary layout it walks the wide leaves in their stored order. */
bool bvh_intersect_brute(const struct bvh *bvh, const struct ray *ray, struct bvh_hit *hit)
{
    struct ray_pre rp;
    ray_setup(ray, &rp);
    float t_hit = ray->t_max;
    float u_hit = 0.0f;
    float v_hit = 0.0f;
    uint32_t prim = UINT32_MAX;
    if (bvh->layouts & BVH_LAYOUT_BINARY) {
        for (uint32_t i = 0; i < bvh->n_tris; i++) {
            float t;
            float u;
            float v;
            if (tri_hit(&bvh->tris[i], &rp, ray->t_min, t_hit, &t, &u, &v)) {
                t_hit = t;
                u_hit = u;
                v_hit = v;
                prim = bvh->prim_idx[i];
            }
        }
    } else if (bvh->n_wide > 0) {
        /* every leaf, depth first in stored order; leaf triangles are stored in that order */
        uint32_t stack[WIDE_STACK_SIZE];
        uint32_t n_stack = 0;
        stack[n_stack++] = 0;
        while (n_stack > 0) {
            uint32_t ref = stack[--n_stack];
            if (!(ref & WIDE_LEAF)) {
                const struct wide_node *node = &bvh->wide[ref];
                for (uint32_t c = node->n_children; c-- > 0;)
                    stack[n_stack++] = node->child[c];
                continue;
            }
            uint32_t first = (ref & ~WIDE_LEAF) >> 3;
            uint32_t n = (ref & 7u) + 1;
            const float *base = bvh->leaf_tris + 9 * (size_t)first;
            for (uint32_t i = 0; i < n; i++) {
                struct bvh_tri tri;
                float *p[3] = {tri.p0, tri.p1, tri.p2};
                for (int k = 0; k < 3; k++)
                    for (int a = 0; a < 3; a++)
                        p[k][a] = base[(size_t)(3 * k + a) * n + i];
                float t;
                float u;
                float v;
                if (tri_hit(&tri, &rp, ray->t_min, t_hit, &t, &u, &v)) {
                    t_hit = t;
                    u_hit = u;
                    v_hit = v;
                    prim = bvh->wide_prim_idx[first + i];
                }
            }
        }
    }
    if (prim == UINT32_MAX)
        return false;
    *hit = (struct bvh_hit){t_hit, u_hit, v_hit, prim};
    return true;
}

/* ---- Stats ------------------------------------------------------------------------------------
 * SAH cost of the finished binary tree, normalised by the root's area (Wald 2007's cost model
 * summed over the tree; A(n) / A(root) is the probability that a ray hitting the root hits n):
 *   C = sum_interior C_trav A(n) / A(root) + sum_leaves C_isect N(n) A(n) / A(root)
 * When the root has zero area (every triangle at one point) all ratios are taken as 1. */
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
}

struct bvh_stats bvh_get_stats(const struct bvh *bvh) { return bvh->stats; }

void bvh_free(struct bvh *bvh)
{
    if (!bvh)
        return;
    free(bvh->nodes);
    free(bvh->tris);
    free(bvh->prim_idx);
    free(bvh->wide);
    free(bvh->leaf_tris);
    free(bvh->wide_prim_idx);
    free(bvh);
}
