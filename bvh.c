/* bvh.c - the scalar reference BVH over triangles: 32-byte binary nodes in one flat array,
 * triangles permuted into BVH order, the binned-SAH build (Wald 2007, "On fast Construction of
 * SAH-based Bounding Volume Hierarchies") with spatial splits (Stich, Friedrich, Dietrich 2009,
 * "Spatial Splits in Bounding Volume Hierarchies") on several threads for large meshes, ordered
 * traversal with a conservative slab test (PBRT 4e, ch. 6, "Conservative Ray-Bounds
 * Intersections"), the watertight triangle test (Woop, Benthin, Wald 2013, "Watertight
 * Ray/Triangle Intersection"), brute force and stats.  Reading order: layout, build, spatial
 * splits, traversal, triangle test, brute force, stats.  The fast 8-wide layout is converted
 * from this tree in bvh_wide.c, which is checked against it; bvh_internal.h is what the two
 * share.  Measurements: docs/bvh.md. */
#include "bvh.h"

#include <assert.h>
#include <float.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <time.h>

#include "bvh_internal.h"

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
 * Depth (root = 0) is at most BVH_MAX_DEPTH (64), so the traversal stack of BVH_MAX_DEPTH entries
 *   cannot overflow: it holds at most one pending sibling per level.
 * Triangles keep their three vertices exactly as given, in input order (struct bvh_tri, 36 bytes,
 *   bvh_internal.h), so the hit point is (1 - u - v) p0 + u p1 + v p2 of the caller's triangle
 *   prim_idx.  Shading data stays with the caller; the BVH returns prim_idx, t, u and v. */

/* ---- Build: binned SAH, Wald 2007 ------------------------------------------------------------
 * The build sees only one box and one centre per triangle (the centre of its box).  At each
 * node the centres' bounds are cut into BVH_N_BINS equal bins on each axis; every plane between
 * two bins is a candidate, and the cheapest by the surface area heuristic wins:
 *   C_split = C_trav + (A_L / A) * N_L * C_isect + (A_R / A) * N_R * C_isect
 *   C_leaf  = N * C_isect
 * with A the surface area of the node's box, A_L/A_R those of the children's boxes and N_L/N_R
 * their triangle counts.  A node becomes a leaf when C_leaf <= C_split and N <= BVH_MAX_LEAF_TRIS,
 * when N <= BVH_UNBINNED_LEAF_TRIS (without binning), or at depth BVH_MAX_DEPTH (any size).
 * When all centres coincide no plane separates them: a node of more than BVH_MAX_LEAF_TRIS
 * triangles is then cut in the middle of its index range, so leaves stay bounded and depth grows
 * only as log2(N).
 * Threads: every node's split depends only on its own range of refs, so the tree is the same
 * for any thread count.  With several threads the top nodes are split first, in waves: the
 * largest pending nodes, up to one per thread, are split side by side, each binned on its share
 * of the threads (each fills private bins over a slice, then they are merged: box unions and
 * counts are exact), until there are BVH_SUBTREES_PER_THREAD subtrees per thread; those are
 * built in parallel into reserved node ranges and renumbered into the order above. */

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
/* A node of at most 6 triangles is a leaf without being binned.  The wide layout tests 8
 * triangles at once and its collapse (bvh_wide.c) merged most such subtrees into one leaf
 * anyway; binning the nodes of at most 8 took a fifth of the build.  Measured (docs/bvh.md,
 * "Small nodes"): dragon binned build -21 to -22% (8: -25%), the collapse's SAH cost
 * +0.2-0.9%, Sponza's camera-ray packets 1% slower (8: 5%, a packet tests a leaf's triangles
 * one by one). */
#define BVH_UNBINNED_LEAF_TRIS 6
_Static_assert(BVH_UNBINNED_LEAF_TRIS >= 2 && BVH_UNBINNED_LEAF_TRIS <= BVH_MAX_LEAF_TRIS,
               "at N <= C_trav / C_isect = 2 the leaf always wins; leaves stay <= 8");
/* BVH_MAX_DEPTH (64, deepest node) is in bvh_internal.h: the wide layout's stacks depend on it */
#define BVH_PARALLEL_MIN_TRIS 65536 /* fewer: build on one thread (the threads cost more) */
#define BVH_PARALLEL_BIN_MIN 16384  /* top nodes with more refs share their binning */
#define BVH_WAVE_MIN_REFS 2048      /* smaller pending nodes are not split before the subtrees */
#define BVH_SUBTREES_PER_THREAD 4   /* subtrees handed to the threads, per thread */
#define BVH_MAX_THREADS 64

/* What the build knows of one triangle, or of the part of one that a spatial split left on one
 * side of its plane: its box (the centre is derived from it). */
struct prim_ref {
    float min[3];           /* lower corner of the box of the stored vertices */
    uint32_t prim_idx;      /* the caller's index of the triangle */
    float max[3];           /* upper corner */
    uint32_t is_degenerate; /* 1 for a zero-area triangle (dropped from the wide layout) */
};                          /* 32 bytes */

/* Per axis, per bin: the union of the boxes of the triangles whose centre falls in the bin, and
 * their number (kept apart, so that each box sits on a 32-byte boundary, in one cache line). */
struct bins {
    struct box box[3][BVH_N_BINS] __attribute__((aligned(32)));
    uint32_t n[3][BVH_N_BINS];
}; /* 1728 bytes */

/* A node waiting to be built: refs[begin, end) at depth, with the bounds of the refs' boxes
 * and of their centres (computed while the parent partitioned them); refs[end, cap) are spare
 * slots for the copies of spatial splits (none in a binned build). */
struct build_task {
    uint32_t node_idx;        /* node to fill */
    uint32_t begin;           /* first ref */
    uint32_t end;             /* one past the last */
    uint32_t cap;             /* one past the last slot the task owns */
    uint32_t depth;           /* root = 0 */
    uint32_t node_base;       /* parallel subtrees: first node index of its reserved range */
    struct box bounds;        /* of the refs' boxes */
    struct box centre_bounds; /* of their centres */
};                            /* 88 bytes */

/* A split candidate: sah_sum = A_L N_L + A_R N_R (half areas), the part of C_split that varies. */
struct split {
    int axis;      /* 0, 1, 2; -1 when no candidate separates the centres */
    int bin;       /* the left child takes bins 0..bin */
    float sah_sum; /* A_L * N_L + A_R * N_R */
};                 /* 12 bytes */

struct build_ctx {
    struct prim_ref *refs;  /* the refs, permuted into BVH order by the build (with gaps) */
    struct bvh_node *nodes; /* node array being written */
    int n_threads;          /* 1 .. BVH_MAX_THREADS */
    bool spatial;           /* spatial splits (BVH_QUALITY_SPATIAL) */
    float min_overlap;      /* half area of overlap that tries a spatial split */
    const vec3 *positions;  /* the caller's mesh, for clipping triangles */
    const uint32_t *indices;
};

/* Four float lanes (x, y, z and a padding lane kept 0) as a GNU C vector type, which gcc and clang
 * compile to one SIMD operation where the target has SIMD and to scalar code elsewhere: portable
 * C, not intrinsics (STYLE.md, section 3).  v4_min(a, b) is a < b ? a : b lane by lane, the
 * comparison box_grow makes, so both give the same bits. */
typedef float v4f __attribute__((vector_size(16)));
typedef int32_t v4i __attribute__((vector_size(16)));

static inline v4f v4_load(const float p[4])
{
    v4f v;
    memcpy(&v, p, sizeof v);
    return v;
}

static inline void v4_store(float p[4], v4f v) { memcpy(p, &v, sizeof v); }

static inline v4f v4_min(v4f a, v4f b)
{
    v4i m = a < b;
    return (v4f)((m & (v4i)a) | (~m & (v4i)b));
}

static inline v4f v4_max(v4f a, v4f b)
{
    v4i m = a > b;
    return (v4f)((m & (v4i)a) | (~m & (v4i)b));
}

/* m ? a : b lane by lane (m's lanes all ones or zeros, as comparisons make them) */
static inline v4f v4_select(v4i m, v4f a, v4f b) { return (v4f)((m & (v4i)a) | (~m & (v4i)b)); }

/* A ref's corners as vectors: one load each, lane 3 (prim_idx, is_degenerate in memory) masked
 * to 0. */
static inline v4f ref_lo(const struct prim_ref *r)
{
    v4f v;
    memcpy(&v, r->min, sizeof v); /* min[3] and prim_idx */
    return (v4f)((v4i)v & (v4i){-1, -1, -1, 0});
}

static inline v4f ref_hi(const struct prim_ref *r)
{
    v4f v;
    memcpy(&v, r->max, sizeof v); /* max[3] and is_degenerate */
    return (v4f)((v4i)v & (v4i){-1, -1, -1, 0});
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

static void ref_centre(const struct prim_ref *r, float c[3])
{
    for (int a = 0; a < 3; a++)
        c[a] = 0.5f * (r->min[a] + r->max[a]);
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
            bins->box[axis][k] = empty_box;
    memset(bins->n, 0, sizeof bins->n);
}

/* What binning needs of a task's centre bounds, as 4-lane vectors (lane 3 is zero padding):
 * the lower corner, bin_scale per axis and the last bin. */
struct bin_map {
    v4f c_min;
    v4f scale;
    v4f last;
};

static struct bin_map bin_map_of(const struct box *centre_bounds)
{
    return (
        struct bin_map){{centre_bounds->min[0], centre_bounds->min[1], centre_bounds->min[2], 0.0f},
                        {bin_scale(centre_bounds, 0), bin_scale(centre_bounds, 1),
                         bin_scale(centre_bounds, 2), 0.0f},
                        {BVH_N_BINS - 1, BVH_N_BINS - 1, BVH_N_BINS - 1, BVH_N_BINS - 1}};
}

/* The bins of centre c on the three axes in one vector operation,
 *   k_a = (int) min((c_a - c_min_a) scale_a, N - 1),
 * the one formula of both binning and partitioning (so a ref goes to the side its bin is on). */
static inline v4i centre_bins(const struct bin_map *m, v4f c)
{
    return __builtin_convertvector(v4_min((c - m->c_min) * m->scale, m->last), v4i);
}

/* centre_bins(m, c)[axis], with scalar arithmetic (the same operations on the same lane) */
static inline int centre_bin(const struct bin_map *m, v4f c, int axis)
{
    float x = (c[axis] - m->c_min[axis]) * m->scale[axis];
    return (int)(x < m->last[axis] ? x : m->last[axis]);
}

/* One pass fills the bins of all three axes (Wald 2007, sec. 3.2): one ref's box, centre and
 * three bin indices are each one 4-lane vector operation. */
static void bins_fill(struct bins *bins, const struct prim_ref *refs, uint32_t begin, uint32_t end,
                      const struct box *centre_bounds)
{
    const struct bin_map m = bin_map_of(centre_bounds);
    for (uint32_t i = begin; i < end; i++) {
        const struct prim_ref *r = &refs[i];
        v4f lo = ref_lo(r);
        v4f hi = ref_hi(r);
        v4i k = centre_bins(&m, 0.5f * (lo + hi));
        for (int axis = 0; axis < 3; axis++) {
            struct box *b = &bins->box[axis][k[axis]];
            v4_store(b->min, v4_min(lo, v4_load(b->min)));
            v4_store(b->max, v4_max(hi, v4_load(b->max)));
            bins->n[axis][k[axis]]++;
        }
    }
}

static void bins_merge(struct bins *into, const struct bins *from)
{
    for (int axis = 0; axis < 3; axis++) {
        for (int k = 0; k < BVH_N_BINS; k++) {
            box_union(&into->box[axis][k], &from->box[axis][k]);
            into->n[axis][k] += from->n[axis][k];
        }
    }
}

/* The cheapest plane of n binned refs: per axis a sweep from the right gathers the right
 * children's areas and one from the left evaluates every plane.  The running box is one vector
 * and its half area dx dy + dy dz + dz dx comes from one rotated product, added in
 * box_half_area's order (so both give the same bits). */
static inline float half_area_v4(v4f lo, v4f hi)
{
    v4f d = hi - lo;
    v4f p = d * __builtin_shufflevector(d, d, 1, 2, 0, 3); /* dx dy, dy dz, dz dx */
    return p[0] + p[1] + p[2];
}

static struct split bins_best_split(const struct bins *bins, uint32_t n)
{
    struct split best = {-1, 0, INFINITY};
    const v4f empty_lo = v4_load(empty_box.min);
    const v4f empty_hi = v4_load(empty_box.max);
    for (int axis = 0; axis < 3; axis++) {
        const struct box *b = bins->box[axis];
        const uint32_t *b_n = bins->n[axis];
        /* right sweep: right_area[k], right_n[k] describe bins k .. BVH_N_BINS - 1 */
        float right_area[BVH_N_BINS];
        uint32_t right_n[BVH_N_BINS];
        v4f lo = empty_lo;
        v4f hi = empty_hi;
        uint32_t acc_n = 0;
        for (int k = BVH_N_BINS - 1; k > 0; k--) {
            lo = v4_min(v4_load(b[k].min), lo);
            hi = v4_max(v4_load(b[k].max), hi);
            acc_n += b_n[k];
            right_area[k] = acc_n > 0 ? half_area_v4(lo, hi) : 0.0f;
            right_n[k] = acc_n;
        }
        /* left sweep: the plane after bin k puts bins 0..k left, k+1.. right */
        lo = empty_lo;
        hi = empty_hi;
        acc_n = 0;
        for (int k = 0; k < BVH_N_BINS - 1; k++) {
            lo = v4_min(v4_load(b[k].min), lo);
            hi = v4_max(v4_load(b[k].max), hi);
            acc_n += b_n[k];
            if (acc_n == 0 || acc_n == n)
                continue; /* one side would be empty */
            float sah_sum = half_area_v4(lo, hi) * (float)acc_n +
                            right_area[k + 1] * (float)right_n[k + 1];
            if (sah_sum < best.sah_sum)
                best = (struct split){axis, k, sah_sum};
        }
    }
    return best;
}

void bvh_run_jobs(int n_jobs, void *(*fn)(void *), void *args, size_t arg_bytes)
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

/* Start of slice i of n_slices equal slices of [begin, begin + n). */
static uint32_t slice_begin(uint32_t begin, uint32_t n, int i, int n_slices)
{
    return begin + (uint32_t)((uint64_t)n * (uint64_t)i / (uint64_t)n_slices);
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
    /* aligned: struct bins asks for 32 bytes */
    struct bin_job *jobs = bvh_alloc_aligned((size_t)n_threads, sizeof *jobs);
    if (!jobs) {
        bins_clear(bins);
        bins_fill(bins, refs, begin, end, centre_bounds);
        return;
    }
    uint32_t n = end - begin;
    for (int i = 0; i < n_threads; i++) {
        jobs[i].refs = refs;
        jobs[i].begin = slice_begin(begin, n, i, n_threads);
        jobs[i].end = slice_begin(begin, n, i + 1, n_threads);
        jobs[i].centre_bounds = centre_bounds;
    }
    bvh_run_jobs(n_threads, bin_job_run, jobs, sizeof *jobs);
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

/* ---- Spatial splits: Stich, Friedrich, Dietrich 2009, "Spatial Splits in Bounding Volume
 * Hierarchies" -----------------------------------------------------------------------------------
 * An object split sends each triangle whole to one side.  Where the two children's boxes then
 * overlap a lot (long thin triangles, architecture), a plane that cuts triangles can do better.
 * The node's box (not its centres' box) is cut into BVH_N_SPATIAL_BINS slabs per axis, and each
 * ref is clipped into every slab it crosses: the slab's box grows by the box of the triangle's
 * part inside it ("chopped binning", sec. 4.2), and the ref is counted entering its first slab
 * and leaving its last.  The plane after slab k then costs, as an object split does,
 *   sah_sum = A_L N_L + A_R N_R,   N_L = refs entering slabs 0..k,   N_R = refs leaving k+1..
 * Spatial splits are searched only where the best object split's children overlap by more
 * than alpha = 1e-5 of the root's area (sec. 4.3), and taken when cheaper.  A ref the chosen
 * plane cuts is kept whole on one side when that costs less than the two copies (reference
 * unsplitting, sec. 4.4):
 *   both:  A_L N_L + A_R N_R,   left only:  A(L + ref) N_L + A_R (N_R - 1),   right: alike
 * Clipping never loses part of a triangle: a ref's box is that of the triangle's vertices on
 * its side and of the points where its edges cross the plane, computed in double and widened
 * by one float step (so each contains the exact point), then cut to the ref's old box.  Copies
 * cost memory: a task owns refs[begin, cap), its refs in [begin, end) and spare slots after
 * them; the root gets BVH_SPLIT_BUDGET of the triangle count spare, and each split shares what
 * is left between its children in proportion to their refs.  A cut ref finding no spare slot
 * is unsplit.  All of this depends only on the node's refs, so the tree is still the same for
 * any thread count. */
#define BVH_N_SPATIAL_BINS 16             /* slabs per axis */
#define BVH_SPLIT_ALPHA 1e-5f             /* Stich et al. 2009, sec. 4.3: overlap / root area */
#define BVH_SPLIT_BUDGET 0.25             /* spare refs for copies, fraction of the triangles */
#define BVH_SPATIAL_MIN_REFS 64           /* smaller nodes: object splits only */
#define BVH_SPATIAL_MIN_NODE_OVERLAP 0.1f /* and overlap / the node's own area, to search */

struct spatial_bin {
    struct box box; /* union of the boxes of the refs' parts inside the slab */
    uint32_t enter; /* refs whose first slab this is */
    uint32_t exit;  /* refs whose last slab this is */
};                  /* 40 bytes */

struct spatial_bins {
    struct spatial_bin b[3][BVH_N_SPATIAL_BINS]; /* per axis */
};                                               /* 1920 bytes */

/* The slabs of a node's box: slab k of axis a is [lo + k step, lo + (k + 1) step]. */
struct slab_grid {
    float lo[3];
    float step[3];     /* extent / BVH_N_SPATIAL_BINS */
    float inv_step[3]; /* BVH_N_SPATIAL_BINS / extent; 0 where the axis offers no plane */
};

static void slab_grid_init(struct slab_grid *g, const struct box *bounds)
{
    for (int a = 0; a < 3; a++) {
        float extent = bounds->max[a] - bounds->min[a];
        g->lo[a] = bounds->min[a];
        g->step[a] = extent / (float)BVH_N_SPATIAL_BINS;
        float inv = (float)BVH_N_SPATIAL_BINS / extent;
        g->inv_step[a] = extent > 0.0f && g->step[a] > 0.0f && isfinite(inv) ? inv : 0.0f;
    }
}

/* Clamped in float before the conversion: a vertex of a clipped ref can lie farther from the
 * node than an int can count slabs (and NaN goes to 0), so the slab is defined and monotone in x. */
static inline float slab_clamp(float t)
{
    t = t > 0.0f ? t : 0.0f;
    return t < (float)(BVH_N_SPATIAL_BINS - 1) ? t : (float)(BVH_N_SPATIAL_BINS - 1);
}

static int slab_of(const struct slab_grid *g, int a, float x)
{
    return (int)slab_clamp((x - g->lo[a]) * g->inv_step[a]);
}

/* slab_of on the three axes at once (lane a: axis a; lane 3 unused): the same operations, so the
 * same slabs.  lo and inv are g's lo and inv_step as vectors. */
static inline v4i slabs_of(v4f lo, v4f inv, v4f x)
{
    v4f t = (x - lo) * inv;
    for (int i = 0; i < 4; i++)
        t[i] = slab_clamp(t[i]);
    return __builtin_convertvector(t, v4i);
}

/* The plane between slabs k - 1 and k of axis a. */
static float slab_plane(const struct slab_grid *g, int a, int k)
{
    return g->lo[a] + (float)k * g->step[a];
}

static bool box_is_empty(const struct box *b)
{
    return !(b->min[0] <= b->max[0] && b->min[1] <= b->max[1] && b->min[2] <= b->max[2]);
}

static struct box box_of_ref(const struct prim_ref *r)
{
    return (struct box){{r->min[0], r->min[1], r->min[2], 0.0f},
                        {r->max[0], r->max[1], r->max[2], 0.0f}};
}

/* b shrinks to its intersection with c (empty when they do not meet). */
static void box_clip(struct box *b, const struct box *c)
{
    for (int a = 0; a < 3; a++) {
        b->min[a] = c->min[a] > b->min[a] ? c->min[a] : b->min[a];
        b->max[a] = c->max[a] < b->max[a] ? c->max[a] : b->max[a];
    }
}

/* The boxes of the parts of triangle tri inside box `in` on either side of the plane
 * x_axis = plane, each cut to `in`: box_is_empty for a side it does not reach. */
static void split_tri_box(const struct bvh_tri *tri, const struct box *in, int axis, float plane,
                          struct box *left, struct box *right)
{
    const float *v[3] = {tri->p0, tri->p1, tri->p2};
    *left = empty_box;
    *right = empty_box;
    for (int k = 0; k < 3; k++) {
        const float *u = v[k];
        const float *w = v[k == 2 ? 0 : k + 1];
        if (u[axis] <= plane)
            box_grow(left, u, u);
        if (u[axis] >= plane)
            box_grow(right, u, u);
        if ((u[axis] < plane && w[axis] > plane) || (u[axis] > plane && w[axis] < plane)) {
            /* the edge meets the plane at u + s (w - u), s = (plane - u_a) / (w_a - u_a); in
             * double each coordinate is within 2^-50 of its value relative, and one float step
             * either side of its rounding brackets it */
            double s = ((double)plane - (double)u[axis]) / ((double)w[axis] - (double)u[axis]);
            float lo[3];
            float hi[3];
            for (int a = 0; a < 3; a++) {
                if (a == axis) {
                    lo[a] = hi[a] = plane;
                    continue;
                }
                float x = (float)((double)u[a] + s * ((double)w[a] - (double)u[a]));
                lo[a] = nextafterf(x, -INFINITY);
                hi[a] = nextafterf(x, INFINITY);
            }
            box_grow(left, lo, hi);
            box_grow(right, lo, hi);
        }
    }
    box_clip(left, in);
    box_clip(right, in);
}

static void spatial_bins_clear(struct spatial_bins *sb)
{
    for (int a = 0; a < 3; a++)
        for (int k = 0; k < BVH_N_SPATIAL_BINS; k++)
            sb->b[a][k] = (struct spatial_bin){empty_box, 0, 0};
}

/* The triangle's parts in the slabs first..last of axis a, cut to the ref's box [lo, hi], into
 * the bins (chopped binning).  With the vertices sorted along a (A <= B <= C), a plane between
 * two slabs crosses edge AC and edge AB (below B) or BC (above): slab k's part is bounded by
 * the crossings on its two planes and by the vertices inside it.  The crossings are computed in
 * float without widening: these boxes only estimate the SAH; the refs themselves are clipped
 * conservatively by split_tri_box. */
static void chop_into_bins(struct spatial_bin *bins, const struct slab_grid *g, int a, int first,
                           int last, const v4f v[3], const v4i v_slab[3], v4f lo, v4f hi)
{
    /* the vertices sorted along a, stably, by their ranks (no branches: the order is random) */
    const float x0 = v[0][a], x1 = v[1][a], x2 = v[2][a];
    int order[3];
    order[(x1 < x0) + (x2 < x0)] = 0;
    order[(x0 <= x1) + (x2 < x1)] = 1;
    order[(x0 <= x2) + (x1 <= x2)] = 2;
    const int ia = order[0], ib = order[1], ic = order[2];
    const v4f A = v[ia];
    const v4f B = v[ib];
    const v4f C = v[ic];
    /* the slabs from first to last in one pass: slab k's part is bounded by the crossings on
     * planes k and k + 1 (the previous step's and this one's) and by the vertices inside it,
     * which, sorted along a, fall into slabs in order (slab_of is monotone) */
    const v4f *vert[3] = {&v[ia], &v[ib], &v[ic]};
    const int vert_slab[3] = {v_slab[ia][a], v_slab[ib][a], v_slab[ic][a]};
    int next_vert = 0;
    v4f cross_lo = {INFINITY, INFINITY, INFINITY, 0.0f}; /* plane k's crossings, none at first */
    v4f cross_hi = {-INFINITY, -INFINITY, -INFINITY, 0.0f};
    /* where plane j = first + 1 + i crosses edge AC (s_ac[i]) and edge AB or BC (s_uw[i]), as
     * fractions of the edge, four planes a vector: each lane the operations of slab_plane and
     * of one plane at a time, so the same bits, with a quarter of the divisions */
    float plane[BVH_N_SPATIAL_BINS + 3], s_ac[BVH_N_SPATIAL_BINS + 3], s_uw[BVH_N_SPATIAL_BINS + 3];
    const v4f zero = {0.0f, 0.0f, 0.0f, 0.0f}, one = {1.0f, 1.0f, 1.0f, 1.0f};
    const v4f a_a = zero + A[a], b_a = zero + B[a], c_a = zero + C[a];
    for (int i = 0; i < last - first; i += 4) {
        float j = (float)(first + 1 + i);
        v4f p = (zero + g->lo[a]) + (v4f){j, j + 1.0f, j + 2.0f, j + 3.0f} * g->step[a];
        v4i ac_ok = c_a > a_a; /* else the edge is flat along a: s = 0 */
        v4f s = v4_select(ac_ok, (p - a_a) / v4_select(ac_ok, c_a - a_a, one), zero);
        s = v4_select(s < zero, zero, v4_select(s > one, one, s));
        v4i below_b = p <= b_a; /* the other edge crossed: AB or BC */
        v4f u_a = v4_select(below_b, a_a, b_a);
        v4f w_a = v4_select(below_b, b_a, c_a);
        v4i uw_ok = w_a > u_a;
        v4f t = v4_select(uw_ok, (p - u_a) / v4_select(uw_ok, w_a - u_a, one), zero);
        t = v4_select(t < zero, zero, v4_select(t > one, one, t));
        memcpy(&plane[i], &p, sizeof p);
        memcpy(&s_ac[i], &s, sizeof s);
        memcpy(&s_uw[i], &t, sizeof t);
    }
    for (int k = first; k <= last; k++) {
        v4f part_lo = cross_lo;
        v4f part_hi = cross_hi;
        for (; next_vert < 3; next_vert++) {
            if (vert_slab[next_vert] > k && k < last)
                break;
            part_lo = v4_min(part_lo, *vert[next_vert]);
            part_hi = v4_max(part_hi, *vert[next_vert]);
        }
        if (k < last) { /* plane k + 1's two crossings bound slabs k and k + 1 */
            int i = k - first;
            v4f x = A + (C - A) * s_ac[i];
            const v4f U = plane[i] <= B[a] ? A : B;
            const v4f W = plane[i] <= B[a] ? B : C;
            v4f y = U + (W - U) * s_uw[i];
            cross_lo = v4_min(x, y);
            cross_hi = v4_max(x, y);
            part_lo = v4_min(part_lo, cross_lo);
            part_hi = v4_max(part_hi, cross_hi);
        }
        v4f l = v4_max(part_lo, lo); /* cut to the ref's box */
        v4f h = v4_min(part_hi, hi);
        v4i nonempty = l <= h; /* lane 3: 0 <= 0 */
        uint64_t half[2];
        memcpy(half, &nonempty, sizeof half);
        if ((half[0] & half[1]) == UINT64_MAX) { /* all four lanes: one test, not three */
            struct box *b = &bins[k].box;
            v4_store(b->min, v4_min(l, v4_load(b->min)));
            v4_store(b->max, v4_max(h, v4_load(b->max)));
        }
    }
}

/* Chopped binning of refs[begin, end) into the slabs of g. */
static void spatial_bins_fill(struct spatial_bins *sb, const struct build_ctx *ctx, uint32_t begin,
                              uint32_t end, const struct slab_grid *g)
{
    const v4f g_lo = {g->lo[0], g->lo[1], g->lo[2], 0.0f};
    const v4f g_inv = {g->inv_step[0], g->inv_step[1], g->inv_step[2], 0.0f};
    for (uint32_t i = begin; i < end; i++) {
        const struct prim_ref *r = &ctx->refs[i];
        /* the refs are in no order of the mesh: the vertices a later ref may clip are requested
         * ahead (its indices 16 refs ahead, its positions 8, through those indices) */
        if (i + 16 < end)
            __builtin_prefetch(&ctx->indices[3 * (size_t)ctx->refs[i + 16].prim_idx]);
        if (i + 8 < end) {
            const uint32_t *idx = &ctx->indices[3 * (size_t)ctx->refs[i + 8].prim_idx];
            for (int k = 0; k < 3; k++)
                __builtin_prefetch(&ctx->positions[idx[k]]);
        }
        const v4f lo = ref_lo(r);
        const v4f hi = ref_hi(r);
        const v4i first_v = slabs_of(g_lo, g_inv, lo);
        const v4i last_v = slabs_of(g_lo, g_inv, hi);
        bool have_tri = false;
        v4f v[3];
        v4i v_slab[3];
        for (int a = 0; a < 3; a++) {
            if (g->inv_step[a] == 0.0f)
                continue;
            int first = first_v[a];
            int last = last_v[a];
            sb->b[a][first].enter++;
            sb->b[a][last].exit++;
            if (first == last) {
                struct box *b = &sb->b[a][first].box;
                v4_store(b->min, v4_min(lo, v4_load(b->min)));
                v4_store(b->max, v4_max(hi, v4_load(b->max)));
                continue;
            }
            if (!have_tri) {
                for (int k = 0; k < 3; k++) {
                    vec3 p = ctx->positions[ctx->indices[3 * (size_t)r->prim_idx + (size_t)k]];
                    v[k] = (v4f){p.x, p.y, p.z, 0.0f};
                    v_slab[k] = slabs_of(g_lo, g_inv, v[k]);
                }
                have_tri = true;
            }
            chop_into_bins(sb->b[a], g, a, first, last, v, v_slab, lo, hi);
        }
    }
}

struct spatial_job {
    const struct build_ctx *ctx;
    uint32_t begin;
    uint32_t end;
    const struct slab_grid *grid;
    struct spatial_bins bins;
};

static void *spatial_job_run(void *arg)
{
    struct spatial_job *job = arg;
    spatial_bins_clear(&job->bins);
    spatial_bins_fill(&job->bins, job->ctx, job->begin, job->end, job->grid);
    return NULL;
}

/* Chopped binning on n_threads threads (private bins per slice, merged: exact). */
static void spatial_bins_fill_parallel(struct spatial_bins *sb, const struct build_ctx *ctx,
                                       uint32_t begin, uint32_t end, const struct slab_grid *g,
                                       int n_threads)
{
    struct spatial_job *jobs = malloc((size_t)n_threads * sizeof *jobs);
    spatial_bins_clear(sb);
    if (!jobs) {
        spatial_bins_fill(sb, ctx, begin, end, g);
        return;
    }
    for (int i = 0; i < n_threads; i++)
        jobs[i] = (struct spatial_job){.ctx = ctx,
                                       .begin = slice_begin(begin, end - begin, i, n_threads),
                                       .end = slice_begin(begin, end - begin, i + 1, n_threads),
                                       .grid = g};
    bvh_run_jobs(n_threads, spatial_job_run, jobs, sizeof *jobs);
    for (int i = 0; i < n_threads; i++) {
        for (int a = 0; a < 3; a++) {
            for (int k = 0; k < BVH_N_SPATIAL_BINS; k++) {
                box_union(&sb->b[a][k].box, &jobs[i].bins.b[a][k].box);
                sb->b[a][k].enter += jobs[i].bins.b[a][k].enter;
                sb->b[a][k].exit += jobs[i].bins.b[a][k].exit;
            }
        }
    }
    free(jobs);
}

/* The two sides of the plane after slab k of axis a: their boxes and ref counts. */
static void spatial_sides(const struct spatial_bins *sb, int a, int k, struct box *left,
                          struct box *right, uint32_t *n_left, uint32_t *n_right)
{
    *left = empty_box;
    *right = empty_box;
    *n_left = 0;
    *n_right = 0;
    for (int j = 0; j < BVH_N_SPATIAL_BINS; j++) {
        const struct spatial_bin *b = &sb->b[a][j];
        if (j <= k) {
            box_union(left, &b->box);
            *n_left += b->enter;
        } else {
            box_union(right, &b->box);
            *n_right += b->exit;
        }
    }
}

/* The cheapest plane between slabs, swept as bins_best_split does. */
static struct split spatial_best_split(const struct spatial_bins *sb, const struct slab_grid *g)
{
    struct split best = {-1, 0, INFINITY};
    for (int a = 0; a < 3; a++) {
        if (g->inv_step[a] == 0.0f)
            continue;
        const struct spatial_bin *b = sb->b[a];
        float right_area[BVH_N_SPATIAL_BINS];
        uint32_t right_n[BVH_N_SPATIAL_BINS];
        struct box acc = empty_box;
        uint32_t acc_n = 0;
        for (int k = BVH_N_SPATIAL_BINS - 1; k > 0; k--) {
            box_union(&acc, &b[k].box);
            acc_n += b[k].exit;
            right_area[k] = acc_n > 0 ? box_half_area(&acc) : 0.0f;
            right_n[k] = acc_n;
        }
        acc = empty_box;
        acc_n = 0;
        for (int k = 0; k < BVH_N_SPATIAL_BINS - 1; k++) {
            box_union(&acc, &b[k].box);
            acc_n += b[k].enter;
            if (acc_n == 0 || right_n[k + 1] == 0)
                continue;
            float sah_sum = box_half_area(&acc) * (float)acc_n +
                            right_area[k + 1] * (float)right_n[k + 1];
            if (sah_sum < best.sah_sum)
                best = (struct split){a, k, sah_sum};
        }
    }
    return best;
}

/* Gives the children their ranges: left refs in [begin, left_end), right refs in
 * [right_begin, right_end) (right_begin >= left_end, right_end <= cap); the spare slots
 * cap - begin - n_L - n_R are shared in proportion to the counts, the right block moving up to
 * make the left one's share. */
static void place_children(struct prim_ref *refs, const struct build_task *task, uint32_t left_end,
                           uint32_t right_begin, uint32_t right_end, struct build_task child[2])
{
    uint32_t n_l = left_end - task->begin;
    uint32_t n_r = right_end - right_begin;
    uint32_t spare = task->cap - task->begin - n_l - n_r;
    uint32_t spare_l = (uint32_t)((uint64_t)spare * n_l / (n_l + n_r));
    uint32_t dest = left_end + spare_l;
    if (dest != right_begin)
        memmove(&refs[dest], &refs[right_begin], (size_t)n_r * sizeof *refs);
    child[0].begin = task->begin;
    child[0].end = left_end;
    child[0].cap = dest;
    child[1].begin = dest;
    child[1].end = dest + n_r;
    child[1].cap = task->cap;
}

/* The spatial split s of task: refs wholly left of the plane go left, wholly right go right,
 * each cut one to both sides as two clipped refs or whole to one side (unsplitting, within the
 * spare slots).  false, with task's refs permuted but the same multiset in [begin, end), when a
 * side would be empty or memory is short: the caller then splits by objects. */
static bool spatial_partition(const struct build_ctx *ctx, const struct build_task *task,
                              const struct spatial_bins *sb, const struct slab_grid *g,
                              struct split s, struct build_task child[2])
{
    struct prim_ref *refs = ctx->refs;
    const uint32_t begin = task->begin;
    const uint32_t end = task->end;
    const int axis = s.axis;
    const float plane = slab_plane(g, axis, s.bin + 1);
    /* three ways: [begin, lt) left of the plane, [lt, gt) cut by it, [gt, end) right */
    uint32_t lt = begin;
    uint32_t i = begin;
    uint32_t gt = end;
    while (i < gt) {
        struct prim_ref tmp = refs[i];
        if (slab_of(g, axis, tmp.max[axis]) <= s.bin) {
            refs[i++] = refs[lt];
            refs[lt++] = tmp;
        } else if (slab_of(g, axis, tmp.min[axis]) > s.bin) {
            refs[i] = refs[--gt];
            refs[gt] = tmp;
        } else {
            i++;
        }
    }
    uint32_t n_cut = gt - lt;
    struct prim_ref *right_parts = malloc((size_t)n_cut * sizeof *right_parts + 1);
    if (!right_parts)
        return false;
    struct box left_box;
    struct box right_box;
    uint32_t n_left;
    uint32_t n_right;
    spatial_sides(sb, axis, s.bin, &left_box, &right_box, &n_left, &n_right);
    float a_l = box_half_area(&left_box);
    float a_r = box_half_area(&right_box);
    uint32_t spare = task->cap - end;
    uint32_t wl = lt; /* the cut refs' left parts are written back in place, from lt on */
    uint32_t n_rp = 0;
    for (uint32_t k = lt; k < gt; k++) {
        struct prim_ref r = refs[k];
        struct bvh_tri tri;
        bvh_load_tri(&tri, ctx->positions, ctx->indices, r.prim_idx);
        struct box whole = box_of_ref(&r);
        struct box l;
        struct box rt;
        split_tri_box(&tri, &whole, axis, plane, &l, &rt);
        enum { TO_LEFT, TO_RIGHT, TO_BOTH } to;
        if (box_is_empty(&l)) {
            to = TO_RIGHT;
        } else if (box_is_empty(&rt)) {
            to = TO_LEFT;
        } else {
            struct box l_whole = left_box;
            struct box r_whole = right_box;
            box_union(&l_whole, &whole);
            box_union(&r_whole, &whole);
            float c_both = a_l * (float)n_left + a_r * (float)n_right;
            float c_left = box_half_area(&l_whole) * (float)n_left + a_r * (float)(n_right - 1);
            float c_right = a_l * (float)(n_left - 1) + box_half_area(&r_whole) * (float)n_right;
            to = c_left <= c_right ? TO_LEFT : TO_RIGHT;
            if (c_both < (c_left <= c_right ? c_left : c_right) && spare > 0) {
                to = TO_BOTH;
                spare--;
            }
        }
        if (to != TO_RIGHT) {
            struct prim_ref part = r;
            if (to == TO_BOTH) {
                memcpy(part.min, l.min, sizeof part.min);
                memcpy(part.max, l.max, sizeof part.max);
            }
            refs[wl++] = part;
        }
        if (to != TO_LEFT) {
            struct prim_ref part = r;
            if (to == TO_BOTH) {
                memcpy(part.min, rt.min, sizeof part.min);
                memcpy(part.max, rt.max, sizeof part.max);
            }
            right_parts[n_rp++] = part;
        }
    }
    /* the right block: the right parts of cut refs, then the refs wholly right */
    uint32_t n_r = n_rp + (end - gt);
    memmove(&refs[wl + n_rp], &refs[gt], (size_t)(end - gt) * sizeof *refs);
    memcpy(&refs[wl], right_parts, (size_t)n_rp * sizeof *refs);
    free(right_parts);
    if (wl == begin || n_r == 0) /* no copy was made (a copy puts a ref on both sides) */
        return false;
    range_bounds(refs, begin, wl, &child[0].bounds, &child[0].centre_bounds);
    range_bounds(refs, wl, wl + n_r, &child[1].bounds, &child[1].centre_bounds);
    place_children(refs, task, wl, wl, wl + n_r, child);
    return true;
}

/* Whether ref r belongs right of the plane after bin `bin` on axis, by the binning's formula. */
static inline uint32_t ref_goes_right(const struct prim_ref *r, const struct bin_map *m, int axis,
                                      int bin)
{
    return centre_bin(m, 0.5f * (ref_lo(r) + ref_hi(r)), axis) > bin;
}

static inline void ref_swap(struct prim_ref *a, struct prim_ref *b)
{
    struct prim_ref tmp = *a;
    *a = *b;
    *b = tmp;
}

/* Partitions refs[begin, end) into those left of the plane after bin `bin` on axis, then those
 * right of it, and returns where the right ones start.  A ref's side is unpredictable deep in
 * the tree, so the bulk runs without a branch on it (Edelkamp & Weiss, "BlockQuicksort:
 * Avoiding Branch Mispredictions in Quicksort", ESA 2016): a block at each end records the
 * offsets of its misplaced refs, and as many pairs as both blocks have are swapped.  The last
 * fewer than 2 PARTITION_BLOCK refs are partitioned as Hoare did, with a branch. */
#define PARTITION_BLOCK 32

static uint32_t partition_refs(struct prim_ref *refs, uint32_t begin, uint32_t end,
                               const struct bin_map *m, int axis, int bin)
{
    uint8_t off_l[PARTITION_BLOCK]; /* right-bound refs in refs[lo, lo + BLOCK) */
    uint8_t off_r[PARTITION_BLOCK]; /* left-bound refs in refs[hi - BLOCK, hi), from hi down */
    uint32_t n_l = 0;
    uint32_t n_r = 0;
    uint32_t next_l = 0;
    uint32_t next_r = 0;
    uint32_t lo = begin; /* refs[begin, lo) are left, refs[hi, end) right */
    uint32_t hi = end;
    while (hi - lo >= 2 * PARTITION_BLOCK) {
        if (n_l == 0) {
            next_l = 0;
            for (uint32_t k = 0; k < PARTITION_BLOCK; k++) {
                off_l[n_l] = (uint8_t)k;
                n_l += ref_goes_right(&refs[lo + k], m, axis, bin);
            }
        }
        if (n_r == 0) {
            next_r = 0;
            for (uint32_t k = 0; k < PARTITION_BLOCK; k++) {
                off_r[n_r] = (uint8_t)k;
                n_r += 1 - ref_goes_right(&refs[hi - 1 - k], m, axis, bin);
            }
        }
        uint32_t n_swap = n_l < n_r ? n_l : n_r;
        for (uint32_t k = 0; k < n_swap; k++)
            ref_swap(&refs[lo + off_l[next_l + k]], &refs[hi - 1 - off_r[next_r + k]]);
        n_l -= n_swap;
        n_r -= n_swap;
        next_l += n_swap;
        next_r += n_swap;
        if (n_l == 0)
            lo += PARTITION_BLOCK;
        if (n_r == 0)
            hi -= PARTITION_BLOCK;
    }
    /* a block with refs still misplaced was not passed: [lo, hi) holds it */
    while (lo < hi) {
        if (!ref_goes_right(&refs[lo], m, axis, bin))
            lo++;
        else
            ref_swap(&refs[lo], &refs[--hi]);
    }
    return lo;
}

/* Bounds of the centres of refs[begin, end). */
static void centre_bounds_of(const struct prim_ref *refs, uint32_t begin, uint32_t end,
                             struct box *out)
{
    v4f c_lo = v4_load(empty_box.min);
    v4f c_hi = v4_load(empty_box.max);
    for (uint32_t k = begin; k < end; k++) {
        v4f c = 0.5f * (ref_lo(&refs[k]) + ref_hi(&refs[k]));
        c_lo = v4_min(c, c_lo);
        c_hi = v4_max(c, c_hi);
    }
    v4_store(out->min, c_lo);
    v4_store(out->max, c_hi);
}

/* Decides task's node: false when it is to be a leaf; otherwise partitions its refs and fills
 * the children's ranges and bounds (child[i]: begin, end, cap, bounds, centre_bounds). */
static bool split_task(const struct build_ctx *ctx, const struct build_task *task, int n_threads,
                       struct build_task child[2])
{
    struct prim_ref *refs = ctx->refs;
    uint32_t begin = task->begin;
    uint32_t end = task->end;
    uint32_t n = end - begin;
    if (n <= BVH_UNBINNED_LEAF_TRIS || task->depth >= BVH_MAX_DEPTH)
        return false;
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
            return false;
        uint32_t mid = begin + n / 2;
        range_bounds(refs, begin, mid, &child[0].bounds, &child[0].centre_bounds);
        range_bounds(refs, mid, end, &child[1].bounds, &child[1].centre_bounds);
        place_children(refs, task, mid, mid, end, child);
        return true;
    }
    /* a spatial split, where the object split's children overlap */
    struct split spatial = {-1, 0, INFINITY};
    struct spatial_bins sbins;
    struct slab_grid grid;
    if (ctx->spatial && n >= BVH_SPATIAL_MIN_REFS) {
        struct box side[2] = {empty_box, empty_box};
        for (int k = 0; k < BVH_N_BINS; k++)
            box_union(&side[k <= best.bin ? 0 : 1], &bins.box[best.axis][k]);
        box_clip(&side[0], &side[1]);
        float overlap = box_is_empty(&side[0]) ? 0.0f : box_half_area(&side[0]);
        if (overlap > ctx->min_overlap &&
            overlap > BVH_SPATIAL_MIN_NODE_OVERLAP * box_half_area(&task->bounds)) {
            slab_grid_init(&grid, &task->bounds);
            if (n_threads > 1 && n >= BVH_PARALLEL_BIN_MIN) {
                spatial_bins_fill_parallel(&sbins, ctx, begin, end, &grid, n_threads);
            } else {
                spatial_bins_clear(&sbins);
                spatial_bins_fill(&sbins, ctx, begin, end, &grid);
            }
            spatial = spatial_best_split(&sbins, &grid);
        }
    }
    /* C_split < C_leaf, both multiplied by A so that a zero-area box (a point) needs no division:
     * C_trav A + C_isect (A_L N_L + A_R N_R) < C_isect N A */
    float area = box_half_area(&task->bounds);
    float sah_sum = spatial.sah_sum < best.sah_sum ? spatial.sah_sum : best.sah_sum;
    float split_cost = BVH_COST_TRAVERSAL * area + BVH_COST_INTERSECT * sah_sum;
    float leaf_cost = BVH_COST_INTERSECT * (float)n * area;
    if (split_cost >= leaf_cost && n <= BVH_MAX_LEAF_TRIS)
        return false;
    if (spatial.sah_sum < best.sah_sum &&
        spatial_partition(ctx, task, &sbins, &grid, spatial, child))
        return true;
    /* The object split: left takes the centres in bins 0..best.bin.  A side's box is the union
     * of its bins' boxes (the same refs, so the same bits); its centres' bounds come from one
     * pass over its refs after the partition. */
    const struct bin_map m = bin_map_of(&task->centre_bounds);
    uint32_t i = partition_refs(refs, begin, end, &m, best.axis, best.bin);
    struct box child_bounds[2] = {empty_box, empty_box};
    for (int k = 0; k < BVH_N_BINS; k++)
        box_union(&child_bounds[k <= best.bin ? 0 : 1], &bins.box[best.axis][k]);
    struct box child_centres[2];
    centre_bounds_of(refs, begin, i, &child_centres[0]);
    centre_bounds_of(refs, i, end, &child_centres[1]);
    assert(i > begin && i < end); /* bins_best_split only offers planes with both sides used */
    for (int side = 0; side < 2; side++) {
        child[side].bounds = child_bounds[side];
        child[side].centre_bounds = child_centres[side];
    }
    place_children(refs, task, i, i, end, child);
    return true;
}

static void node_set_box(struct bvh_node *node, const struct box *b)
{
    memcpy(node->min, b->min, sizeof node->min);
    memcpy(node->max, b->max, sizeof node->max);
}

/* Fills task's node: a leaf, or an interior node whose child pair is allocated at *next (which
 * grows by 2) and returned in child[0] (left) and child[1] (right).  Returns whether it split. */
static bool build_node(const struct build_ctx *ctx, const struct build_task *task, int n_threads,
                       uint32_t *next, struct build_task child[2])
{
    struct bvh_node *node = &ctx->nodes[task->node_idx];
    node_set_box(node, &task->bounds);
    if (!split_task(ctx, task, n_threads, child)) {
        node->left_first = task->begin;
        node->n_tris = task->end - task->begin;
        return false;
    }
    uint32_t left_idx = *next;
    *next += 2;
    node->left_first = left_idx;
    node->n_tris = 0;
    for (int side = 0; side < 2; side++) {
        child[side].node_idx = left_idx + (uint32_t)side;
        child[side].depth = task->depth + 1;
        child[side].node_base = 0;
    }
    return true;
}

/* Builds the subtree of root depth first from an explicit stack, allocating child pairs from
 * root.node_base on.  Returns the deepest depth reached; *n_next is one past the last node
 * used.  Started at the root with node_base 2, this numbers nodes in the canonical order. */
static uint32_t build_subtree(const struct build_ctx *ctx, struct build_task root, uint32_t *n_next)
{
    struct build_task stack[BVH_MAX_DEPTH + 2]; /* one pending right child per level + current */
    int n_stack = 0;
    uint32_t max_depth = 0;
    uint32_t next = root.node_base;
    stack[n_stack++] = root;
    while (n_stack > 0) {
        struct build_task task = stack[--n_stack];
        if (task.depth > max_depth)
            max_depth = task.depth;
        struct build_task child[2];
        if (!build_node(ctx, &task, 1, &next, child))
            continue;
        assert(n_stack + 2 <= (int)(sizeof stack / sizeof stack[0]));
        stack[n_stack++] = child[1];
        stack[n_stack++] = child[0]; /* the left subtree first */
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
void *bvh_alloc_aligned(size_t n, size_t size)
{
    if (size != 0 && n > (SIZE_MAX - 64) / size)
        return NULL;
    size_t bytes = (n * size + 63) / 64 * 64;
    return aligned_alloc(64, bytes == 0 ? 64 : bytes);
}

/* malloc of n elements of size bytes, NULL on overflow. */
void *bvh_alloc_array(size_t n, size_t size)
{
    if (size != 0 && n > SIZE_MAX / size)
        return NULL;
    return malloc(n * size == 0 ? 1 : n * size);
}

/* Builds the binary tree over ctx->refs[0, n) (with room for cap refs) into a fresh exact-size
 * node array (*out_nodes, *out_n_nodes).  Returns the maximum depth, or UINT32_MAX when out of
 * memory. */
/* One task of a wave of top nodes (build_tree): split on its share of the threads. */
struct wave_job {
    const struct build_ctx *ctx;
    struct build_task task;
    int n_threads;
    uint32_t next;             /* the child pair's node index, if it splits */
    bool split;
    struct build_task child[2];
};

static void *wave_job_run(void *arg)
{
    struct wave_job *job = arg;
    job->split = build_node(job->ctx, &job->task, job->n_threads, &job->next, job->child);
    return NULL;
}

static uint32_t build_tree(struct build_ctx *ctx, uint32_t n, uint32_t cap,
                           const struct box *root_bounds, const struct box *root_centres,
                           struct bvh_node **out_nodes, uint32_t *out_n_nodes)
{
    struct bvh_node *work = bvh_alloc_aligned(2 * (size_t)cap, sizeof *work);
    struct build_task *pending = NULL;
    if (!work)
        return UINT32_MAX;
    ctx->nodes = work;
    work[1] = (struct bvh_node){{0}, 0, {0}, 0};
    struct build_task root = {0, 0, n, cap, 0, 2, *root_bounds, *root_centres};
    uint32_t max_depth = 0;
    uint32_t n_used = 0;
    bool renumbered = false;
    if (ctx->n_threads <= 1 || n < BVH_PARALLEL_MIN_TRIS) {
        max_depth = build_subtree(ctx, root, &n_used);
    } else {
        /* top nodes, largest first, until every thread has BVH_SUBTREES_PER_THREAD subtrees */
        uint32_t target = (uint32_t)ctx->n_threads * BVH_SUBTREES_PER_THREAD;
        uint32_t max_pending = 2 * target + 2;
        pending = malloc(max_pending * sizeof *pending);
        if (!pending) {
            free(work);
            return UINT32_MAX;
        }
        uint32_t n_pending = 0;
        pending[n_pending++] = root;
        uint32_t next = 2;
        while (n_pending < target) {
            /* a wave: the largest pending tasks of at least BVH_WAVE_MIN_REFS refs, at most
             * one per thread and no more than the subtrees still wanted, split side by side,
             * the threads shared among them (the root alone has them all) */
            qsort(pending, n_pending, sizeof *pending, compare_task_size);
            uint32_t k = 0;
            while (k < n_pending && k < (uint32_t)ctx->n_threads && k < target - n_pending &&
                   pending[k].end - pending[k].begin >= BVH_WAVE_MIN_REFS)
                k++;
            if (k == 0)
                break; /* the rest is small: leave it to the subtree threads */
            struct wave_job jobs[BVH_MAX_THREADS];
            for (uint32_t j = 0; j < k; j++) {
                jobs[j].ctx = ctx;
                jobs[j].task = pending[j];
                jobs[j].n_threads = ctx->n_threads / (int)k + ((int)j < ctx->n_threads % (int)k);
                jobs[j].next = next + 2 * j; /* a pair each; a task that ends as a leaf leaves
                                              * a hole, covered by its refs' unused reserve */
                if (pending[j].depth > max_depth)
                    max_depth = pending[j].depth;
            }
            next += 2 * k;
            bvh_run_jobs((int)k, wave_job_run, jobs, sizeof jobs[0]);
            uint32_t n_rest = n_pending - k;
            memmove(pending, pending + k, n_rest * sizeof *pending);
            n_pending = n_rest;
            for (uint32_t j = 0; j < k; j++) {
                if (!jobs[j].split)
                    continue;
                pending[n_pending++] = jobs[j].child[0];
                pending[n_pending++] = jobs[j].child[1];
            }
        }
        /* a subtree of at most m refs (cap - begin) has at most 2 (m - 1) nodes below its root */
        qsort(pending, n_pending, sizeof *pending, compare_task_size);
        for (uint32_t i = 0; i < n_pending; i++) {
            pending[i].node_base = next;
            next += 2 * (pending[i].cap - pending[i].begin - 1);
        }
        assert(next <= 2 * cap);
        struct subtree_pool pool = {ctx, pending, n_pending, 0, max_depth};
        struct subtree_pool *handles[BVH_MAX_THREADS];
        for (int i = 0; i < ctx->n_threads; i++)
            handles[i] = &pool;
        bvh_run_jobs(ctx->n_threads, subtree_worker, handles, sizeof handles[0]);
        max_depth = atomic_load(&pool.max_depth);
        free(pending);
        n_used = count_nodes(work);
        renumbered = true;
    }
    struct bvh_node *nodes = bvh_alloc_aligned(n_used, sizeof *nodes);
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

void bvh_load_tri(struct bvh_tri *tri, const vec3 *positions, const uint32_t *indices,
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
        bvh_load_tri(&tri, job->positions, job->indices, i);
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

/* The build sees only boxes (of the stored, possibly collapsed, vertices): the refs of all
 * n_tris triangles, in parallel slices for large meshes, and the bounds of their boxes and of
 * their centres. */
static void make_refs(struct prim_ref *refs, const vec3 *positions, const uint32_t *indices,
                      uint32_t n_tris, int n_threads, struct box *bounds, struct box *centres)
{
    int n_jobs = n_tris >= BVH_PARALLEL_MIN_TRIS ? n_threads : 1;
    struct ref_job jobs[BVH_MAX_THREADS];
    for (int i = 0; i < n_jobs; i++)
        jobs[i] = (struct ref_job){refs,
                                   positions,
                                   indices,
                                   slice_begin(0, n_tris, i, n_jobs),
                                   slice_begin(0, n_tris, i + 1, n_jobs),
                                   empty_box,
                                   empty_box};
    bvh_run_jobs(n_jobs, ref_job_run, jobs, sizeof jobs[0]);
    *bounds = empty_box;
    *centres = empty_box;
    for (int i = 0; i < n_jobs; i++) {
        box_grow(bounds, jobs[i].bounds.min, jobs[i].bounds.max);
        box_grow(centres, jobs[i].centres.min, jobs[i].centres.max);
    }
}

/* The leaves' ranges of refs have gaps (the spare slots of spatial splits): the refs are copied
 * into one sequence in depth-first leaf order, each leaf pointing at its new range (for a
 * binned build this changes nothing).  prim_idx and degenerate get n_refs entries. */
static void compact_leaves(struct bvh_node *nodes, const struct prim_ref *refs, uint32_t *prim_idx,
                           uint8_t *degenerate)
{
    uint32_t stack[BVH_MAX_DEPTH + 2];
    int n_stack = 0;
    uint32_t k = 0;
    stack[n_stack++] = 0;
    while (n_stack > 0) {
        struct bvh_node *node = &nodes[stack[--n_stack]];
        if (node->n_tris == 0) {
            stack[n_stack++] = node->left_first + 1;
            stack[n_stack++] = node->left_first;
            continue;
        }
        for (uint32_t j = 0; j < node->n_tris; j++) {
            prim_idx[k + j] = refs[node->left_first + j].prim_idx;
            degenerate[k + j] = (uint8_t)refs[node->left_first + j].is_degenerate;
        }
        node->left_first = k;
        k += node->n_tris;
    }
}

static double now_ms(void)
{
    struct timespec ts;
    timespec_get(&ts, TIME_UTC);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static void compute_stats(struct bvh *bvh);

struct bvh *bvh_build(const vec3 *positions, const uint32_t *indices, uint32_t n_tris,
                      int n_threads)
{
    struct bvh_build_options opt = {n_threads, BVH_LAYOUT_WIDE, BVH_QUALITY_DEFAULT};
    return bvh_build_with(positions, indices, n_tris, &opt);
}

struct bvh *bvh_build_with(const vec3 *positions, const uint32_t *indices, uint32_t n_tris,
                           const struct bvh_build_options *opt)
{
    double t_start_ms = now_ms();
    struct bvh_build_options o = opt ? *opt
                                     : (struct bvh_build_options){1, BVH_LAYOUT_WIDE,
                                                                  BVH_QUALITY_DEFAULT};
    unsigned layouts = o.layouts ? o.layouts : BVH_LAYOUT_WIDE;
    if (n_tris >= BVH_WIDE_MAX_TRIS)
        layouts = BVH_LAYOUT_BINARY;
    int n_threads = o.n_threads < 1                 ? 1
                    : o.n_threads > BVH_MAX_THREADS ? BVH_MAX_THREADS
                                                    : o.n_threads;
    bool spatial = o.quality != BVH_QUALITY_BINNED;
    struct build_ctx ctx = {NULL, NULL, n_threads, spatial, 0.0f, positions, indices};
    uint8_t *degenerate = NULL; /* per binary triangle position, for the conversion */
    struct bvh *bvh = calloc(1, sizeof *bvh);
    if (!bvh)
        goto fail;
    bvh->n_tris = n_tris;
    bvh->stats.n_threads = n_threads;
    if (n_tris > 0) {
        /* room for the copies of spatial splits: 2 cap nodes (2 cap - 1 and the unused
         * nodes[1]) must fit in uint32_t */
        uint64_t cap = n_tris + (spatial ? (uint64_t)((double)n_tris * BVH_SPLIT_BUDGET) : 0);
        if ((layouts & BVH_LAYOUT_WIDE) && cap >= BVH_WIDE_MAX_TRIS) /* copies count there */
            cap = BVH_WIDE_MAX_TRIS - 1 > n_tris ? BVH_WIDE_MAX_TRIS - 1 : n_tris;
        if (cap > UINT32_MAX / 2)
            goto fail;
        ctx.refs = bvh_alloc_aligned(cap, sizeof *ctx.refs);
        if (!ctx.refs)
            goto fail;
        struct box bounds;
        struct box centres;
        make_refs(ctx.refs, positions, indices, n_tris, n_threads, &bounds, &centres);
        ctx.min_overlap = BVH_SPLIT_ALPHA * box_half_area(&bounds);
        uint32_t depth = build_tree(&ctx, n_tris, (uint32_t)cap, &bounds, &centres, &bvh->nodes,
                                    &bvh->n_nodes);
        if (depth == UINT32_MAX)
            goto fail;
        bvh->stats.max_depth = depth;
        /* the refs are in BVH order now; keep what the conversion needs of them */
        uint32_t n_refs = 0;
        for (uint32_t i = 0; i < bvh->n_nodes; i++)
            n_refs += i == 1 ? 0 : bvh->nodes[i].n_tris;
        bvh->n_refs = n_refs;
        bvh->prim_idx = bvh_alloc_array(n_refs, sizeof *bvh->prim_idx);
        degenerate = bvh_alloc_array(n_refs, sizeof *degenerate);
        if (!bvh->prim_idx || !degenerate)
            goto fail;
        compact_leaves(bvh->nodes, ctx.refs, bvh->prim_idx, degenerate);
        free(ctx.refs);
        ctx.refs = NULL;
        compute_stats(bvh); /* of the binary tree, before it may be dropped */
        if (layouts & BVH_LAYOUT_WIDE) {
            double t_convert_ms = now_ms();
            if (!bvh_wide_convert(bvh, positions, indices, degenerate,
                                  n_tris >= BVH_PARALLEL_MIN_TRIS ? n_threads : 1))
                goto fail;
            bvh->stats.convert_ms = now_ms() - t_convert_ms;
        }
        free(degenerate);
        degenerate = NULL;
        if (layouts & BVH_LAYOUT_BINARY) {
            bvh->tris = bvh_alloc_array(bvh->n_refs, sizeof *bvh->tris);
            if (!bvh->tris)
                goto fail;
            for (uint32_t i = 0; i < bvh->n_refs; i++)
                bvh_load_tri(&bvh->tris[i], positions, indices, bvh->prim_idx[i]);
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
                                        (size_t)bvh->n_refs *
                                            (sizeof(struct bvh_tri) + sizeof(uint32_t))
                                  : 0;
    bvh->stats.bytes = bvh->stats.binary_bytes + bvh->stats.wide_bytes; /* by bvh_wide_convert */
    bvh->stats.build_ms = now_ms() - t_start_ms;
    return bvh;
fail:
    free(ctx.refs);
    free(degenerate);
    bvh_free(bvh);
    return NULL;
}

unsigned bvh_layouts(const struct bvh *bvh) { return bvh->layouts; }

/* ---- Reference traversal ----------------------------------------------------------------------
 * Closest hit: iterative, depth first, nearer child first.  At an interior node both children's
 * boxes are tested against [t_min, t_hit] (t_hit = the closest hit so far, initially t_max); if
 * both are hit the farther one is pushed with its entry distance and the nearer one visited.
 * A popped node whose entry distance now lies beyond t_hit is skipped.  No allocation.
 * The result is bit for bit that of bvh_intersect_brute (same t, u, v, prim_idx; among exactly
 * equal t either triangle), with one exception: where several triangles are hit within a few
 * ulps of each other (a ray through a shared vertex or edge), the box of the marginally nearer
 * one can start a few ulps beyond t_hit and be culled.  The reported hit is then one of those
 * triangles, at the same point to within rounding.  The wide traversal (bvh_wide.c) has the
 * same contract.
 * A ray starting on a surface (t_min = 0) reports that surface only when its origin lies
 * measurably in front of the plane (tri_hit decides the side exactly, in double where float
 * cannot); an origin on the plane within double rounding finds nothing there.  Spawned rays
 * start at offset_ray_origin (vec.h), which puts the origin on the correct side by the hit
 * point's error bound.  The renderer also names the triangle a ray leaves (`from`,
 * bvh_intersect_from), and every traversal skips it: for such a ray it cannot be a hit, and it
 * is the one triangle whose test float leaves to double (t ~ 0).
 * The per-ray constants (struct ray_pre) and the conservative slab test box_hit, which the wide
 * layout uses too, are in bvh_internal.h. */

/* All of a ray's constants: the slab test's and Woop's. */
static void ray_setup(const struct ray *ray, struct ray_pre *rp)
{
    ray_setup_box(ray, rp);
    ray_setup_woop(rp);
}

static bool tri_hit(const struct bvh_tri *tri, const struct ray_pre *rp, float t_min, float t_max,
                    float *t_out, float *u_out, float *v_out);

/* The closest-hit loops' interior step: node's two children tested against [t_min, t_max]; where
 * both are hit the nearer becomes *node_idx and the farther is pushed with its entry distance,
 * where one is, it becomes *node_idx.  False where neither is (the caller pops). */
static inline bool descend(const struct bvh_node *nodes, const struct bvh_node *node,
                           const struct ray_pre *rp, float t_min, float t_max, uint32_t *node_idx,
                           struct stack_entry *stack, uint32_t *n_stack)
{
    uint32_t near_idx = node->left_first;
    uint32_t far_idx = near_idx + 1;
    float t_near;
    float t_far;
    bool hit_near = box_hit(&nodes[near_idx], rp, t_min, t_max, &t_near);
    bool hit_far = box_hit(&nodes[far_idx], rp, t_min, t_max, &t_far);
    if (hit_near && hit_far) {
        if (t_far < t_near) {
            uint32_t tmp_idx = near_idx;
            near_idx = far_idx;
            far_idx = tmp_idx;
            t_far = t_near;
        }
        assert(*n_stack < BVH_MAX_DEPTH);
        stack[(*n_stack)++] = (struct stack_entry){far_idx, t_far};
        *node_idx = near_idx;
        return true;
    }
    *node_idx = hit_near ? near_idx : far_idx;
    return hit_near || hit_far;
}

/* Pops the next pending node that still starts before t_max (the closest hit so far) into
 * *node_idx; false where none is left. */
static inline bool pop_before(const struct stack_entry *stack, uint32_t *n_stack, float t_max,
                              uint32_t *node_idx)
{
    do {
        if (*n_stack == 0)
            return false;
        (*n_stack)--;
    } while (stack[*n_stack].t_entry > t_max);
    *node_idx = stack[*n_stack].node_idx;
    return true;
}

static bool binary_intersect(const struct bvh *bvh, const struct ray *ray, uint32_t from,
                             struct bvh_hit *hit)
{
    if (bvh->n_nodes == 0 || !ray_is_valid(ray))
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
                if (bvh->prim_idx[i] != from &&
                    tri_hit(&bvh->tris[i], &rp, t_min, t_hit, &t, &u, &v)) {
                    t_hit = t;
                    u_hit = u;
                    v_hit = v;
                    tri_idx = i;
                }
            }
        } else if (descend(nodes, node, &rp, t_min, t_hit, &node_idx, stack, &n_stack)) {
            continue;
        }
        if (!pop_before(stack, &n_stack, t_hit, &node_idx))
            break;
    }
    if (tri_idx == UINT32_MAX)
        return false;
    *hit = (struct bvh_hit){t_hit, u_hit, v_hit, bvh->prim_idx[tri_idx]};
    return true;
}

/* Any hit: the same boxes against the fixed [t_min, t_max], children in stored order, and the
 * first triangle hit ends the search.  It reports a hit exactly when binary_intersect does. */
static bool binary_occluded(const struct bvh *bvh, const struct ray *ray, uint32_t from)
{
    if (bvh->n_nodes == 0 || !ray_is_valid(ray))
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
                if (bvh->prim_idx[i] != from &&
                    tri_hit(&bvh->tris[i], &rp, t_min, t_max, &t, &u, &v))
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

/* The public entry points: the wide layout when the BVH carries it (bvh_wide.c), else the
 * binary reference. */
bool bvh_intersect_from(const struct bvh *bvh, const struct ray *ray, uint32_t from,
                        struct bvh_hit *hit)
{
    if (bvh->layouts & BVH_LAYOUT_WIDE)
        return bvh_wide_intersect(bvh, ray, from, hit);
    return binary_intersect(bvh, ray, from, hit);
}

bool bvh_occluded_from(const struct bvh *bvh, const struct ray *ray, uint32_t from)
{
    if (bvh->layouts & BVH_LAYOUT_WIDE)
        return bvh_wide_occluded(bvh, ray, from);
    return binary_occluded(bvh, ray, from);
}

void bvh_intersect_stream(const struct bvh *bvh, const struct ray *rays, const uint32_t *from,
                          size_t n, struct bvh_hit *out, bool *is_hit)
{
    if (bvh->layouts & BVH_LAYOUT_WIDE) {
        bvh_wide_intersect_stream(bvh, rays, from, n, out, is_hit);
        return;
    }
    for (size_t i = 0; i < n; i++)
        is_hit[i] = binary_intersect(bvh, &rays[i], from ? from[i] : BVH_NO_PRIM, &out[i]);
}

void bvh_occluded_stream(const struct bvh *bvh, const struct ray *rays, const uint32_t *from,
                         size_t n, bool *occluded)
{
    if (bvh->layouts & BVH_LAYOUT_WIDE) {
        bvh_wide_occluded_stream(bvh, rays, from, n, occluded);
        return;
    }
    for (size_t i = 0; i < n; i++)
        occluded[i] = binary_occluded(bvh, &rays[i], from ? from[i] : BVH_NO_PRIM);
}

bool bvh_intersect(const struct bvh *bvh, const struct ray *ray, struct bvh_hit *hit)
{
    return bvh_intersect_from(bvh, ray, BVH_NO_PRIM, hit);
}

bool bvh_occluded(const struct bvh *bvh, const struct ray *ray)
{
    return bvh_occluded_from(bvh, ray, BVH_NO_PRIM);
}

bool bvh_intersect_layout(const struct bvh *bvh, enum bvh_layout layout, const struct ray *ray,
                          struct bvh_hit *hit)
{
    assert(bvh->n_tris == 0 || (bvh->layouts & (unsigned)layout));
    return layout == BVH_LAYOUT_WIDE ? bvh_wide_intersect(bvh, ray, BVH_NO_PRIM, hit)
                                     : binary_intersect(bvh, ray, BVH_NO_PRIM, hit);
}

bool bvh_occluded_layout(const struct bvh *bvh, enum bvh_layout layout, const struct ray *ray)
{
    assert(bvh->n_tris == 0 || (bvh->layouts & (unsigned)layout));
    return layout == BVH_LAYOUT_WIDE ? bvh_wide_occluded(bvh, ray, BVH_NO_PRIM)
                                     : binary_occluded(bvh, ray, BVH_NO_PRIM);
}

/* ---- Watertight ray-triangle test: Woop, Benthin, Wald 2013 -----------------------------------
 * Translate the vertices to the ray origin, shear so the ray runs along +z from the origin, and
 * the question becomes 2D: does (0, 0) lie inside the projected triangle A, B, C?  The scaled
 * barycentric coordinates are the 2D edge functions
 *   U = Cx By - Cy Bx   (weight of A = p0),  V = Ax Cy - Ay Cx  (p1),  W = Bx Ay - By Ax  (p2)
 * Two triangles sharing an edge evaluate that edge's function on the same sheared endpoints with
 * the operands swapped, and fl(a b - c d) = -fl(c d - a b), so no ray can slip between them
 * (watertight along edges and at vertices).  This needs the products not to be contracted into
 * FMAs (see the pragma in bvh_internal.h).  Where a float edge function is exactly 0 the
 * sign is unreliable and all three are recomputed in double (the paper's double-precision
 * fallback; the products of floats are exact in double).  Both signs are accepted (no culling).
 *   det = U + V + W,  T = U Az + V Bz + W Cz,  t = T / det,  u = V / det,  v = W / det
 * det == 0 (ray parallel to, or in, the plane) is a miss.
 *
 * Which side of the origin: T and det carry rounding errors bounded by delta_T and delta_det
 * (PBRT 4e, ch. 6, "Avoiding Intersections Behind Ray Origins", derived again in
 * docs/theory.md, "Self-intersection").  When |T| > delta_T and |det| > delta_det the signs are
 * exact and so is the sign of t: the hit is certainly in front of the origin or certainly
 * behind it.  Otherwise (the origin within rounding of the plane, a grazing ray, or a float
 * that overflowed or underflowed) the float test cannot say, and PBRT's rule of rejecting
 * such hits would throw true hits away (a ray leaving a floor near a concave edge meets the
 * wall at t ~ 1e-5 < delta_t).  Instead the same computation is done again in double,
 * bvh_tri_hit_double, from the stored vertices, whose own bounds are about 2^29 times
 * smaller; the float inside/outside decision is kept, so watertightness is unchanged.  Only
 * hits at t ~ 0, grazing hits and extreme coordinates take that path.  The same test is written
 * a second time, on eight lanes, as woop8 in bvh_wide.c: the same operations in the same order,
 * so its t, u, v and its undecided lanes are the same bits, and those lanes go to the same
 * bvh_tri_hit_double.  This scalar form is the reference the SIMD one is tested against (every
 * traversal against bvh_intersect_brute, which uses tri_hit). */
static inline float max_abs3(float a, float b, float c)
{
    float m = fabsf(a) > fabsf(b) ? fabsf(a) : fabsf(b);
    return fabsf(c) > m ? fabsf(c) : m;
}

static inline double max_abs3_d(double a, double b, double c)
{
    return fmax(fabs(a), fmax(fabs(b), fabs(c)));
}

/* gamma(n) of double precision, n u / (1 - n u) with u = 2^-53 (PBRT 4e, ch. 6, "Managing
 * Rounding Error"). */
static inline double gamma_double(int n)
{
    const double u = 0x1p-53;
    return ((double)n * u) / (1.0 - (double)n * u);
}

/* The double-precision fallback for one triangle's sheared 2D vertices (woop8 uses it too). */
void bvh_edge_functions_double(float Ax, float Ay, float Bx, float By, float Cx, float Cy, float *U,
                               float *V, float *W)
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

/* Woop's test redone in double for a (ray, triangle) pair whose float result could not decide
 * the side of the origin (tri_hit, woop8).  Every float input (vertex, origin, direction) is
 * exact in double; the shear constants, translation, shear, edge functions, T and det are
 * recomputed, with the same error bounds in units of u = 2^-53.  For float inputs no double
 * operation here overflows or underflows (products of at most four floats stay within 2^+-600),
 * so the bounds need no absolute term.  A hit needs t certainly > 0 and t_min < t < t_max, the
 * latter tested on the float t returned (the double one rounded).  When even double cannot
 * decide (the origin within about 2^-50 of the plane, relative to the triangle's extent from
 * it), the hit is rejected: the origin lies on the plane, and t_min is exclusive. */
bool bvh_tri_hit_double(const struct bvh_tri *tri, const struct ray_pre *rp, const float edge[3],
                        float t_min, float t_max, float *t_out, float *u_out, float *v_out)
{
    const int kx = rp->kx;
    const int ky = rp->ky;
    const int kz = rp->kz;
    const double o[3] = {rp->o[0], rp->o[1], rp->o[2]};
    /* First the side alone, from the plane, n = (p1 - p0) x (p2 - p0) in double: t has the sign
     * of n . (p0 - o) / n . d.  With n's components off by gamma(2) of the sums of their terms'
     * magnitudes (n_abs) and p0 - o by gamma(1), both dot products are within gamma(6) n_abs .
     * |.| of exact.  A hit certainly behind the origin (a spawned ray's own triangle, most of
     * this function's calls) needs nothing more. */
    double e1[3], e2[3], po[3];
    for (int a = 0; a < 3; a++) {
        e1[a] = (double)tri->p1[a] - tri->p0[a];
        e2[a] = (double)tri->p2[a] - tri->p0[a];
        po[a] = (double)tri->p0[a] - o[a];
    }
    double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                   e1[0] * e2[1] - e1[1] * e2[0]};
    double n_abs[3] = {fabs(e1[1] * e2[2]) + fabs(e1[2] * e2[1]),
                       fabs(e1[2] * e2[0]) + fabs(e1[0] * e2[2]),
                       fabs(e1[0] * e2[1]) + fabs(e1[1] * e2[0])};
    double num = n[0] * po[0] + n[1] * po[1] + n[2] * po[2];
    double den = n[0] * rp->d[0] + n[1] * rp->d[1] + n[2] * rp->d[2];
    double num_err = gamma_double(6) *
                     (n_abs[0] * fabs(po[0]) + n_abs[1] * fabs(po[1]) + n_abs[2] * fabs(po[2]));
    double den_err = gamma_double(6) * (n_abs[0] * fabs(rp->d[0]) + n_abs[1] * fabs(rp->d[1]) +
                                        n_abs[2] * fabs(rp->d[2]));
    bool plane_sure = fabs(num) > num_err && fabs(den) > den_err;
    if (plane_sure && (num > 0.0) != (den > 0.0))
        return false;
    /* the shear of the ray itself, in double: the float constants turn its direction by up to
     * 2^-24, which decides the side of a ray that grazes the plane at a smaller angle (within
     * the bounds below: they cover one rounding of sx, sy and sz) */
    const double sx = (double)rp->d[kx] / (double)rp->d[kz];
    const double sy = (double)rp->d[ky] / (double)rp->d[kz];
    const double sz = 1.0 / (double)rp->d[kz];
    double a_x = (double)tri->p0[kx] - o[kx];
    double a_y = (double)tri->p0[ky] - o[ky];
    double a_z = (double)tri->p0[kz] - o[kz];
    double b_x = (double)tri->p1[kx] - o[kx];
    double b_y = (double)tri->p1[ky] - o[ky];
    double b_z = (double)tri->p1[kz] - o[kz];
    double c_x = (double)tri->p2[kx] - o[kx];
    double c_y = (double)tri->p2[ky] - o[ky];
    double c_z = (double)tri->p2[kz] - o[kz];
    double Ax = a_x - sx * a_z;
    double Ay = a_y - sy * a_z;
    double Bx = b_x - sx * b_z;
    double By = b_y - sy * b_z;
    double Cx = c_x - sx * c_z;
    double Cy = c_y - sy * c_z;
    double U = Cx * By - Cy * Bx;
    double V = Ax * Cy - Ay * Cx;
    double W = Bx * Ay - By * Ax;
    /* inside: the float signs, as every float test decides them (watertight); an edge function
     * that is 0 in float (a product underflowed, or the ray meets the edge) takes its sign from
     * double, so a triangle far below float resolution is not hit through its zeros */
    double s_U = edge[0] != 0.0f ? (double)edge[0] : U;
    double s_V = edge[1] != 0.0f ? (double)edge[1] : V;
    double s_W = edge[2] != 0.0f ? (double)edge[2] : W;
    if ((s_U < 0.0 || s_V < 0.0 || s_W < 0.0) && (s_U > 0.0 || s_V > 0.0 || s_W > 0.0))
        return false;
    double det = U + V + W;
    double Az = sz * a_z;
    double Bz = sz * b_z;
    double Cz = sz * c_z;
    double T = U * Az + V * Bz + W * Cz;
    /* the bounds of tri_hit, in double */
    double max_xt = max_abs3_d(Ax, Bx, Cx);
    double max_yt = max_abs3_d(Ay, By, Cy);
    double max_zu = max_abs3_d(a_z, b_z, c_z);
    double max_zt = max_abs3_d(Az, Bz, Cz);
    double max_e = max_abs3_d(U, V, W);
    double delta_x = gamma_double(5) * (max_xt + 2.0 * max_zu);
    double delta_y = gamma_double(5) * (max_yt + 2.0 * max_zu);
    double delta_z = gamma_double(4) * max_zt;
    double delta_e = 2.0 * (gamma_double(3) * max_xt * max_yt + delta_y * max_xt +
                            delta_x * max_yt + delta_x * delta_y);
    double delta_T = 3.0 * (gamma_double(4) * max_e * max_zt + delta_z * max_e + delta_e * max_zt +
                            delta_z * delta_e);
    double delta_det = 3.0 * (gamma_double(3) * max_e + delta_e);
    if (!(fabs(det) > delta_det))
        return false; /* undecided even in double: the ray lies in the plane */
    double t = T / det;
    if (!(fabs(T) > delta_T)) {
        /* T's bound grows with the vertices' distance from the origin (a floor of 1e15 seen
         * from 1 unit above it); the plane's t, n . (p0 - o) / n . d, does not where n's terms
         * are few (an axis-aligned plane: one).  Used when its sign is certain and its relative
         * error bound at most 2^-30, else the origin counts as on the plane: no hit. */
        if (!(plane_sure && num_err / fabs(num) + den_err / fabs(den) <= 0x1p-30))
            return false;
        t = num / den;
    }
    if (!(t > 0.0))
        return false;
    /* t rounded to float (a positive t that underflows becomes the least positive float), then
     * tested against the interval as float tests it: the result depends on t_min and t_max only
     * through that test, so every traversal gets the same bits */
    float tf = (float)t > 0.0f ? (float)t : FLT_TRUE_MIN;
    if (!(tf > t_min && tf < t_max))
        return false;
    *t_out = tf;
    *u_out = (float)(V / det);
    *v_out = (float)(W / det);
    return true;
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
        bvh_edge_functions_double(Ax, Ay, Bx, By, Cx, Cy, &U, &V, &W);
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
    /* the rounding errors of T and det (docs/theory.md, "Self-intersection"): X, Y the sheared
     * extents, Zu the unscaled and Zs the scaled z extent, E the largest edge function;
     *   delta_x = gamma(5) (X + 2 Zu),  delta_y = gamma(5) (Y + 2 Zu),  delta_z = gamma(4) Zs
     *   delta_e = 2 (gamma(3) X Y + delta_y X + delta_x Y + delta_x delta_y)
     *   delta_T = 3 (gamma(4) E Zs + delta_z E + delta_e Zs + delta_z delta_e)
     *   delta_det = 3 (gamma(3) E + delta_e)
     * each one gamma above the derivation's, for the rounding of the bound itself; + FLT_MIN
     * covers the absolute error of a product that underflows (2^-150 at most). */
    float max_xt = max_abs3(Ax, Bx, Cx);
    float max_yt = max_abs3(Ay, By, Cy);
    float max_zu = max_abs3(a_z, b_z, c_z);
    float max_zt = max_abs3(Az, Bz, Cz);
    float max_e = max_abs3(U, V, W);
    float delta_x = mcpt_gamma(5) * (max_xt + 2.0f * max_zu) + FLT_MIN;
    float delta_y = mcpt_gamma(5) * (max_yt + 2.0f * max_zu) + FLT_MIN;
    float delta_z = mcpt_gamma(4) * max_zt + FLT_MIN;
    float delta_e = 2.0f * (mcpt_gamma(3) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt +
                            delta_x * delta_y) +
                    FLT_MIN;
    float delta_T = 3.0f * (mcpt_gamma(4) * max_e * max_zt + delta_z * max_e + delta_e * max_zt +
                            delta_z * delta_e) +
                    FLT_MIN;
    float delta_det = 3.0f * (mcpt_gamma(3) * max_e + delta_e);
    /* t's own precision: t = sum b_i z_i with b = (U, V, W) / det and sum b_i = 1, so
     *   |t - t*| |det| <= spread (3 delta_e + delta_det) + delta_z |det|
     *                  <= 2 spread delta_det + delta_z |det| = err_t     (delta_det >= 3 delta_e)
     * with spread the extent of Az, Bz, Cz.  A hit in front needs err_t <= 2^-10 |det| (|t| +
     * |o| |sz|): t known to 2^-10 of the larger of itself and the origin's magnitude, in units
     * of t (a bound, pessimistic: typically 2^-20 is met).  A triangle huge beside both (a floor
     * of size 1e7 seen from 1 away, whose float t is off by whole units) goes to double. */
    float z_lo = min_num(min_num(Az, Bz), Cz);
    float z_hi = max_num(max_num(Az, Bz), Cz);
    float err_t = 2.0f * (z_hi - z_lo) * delta_det + delta_z * fabsf(det);
    /* decided: T finite and both signs exact (a NaN or infinite bound leaves it undecided), and
     * behind the origin, or in front with a precise t */
    bool decided = fabsf(T) > delta_T && fabsf(T) <= FLT_MAX && fabsf(det) > delta_det &&
                   (!(t > 0.0f) || err_t <= 0x1p-10f * (fabsf(T) + fabsf(det) * rp->o_scale));
    if (!decided) {
        const float edge[3] = {U, V, W};
        return bvh_tri_hit_double(tri, rp, edge, t_min, t_max, t_out, u_out, v_out);
    }
    if (!(t > 0.0f && t > t_min && t < t_max)) /* written so that a NaN t is a miss */
        return false;
    *t_out = t;
    *u_out = V * inv_det;
    *v_out = W * inv_det;
    return true;
}

/* ---- Brute force: every triangle, the same test ----------------------------------------------
 * O(n) per ray, the baseline of the BVH-versus-naive table and the oracle of the tests.  It
 * tests the BVH-ordered triangles with the scalar tri_hit, so a triangle's t, u, v are
 * bit-identical to what the traversals compute for it; among exactly equal t the lowest BVH
 * position wins.  Without the binary layout it walks the wide leaves in their stored order
 * (bvh_wide_brute). */
void bvh_brute_step(const struct bvh_tri *tri, uint32_t prim, const struct ray_pre *rp, float t_min,
                    struct bvh_hit *best)
{
    float t;
    float u;
    float v;
    if (tri_hit(tri, rp, t_min, best->t, &t, &u, &v))
        *best = (struct bvh_hit){t, u, v, prim};
}

bool bvh_intersect_brute(const struct bvh *bvh, const struct ray *ray, struct bvh_hit *hit)
{
    return bvh_intersect_brute_from(bvh, ray, BVH_NO_PRIM, hit);
}

bool bvh_intersect_brute_from(const struct bvh *bvh, const struct ray *ray, uint32_t from,
                              struct bvh_hit *hit)
{
    if (!ray_is_valid(ray))
        return false;
    struct ray_pre rp;
    ray_setup(ray, &rp);
    struct bvh_hit best = {ray->t_max, 0.0f, 0.0f, UINT32_MAX};
    if (bvh->layouts & BVH_LAYOUT_BINARY) {
        for (uint32_t i = 0; i < bvh->n_refs; i++)
            if (bvh->prim_idx[i] != from)
                bvh_brute_step(&bvh->tris[i], bvh->prim_idx[i], &rp, ray->t_min, &best);
    } else if (bvh->n_wide > 0) {
        bvh_wide_brute(bvh, &rp, ray->t_min, from, &best);
    }
    if (best.prim_idx == UINT32_MAX)
        return false;
    *hit = best;
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
    st->n_refs = bvh->n_refs;
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

uint64_t bvh_hash_bytes(uint64_t h, const void *p, size_t n)
{
    const unsigned char *c = p;
    for (size_t i = 0; i < n; i += 8) {
        uint64_t w = 0;
        memcpy(&w, c + i, n - i < 8 ? n - i : 8);
        h = (h ^ w) * 0x9fb21c651e98df25ull; /* a multiply-xorshift mix per word */
        h ^= h >> 29;
    }
    return h;
}

uint64_t bvh_layout_hash(const struct bvh *bvh)
{
    uint64_t h = bvh_hash_bytes(0x9e3779b97f4a7c15ull, &bvh->n_tris, sizeof bvh->n_tris);
    /* the binary layout; nodes[1], unused, holds whatever aligned_alloc left there */
    if (bvh->nodes && bvh->n_nodes > 0) {
        h = bvh_hash_bytes(h, &bvh->nodes[0], sizeof *bvh->nodes);
        if (bvh->n_nodes > 2)
            h = bvh_hash_bytes(h, &bvh->nodes[2], sizeof *bvh->nodes * (bvh->n_nodes - 2));
        if (bvh->tris)
            h = bvh_hash_bytes(h, bvh->tris, sizeof *bvh->tris * bvh->n_refs);
        h = bvh_hash_bytes(h, bvh->prim_idx, sizeof *bvh->prim_idx * bvh->n_refs);
    }
    return bvh_wide_hash(bvh, h);
}

/* ---- A tree over boxes: the analytic shapes -------------------------------------------------
 * The same binned SAH build as the triangles' (no spatial splits: a box cannot be clipped), kept
 * in the binary layout, and the reference traversal's loop with the primitives left to the
 * caller (trace.c tests its spheres and quads itself). */
struct bvh_boxes {
    struct bvh_node *nodes; /* root at 0, nodes[1] unused */
    uint32_t *prim_idx;     /* the caller's index of each leaf entry, in leaf order */
    uint32_t n_nodes;
};

struct bvh_boxes *bvh_boxes_build(const float (*boxes)[2][3], uint32_t n)
{
    if (n == 0 || n > UINT32_MAX / 2)
        return NULL;
    struct bvh_boxes *tree = calloc(1, sizeof *tree);
    struct prim_ref *refs = bvh_alloc_aligned(n, sizeof *refs);
    uint8_t *degenerate = malloc(n);
    if (!tree || !refs || !degenerate)
        goto fail;
    struct box bounds = empty_box, centres = empty_box;
    for (uint32_t i = 0; i < n; i++) {
        struct prim_ref *r = &refs[i];
        for (int a = 0; a < 3; a++) {
            r->min[a] = boxes[i][0][a];
            r->max[a] = boxes[i][1][a];
        }
        r->prim_idx = i;
        r->is_degenerate = 0;
        float c[3];
        ref_centre(r, c);
        box_grow(&bounds, r->min, r->max);
        box_grow(&centres, c, c);
    }
    struct build_ctx ctx = {refs, NULL, 1, false, 0.0f, NULL, NULL};
    if (build_tree(&ctx, n, n, &bounds, &centres, &tree->nodes, &tree->n_nodes) == UINT32_MAX)
        goto fail;
    tree->prim_idx = bvh_alloc_array(n, sizeof *tree->prim_idx);
    if (!tree->prim_idx)
        goto fail;
    compact_leaves(tree->nodes, refs, tree->prim_idx, degenerate);
    free(refs);
    free(degenerate);
    return tree;
fail:
    free(refs);
    free(degenerate);
    bvh_boxes_free(tree);
    return NULL;
}

bool bvh_boxes_traverse(const struct bvh_boxes *tree, struct ray *ray, bvh_box_visit visit,
                        void *ctx)
{
    if (!ray_is_valid(ray))
        return false;
    struct ray_pre rp;
    ray_setup_box(ray, &rp);
    const struct bvh_node *nodes = tree->nodes;
    const float t_min = ray->t_min;
    float t_entry;
    if (!box_hit(&nodes[0], &rp, t_min, ray->t_max, &t_entry))
        return false;
    struct stack_entry stack[BVH_MAX_DEPTH];
    uint32_t n_stack = 0;
    uint32_t node_idx = 0;
    for (;;) {
        const struct bvh_node *node = &nodes[node_idx];
        if (node->n_tris > 0) {
            uint32_t end = node->left_first + node->n_tris;
            for (uint32_t i = node->left_first; i < end; i++)
                if (visit(ctx, tree->prim_idx[i], ray))
                    return true;
        } else if (descend(nodes, node, &rp, t_min, ray->t_max, &node_idx, stack, &n_stack)) {
            continue;
        }
        if (!pop_before(stack, &n_stack, ray->t_max, &node_idx))
            return false;
    }
}

void bvh_boxes_free(struct bvh_boxes *tree)
{
    if (!tree)
        return;
    free(tree->nodes);
    free(tree->prim_idx);
    free(tree);
}

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
