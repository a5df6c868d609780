/* bvh_wide.c - the fast layout, converted from bvh.c's binary reference and checked against it
 * (tinybvh's way): the SAH-optimal collapse into 8-wide nodes (Ylitie, Karras, Laine 2017,
 * "Efficient Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs", sec. 4.1) with SoA
 * child boxes, a child order per ray octant (Fuetterling et al. 2017) and SoA leaves of up to 8
 * triangles; eight SIMD lanes (AVX2 intrinsics, or the scalar loops that define them); Woop,
 * Benthin, Wald 2013's watertight test on eight lanes; single rays near child first (Wald et
 * al. 2008, "Getting Rid of Packets") and 8-ray packets (Benthin et al. 2012).  Every hit equals
 * the reference's to the bit.  Reading order: layout, conversion, SIMD lanes, woop8, wide
 * traversal, packets, brute force over the leaves.  Public API in bvh.h; bvh_internal.h is what
 * this file shares with bvh.c. */
#include "bvh_internal.h"

#include <assert.h>
#include <float.h>
#include <stdatomic.h>
#include <stdlib.h>

/* ---- The 8-wide layout --------------------------------------------------------------------------
 * Converted from the binary tree (bvh_wide_convert, "Conversion" below): each wide node gathers up
 * to BVH_WIDTH binary descendants as children, and small subtrees become single leaves, as the
 * SAH decides.  The child boxes are stored SoA, bounds[2 a][lane] = min along axis a and
 * bounds[2 a + 1][lane] = max, so one ray meets all eight boxes in one SIMD slab test.
 * A child reference is a wide node index, or WIDE_LEAF | first << 3 | (n - 1) for a leaf of
 * n in 1..8 triangles starting at wide triangle `first`.  An unused lane has the empty box
 * (min +inf, max -inf), which no ray hits, whatever the signs of its direction, and reference
 * 0.  order[] holds, for each of the 8 octants of ray directions, the children from the
 * farthest to the nearest along that octant's diagonal (wide_node_set_order).
 * A leaf holds the triangles of one binary subtree (at most 8 references) minus the degenerate
 * ones, each triangle once (a binary leaf of more than 8, which only the depth cap makes,
 * becomes a small wide subtree of 8-triangle leaves).  A leaf's triangles
 * are SoA: leaf_tris[9 first + (3 k + a) n + i] is coordinate a of vertex k of its triangle i
 * (the same three vertices as struct bvh_tri, so the test stays watertight), and
 * wide_prim_idx[first + i] is the caller's index.  The array has 8 floats of padding at its end
 * so that an 8-lane load of any leaf row stays inside it; lanes i >= n are masked.
 * Wide nodes are numbered in depth-first order, root = 0; leaves' triangles in the same order. */
#define BVH_WIDTH 8
#define WIDE_LEAF 0x80000000u
/* first must fit in 28 bits: BVH_WIDE_MAX_TRIS (bvh_internal.h); bvh.c builds only the binary
 * layout for more triangles */

struct wide_node {
    _Alignas(64) float bounds[6][BVH_WIDTH]; /* SoA child boxes: min x, max x, min y, ... */
    uint32_t child[BVH_WIDTH];               /* child references; 0 in unused lanes */
    uint32_t order[BVH_WIDTH];               /* per octant, the lanes farthest first (below) */
};                                           /* 256 bytes: four cache lines */
_Static_assert(sizeof(struct wide_node) == 256, "wide_node must be 256 bytes");

/* The children in use fill lanes 0 .. n - 1; a child reference is never 0 (the root is nobody's
 * child), so 0 marks an unused lane. */
static inline uint32_t wide_n_children(const struct wide_node *w)
{
    uint32_t n = 0;
    while (n < BVH_WIDTH && w->child[n] != 0)
        n++;
    return n;
}

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
 * that the arrays are allocated once at their exact size.  With threads, that pass also notes
 * where each wide subtree two levels below the root begins; the second pass writes the levels
 * above them and the threads write the subtrees there, so the layout is the same bits. */
#define WIDE_COST_NODE 1.0f /* c_node: one wide node visit (eight box tests) */
#define WIDE_COST_LEAF                                                                             \
    1.0f /* c_leaf: one leaf (woop8), in units of c_node; 1.5 and 2.0 gave
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
    const struct bvh *bvh;           /* binary tree: nodes, prim_idx */
    const uint8_t *degenerate;       /* per binary triangle position: zero area, dropped */
    const struct collapse_entry *dp; /* per binary node */
    const vec3 *positions;           /* the caller's mesh, read again for the leaves */
    const uint32_t *indices; /* (the wide leaves keep the same vertices as struct bvh_tri) */
    struct wide_node *wide;  /* NULL in the counting pass */
    float *leaf_tris;        /* SoA leaves */
    uint32_t *prim_idx;      /* of the wide triangles */
    uint32_t *scratch;       /* valid triangles of one leaf */
    uint32_t n_wide;         /* nodes allocated so far */
    uint32_t n_wide_tris;    /* triangles written so far */
    uint32_t n_leaves;       /* wide leaves */
    uint32_t depth;          /* current wide depth, root = 0 */
    uint32_t max_depth;      /* deepest wide node */
    /* Subtrees written by the threads (bvh_wide_convert): the wide nodes opened at depth
     * CONVERT_TASK_DEPTH.  The counting pass records them in order (tasks, n_tasks; NULL: do
     * not), the writing pass skips them (skip_tasks), leaving their places to the threads. */
    struct convert_task *tasks;
    uint32_t n_tasks;
    bool skip_tasks;
};

/* A subtree of the wide tree: binary node idx emitted as a wide node, and the wide nodes,
 * triangles and leaves the counting pass saw before it (begin) and after it (end). */
struct convert_task {
    uint32_t idx;
    uint32_t wide_begin, wide_end;
    uint32_t tris_begin, tris_end;
    uint32_t leaves_begin, leaves_end;
};
#define CONVERT_TASK_DEPTH 2 /* up to 64 subtrees, for up to 64 threads */

/* Wide depth stays below the binary depth cap plus the levels of one oversized leaf
 * (8-way splits of at most 2^28 triangles). */
#define WIDE_MAX_DEPTH (BVH_MAX_DEPTH + 10)
#define WIDE_STACK_SIZE (7 * WIDE_MAX_DEPTH + 8)

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
        w->order[lane] = 0;
    }
}

static void wide_node_add(struct wide_node *w, const struct box *b, uint32_t ref)
{
    uint32_t lane = wide_n_children(w);
    assert(lane < BVH_WIDTH && ref != 0);
    for (int a = 0; a < 3; a++) {
        w->bounds[2 * a][lane] = b->min[a];
        w->bounds[2 * a + 1][lane] = b->max[a];
    }
    w->child[lane] = ref;
}

/* The child order of each octant (struct wide_node's order), once its children are in place.
 * A ray whose direction signs are those of octant o, s_a = -1 where bit a of o is set and +1
 * elsewhere, meets boxes roughly in the order of their centres' depth along s, so children are
 * ranked by s . (min + max) (twice that depth), farthest first; the sort is stable and unused
 * lanes, never hit, rank first.  Fuetterling, Lojewski, Pfreundt, Ebert 2017, "Accelerated
 * Single Ray Tracing for Wide Vector Units", store such per-octant orders in the node (as does
 * tinybvh's BVH8_CPU). */
static void wide_node_set_order(struct wide_node *w)
{
    uint32_t n = wide_n_children(w);
    for (uint32_t octant = 0; octant < 8; octant++) {
        float depth[BVH_WIDTH];
        uint32_t lanes[BVH_WIDTH];
        for (uint32_t lane = 0; lane < n; lane++) {
            depth[lane] = 0.0f;
            for (int a = 0; a < 3; a++) {
                float twice_centre = w->bounds[2 * a][lane] + w->bounds[2 * a + 1][lane];
                depth[lane] += (octant >> a & 1u) ? -twice_centre : twice_centre;
            }
            lanes[lane] = lane;
        }
        /* insertion sort, deepest first; the unused lanes n .. 7 come before them */
        for (uint32_t i = 1; i < n; i++) {
            uint32_t lane = lanes[i];
            uint32_t j = i;
            while (j > 0 && depth[lanes[j - 1]] < depth[lane]) {
                lanes[j] = lanes[j - 1];
                j--;
            }
            lanes[j] = lane;
        }
        for (uint32_t r = 0; r < BVH_WIDTH; r++) {
            uint32_t lane = r < BVH_WIDTH - n ? n + r : lanes[r - (BVH_WIDTH - n)];
            w->order[r] = (w->order[r] & ~(7u << (3 * octant))) | lane << (3 * octant);
        }
    }
}

/* The next wide node, empty (initialised in the writing pass only). */
static uint32_t new_wide_node(struct convert *cv)
{
    uint32_t w = cv->n_wide++;
    if (cv->wide)
        wide_node_init(&cv->wide[w]);
    return w;
}

/* Child ref with box b into the next free lane of wide node w (writing pass only). */
static void add_child(struct convert *cv, uint32_t w, const struct box *b, uint32_t ref)
{
    if (cv->wide)
        wide_node_add(&cv->wide[w], b, ref);
}

/* One level down: the children of the node just opened. */
static void descend(struct convert *cv)
{
    cv->depth++;
    if (cv->depth > cv->max_depth)
        cv->max_depth = cv->depth;
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
        bvh_load_tri(&tri, cv->positions, cv->indices, prim);
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
    uint32_t w = new_wide_node(cv);
    descend(cv);
    uint32_t n_parts = (n + BVH_WIDTH - 1) / BVH_WIDTH < BVH_WIDTH ? (n + BVH_WIDTH - 1) / BVH_WIDTH
                                                                   : BVH_WIDTH;
    for (uint32_t part = 0; part < n_parts; part++) {
        uint32_t begin = (uint32_t)((uint64_t)n * part / n_parts);
        uint32_t end = (uint32_t)((uint64_t)n * (part + 1) / n_parts);
        struct box part_box = empty_box;
        uint32_t ref = emit_triangles(cv, tris + begin, end - begin, &part_box);
        box_grow(box, part_box.min, part_box.max);
        add_child(cv, w, &part_box, ref);
    }
    if (cv->wide)
        wide_node_set_order(&cv->wide[w]);
    cv->depth--;
    return w;
}

/* The wide leaf of binary subtree idx without its degenerate triangles, and with each triangle
 * once (the two parts of a triangle cut by a spatial split may meet again in one leaf); false
 * when none is left (the leaf is dropped). */
static bool emit_subtree_leaf(struct convert *cv, uint32_t idx, uint32_t *ref)
{
    const struct collapse_entry *e = &cv->dp[idx];
    const uint32_t *prim_idx = cv->bvh->prim_idx;
    uint32_t n = 0;
    for (uint32_t i = e->first; i < e->first + e->n_tris; i++) {
        bool seen = cv->degenerate[i];
        for (uint32_t j = 0; j < n && !seen; j++)
            seen = prim_idx[cv->scratch[j]] == prim_idx[i];
        if (!seen)
            cv->scratch[n++] = i;
    }
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
    if (cv->tasks && cv->depth == CONVERT_TASK_DEPTH) {
        struct convert_task *t = &cv->tasks[cv->n_tasks++];
        if (cv->skip_tasks) { /* the thread writes it where the counting pass found it */
            *ref = t->wide_begin;
            cv->n_wide = t->wide_end;
            cv->n_wide_tris = t->tris_end;
            cv->n_leaves = t->leaves_end;
            return true;
        }
        *t = (struct convert_task){idx, cv->n_wide, 0, cv->n_wide_tris, 0, cv->n_leaves, 0};
        *ref = emit_wide(cv, idx);
        t->wide_end = cv->n_wide;
        t->tris_end = cv->n_wide_tris;
        t->leaves_end = cv->n_leaves;
        return true;
    }
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
    uint32_t w = new_wide_node(cv);
    descend(cv);
    for (int i = 0; i < n_slots; i++) {
        struct box b = node_box(&nodes[slots[i]]);
        uint32_t ref;
        if (emit_slot(cv, slots[i], &ref))
            add_child(cv, w, &b, ref);
    }
    if (cv->wide)
        wide_node_set_order(&cv->wide[w]);
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
    uint32_t w = new_wide_node(cv);
    struct box b = node_box(&cv->bvh->nodes[0]);
    uint32_t ref;
    if (emit_subtree_leaf(cv, 0, &ref))
        add_child(cv, w, &b, ref);
    if (cv->wide)
        wide_node_set_order(&cv->wide[w]);
}

/* The threads' share of the writing pass: subtrees taken largest first from a shared counter,
 * each written by the operations the single-thread pass would perform, at the places the
 * counting pass found for it, so the layout is the same bits for any thread count. */
struct convert_job {
    const struct convert *proto; /* the writing pass's state, arrays included */
    const struct convert_task *tasks;
    const uint32_t *order; /* task indices, largest subtree first */
    uint32_t n_tasks;
    _Atomic uint32_t *next; /* the next entry of order to take */
    uint32_t *scratch;      /* this thread's, room for the largest leaf */
};

static void *convert_job_run(void *arg)
{
    const struct convert_job *job = arg;
    for (;;) {
        uint32_t k = atomic_fetch_add(job->next, 1u);
        if (k >= job->n_tasks)
            return NULL;
        const struct convert_task *t = &job->tasks[job->order[k]];
        struct convert cv = *job->proto;
        cv.scratch = job->scratch;
        cv.tasks = NULL;
        cv.n_wide = t->wide_begin;
        cv.n_wide_tris = t->tris_begin;
        cv.n_leaves = t->leaves_begin;
        cv.depth = CONVERT_TASK_DEPTH;
        emit_wide(&cv, t->idx);
        assert(cv.n_wide == t->wide_end && cv.n_wide_tris == t->tris_end);
    }
}

/* order[0 .. n) = 0 .. n - 1 sorted by the subtrees' triangle counts, largest first (an
 * insertion sort of at most 64 entries; ties keep their order). */
static void order_tasks(const struct convert_task *tasks, uint32_t n, uint32_t *order)
{
    for (uint32_t i = 0; i < n; i++) {
        uint32_t work = tasks[i].tris_end - tasks[i].tris_begin;
        uint32_t j = i;
        for (; j > 0; j--) {
            const struct convert_task *t = &tasks[order[j - 1]];
            if (t->tris_end - t->tris_begin >= work)
                break;
            order[j] = order[j - 1];
        }
        order[j] = i;
    }
}

bool bvh_wide_convert(struct bvh *bvh, const vec3 *positions, const uint32_t *indices,
                      const uint8_t *degenerate, int n_threads)
{
    bool ok = false;
    enum { MAX_TASKS = BVH_WIDTH * BVH_WIDTH };
    struct convert_task tasks[MAX_TASKS];
    uint32_t order[MAX_TASKS];
    /* a scratch list of one leaf's triangles per thread: a wide leaf merges at most 8, a binary
     * leaf can hold more where the depth cap stopped the build */
    size_t max_leaf = BVH_WIDTH;
    for (uint32_t i = 0; i < bvh->n_nodes; i++)
        if (i != 1 && bvh->nodes[i].n_tris > max_leaf)
            max_leaf = bvh->nodes[i].n_tris;
    int n_jobs = n_threads > 1 ? (n_threads < MAX_TASKS ? n_threads : MAX_TASKS) : 1;
    struct collapse_entry *dp = bvh_alloc_array(bvh->n_nodes, sizeof *dp);
    uint32_t *scratch = bvh_alloc_array((size_t)n_jobs * max_leaf, sizeof *scratch);
    if (!dp || !scratch)
        goto done;
    collapse_costs(bvh, dp);
    /* pass 1: count (and, for threads, find the subtrees they will write) */
    struct convert cv = {.bvh = bvh,
                         .degenerate = degenerate,
                         .dp = dp,
                         .positions = positions,
                         .indices = indices,
                         .scratch = scratch,
                         .tasks = n_jobs > 1 ? tasks : NULL};
    emit_root(&cv);
    assert(cv.max_depth <= WIDE_MAX_DEPTH && cv.n_tasks <= MAX_TASKS);
    uint32_t n_wide = cv.n_wide;
    uint32_t n_wide_tris = cv.n_wide_tris;
    uint32_t n_tasks = cv.n_tasks;
    /* pass 2: write, the top levels here, the subtrees below them on the threads */
    bvh->wide = bvh_alloc_aligned(n_wide, sizeof *bvh->wide);
    bvh->leaf_tris = bvh_alloc_aligned(9 * (size_t)n_wide_tris + 8, sizeof(float));
    bvh->wide_prim_idx = bvh_alloc_array(n_wide_tris, sizeof(uint32_t));
    if (!bvh->wide || !bvh->leaf_tris || !bvh->wide_prim_idx)
        goto done;
    memset(bvh->leaf_tris + 9 * (size_t)n_wide_tris, 0, 8 * sizeof(float));
    cv = (struct convert){.bvh = bvh,
                          .degenerate = degenerate,
                          .dp = dp,
                          .positions = positions,
                          .indices = indices,
                          .wide = bvh->wide,
                          .leaf_tris = bvh->leaf_tris,
                          .prim_idx = bvh->wide_prim_idx,
                          .scratch = scratch,
                          .tasks = n_tasks > 0 ? tasks : NULL,
                          .skip_tasks = true};
    emit_root(&cv);
    assert(cv.n_wide == n_wide && cv.n_wide_tris == n_wide_tris);
    if (n_tasks > 0) {
        order_tasks(tasks, n_tasks, order);
        _Atomic uint32_t next = 0;
        if (n_jobs > (int)n_tasks)
            n_jobs = (int)n_tasks;
        struct convert_job jobs[MAX_TASKS];
        for (int i = 0; i < n_jobs; i++)
            jobs[i] = (struct convert_job){.proto = &cv,
                                           .tasks = tasks,
                                           .order = order,
                                           .n_tasks = n_tasks,
                                           .next = &next,
                                           .scratch = scratch + (size_t)i * max_leaf};
        bvh_run_jobs(n_jobs, convert_job_run, jobs, sizeof jobs[0]);
    }
    bvh->n_wide = n_wide;
    bvh->n_wide_tris = n_wide_tris;
    bvh->bounds = bvh->nodes[0];
    bvh->stats.n_wide_nodes = n_wide;
    bvh->stats.n_wide_leaves = cv.n_leaves;
    bvh->stats.wide_bytes = (size_t)n_wide * sizeof(struct wide_node) +
                            ((size_t)n_wide_tris * 9 + 8) * sizeof(float) +
                            (size_t)n_wide_tris * sizeof(uint32_t);
    ok = true;
done:
    free(dp);
    free(scratch);
    return ok;
}

/* ---- Eight SIMD lanes -----------------------------------------------------------------------
 * struct f8 holds eight floats, struct m8 eight lane masks (all ones or all zeros).  Each
 * operation is written twice, side by side: with AVX2 it is one intrinsic on a 256-bit
 * register; the scalar loop under #else is its scalar equivalent and the definition of what the
 * intrinsic computes (compiled by PORTABLE=1 builds and -DBVH_NO_SIMD, where the suite runs
 * too).  f8_max_num and f8_min_num keep the running value when the candidate is NaN, as
 * max_num and min_num (bvh_internal.h) do.  These are the only intrinsics of the traversal. */
#if defined(__AVX2__) && !defined(BVH_NO_SIMD)
#define BVH_AVX2 1
#include <immintrin.h>
struct f8 {
    __m256 v;
};
struct m8 {
    __m256 v;
};
struct i8 {
    __m256i v;
};
#else
#define BVH_AVX2 0
struct f8 {
    float v[8];
};
struct m8 {
    int32_t v[8]; /* 0 or -1 */
};
struct i8 {
    uint32_t v[8];
};
#endif

/* The scalar forms: r.v[i] = expr for each lane i (a mask lane is -1 where expr holds). */
#define F8_MAP(expr)                                                                               \
    struct f8 r;                                                                                   \
    for (int i = 0; i < 8; i++)                                                                    \
        r.v[i] = (expr);                                                                           \
    return r
#define M8_MAP(expr)                                                                               \
    struct m8 r;                                                                                   \
    for (int i = 0; i < 8; i++)                                                                    \
        r.v[i] = (expr) ? -1 : 0;                                                                  \
    return r

const char *bvh_simd_name(void) { return BVH_AVX2 ? "avx2" : "scalar"; }

static inline struct f8 f8_set1(float s)
{
#if BVH_AVX2
    return (struct f8){_mm256_set1_ps(s)};
#else
    F8_MAP(s);
#endif
}
/* p 32-byte aligned */
static inline struct f8 f8_load(const float *p)
{
#if BVH_AVX2
    return (struct f8){_mm256_load_ps(p)};
#else
    F8_MAP(p[i]);
#endif
}
static inline struct f8 f8_loadu(const float *p)
{
#if BVH_AVX2
    return (struct f8){_mm256_loadu_ps(p)};
#else
    F8_MAP(p[i]);
#endif
}
static inline void f8_store(float *p, struct f8 a)
{
#if BVH_AVX2
    _mm256_storeu_ps(p, a.v);
#else
    memcpy(p, a.v, sizeof a.v);
#endif
}
static inline struct f8 f8_add(struct f8 a, struct f8 b)
{
#if BVH_AVX2
    return (struct f8){_mm256_add_ps(a.v, b.v)};
#else
    F8_MAP(a.v[i] + b.v[i]);
#endif
}
static inline struct f8 f8_sub(struct f8 a, struct f8 b)
{
#if BVH_AVX2
    return (struct f8){_mm256_sub_ps(a.v, b.v)};
#else
    F8_MAP(a.v[i] - b.v[i]);
#endif
}
static inline struct f8 f8_mul(struct f8 a, struct f8 b)
{
#if BVH_AVX2
    return (struct f8){_mm256_mul_ps(a.v, b.v)};
#else
    F8_MAP(a.v[i] * b.v[i]);
#endif
}
static inline struct f8 f8_div(struct f8 a, struct f8 b)
{
#if BVH_AVX2
    return (struct f8){_mm256_div_ps(a.v, b.v)};
#else
    F8_MAP(a.v[i] / b.v[i]);
#endif
}
/* a b - c rounded once (vfmsub); only the fused slab test uses it, and only where
 * BVH_FUSED_SLABS is 1.  Without FMA hardware fmaf is a slow library call, so those builds keep
 * the sub-and-multiply slab test and never call this. */
#if BVH_AVX2 && defined(__FMA__)
#define BVH_FUSED_SLABS 1
#else
#define BVH_FUSED_SLABS 0
#endif
static inline struct f8 f8_fmsub(struct f8 a, struct f8 b, struct f8 c)
{
#if BVH_FUSED_SLABS
    return (struct f8){_mm256_fmsub_ps(a.v, b.v, c.v)};
#elif BVH_AVX2
    return (struct f8){_mm256_sub_ps(_mm256_mul_ps(a.v, b.v), c.v)}; /* never called */
#else
    F8_MAP(fmaf(a.v[i], b.v[i], -c.v[i]));
#endif
}
/* candidate > running ? candidate : running (vmaxps returns its second operand on NaN) */
static inline struct f8 f8_max_num(struct f8 running, struct f8 candidate)
{
#if BVH_AVX2
    return (struct f8){_mm256_max_ps(candidate.v, running.v)};
#else
    F8_MAP(max_num(running.v[i], candidate.v[i]));
#endif
}
static inline struct f8 f8_min_num(struct f8 running, struct f8 candidate)
{
#if BVH_AVX2
    return (struct f8){_mm256_min_ps(candidate.v, running.v)};
#else
    F8_MAP(min_num(running.v[i], candidate.v[i]));
#endif
}
static inline struct f8 f8_abs(struct f8 a)
{
#if BVH_AVX2
    return (struct f8){_mm256_andnot_ps(_mm256_set1_ps(-0.0f), a.v)};
#else
    F8_MAP(fabsf(a.v[i]));
#endif
}
static inline struct m8 f8_lt(struct f8 a, struct f8 b)
{
#if BVH_AVX2
    return (struct m8){_mm256_cmp_ps(a.v, b.v, _CMP_LT_OQ)};
#else
    M8_MAP(a.v[i] < b.v[i]);
#endif
}
static inline struct m8 f8_le(struct f8 a, struct f8 b)
{
#if BVH_AVX2
    return (struct m8){_mm256_cmp_ps(a.v, b.v, _CMP_LE_OQ)};
#else
    M8_MAP(a.v[i] <= b.v[i]);
#endif
}
static inline struct m8 f8_gt(struct f8 a, struct f8 b)
{
#if BVH_AVX2
    return (struct m8){_mm256_cmp_ps(a.v, b.v, _CMP_GT_OQ)};
#else
    M8_MAP(a.v[i] > b.v[i]);
#endif
}
static inline struct m8 f8_eq(struct f8 a, struct f8 b)
{
#if BVH_AVX2
    return (struct m8){_mm256_cmp_ps(a.v, b.v, _CMP_EQ_OQ)};
#else
    M8_MAP(a.v[i] == b.v[i]);
#endif
}
static inline struct m8 m8_or(struct m8 a, struct m8 b)
{
#if BVH_AVX2
    return (struct m8){_mm256_or_ps(a.v, b.v)};
#else
    M8_MAP(a.v[i] | b.v[i]);
#endif
}
static inline struct m8 m8_and(struct m8 a, struct m8 b)
{
#if BVH_AVX2
    return (struct m8){_mm256_and_ps(a.v, b.v)};
#else
    M8_MAP(a.v[i] & b.v[i]);
#endif
}
/* a and not b */
static inline struct m8 m8_andnot(struct m8 a, struct m8 b)
{
#if BVH_AVX2
    return (struct m8){_mm256_andnot_ps(b.v, a.v)};
#else
    M8_MAP(a.v[i] & ~b.v[i]);
#endif
}
/* bit i set when lane i is */
static inline uint32_t m8_bits(struct m8 m)
{
#if BVH_AVX2
    return (uint32_t)_mm256_movemask_ps(m.v);
#else
    uint32_t bits = 0;
    for (int i = 0; i < 8; i++)
        bits |= (m.v[i] ? 1u : 0u) << i;
    return bits;
#endif
}
/* lane i set when bit i of bits is */
static inline struct m8 m8_from_bits(uint32_t bits)
{
#if BVH_AVX2
    const __m256i lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    __m256i b = _mm256_and_si256(_mm256_set1_epi32((int)bits), lane_bit);
    return (struct m8){_mm256_castsi256_ps(_mm256_cmpeq_epi32(b, lane_bit))};
#else
    M8_MAP((bits >> i) & 1u);
#endif
}
/* m ? a : b per lane */
static inline struct f8 f8_select(struct m8 m, struct f8 a, struct f8 b)
{
#if BVH_AVX2
    return (struct f8){_mm256_blendv_ps(b.v, a.v, m.v)};
#else
    F8_MAP(m.v[i] ? a.v[i] : b.v[i]);
#endif
}
/* smallest lane */
static inline float f8_hmin(struct f8 a)
{
#if BVH_AVX2
    __m256 m = _mm256_min_ps(a.v, _mm256_permute2f128_ps(a.v, a.v, 1));
    m = _mm256_min_ps(m, _mm256_shuffle_ps(m, m, _MM_SHUFFLE(1, 0, 3, 2)));
    m = _mm256_min_ps(m, _mm256_shuffle_ps(m, m, _MM_SHUFFLE(2, 3, 0, 1)));
    return _mm256_cvtss_f32(m);
#else
    float m = a.v[0];
    for (int i = 1; i < 8; i++)
        m = a.v[i] < m ? a.v[i] : m;
    return m;
#endif
}
/* Eight uint32 lanes: child references and lane indices, for the ordered push of the single-ray
 * traversal. */
#define I8_MAP(expr)                                                                               \
    struct i8 r;                                                                                   \
    for (int i = 0; i < 8; i++)                                                                    \
        r.v[i] = (expr);                                                                           \
    return r
/* (p[i] >> shift) & 7, p 32-byte aligned: a node's child order for one octant */
static inline struct i8 i8_order(const uint32_t *p, int shift)
{
#if BVH_AVX2
    __m256i v = _mm256_srli_epi32(_mm256_load_si256((const __m256i *)p), shift);
    return (struct i8){_mm256_and_si256(v, _mm256_set1_epi32(7))};
#else
    I8_MAP(p[i] >> shift & 7u);
#endif
}
/* p 32-byte aligned */
static inline struct i8 i8_load(const uint32_t *p)
{
#if BVH_AVX2
    return (struct i8){_mm256_load_si256((const __m256i *)p)};
#else
    I8_MAP(p[i]);
#endif
}
static inline void i8_store(uint32_t *p, struct i8 a)
{
#if BVH_AVX2
    _mm256_storeu_si256((__m256i *)p, a.v);
#else
    memcpy(p, a.v, sizeof a.v);
#endif
}
/* r[i] = a[idx[i]], idx in 0..7 */
static inline struct i8 i8_permute(struct i8 a, struct i8 idx)
{
#if BVH_AVX2
    return (struct i8){_mm256_permutevar8x32_epi32(a.v, idx.v)};
#else
    I8_MAP(a.v[idx.v[i]]);
#endif
}
static inline struct f8 f8_permute(struct f8 a, struct i8 idx)
{
#if BVH_AVX2
    return (struct f8){_mm256_permutevar8x32_ps(a.v, idx.v)};
#else
    F8_MAP(a.v[idx.v[i]]);
#endif
}
/* every lane: lane `lane` of a */
static inline struct f8 f8_splat_lane(struct f8 a, int lane)
{
#if BVH_AVX2
    return (struct f8){_mm256_permutevar8x32_ps(a.v, _mm256_set1_epi32(lane))};
#else
    F8_MAP(a.v[lane]);
#endif
}
static inline struct m8 m8_permute(struct m8 a, struct i8 idx)
{
#if BVH_AVX2
    return (struct m8){_mm256_permutevar8x32_ps(a.v, idx.v)};
#else
    struct m8 r;
    for (int i = 0; i < 8; i++)
        r.v[i] = a.v[idx.v[i]];
    return r;
#endif
}
#if BVH_AVX2 && !(defined(__AVX512F__) && defined(__AVX512VL__))
/* The positions of the set bits of a nibble, in order, one per byte (unused bytes 0). */
static const uint32_t nibble_lanes[16] = {
    0x00000000, 0x00000000, 0x00000001, 0x00000100, 0x00000002, 0x00000200,
    0x00000201, 0x00020100, 0x00000003, 0x00000300, 0x00000301, 0x00030100,
    0x00000302, 0x00030200, 0x00030201, 0x03020100,
};
#endif

/* The lanes i of a whose bit i is set, in order, moved to lanes 0, 1, ...; the rest is 0.
 * AVX-512 has the instruction (vpcompressd).  With AVX2 the permutation that does it is
 * looked up a nibble of bits at a time: the high nibble's lane numbers (+ 4) follow the low
 * nibble's count of them.  (BMI2's pdep/pext build it in two instructions, but on AMD before
 * Zen 3 they are microcoded, with a latency that grows with the bits set: 10% of the closest-hit
 * loop's samples fell on them there; docs/bvh.md, "Levers measured".) */
static inline struct i8 i8_compress(struct i8 a, uint32_t bits)
{
#if BVH_AVX2 && defined(__AVX512F__) && defined(__AVX512VL__)
    return (struct i8){_mm256_maskz_compress_epi32((__mmask8)bits, a.v)};
#elif BVH_AVX2
    uint32_t low = bits & 15u;
    uint64_t lanes = (uint64_t)nibble_lanes[low] |
                     (uint64_t)(nibble_lanes[bits >> 4 & 15u] | 0x04040404u)
                         << (8 * __builtin_popcount(low));
    __m256i idx = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128((long long)lanes));
    __m256i kept = _mm256_permutevar8x32_epi32(a.v, idx);
    /* zero the lanes past the count (the table's unused bytes repeat lane 0 or 4) */
    __m256i count = _mm256_set1_epi32(__builtin_popcount(bits));
    __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    return (struct i8){_mm256_and_si256(kept, _mm256_cmpgt_epi32(count, lane))};
#else
    uint32_t in[8];
    uint32_t out[8] = {0};
    i8_store(in, a);
    int n = 0;
    for (int i = 0; i < 8; i++)
        if (bits >> i & 1u)
            out[n++] = in[i];
    return i8_load(out);
#endif
}
/* bit i: the top bit of lane i */
static inline uint32_t i8_top_bits(struct i8 a)
{
#if BVH_AVX2
    return (uint32_t)_mm256_movemask_ps(_mm256_castsi256_ps(a.v));
#else
    uint32_t bits = 0;
    for (int i = 0; i < 8; i++)
        bits |= (a.v[i] >> 31) << i;
    return bits;
#endif
}
/* lane i of a */
static inline uint32_t i8_lane(struct i8 a, int i)
{
#if BVH_AVX2
    return (uint32_t)_mm256_cvtsi256_si32(_mm256_permutevar8x32_epi32(a.v, _mm256_set1_epi32(i)));
#else
    return a.v[i];
#endif
}
#undef I8_MAP
#undef F8_MAP
#undef M8_MAP

/* The traversal loops take `fast` as a constant argument; inlining them at each call
 * (ALWAYS_INLINE, vec.h) gives one specialised copy per slab-test form instead of a branch per
 * node. */

static inline int lowest_bit(uint32_t bits)
{
    assert(bits != 0);
    return __builtin_ctz(bits);
}

/* ---- Woop's test on eight lanes ----------------------------------------------------------------
 * A lane is one (ray, triangle) pair: eight triangles against one ray in a leaf, or one
 * triangle against eight rays in a packet.  The inputs are the vertices relative to the ray
 * origin, components already permuted to (kx, ky, kz) of the lane's ray.  This is bvh.c's
 * tri_hit written a second time, on purpose: every operation is tri_hit's, in the same order, so
 * a lane's t, u, v equal tri_hit's to the bit, and tri_hit is the reference it is tested
 * against (every wide and packet traversal against brute force, tests/bvh_wide_test.c).  Lanes
 * outside `valid` are ignored (their inputs may be garbage).  Returns the mask of lanes that
 * hit. */
struct woop8_in {
    struct f8 a[3]; /* p0 - o: (kx, ky, kz) components */
    struct f8 b[3]; /* p1 - o */
    struct f8 c[3]; /* p2 - o */
    struct f8 sx;   /* shear constants of each lane's ray */
    struct f8 sy;
    struct f8 sz;
    struct f8 o_scale; /* ray_pre's o_scale of each lane's ray */
    struct f8 t_min;   /* hit interval (t_min, t_max) */
    struct f8 t_max;
};

struct woop8_out {
    struct f8 t;
    struct f8 u;        /* V / det */
    struct f8 v;        /* W / det */
    uint32_t undecided; /* inside lanes whose side of the origin float could not decide */
    struct f8 edge[3];  /* U, V, W, filled only when undecided != 0 */
};

static COLD void woop8_fallback(uint32_t lanes, struct f8 Ax, struct f8 Ay, struct f8 Bx,
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
        bvh_edge_functions_double(ax[i], ay[i], bx[i], by[i], cx[i], cy[i], &u[i], &v[i], &w[i]);
    }
    *U = f8_loadu(u);
    *V = f8_loadu(v);
    *W = f8_loadu(w);
}

/* woop8's first half: the sheared vertices and the edge functions. */
struct woop8_edges {
    struct f8 Ax, Ay, Bx, By, Cx, Cy;
    struct f8 U, V, W;
};

/* The lanes of `valid` whose line passes inside the triangle (edge functions that agree in
 * sign), with what woop8_finish needs in *e. */
static ALWAYS_INLINE uint32_t woop8_inside(const struct woop8_in *in, uint32_t valid,
                                           struct woop8_edges *e)
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
    *e = (struct woop8_edges){Ax, Ay, Bx, By, Cx, Cy, U, V, W};
    return valid & ~m8_bits(m8_and(any_neg, any_pos));
}

/* woop8's second half, for the lanes `inside` that woop8_inside found: returns the lanes
 * certainly hit in (t_min, t_max); out->undecided gets the inside lanes whose side of the origin
 * the float bounds leave open, for the caller to decide with bvh_tri_hit_double (it has the
 * stored vertices, woop8 only their translated copies). */
static ALWAYS_INLINE uint32_t woop8_finish(const struct woop8_in *in, uint32_t inside,
                                           const struct woop8_edges *e, struct woop8_out *out)
{
    const struct f8 zero = f8_set1(0.0f);
    struct f8 Ax = e->Ax, Ay = e->Ay, Bx = e->Bx, By = e->By, Cx = e->Cx, Cy = e->Cy;
    struct f8 U = e->U, V = e->V, W = e->W;
    out->undecided = 0;
    struct f8 det = f8_add(f8_add(U, V), W);
    inside &= ~m8_bits(f8_eq(det, zero));
    if (!inside)
        return 0;
    struct f8 Az = f8_mul(in->sz, in->a[2]);
    struct f8 Bz = f8_mul(in->sz, in->b[2]);
    struct f8 Cz = f8_mul(in->sz, in->c[2]);
    struct f8 T = f8_add(f8_add(f8_mul(U, Az), f8_mul(V, Bz)), f8_mul(W, Cz));
    struct f8 inv_det = f8_div(f8_set1(1.0f), det);
    struct f8 t = f8_mul(T, inv_det);
    /* the error bounds of T and det, as in tri_hit (docs/theory.md, "Self-intersection") */
    const struct f8 tiny = f8_set1(FLT_MIN);
    struct f8 max_xt = f8_max_num(f8_max_num(f8_abs(Ax), f8_abs(Bx)), f8_abs(Cx));
    struct f8 max_yt = f8_max_num(f8_max_num(f8_abs(Ay), f8_abs(By)), f8_abs(Cy));
    struct f8 max_zu = f8_max_num(f8_max_num(f8_abs(in->a[2]), f8_abs(in->b[2])), f8_abs(in->c[2]));
    struct f8 max_zt = f8_max_num(f8_max_num(f8_abs(Az), f8_abs(Bz)), f8_abs(Cz));
    struct f8 max_e = f8_max_num(f8_max_num(f8_abs(U), f8_abs(V)), f8_abs(W));
    struct f8 two_zu = f8_mul(f8_set1(2.0f), max_zu);
    struct f8 delta_x = f8_add(f8_mul(f8_set1(mcpt_gamma(5)), f8_add(max_xt, two_zu)), tiny);
    struct f8 delta_y = f8_add(f8_mul(f8_set1(mcpt_gamma(5)), f8_add(max_yt, two_zu)), tiny);
    struct f8 delta_z = f8_add(f8_mul(f8_set1(mcpt_gamma(4)), max_zt), tiny);
    struct f8 delta_e =
        f8_add(f8_mul(f8_set1(2.0f),
                      f8_add(f8_add(f8_add(f8_mul(f8_mul(f8_set1(mcpt_gamma(3)), max_xt), max_yt),
                                           f8_mul(delta_y, max_xt)),
                                    f8_mul(delta_x, max_yt)),
                             f8_mul(delta_x, delta_y))),
               tiny);
    struct f8 delta_T =
        f8_add(f8_mul(f8_set1(3.0f),
                      f8_add(f8_add(f8_add(f8_mul(f8_mul(f8_set1(mcpt_gamma(4)), max_e), max_zt),
                                           f8_mul(delta_z, max_e)),
                                    f8_mul(delta_e, max_zt)),
                             f8_mul(delta_z, delta_e))),
               tiny);
    struct f8 delta_det = f8_mul(f8_set1(3.0f),
                                 f8_add(f8_mul(f8_set1(mcpt_gamma(3)), max_e), delta_e));
    /* t's own precision, as in tri_hit */
    struct f8 z_lo = f8_min_num(f8_min_num(Az, Bz), Cz);
    struct f8 z_hi = f8_max_num(f8_max_num(Az, Bz), Cz);
    struct f8 abs_det = f8_abs(det);
    struct f8 err_t = f8_add(f8_mul(f8_mul(f8_set1(2.0f), f8_sub(z_hi, z_lo)), delta_det),
                             f8_mul(delta_z, abs_det));
    /* decided: T finite, both signs exact, and behind the origin or a precise t, as in tri_hit */
    struct f8 abs_T = f8_abs(T);
    struct m8 t_pos = f8_gt(t, zero);
    struct m8 sign_known = m8_and(m8_and(f8_gt(abs_T, delta_T), f8_le(abs_T, f8_set1(FLT_MAX))),
                                  f8_gt(abs_det, delta_det));
    struct m8 precise = f8_le(err_t, f8_mul(f8_set1(0x1p-10f),
                                            f8_add(abs_T, f8_mul(abs_det, in->o_scale))));
    uint32_t decided = m8_bits(sign_known) & ~(m8_bits(t_pos) & ~m8_bits(precise));
    out->undecided = inside & ~decided;
    if (out->undecided) {
        out->edge[0] = U;
        out->edge[1] = V;
        out->edge[2] = W;
    }
    uint32_t hit = inside & decided &
                   m8_bits(m8_and(m8_and(t_pos, f8_gt(t, in->t_min)), f8_lt(t, in->t_max)));
    out->t = t;
    out->u = f8_mul(V, inv_det);
    out->v = f8_mul(W, inv_det);
    return hit;
}

/* Both halves: the lanes of `valid` certainly hit, as woop8_finish. */
static ALWAYS_INLINE uint32_t woop8(const struct woop8_in *in, uint32_t valid,
                                    struct woop8_out *out)
{
    struct woop8_edges e;
    out->undecided = 0;
    uint32_t inside = woop8_inside(in, valid, &e);
    return inside ? woop8_finish(in, inside, &e, out) : 0;
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
};                      /* 104 bytes */

/* struct wide_ray broadcast to eight lanes, a local of the traversal loop. */
struct wide_ray8 {
    struct f8 o[3];         /* origin, slab order */
    struct f8 inv_d[3];     /* 1 / d */
    struct f8 inv_d_far[3]; /* the conservative far-plane factor */
    struct f8 c_near[3];    /* fused form constants */
    struct f8 c_far[3];
    struct f8 t_min;
    struct f8 o_k[3]; /* Woop: o[kx], o[ky], o[kz] (set at the first leaf) */
    struct f8 sx;     /* Woop's shear constants */
    struct f8 sy;
    struct f8 sz;
    struct f8 o_scale;  /* Woop: the origin's magnitude in units of t */
    int k[3];           /* kx, ky, kz */
    float rp_t_min;     /* the ray's t_min, for bvh_tri_hit_double */
    size_t near_off[3]; /* byte offsets of the near and far bounds rows in a node */
    size_t far_off[3];
    int order_shift;              /* 3 octant: the ray's child order (struct wide_node) */
    const struct wide_node *wide; /* the node array */
    struct ray_pre *rp;           /* the caller's; Woop's constants go there at the first leaf */
    uint32_t from;                /* the triangle the ray leaves (never reported), or BVH_NO_PRIM */
};                                /* 640 bytes with AVX2 */

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
    v->rp_t_min = wr->t_min;
    const int *is_neg = wr->rp->is_neg;
    v->order_shift = 3 * (is_neg[0] | is_neg[1] << 1 | is_neg[2] << 2);
    v->rp = wr->rp;
    v->from = BVH_NO_PRIM;
}

/* Woop's constants: computed into *rp (which the caller owns) on the first leaf. */
static inline void wide_ray8_woop(struct wide_ray8 *v)
{
    struct ray_pre *rp = v->rp;
    ray_setup_woop_as(rp, true); /* single rays: incoherent ones gain (docs/bvh.md) */
    v->k[0] = rp->kx;
    v->k[1] = rp->ky;
    v->k[2] = rp->kz;
    for (int j = 0; j < 3; j++)
        v->o_k[j] = f8_set1(rp->o[v->k[j]]);
    v->sx = f8_set1(rp->sx);
    v->sy = f8_set1(rp->sy);
    v->sz = f8_set1(rp->sz);
    v->o_scale = f8_set1(rp->o_scale);
    v->rp = rp;
}

/* Slab test of one ray against a wide node's children; returns the mask of children hit in
 * [t_min, t_max] and their entry distances. */
static inline struct m8 wide_box_hit(const struct wide_node *node, const struct wide_ray8 *v,
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
    return f8_le(t0, t1);
}

/* Triangle i of the leaf at wide triangle `first` (n triangles), unpacked from SoA. */
static void leaf_tri(const struct bvh *bvh, uint32_t first, uint32_t n, uint32_t i,
                     struct bvh_tri *tri)
{
    const float *base = bvh->leaf_tris + 9 * (size_t)first;
    float *p[3] = {tri->p0, tri->p1, tri->p2};
    for (int k = 0; k < 3; k++)
        for (int a = 0; a < 3; a++)
            p[k][a] = base[(size_t)(3 * k + a) * n + i];
}

/* The lanes woop8 left undecided, decided by bvh_tri_hit_double (rare: hits at t ~ 0, grazing
 * hits, extreme coordinates): one ray rp against the leaf's triangles in `lanes`.  Their t, u, v
 * replace the lanes' in *out; returns the lanes hit. */
static COLD uint32_t leaf_undecided(const struct bvh *bvh, uint32_t first, uint32_t n,
                                    const struct ray_pre *rp, float t_min, float t_max,
                                    uint32_t lanes, struct woop8_out *out)
{
    float t[8];
    float u[8];
    float v[8];
    float e[3][8];
    f8_store(t, out->t);
    f8_store(u, out->u);
    f8_store(v, out->v);
    for (int j = 0; j < 3; j++)
        f8_store(e[j], out->edge[j]);
    uint32_t hits = 0;
    for (uint32_t bits = lanes; bits; bits &= bits - 1) {
        int i = lowest_bit(bits);
        struct bvh_tri tri;
        leaf_tri(bvh, first, n, (uint32_t)i, &tri);
        const float edge[3] = {e[0][i], e[1][i], e[2][i]};
        if (bvh_tri_hit_double(&tri, rp, edge, t_min, t_max, &t[i], &u[i], &v[i]))
            hits |= 1u << i;
    }
    out->t = f8_loadu(t);
    out->u = f8_loadu(u);
    out->v = f8_loadu(v);
    return hits;
}

/* Of the lanes of the leaf at wide triangle `first`, those holding triangle `from` (the one a
 * spawned ray leaves: bvh_intersect_from).  Only the lanes whose line passes inside
 * (woop8_inside) are looked at, so the lookup costs nothing on the leaves a ray merely passes. */
static inline uint32_t leaf_own(const struct bvh *bvh, uint32_t first, uint32_t lanes,
                                uint32_t from)
{
    uint32_t own = 0;
    for (; lanes; lanes &= lanes - 1) {
        int i = lowest_bit(lanes);
        if (bvh->wide_prim_idx[first + (uint32_t)i] == from)
            own |= 1u << i;
    }
    return own;
}

/* woop8 of one ray against the n (1..8) triangles of the leaf at wide triangle `first`, without
 * the ray's own triangle (v->from). */
static ALWAYS_INLINE uint32_t wide_leaf_hit(const struct bvh *bvh, uint32_t first, uint32_t n,
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
    in.o_scale = v->o_scale;
    in.t_min = v->t_min;
    in.t_max = f8_set1(t_max);
    struct woop8_edges e;
    uint32_t inside = woop8_inside(&in, (1u << n) - 1u, &e);
    /* the ray's own triangle leaves before its error bounds are computed: the line of a ray
     * spawned on it passes inside it (at t ~ 0), so without this every spawned ray would pay
     * woop8_finish at its own leaf */
    if (inside && v->from != BVH_NO_PRIM)
        inside &= ~leaf_own(bvh, first, inside, v->from);
    if (!inside)
        return 0;
    uint32_t hits = woop8_finish(&in, inside, &e, out);
    if (out->undecided)
        hits |= leaf_undecided(bvh, first, n, v->rp, v->rp_t_min, t_max, out->undecided, out);
    return hits;
}

/* The closest hit so far. */
struct wide_hit {
    float t; /* t_hit, initially the ray's t_max */
    float u;
    float v;
    uint32_t tri; /* wide triangle index, UINT32_MAX while none */
};

/* The nearest of a leaf's hits (lanes `hits` of *out, the leaf at wide triangle `first`); among
 * equal t the lowest lane: the first in BVH order, as brute force. */
static ALWAYS_INLINE struct wide_hit leaf_nearest(uint32_t first, uint32_t hits,
                                                  const struct woop8_out *out)
{
    struct f8 t_hits = f8_select(m8_from_bits(hits), out->t, f8_set1(INFINITY));
    float t_best = f8_hmin(t_hits);
    int lane = lowest_bit(hits & m8_bits(f8_eq(t_hits, f8_set1(t_best))));
    float u[8];
    float uv_v[8];
    f8_store(u, out->u);
    f8_store(uv_v, out->v);
    return (struct wide_hit){t_best, u[lane], uv_v[lane], first + (uint32_t)lane};
}

/* The hit children of a node (vector mask hit, entry distances t_entry), two or more of them,
 * onto the stack in the node's order for the ray's octant, nearest on top: the order's ranks
 * whose lane is hit are compressed into lanes 0 .. k - 1, farthest first, and references and
 * distances stored as two vectors (the stack has room for eight more).  No comparison of
 * distances, no branch per child: the order is precomputed, so it is only approximately by
 * entry distance (Fuetterling et al. 2017).  Returns the nearest, which is not kept. */
static inline uint32_t push_ordered(uint32_t *stack_ref, float *stack_t, uint32_t *n_stack,
                                    const struct wide_node *node, int order_shift, struct m8 hit,
                                    struct f8 t_entry)
{
    struct i8 order = i8_order(node->order, order_shift);
    uint32_t ranked = m8_bits(m8_permute(hit, order)); /* bit r: the child of rank r is hit */
    struct i8 lanes = i8_compress(order, ranked);
    int k = __builtin_popcount(ranked);
    struct i8 refs = i8_permute(i8_load(node->child), lanes);
    i8_store(stack_ref + *n_stack, refs);
    f8_store(stack_t + *n_stack, f8_permute(t_entry, lanes));
    *n_stack += (uint32_t)k - 1;
    return i8_lane(refs, k - 1);
}

/* The interior children a node visit found hit, all four cache lines of each, requested from
 * memory before the traversal knows which it takes next: incoherent rays wait mostly on node
 * and leaf loads, and the address of the next node is otherwise known only after the ordering
 * (push_ordered) and the stack.  Leaves are not prefetched (their rows measured no faster).
 * Figures in docs/bvh.md, "Levers measured". */
static inline void prefetch_hit_nodes(const struct wide_node *wide, const struct wide_node *node,
                                      uint32_t mask)
{
    /* the interior children, from the references' top bits (WIDE_LEAF) at once: a test per
     * child would be a branch that incoherent rays mispredict */
    mask &= ~i8_top_bits(i8_load(node->child));
    for (; mask; mask &= mask - 1) {
        const char *p = (const char *)&wide[node->child[lowest_bit(mask)]];
        for (int line = 0; line < 4; line++)
            __builtin_prefetch(p + 64 * line);
    }
}

/* Closest hit below wide reference `root` (a node or a leaf) for t in (t_min, hit->t). */
static ALWAYS_INLINE void wide_closest(const struct bvh *bvh, uint32_t root, struct wide_ray8 *v,
                                       struct wide_hit *hit, const bool fast)
{
    bool woop_ready = false;
    /* a visit pushes at most 7 entries (and writes 8 lanes) */
    uint32_t stack_ref[WIDE_STACK_SIZE];
    float stack_t[WIDE_STACK_SIZE];
    uint32_t n_stack = 0;
    uint32_t ref = root;
    for (;;) {
        if (!(ref & WIDE_LEAF)) {
            const struct wide_node *node = &v->wide[ref];
            struct f8 t_entry;
            struct m8 hit_m = wide_box_hit(node, v, fast, hit->t, &t_entry);
            uint32_t mask = m8_bits(hit_m);
            prefetch_hit_nodes(v->wide, node, mask);
            if (mask) {
                int c0 = lowest_bit(mask);
                uint32_t rest = mask & (mask - 1);
                if (!rest) { /* one child: no stack */
                    ref = node->child[c0];
                    continue;
                }
                if (!(rest & (rest - 1))) { /* two: one comparison */
                    float dist[8];
                    f8_store(dist, t_entry);
                    int c1 = lowest_bit(rest);
                    /* nearer first, by a select rather than a branch (unpredictable here) */
                    int swap = (c0 ^ c1) & -(int)(dist[c1] < dist[c0]);
                    c0 ^= swap;
                    c1 ^= swap;
                    stack_ref[n_stack] = node->child[c1];
                    stack_t[n_stack++] = dist[c1];
                    ref = node->child[c0];
                    continue;
                }
                assert(n_stack + 8 <= WIDE_STACK_SIZE);
                ref = push_ordered(stack_ref, stack_t, &n_stack, node, v->order_shift, hit_m,
                                   t_entry);
                continue;
            }
        } else {
            if (!woop_ready) {
                wide_ray8_woop(v);
                woop_ready = true;
            }
            uint32_t first = (ref & ~WIDE_LEAF) >> 3;
            uint32_t n = (ref & 7u) + 1;
            struct woop8_out out;
            uint32_t hits = wide_leaf_hit(bvh, first, n, v, hit->t, &out);
            if (hits)
                *hit = leaf_nearest(first, hits, &out);
        }
        /* pop the next pending node that still starts before the closest hit */
        do {
            if (n_stack == 0)
                return;
            n_stack--;
        } while (stack_t[n_stack] > hit->t);
        ref = stack_ref[n_stack];
    }
}

/* Any hit below `root` for t in (t_min, t_max): children in any order, the first hit ends it
 * (nearest-first order measured no faster for shadow rays, docs/bvh.md). */
static ALWAYS_INLINE bool wide_any(const struct bvh *bvh, uint32_t root, struct wide_ray8 *v,
                                   float t_max, const bool fast)
{
    bool woop_ready = false;
    uint32_t stack[WIDE_STACK_SIZE];
    uint32_t n_stack = 0;
    uint32_t ref = root;
    for (;;) {
        if (!(ref & WIDE_LEAF)) {
            const struct wide_node *node = &v->wide[ref];
            struct f8 t_entry;
            struct m8 hit_m = wide_box_hit(node, v, fast, t_max, &t_entry);
            uint32_t mask = m8_bits(hit_m);
            prefetch_hit_nodes(v->wide, node, mask);
            if (mask) {
                ref = node->child[lowest_bit(mask)];
                /* the others in lane order, compressed into one store: a loop over them would
                 * end at a count that incoherent rays make unpredictable */
                uint32_t rest = mask & (mask - 1);
                assert(n_stack + 8 <= WIDE_STACK_SIZE);
                i8_store(stack + n_stack, i8_compress(i8_load(node->child), rest));
                n_stack += (uint32_t)__builtin_popcount(rest);
                continue;
            }
        } else {
            if (!woop_ready) {
                wide_ray8_woop(v);
                woop_ready = true;
            }
            struct woop8_out out;
            if (wide_leaf_hit(bvh, (ref & ~WIDE_LEAF) >> 3, (ref & 7u) + 1, v, t_max, &out))
                return true;
        }
        if (n_stack == 0)
            return false;
        ref = stack[--n_stack];
    }
}

/* The specialised copies, one function each (two copies in one function made gcc stop inlining
 * wide_leaf_hit: 8% more instructions on diffuse rays), and the choice between them by the
 * ray's slab form. */
static void wide_closest_fast(const struct bvh *bvh, uint32_t root, struct wide_ray8 *v,
                              struct wide_hit *hit)
{
    wide_closest(bvh, root, v, hit, true);
}

static void wide_closest_safe(const struct bvh *bvh, uint32_t root, struct wide_ray8 *v,
                              struct wide_hit *hit)
{
    wide_closest(bvh, root, v, hit, false);
}

static bool wide_any_fast(const struct bvh *bvh, uint32_t root, struct wide_ray8 *v, float t_max)
{
    return wide_any(bvh, root, v, t_max, true);
}

static bool wide_any_safe(const struct bvh *bvh, uint32_t root, struct wide_ray8 *v, float t_max)
{
    return wide_any(bvh, root, v, t_max, false);
}

static inline void wide_closest_ray(const struct bvh *bvh, uint32_t root, const struct wide_ray *wr,
                                    uint32_t from, struct wide_hit *hit)
{
    struct wide_ray8 v;
    wide_ray8_box(bvh, wr, &v);
    v.from = from;
    if (wr->fast)
        wide_closest_fast(bvh, root, &v, hit);
    else
        wide_closest_safe(bvh, root, &v, hit);
}

static inline bool wide_any_ray(const struct bvh *bvh, uint32_t root, const struct wide_ray *wr,
                                uint32_t from, float t_max)
{
    struct wide_ray8 v;
    wide_ray8_box(bvh, wr, &v);
    v.from = from;
    return wr->fast ? wide_any_fast(bvh, root, &v, t_max) : wide_any_safe(bvh, root, &v, t_max);
}

/* Most camera rays of a small object miss it altogether: a test against the tree's box lets
 * them return before the traversal's setup.  The general setup is scalar: ray_setup_box, the
 * reference test box_hit, wide_ray_setup; *wr (which keeps a pointer to *rp) is then ready for
 * wide_closest_ray / wide_any_ray.  Rays with finite constants take wide_ray8_fast first. */
static inline bool wide_ray_begin(const struct bvh *bvh, const struct ray *ray, struct ray_pre *rp,
                                  struct wide_ray *wr)
{
    if (bvh->n_wide == 0 || !ray_is_valid(ray))
        return false;
    ray_setup_box(ray, rp);
    float t_entry;
    if (!box_hit(&bvh->bounds, rp, ray->t_min, ray->t_max, &t_entry))
        return false;
    wide_ray_setup(rp, ray->t_min, wr);
    return true;
}

/* The fused path's setup, from the ray straight to struct wide_ray8, on four SSE lanes (x, y, z
 * and lane 3, which carries t_min and t_max): the operations of ray_setup_box and
 * wide_ray_setup lane by lane, so every constant is the same bits as theirs, then the tree's
 * box in the fused form (conservative like wide_box_hit; box_hit is its reference).  About 60
 * instructions against 150 for the scalar chain, which is most of the cost of a ray that
 * misses.  Returns false, leaving the ray to the scalar setup, when some 1/d_a or constant is
 * infinite (the NaN-aware form is needed); otherwise *is_miss says whether the ray misses the
 * tree's box, and if not *v is ready for wide_closest_fast / wide_any_fast. */
#if BVH_FUSED_SLABS
/* The fused constants on four SSE lanes (lane 3 unused), as wide_ray8_fast and stream_ray_setup
 * take them from ray_fast_consts. */
struct fast_consts {
    __m128 o, inv_d, inv_d_far, c_near, c_far;
    int neg; /* bit a: inv_d[a] < 0 */
};

/* What Woop's setup at the first leaf reads. */
static ALWAYS_INLINE void ray_pre_od(const struct ray *ray, struct ray_pre *rp)
{
    rp->o[0] = ray->o.x;
    rp->o[1] = ray->o.y;
    rp->o[2] = ray->o.z;
    rp->d[0] = ray->d.x;
    rp->d[1] = ray->d.y;
    rp->d[2] = ray->d.z;
}

/* wide_ray8_fast's first part: its constants into *fc and the test against the tree's box. */
static ALWAYS_INLINE bool ray_fast_consts(const struct bvh *bvh, const struct ray *ray,
                                          struct fast_consts *fc, bool *is_miss)
{
    const float far_scale = 1.0f + 4.0f * mcpt_gamma(3); /* wide_ray_setup's */
    const __m128 zero = _mm_setzero_ps();
    const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7FFFFFFF));
    /* o.x, o.y, o.z, t_min and d.x, d.y, d.z, t_max, a float at a time: the caller has just
     * written the ray so, and a 16-byte load of those bytes would wait for the stores to reach
     * the cache instead of being forwarded from them (docs/performance.md, "Store forwarding") */
    __m128 o_t = _mm_setr_ps(ray->o.x, ray->o.y, ray->o.z, ray->t_min);
    __m128 d_t = _mm_setr_ps(ray->d.x, ray->d.y, ray->d.z, ray->t_max);
    /* ray_setup_box: inv_d = 1 / d (+-inf for d = +-0), near plane max_a where inv_d_a < 0 */
    __m128 d = _mm_blend_ps(d_t, _mm_set1_ps(1.0f), 8);
    __m128 o = _mm_blend_ps(o_t, zero, 8);
    __m128 inv_d = _mm_div_ps(_mm_set1_ps(1.0f), d);
    __m128 is_neg = _mm_cmplt_ps(inv_d, zero);
    /* wide_ray_setup: c_near = o inv_d + (2^-21 |o inv_d| + FLT_MIN), c_far likewise below */
    __m128 inv_d_far = _mm_mul_ps(inv_d, _mm_set1_ps(far_scale));
    __m128 on = _mm_mul_ps(o, inv_d);
    __m128 of = _mm_mul_ps(o, inv_d_far);
    __m128 bias = _mm_set1_ps(SLAB_BIAS);
    __m128 tiny = _mm_set1_ps(FLT_MIN);
    __m128 c_near = _mm_add_ps(on, _mm_add_ps(_mm_mul_ps(bias, _mm_and_ps(abs_mask, on)), tiny));
    __m128 c_far = _mm_sub_ps(of, _mm_add_ps(_mm_mul_ps(bias, _mm_and_ps(abs_mask, of)), tiny));
    /* the fused form needs every constant finite: |x| <= FLT_MAX is false for inf and NaN */
    __m128 big = _mm_set1_ps(FLT_MAX);
    __m128 finite = _mm_and_ps(_mm_cmple_ps(_mm_and_ps(abs_mask, inv_d_far), big),
                               _mm_and_ps(_mm_cmple_ps(_mm_and_ps(abs_mask, c_near), big),
                                          _mm_cmple_ps(_mm_and_ps(abs_mask, c_far), big)));
    if ((_mm_movemask_ps(finite) & 7) != 7)
        return false;
    /* the tree's box: t_near = near inv_d - c_near, t_far = far inv_d_far - c_far; lane 3 takes
     * t_min and t_max; hit iff max(t_near) <= min(t_far) */
    /* lane 3 of the loads is left_first and n_tris: small integers, subnormal as floats, and a
     * subnormal operand of an FMA costs Intel cores a microcode assist (single camera rays ran
     * 1.9x faster without it, docs/bvh.md, "Subnormal operands"): zeroed before use */
    __m128 lo = _mm_blend_ps(_mm_loadu_ps(bvh->bounds.min), zero, 8);
    __m128 hi = _mm_blend_ps(_mm_loadu_ps(bvh->bounds.max), zero, 8);
    __m128 t_near = _mm_fmsub_ps(_mm_blendv_ps(lo, hi, is_neg), inv_d, c_near);
    __m128 t_far = _mm_fmsub_ps(_mm_blendv_ps(hi, lo, is_neg), inv_d_far, c_far);
    t_near = _mm_blend_ps(t_near, o_t, 8);
    t_far = _mm_blend_ps(t_far, d_t, 8);
    t_near = _mm_max_ps(t_near, _mm_shuffle_ps(t_near, t_near, _MM_SHUFFLE(1, 0, 3, 2)));
    t_near = _mm_max_ps(t_near, _mm_shuffle_ps(t_near, t_near, _MM_SHUFFLE(2, 3, 0, 1)));
    t_far = _mm_min_ps(t_far, _mm_shuffle_ps(t_far, t_far, _MM_SHUFFLE(1, 0, 3, 2)));
    t_far = _mm_min_ps(t_far, _mm_shuffle_ps(t_far, t_far, _MM_SHUFFLE(2, 3, 0, 1)));
    *is_miss = !(_mm_cvtss_f32(t_near) <= _mm_cvtss_f32(t_far));
    *fc = (struct fast_consts){o, inv_d, inv_d_far, c_near, c_far, _mm_movemask_ps(is_neg) & 7};
    return true;
}

static inline bool wide_ray8_fast(const struct bvh *bvh, const struct ray *ray, struct ray_pre *rp,
                                  struct wide_ray8 *v, bool *is_miss)
{
    struct fast_consts fc;
    if (!ray_fast_consts(bvh, ray, &fc, is_miss))
        return false;
    if (*is_miss)
        return true;
    /* wide_ray8_box: one constant per register */
    int neg = fc.neg;
    __m256 o8 = _mm256_castps128_ps256(fc.o);
    __m256 inv_d8 = _mm256_castps128_ps256(fc.inv_d);
    __m256 inv_d_far8 = _mm256_castps128_ps256(fc.inv_d_far);
    __m256 c_near8 = _mm256_castps128_ps256(fc.c_near);
    __m256 c_far8 = _mm256_castps128_ps256(fc.c_far);
    for (int a = 0; a < 3; a++) {
        __m256i lane = _mm256_set1_epi32(a);
        v->o[a].v = _mm256_permutevar8x32_ps(o8, lane);
        v->inv_d[a].v = _mm256_permutevar8x32_ps(inv_d8, lane);
        v->inv_d_far[a].v = _mm256_permutevar8x32_ps(inv_d_far8, lane);
        v->c_near[a].v = _mm256_permutevar8x32_ps(c_near8, lane);
        v->c_far[a].v = _mm256_permutevar8x32_ps(c_far8, lane);
        int is_neg_a = neg >> a & 1;
        v->near_off[a] = (size_t)(2 * a + is_neg_a) * sizeof(float) * BVH_WIDTH;
        v->far_off[a] = (size_t)(2 * a + 1 - is_neg_a) * sizeof(float) * BVH_WIDTH;
    }
    v->t_min = f8_set1(ray->t_min);
    v->rp_t_min = ray->t_min;
    v->order_shift = 3 * neg;
    v->wide = bvh->wide;
    ray_pre_od(ray, rp);
    v->rp = rp;
    v->from = BVH_NO_PRIM;
    return true;
}
#endif

bool bvh_wide_intersect(const struct bvh *bvh, const struct ray *ray, uint32_t from,
                        struct bvh_hit *out)
{
    if (bvh->n_wide == 0)
        return false;
    struct ray_pre rp;
    struct wide_hit hit = {ray->t_max, 0.0f, 0.0f, UINT32_MAX};
#if BVH_FUSED_SLABS
    struct wide_ray8 v;
    bool is_miss;
    if (wide_ray8_fast(bvh, ray, &rp, &v, &is_miss)) {
        if (is_miss)
            return false;
        v.from = from;
        wide_closest_fast(bvh, 0, &v, &hit);
    } else
#endif
    {
        struct wide_ray wr;
        if (!wide_ray_begin(bvh, ray, &rp, &wr))
            return false;
        wide_closest_ray(bvh, 0, &wr, from, &hit);
    }
    if (hit.tri == UINT32_MAX)
        return false;
    *out = (struct bvh_hit){hit.t, hit.u, hit.v, bvh->wide_prim_idx[hit.tri]};
    return true;
}

bool bvh_wide_occluded(const struct bvh *bvh, const struct ray *ray, uint32_t from)
{
    if (bvh->n_wide == 0)
        return false;
    struct ray_pre rp;
#if BVH_FUSED_SLABS
    struct wide_ray8 v;
    bool is_miss;
    if (wide_ray8_fast(bvh, ray, &rp, &v, &is_miss)) {
        v.from = from;
        return !is_miss && wide_any_fast(bvh, 0, &v, ray->t_max);
    }
#endif
    struct wide_ray wr;
    if (!wide_ray_begin(bvh, ray, &rp, &wr))
        return false;
    return wide_any_ray(bvh, 0, &wr, from, ray->t_max);
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
    struct f8 c_near[3]; /* the fused slab constants of wide_ray_setup, per lane */
    struct f8 c_far[3];
    struct m8 is_neg[3];  /* near plane is max */
    struct m8 k_is[3][2]; /* k_is[j][m]: lane's k[j] == m (m = 0, 1; else 2) */
    struct f8 o_k[3];     /* o[k[j]] per lane */
    struct f8 sx;
    struct f8 sy;
    struct f8 sz;
    struct f8 o_scale; /* ray_setup_woop's o_scale, per lane */
    struct f8 t_min;
    bool coherent;   /* every lane: same direction signs, fused constants finite */
    int near_row[3]; /* when coherent: bounds rows of the near and far planes */
    int far_row[3];
    bool uniform_k;  /* every lane has the same (kx, ky, kz) */
    int k[3];        /* when uniform_k */
    struct f8 d[3];  /* directions (inactive lanes: the first active ray's) */
    uint32_t finite; /* lanes whose slab constants are all finite (the fused form applies) */
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
        pp->c_near[a] = f8_add(o_inv,
                               f8_add(f8_mul(f8_set1(SLAB_BIAS), f8_abs(o_inv)), f8_set1(FLT_MIN)));
        pp->c_far[a] = f8_sub(o_inv_far, f8_add(f8_mul(f8_set1(SLAB_BIAS), f8_abs(o_inv_far)),
                                                f8_set1(FLT_MIN)));
        magnitude = f8_add(magnitude, f8_add(f8_add(f8_abs(pp->inv_d[a]), f8_abs(pp->inv_d_far[a])),
                                             f8_add(f8_abs(pp->c_near[a]), f8_abs(pp->c_far[a]))));
        uint32_t neg = m8_bits(pp->is_neg[a]);
        coherent = coherent && (neg == 0 || neg == all);
        pp->near_row[a] = 2 * a + (neg ? 1 : 0);
        pp->far_row[a] = 2 * a + 1 - (neg ? 1 : 0);
    }
    pp->finite = m8_bits(f8_le(magnitude, f8_set1(FLT_MAX)));
    coherent = coherent && pp->finite == all;
    pp->coherent = BVH_FUSED_SLABS && coherent;
    for (int a = 0; a < 3; a++)
        pp->d[a] = d[a];
}

/* Which active lanes hit the tree's box (the slab test of box_hit on each lane, NaN-aware),
 * before Woop's constants are computed: most camera rays of a small object miss it. */
static uint32_t packet_root_hit(const struct bvh *bvh, const struct packet_pre *pp,
                                const float t_max[BVH_PACKET_SIZE])
{
    struct f8 t0 = pp->t_min;
    struct f8 t1 = f8_loadu(t_max);
    for (int a = 0; a < 3; a++) {
        struct f8 lo = f8_set1(bvh->bounds.min[a]);
        struct f8 hi = f8_set1(bvh->bounds.max[a]);
        struct f8 near = f8_select(pp->is_neg[a], hi, lo);
        struct f8 far = f8_select(pp->is_neg[a], lo, hi);
        t0 = f8_max_num(t0, f8_mul(f8_sub(near, pp->o[a]), pp->inv_d[a]));
        t1 = f8_min_num(t1, f8_mul(f8_sub(far, pp->o[a]), pp->inv_d_far[a]));
    }
    return m8_bits(f8_le(t0, t1));
}

/* Woop's constants of every lane (ray_setup_woop's operations, lane by lane), at the packet's
 * first leaf. */
static void packet_setup_woop(struct packet_pre *pp)
{
    const struct f8 zero = f8_set1(0.0f);
    const uint32_t all = (1u << BVH_PACKET_SIZE) - 1u;
    const struct f8 *d = pp->d;
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
    /* ray_setup_woop's o_scale, max |o_a| |sz| */
    pp->o_scale = f8_mul(f8_max_num(f8_max_num(f8_abs(pp->o[0]), f8_abs(pp->o[1])),
                                    f8_abs(pp->o[2])),
                         f8_abs(pp->sz));
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

/* Lane `lane` of a packet as one ray (bvh_packet_set's inverse). */
static struct ray packet_lane(const struct bvh_packet *p, int lane)
{
    return (struct ray){{p->o[0][lane], p->o[1][lane], p->o[2][lane]},
                        p->t_min[lane],
                        {p->d[0][lane], p->d[1][lane], p->d[2][lane]},
                        p->t_max[lane]};
}

/* The single-ray constants of lane `lane`, for the rays that leave the packet (*wr keeps a
 * pointer to *rp). */
static void packet_lane_ray(const struct bvh_packet *p, int lane, struct ray_pre *rp,
                            struct wide_ray *wr)
{
    struct ray r = packet_lane(p, lane);
    ray_setup_box(&r, rp);
    wide_ray_setup(rp, r.t_min, wr);
}

/* A lane leaving the packet, with finite constants: its single-ray constants for
 * wide_closest_fast / wide_any_fast are the packet's lane (packet_setup computed them with
 * wide_ray_setup's operations, so they are the same bits), broadcast, instead of the scalar
 * setup.  false for the other lanes, which take packet_lane_ray. */
static inline bool packet_lane_fast(const struct bvh *bvh, const struct bvh_packet *p,
                                    const struct packet_pre *pp, int lane, struct ray_pre *rp,
                                    struct wide_ray8 *v)
{
    if (!BVH_FUSED_SLABS || !(pp->finite >> lane & 1u))
        return false;
    int neg = 0;
    for (int a = 0; a < 3; a++) {
        v->o[a] = f8_splat_lane(pp->o[a], lane);
        v->inv_d[a] = f8_splat_lane(pp->inv_d[a], lane);
        v->inv_d_far[a] = f8_splat_lane(pp->inv_d_far[a], lane);
        v->c_near[a] = f8_splat_lane(pp->c_near[a], lane);
        v->c_far[a] = f8_splat_lane(pp->c_far[a], lane);
        int is_neg = (int)(m8_bits(pp->is_neg[a]) >> lane & 1u);
        v->near_off[a] = (size_t)(2 * a + is_neg) * sizeof(float) * BVH_WIDTH;
        v->far_off[a] = (size_t)(2 * a + 1 - is_neg) * sizeof(float) * BVH_WIDTH;
        neg |= is_neg << a;
        rp->o[a] = p->o[a][lane];
        rp->d[a] = p->d[a][lane];
    }
    v->t_min = f8_splat_lane(pp->t_min, lane);
    v->rp_t_min = p->t_min[lane];
    v->order_shift = 3 * neg;
    v->wide = bvh->wide;
    v->rp = rp;
    v->from = BVH_NO_PRIM;
    return true;
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

/* woop8 of triangle i of the leaf at `first` (n triangles) against the rays in mask; the lanes
 * it leaves undecided go to bvh_tri_hit_double with their single-ray constants, which equal the
 * packet's to the bit (packet_setup). */
static inline uint32_t packet_tri_hit(const struct bvh *bvh, const struct bvh_packet *packet,
                                      uint32_t first, uint32_t n, uint32_t i,
                                      const struct packet_pre *pp, struct f8 t_max, uint32_t mask,
                                      struct woop8_out *out)
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
    in.o_scale = pp->o_scale;
    in.t_min = pp->t_min;
    in.t_max = t_max;
    uint32_t hits = woop8(&in, mask, out);
    if (out->undecided) {
        struct bvh_tri tri;
        leaf_tri(bvh, first, n, i, &tri);
        float t[8];
        float u[8];
        float v[8];
        float t_hi[8];
        float e[3][8];
        f8_store(t, out->t);
        f8_store(u, out->u);
        f8_store(v, out->v);
        f8_store(t_hi, t_max);
        for (int j = 0; j < 3; j++)
            f8_store(e[j], out->edge[j]);
        for (uint32_t bits = out->undecided; bits; bits &= bits - 1) {
            int lane = lowest_bit(bits);
            struct ray r = packet_lane(packet, lane);
            struct ray_pre rp;
            ray_setup_box(&r, &rp);
            ray_setup_woop(&rp);
            const float edge[3] = {e[0][lane], e[1][lane], e[2][lane]};
            if (bvh_tri_hit_double(&tri, &rp, edge, r.t_min, t_hi[lane], &t[lane], &u[lane],
                                   &v[lane]))
                hits |= 1u << lane;
        }
        out->t = f8_loadu(t);
        out->u = f8_loadu(u);
        out->v = f8_loadu(v);
    }
    return hits;
}

struct packet_entry {
    uint32_t ref;  /* wide reference */
    uint32_t mask; /* rays that hit its box */
    float t_entry; /* smallest entry distance among them */
};                 /* 12 bytes */

/* The closest-hit packet loop; `coherent` selects packet_box_hit's form (a constant at each
 * call, so there are two specialised copies). */
static ALWAYS_INLINE uint32_t packet_closest(const struct bvh *bvh, const struct bvh_packet *packet,
                                             uint32_t active, struct packet_pre *pp, float t_hit[8],
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
    bool woop_ready = false; /* Woop's constants are computed at the first leaf */
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
                struct wide_hit h = {t_hit[lane], u_hit[lane], v_hit[lane], tri_hit_idx[lane]};
                struct wide_ray8 v;
                if (packet_lane_fast(bvh, packet, pp, lane, &rp, &v)) {
                    wide_closest_fast(bvh, cur.ref, &v, &h);
                } else {
                    struct wide_ray wr;
                    packet_lane_ray(packet, lane, &rp, &wr);
                    wide_closest_ray(bvh, cur.ref, &wr, BVH_NO_PRIM, &h);
                }
                t_hit[lane] = h.t;
                u_hit[lane] = h.u;
                v_hit[lane] = h.v;
                tri_hit_idx[lane] = h.tri;
            }
            t_hit8 = f8_loadu(t_hit);
        } else if (!(cur.ref & WIDE_LEAF)) {
            const struct wide_node *node = &bvh->wide[cur.ref];
            const uint32_t base = n_stack;
            for (uint32_t c = 0; c < BVH_WIDTH && node->child[c] != 0; c++) {
                struct f8 t_entry;
                uint32_t mask = packet_box_hit(node, (int)c, pp, t_hit8, &t_entry, coherent) &
                                cur.mask;
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
            if (!woop_ready) {
                packet_setup_woop(pp);
                woop_ready = true;
            }
            uint32_t first = (cur.ref & ~WIDE_LEAF) >> 3;
            uint32_t n = (cur.ref & 7u) + 1;
            for (uint32_t i = 0; i < n; i++) {
                struct woop8_out out;
                uint32_t hits = packet_tri_hit(bvh, packet, first, n, i, pp, t_hit8, cur.mask,
                                               &out);
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

/* The lanes of active whose rays the traversals accept (ray_is_valid). */
static uint32_t packet_valid(const struct bvh_packet *packet, uint32_t active)
{
    uint32_t valid = 0;
    for (uint32_t bits = active & ((1u << BVH_PACKET_SIZE) - 1u); bits; bits &= bits - 1) {
        int lane = lowest_bit(bits);
        struct ray r = packet_lane(packet, lane);
        if (ray_is_valid(&r))
            valid |= 1u << lane;
    }
    return valid;
}

uint32_t bvh_intersect_packet(const struct bvh *bvh, const struct bvh_packet *packet,
                              uint32_t active, struct bvh_packet_hit *hit)
{
    active = packet_valid(packet, active);
    if (!(bvh->layouts & BVH_LAYOUT_WIDE) || bvh->n_wide == 0) {
        uint32_t hits = 0;
        for (uint32_t bits = active; bits; bits &= bits - 1) {
            int lane = lowest_bit(bits);
            struct ray r = packet_lane(packet, lane);
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
    active &= packet_root_hit(bvh, &pp, t_hit);
    if (!active)
        return 0;
    return pp.coherent ? packet_closest(bvh, packet, active, &pp, t_hit, hit, true)
                       : packet_closest(bvh, packet, active, &pp, t_hit, hit, false);
}

/* The any-hit packet loop: children in stored order, a lane leaves the packet when occluded. */
static ALWAYS_INLINE uint32_t packet_any(const struct bvh *bvh, const struct bvh_packet *packet,
                                         uint32_t active, struct packet_pre *pp,
                                         const float t_max[8], const bool coherent)
{
    const struct f8 t_max8 = f8_loadu(t_max);
    bool woop_ready = false; /* Woop's constants are computed at the first leaf */
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
                struct wide_ray8 v;
                bool is_occluded;
                if (packet_lane_fast(bvh, packet, pp, lane, &rp, &v)) {
                    is_occluded = wide_any_fast(bvh, cur.ref, &v, packet->t_max[lane]);
                } else {
                    struct wide_ray wr;
                    packet_lane_ray(packet, lane, &rp, &wr);
                    is_occluded = wide_any_ray(bvh, cur.ref, &wr, BVH_NO_PRIM, packet->t_max[lane]);
                }
                if (is_occluded)
                    occluded |= 1u << lane;
            }
        } else if (!(cur.ref & WIDE_LEAF)) {
            const struct wide_node *node = &bvh->wide[cur.ref];
            for (uint32_t c = 0; c < BVH_WIDTH && node->child[c] != 0; c++) {
                struct f8 t_entry;
                uint32_t mask = packet_box_hit(node, (int)c, pp, t_max8, &t_entry, coherent) &
                                cur.mask;
                if (mask)
                    stack[n_stack++] = (struct packet_entry){node->child[c], mask, 0.0f};
            }
        } else {
            if (!woop_ready) {
                packet_setup_woop(pp);
                woop_ready = true;
            }
            uint32_t first = (cur.ref & ~WIDE_LEAF) >> 3;
            uint32_t n = (cur.ref & 7u) + 1;
            for (uint32_t i = 0; i < n && (cur.mask & ~occluded); i++) {
                struct woop8_out out;
                occluded |= packet_tri_hit(bvh, packet, first, n, i, pp, t_max8,
                                           cur.mask & ~occluded, &out);
            }
        }
        if (occluded == active || n_stack == 0)
            return occluded;
        cur = stack[--n_stack];
    }
}

uint32_t bvh_occluded_packet(const struct bvh *bvh, const struct bvh_packet *packet,
                             uint32_t active)
{
    active = packet_valid(packet, active);
    if (!(bvh->layouts & BVH_LAYOUT_WIDE) || bvh->n_wide == 0) {
        uint32_t occluded = 0;
        for (uint32_t bits = active; bits; bits &= bits - 1) {
            int lane = lowest_bit(bits);
            struct ray r = packet_lane(packet, lane);
            if (bvh_occluded(bvh, &r))
                occluded |= 1u << lane;
        }
        return occluded;
    }
    struct packet_pre pp;
    float t_max[8];
    packet_setup(packet, active, &pp, t_max);
    active &= packet_root_hit(bvh, &pp, t_max);
    if (!active)
        return 0;
    return pp.coherent ? packet_any(bvh, packet, active, &pp, t_max, true)
                       : packet_any(bvh, packet, active, &pp, t_max, false);
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

/* ---- Streams: many rays, one traversal ----------------------------------------------------------
 * A batch of rays, BVH_STREAM_RAYS at a time (ray stream tracing: Tsakok 2009, "Faster Incoherent
 * Rays: Multi-BVH Ray Stream Tracing"; Embree's rtcIntersect1M / rtcOccluded1M).  The stream
 * visits a node once for all of its rays that entered it; there each ray runs the single ray's
 * own slab test on the eight children (wide_box_hit's fused form, its constants broadcast from
 * memory) and adds its bit to the ray mask of every child it hits; a child some ray hit is
 * pushed with that mask.  A leaf is tested by each ray of its mask in turn (wide_leaf_hit, the
 * single ray's test).  What the rays share is the node's loads, the stack and the branches of
 * the traversal, which neighbouring rays (camera rays, shadow rays toward one light) share.
 * Any hit: children in stored order, a ray leaves the stream when occluded; it reports a hit iff
 * some leaf its box tests reach holds one, as bvh_occluded_from.  Closest hit: children nearest
 * first by the smallest entry distance among their rays, each ray's interval shortened by its
 * own hits, and an entry dropped for the rays whose hit lies before it; every triangle a ray
 * meets before its closest hit is in a box it enters, so it gets bvh_intersect_from's t (and
 * triangle, up to exact ties).  Rays without the fused constants (a direction parallel to an
 * axis plane) take the single-ray functions.  docs/bvh.md, "Streams", measures both. */
#if BVH_FUSED_SLABS
/* One ray's fused slab constants (wide_ray8_fast's lane 0), scalars broadcast at each test. */
struct stream_ray {
    float inv_d_far[4]; /* x, y, z and an unused lane: stored from struct fast_consts */
    float inv_d[4];
    float c_near[4];
    float c_far[4];
    float t_min;
    float t_max;
    uint32_t near_off[3]; /* byte offsets of the near and far bounds rows */
    uint32_t far_off[3];
}; /* 96 bytes */

/* (BVH_FUSED_SLABS implies AVX2: the helpers below have no scalar form) */

/* wide_box_hit's fused form for ray *r: bit c set when child c is hit in [t_min, t_max]. */
static ALWAYS_INLINE struct m8 stream_box_hit(const struct wide_node *node,
                                              const struct stream_ray *r, struct f8 *t_entry)
{
    struct f8 t_near[3];
    struct f8 t_far[3];
    const char *base = (const char *)node->bounds;
    for (int j = 0; j < 3; j++) {
        struct f8 near = f8_load((const float *)(base + r->near_off[j]));
        struct f8 far = f8_load((const float *)(base + r->far_off[j]));
        t_near[j] = f8_fmsub(near, f8_set1(r->inv_d[j]), f8_set1(r->c_near[j]));
        t_far[j] = f8_fmsub(far, f8_set1(r->inv_d_far[j]), f8_set1(r->c_far[j]));
    }
    struct f8 t0 = f8_max_num(f8_max_num(f8_set1(r->t_min), t_near[2]),
                              f8_max_num(t_near[1], t_near[0]));
    struct f8 t1 = f8_min_num(f8_min_num(f8_set1(r->t_max), t_far[2]),
                              f8_min_num(t_far[1], t_far[0]));
    *t_entry = t0;
    return f8_le(t0, t1);
}

/* rays |= (hit lanes of m) & bit, lane by lane */
static inline struct i8 i8_or_bit(struct i8 rays, struct m8 m, uint32_t bit)
{
    return (struct i8){_mm256_or_si256(rays.v, _mm256_and_si256(_mm256_castps_si256(m.v),
                                                                _mm256_set1_epi32((int)bit)))};
}

/* bit i set where lane i is not 0 */
static inline uint32_t i8_nonzero(struct i8 a)
{
    __m256i zero = _mm256_cmpeq_epi32(a.v, _mm256_setzero_si256());
    return ~(uint32_t)_mm256_movemask_ps(_mm256_castsi256_ps(zero)) & 0xffu;
}

/* wide_ray8_fast's constants of *ray into *r, unbroadcast (and what Woop's setup reads into
 * *rp); false where the fused form does not apply, else *is_miss says whether the ray misses the
 * tree. */
static inline bool stream_ray_setup(const struct bvh *bvh, const struct ray *ray,
                                    struct ray_pre *rp, struct stream_ray *r, bool *is_miss)
{
    struct fast_consts fc;
    if (!ray_fast_consts(bvh, ray, &fc, is_miss))
        return false;
    if (*is_miss)
        return true;
    _mm_storeu_ps(r->inv_d, fc.inv_d);
    _mm_storeu_ps(r->inv_d_far, fc.inv_d_far);
    _mm_storeu_ps(r->c_near, fc.c_near);
    _mm_storeu_ps(r->c_far, fc.c_far);
    for (int a = 0; a < 3; a++) {
        uint32_t is_neg_a = (uint32_t)fc.neg >> a & 1u;
        r->near_off[a] = (2u * (uint32_t)a + is_neg_a) * sizeof(float) * BVH_WIDTH;
        r->far_off[a] = (2u * (uint32_t)a + 1u - is_neg_a) * sizeof(float) * BVH_WIDTH;
    }
    r->t_min = ray->t_min;
    r->t_max = ray->t_max;
    ray_pre_od(ray, rp);
    rp->kz = 3; /* Woop's constants not yet computed (stream_leaf_hit) */
    return true;
}

/* wide_leaf_hit for stream ray *r against the leaf at wide triangle `first` (n triangles) in
 * [t_min, r->t_max], its Woop constants computed into *rp at its first leaf (ray_setup_woop
 * leaves kz = 3 until then: struct ray_pre is set to that by stream_ray_setup) and broadcast as
 * wide_ray8_woop broadcasts them. */
static ALWAYS_INLINE uint32_t stream_leaf_hit(const struct bvh *bvh, uint32_t first, uint32_t n,
                                              const struct stream_ray *r, struct ray_pre *rp,
                                              uint32_t from, struct woop8_out *out)
{
    if (rp->kz == 3)
        ray_setup_woop(rp);
    struct wide_ray8 v;
    v.k[0] = rp->kx;
    v.k[1] = rp->ky;
    v.k[2] = rp->kz;
    for (int j = 0; j < 3; j++)
        v.o_k[j] = f8_set1(rp->o[v.k[j]]);
    v.sx = f8_set1(rp->sx);
    v.sy = f8_set1(rp->sy);
    v.sz = f8_set1(rp->sz);
    v.o_scale = f8_set1(rp->o_scale);
    v.t_min = f8_set1(r->t_min);
    v.rp_t_min = r->t_min;
    v.rp = rp;
    v.from = from;
    return wide_leaf_hit(bvh, first, n, &v, r->t_max, out);
}

struct stream_entry {
    uint32_t ref;  /* wide reference */
    uint32_t rays; /* the stream's rays that hit its box */
};

/* Any hit of rays[0 .. n) (n <= BVH_STREAM_RAYS), each leaving triangle from[i] (from may be
 * NULL): occluded[i]. */
static void stream_any(const struct bvh *bvh, const struct ray *rays, const uint32_t *from,
                       uint32_t n, bool *occluded)
{
    struct stream_ray sr[BVH_STREAM_RAYS];
    struct ray_pre rp[BVH_STREAM_RAYS];
    uint32_t active = 0;
    for (uint32_t i = 0; i < n; i++) {
        bool is_miss;
        occluded[i] = false;
        if (!stream_ray_setup(bvh, &rays[i], &rp[i], &sr[i], &is_miss))
            occluded[i] = bvh_wide_occluded(bvh, &rays[i], from ? from[i] : BVH_NO_PRIM);
        else if (!is_miss)
            active |= 1u << i;
    }
    uint32_t done = 0; /* rays found occluded */
    struct stream_entry stack[WIDE_STACK_SIZE];
    uint32_t n_stack = 0;
    struct stream_entry cur = {0, active};
    for (;;) {
        cur.rays &= ~done;
        if (cur.rays && !(cur.ref & WIDE_LEAF)) {
            const struct wide_node *node = &bvh->wide[cur.ref];
            struct i8 child_rays = {_mm256_setzero_si256()};
            for (uint32_t bits = cur.rays; bits; bits &= bits - 1) {
                int i = lowest_bit(bits);
                struct f8 t_entry;
                child_rays = i8_or_bit(child_rays, stream_box_hit(node, &sr[i], &t_entry), 1u << i);
            }
            uint32_t hit = i8_nonzero(child_rays);
            prefetch_hit_nodes(bvh->wide, node, hit);
            if (hit) {
                uint32_t child_mask[8];
                i8_store(child_mask, child_rays);
                int c0 = lowest_bit(hit);
                assert(n_stack + 8 <= WIDE_STACK_SIZE);
                for (hit &= hit - 1; hit; hit &= hit - 1) {
                    int c = lowest_bit(hit);
                    stack[n_stack++] = (struct stream_entry){node->child[c], child_mask[c]};
                }
                cur = (struct stream_entry){node->child[c0], child_mask[c0]};
                continue;
            }
        } else if (cur.rays) {
            uint32_t first = (cur.ref & ~WIDE_LEAF) >> 3;
            uint32_t n_tris = (cur.ref & 7u) + 1;
            for (uint32_t bits = cur.rays; bits; bits &= bits - 1) {
                int i = lowest_bit(bits);
                struct woop8_out out;
                if (stream_leaf_hit(bvh, first, n_tris, &sr[i], &rp[i],
                                    from ? from[i] : BVH_NO_PRIM, &out)) {
                    done |= 1u << i;
                    occluded[i] = true;
                }
            }
            if (done == active)
                return;
        }
        if (n_stack == 0)
            return;
        cur = stack[--n_stack];
    }
}

struct stream_centry {
    uint32_t ref;  /* wide reference */
    uint32_t rays; /* the stream's rays that hit its box */
    float dist;    /* the smallest entry distance among them */
};

/* Closest hit of rays[0 .. n) (n <= BVH_STREAM_RAYS), each leaving triangle from[i] (from may be
 * NULL): is_hit[i], and out[i] where it hit. */
static void stream_closest(const struct bvh *bvh, const struct ray *rays, const uint32_t *from,
                           uint32_t n, struct bvh_hit *out, bool *is_hit)
{
    struct stream_ray sr[BVH_STREAM_RAYS];
    struct ray_pre rp[BVH_STREAM_RAYS];
    struct wide_hit h[BVH_STREAM_RAYS];
    uint32_t active = 0;
    uint32_t single = 0;
    for (uint32_t i = 0; i < n; i++) {
        bool is_miss;
        h[i] = (struct wide_hit){rays[i].t_max, 0.0f, 0.0f, UINT32_MAX};
        if (!stream_ray_setup(bvh, &rays[i], &rp[i], &sr[i], &is_miss)) {
            is_hit[i] = bvh_wide_intersect(bvh, &rays[i], from ? from[i] : BVH_NO_PRIM, &out[i]);
            single |= 1u << i;
        } else if (!is_miss) {
            active |= 1u << i;
        }
    }
    struct stream_centry stack[WIDE_STACK_SIZE];
    uint32_t n_stack = 0;
    struct stream_centry cur = {0, active, -INFINITY};
    while (cur.rays) {
        if (!(cur.ref & WIDE_LEAF)) {
            const struct wide_node *node = &bvh->wide[cur.ref];
            struct i8 child_rays = {_mm256_setzero_si256()};
            struct f8 dist = f8_set1(INFINITY);
            for (uint32_t bits = cur.rays; bits; bits &= bits - 1) {
                int i = lowest_bit(bits);
                struct f8 t_entry;
                struct m8 m = stream_box_hit(node, &sr[i], &t_entry);
                child_rays = i8_or_bit(child_rays, m, 1u << i);
                dist = f8_min_num(dist, f8_select(m, t_entry, f8_set1(INFINITY)));
            }
            uint32_t hit = i8_nonzero(child_rays);
            prefetch_hit_nodes(bvh->wide, node, hit);
            if (hit) {
                uint32_t child_mask[8];
                float d[8];
                i8_store(child_mask, child_rays);
                f8_store(d, dist);
                /* farthest first onto the stack, the nearest taken now */
                uint32_t base = n_stack;
                for (; hit; hit &= hit - 1) {
                    int c = lowest_bit(hit);
                    struct stream_centry e = {node->child[c], child_mask[c], d[c]};
                    uint32_t k = n_stack++;
                    while (k > base && stack[k - 1].dist < e.dist) {
                        stack[k] = stack[k - 1];
                        k--;
                    }
                    stack[k] = e;
                }
                cur = stack[--n_stack];
                continue;
            }
        } else {
            uint32_t first = (cur.ref & ~WIDE_LEAF) >> 3;
            uint32_t n_tris = (cur.ref & 7u) + 1;
            for (uint32_t bits = cur.rays; bits; bits &= bits - 1) {
                int i = lowest_bit(bits);
                struct woop8_out out;
                uint32_t hits = stream_leaf_hit(bvh, first, n_tris, &sr[i], &rp[i],
                                                from ? from[i] : BVH_NO_PRIM, &out);
                if (hits) {
                    h[i] = leaf_nearest(first, hits, &out);
                    sr[i].t_max = h[i].t;
                }
            }
        }
        /* the next entry some of whose rays may still need it */
        for (;;) {
            if (n_stack == 0) {
                cur.rays = 0;
                break;
            }
            cur = stack[--n_stack];
            uint32_t keep = 0;
            for (uint32_t bits = cur.rays; bits; bits &= bits - 1) {
                int i = lowest_bit(bits);
                if (!(cur.dist > sr[i].t_max))
                    keep |= 1u << i;
            }
            cur.rays = keep;
            if (keep)
                break;
        }
    }
    for (uint32_t i = 0; i < n; i++) {
        if (single >> i & 1u)
            continue;
        is_hit[i] = h[i].tri != UINT32_MAX;
        if (is_hit[i])
            out[i] = (struct bvh_hit){h[i].t, h[i].u, h[i].v, bvh->wide_prim_idx[h[i].tri]};
    }
}
#endif

void bvh_wide_intersect_stream(const struct bvh *bvh, const struct ray *rays, const uint32_t *from,
                               size_t n, struct bvh_hit *out, bool *is_hit)
{
    for (size_t i = 0; i < n; i += BVH_STREAM_RAYS) {
        uint32_t k = n - i < BVH_STREAM_RAYS ? (uint32_t)(n - i) : BVH_STREAM_RAYS;
#if BVH_FUSED_SLABS
        if (bvh->n_wide > 0) {
            stream_closest(bvh, rays + i, from ? from + i : NULL, k, out + i, is_hit + i);
            continue;
        }
#endif
        for (uint32_t j = 0; j < k; j++)
            is_hit[i + j] = bvh_wide_intersect(bvh, &rays[i + j], from ? from[i + j] : BVH_NO_PRIM,
                                               &out[i + j]);
    }
}

void bvh_wide_occluded_stream(const struct bvh *bvh, const struct ray *rays, const uint32_t *from,
                              size_t n, bool *occluded)
{
    for (size_t i = 0; i < n; i += BVH_STREAM_RAYS) {
        uint32_t k = n - i < BVH_STREAM_RAYS ? (uint32_t)(n - i) : BVH_STREAM_RAYS;
#if BVH_FUSED_SLABS
        if (bvh->n_wide > 0) {
            stream_any(bvh, rays + i, from ? from + i : NULL, k, occluded + i);
            continue;
        }
#endif
        for (uint32_t j = 0; j < k; j++)
            occluded[i + j] = bvh_wide_occluded(bvh, &rays[i + j],
                                                from ? from[i + j] : BVH_NO_PRIM);
    }
}

/* ---- Brute force over the wide leaves ---------------------------------------------------------
 * bvh_intersect_brute (bvh.c) for a BVH without the binary layout: every leaf, depth first in
 * stored order (the order of the wide triangles, which is the binary order without the
 * degenerate triangles), each triangle unpacked from SoA and tested by bvh_brute_step, the
 * scalar reference test. */
void bvh_wide_brute(const struct bvh *bvh, const struct ray_pre *rp, float t_min, uint32_t from,
                    struct bvh_hit *best)
{
    uint32_t stack[WIDE_STACK_SIZE];
    uint32_t n_stack = 0;
    stack[n_stack++] = 0;
    while (n_stack > 0) {
        uint32_t ref = stack[--n_stack];
        if (!(ref & WIDE_LEAF)) {
            const struct wide_node *node = &bvh->wide[ref];
            for (uint32_t c = wide_n_children(node); c-- > 0;)
                stack[n_stack++] = node->child[c];
            continue;
        }
        uint32_t first = (ref & ~WIDE_LEAF) >> 3;
        uint32_t n = (ref & 7u) + 1;
        for (uint32_t i = 0; i < n; i++) {
            struct bvh_tri tri;
            if (bvh->wide_prim_idx[first + i] == from)
                continue;
            leaf_tri(bvh, first, n, i, &tri);
            bvh_brute_step(&tri, bvh->wide_prim_idx[first + i], rp, t_min, best);
        }
    }
}

uint64_t bvh_wide_hash(const struct bvh *bvh, uint64_t h)
{
    if (!bvh->wide)
        return h;
    h = bvh_hash_bytes(h, bvh->wide, sizeof *bvh->wide * bvh->n_wide);
    /* the leaf rows without the 8 floats of padding after them */
    h = bvh_hash_bytes(h, bvh->leaf_tris, 9 * sizeof *bvh->leaf_tris * bvh->n_wide_tris);
    h = bvh_hash_bytes(h, bvh->wide_prim_idx, sizeof *bvh->wide_prim_idx * bvh->n_wide_tris);
    return bvh_hash_bytes(h, &bvh->bounds, sizeof bvh->bounds);
}
