/* sample.h - random numbers, samplers, warps with their pdfs, and MIS weights.
 * RNG: PCG32 (O'Neill 2014).  Every sample value is a function of (seed, pixel, sample index,
 * dimension) alone, never of thread state, so images are identical for any thread count.
 * Dimension order of one camera sample (SAMPLE_DIM_*): pixel 2D, lens 2D, then per bounce:
 * light choice 1D, light position 2D, BSDF lobe 1D, BSDF direction 2D, roulette 1D.
 * Samplers: independent, stratified (Kensler 2013), Owen-scrambled Sobol' (Burley 2020). */
#ifndef MCPT_SAMPLE_H
#define MCPT_SAMPLE_H

#include "vec.h"

/* PCG32, O'Neill 2014, "PCG: A Family of Simple Fast Space-Efficient Statistically Good
 * Algorithms for Random Number Generation", pcg32 (XSH RR 64/32). */
struct pcg32 {
    uint64_t state;
    uint64_t inc; /* stream selector, always odd */
};

/* pcg32_srandom_r(initstate, initseq) of the reference implementation. */
void sample_pcg32_seed(struct pcg32 *rng, uint64_t initstate, uint64_t initseq);
uint32_t sample_pcg32_next(struct pcg32 *rng);
/* Uniform float in [0, 1): the top 24 bits of one output. */
float sample_pcg32_float(struct pcg32 *rng);
/* Uniform integer in [0, bound) without modulo bias (O'Neill's pcg32_boundedrand_r). */
uint32_t sample_pcg32_bounded(struct pcg32 *rng, uint32_t bound);
/* Jumps the stream ahead by delta steps in O(log delta) (Brown 1994, "Random number
 * generation with arbitrary strides"). */
void sample_pcg32_advance(struct pcg32 *rng, uint64_t delta);

/* Samplers: how the uniforms of a pixel's samples are spread over [0,1)^dims.  See
 * docs/sampling.md for their convergence on real scenes. */
enum sampler_kind {
    SAMPLER_INDEPENDENT, /* every dimension an independent uniform (PCG32) */
    SAMPLER_STRATIFIED,  /* correlated multi-jittered strata over the pixel's spp (Kensler 2013),
                            dimensions decorrelated by per-pixel hashed permutations */
    SAMPLER_SOBOL,       /* Owen-scrambled Sobol' with a per-pixel shuffled index (Burley 2020):
                            joint over the first SAMPLE_SOBOL_JOINT_DIMS dimensions, the first
                            bounces' BSDF directions from a second point, padded beyond by
                            independently scrambled 2D (0,2)-sequences */
};
#define SAMPLER_COUNT 3
/* The sampler of a scene and command line that name none: the best of the three in the
 * measurements of docs/sampling.md. */
#define SAMPLER_DEFAULT SAMPLER_SOBOL

/* "independent", "stratified", "sobol"; "?" for a value outside the enum. */
const char *sample_sampler_name(enum sampler_kind kind);
/* Sets *kind to the sampler called name; false (kind untouched) when there is none. */
bool sample_sampler_parse(const char *name, enum sampler_kind *kind);

/* Dimension layout of one camera sample. */
enum {
    SAMPLE_DIM_PIXEL = 0,      /* 2D: position inside the pixel */
    SAMPLE_DIM_LENS = 2,       /* 2D: point on the lens */
    SAMPLE_DIM_BOUNCE0 = 4,    /* first dimension of bounce 0 */
    SAMPLE_DIMS_PER_BOUNCE = 7 /* light choice 1, light position 2, lobe 1, direction 2, RR 1 */
};
enum {
    SAMPLE_BOUNCE_LIGHT_CHOICE = 0,
    SAMPLE_BOUNCE_LIGHT_POS = 1,
    SAMPLE_BOUNCE_BSDF_LOBE = 3,
    SAMPLE_BOUNCE_BSDF_DIR = 4,
    SAMPLE_BOUNCE_ROULETTE = 6,
};
/* Extra light samples (trace.c, --light-samples N > 1).  Light sample 0 of bounce k uses the
 * bounce block above; light samples j = 1 .. N-1 of bounce k read their light choice (1D) and
 * light position (2D) from a block past every bounce block (4 + 7 * 1025 < 8192, the depth cap
 * being 1024 bounces):
 *   dim = SAMPLE_DIM_LIGHT_EXTRA + SAMPLE_DIMS_PER_LIGHT * (k * (N - 1) + j - 1) + {0, 1..2}.
 * trace.c reads them through a copy of the path's sampler moved there with sample_set_dim, in
 * increasing order (k, then j), so a sampler only needs random access to dimensions; note for
 * the samplers (issue 5): these dimensions are reached without visiting the ones in between. */
enum {
    SAMPLE_DIM_LIGHT_EXTRA = 8192, /* first dimension of the extra light samples */
    SAMPLE_DIMS_PER_LIGHT = 3      /* light choice 1, light position 2 */
};

/* Dimensions the Sobol' sampler draws from one Sobol' point: pixel, lens and the first
 * bounce's light sample (choice and position: the direct light at the first hit, whose shadow
 * edges couple it with the pixel position), 7 dimensions; every later 1D or 2D request (the
 * first bounce's BSDF sample on) is a separately shuffled and scrambled (0,2)-sequence, but for
 * the BSDF directions of the path point below.
 * docs/sampling.md measures this against the whole first bounce joint (11) and pixel and lens
 * only (4, Burley 2020's choice); -DSAMPLE_SOBOL_JOINT_DIMS=N builds the others. */
#ifndef SAMPLE_SOBOL_JOINT_DIMS
#define SAMPLE_SOBOL_JOINT_DIMS (SAMPLE_DIM_BOUNCE0 + SAMPLE_BOUNCE_BSDF_LOBE)
#endif
#define SAMPLE_SOBOL_MAX_DIMS 16 /* dimensions in the generator-matrix table */
/* The BSDF directions of the first SAMPLE_SOBOL_PATH_DIRS bounces (those the first padding fill
 * holds) that are padded come from a second Sobol' point, shuffled and scrambled apart from the
 * joint one (sample.c, PATH_DIMS: a pair of its dimensions each).  A path's successive directions
 * are then stratified together instead of paired at random (docs/sampling.md; the Cornell box's
 * off-lamp MSE at 256 spp falls 13%, docs/performance.md, "QMC dimension allocation").  0
 * pads them like every other request. */
#ifndef SAMPLE_SOBOL_PATH_DIRS
#define SAMPLE_SOBOL_PATH_DIRS 3
#endif
/* Lanes of the joint point's loops (sample.c): the joint dimensions rounded up to a vector of 8
 * or 16 (the lanes past the joint dimensions are computed and never read). */
#define SAMPLE_SOBOL_JOINT_LANES (SAMPLE_SOBOL_JOINT_DIMS <= 8 ? 8 : SAMPLE_SOBOL_MAX_DIMS)

/* The unscrambled Sobol' point of index in dimension dim < SAMPLE_SOBOL_MAX_DIMS, as a 32-bit
 * fraction (value / 2^32); direction numbers of Joe & Kuo 2008 (sobol_matrices.h). */
uint32_t sample_sobol_u32(uint32_t index, uint32_t dim);

/* Sobol' padding is computed a fill at a time (sample.c, pad_block): from the start of a bounce
 * block, the requests of SAMPLE_PAD_BLOCKS blocks, a lane per request.  A block's requests start
 * at its offsets SAMPLE_BOUNCE_* (SAMPLE_BLOCK_REQUESTS); the two others are the second
 * coordinates of the 2D requests before them, read with them. */
enum {
    SAMPLE_PAD_LANES = 8,           /* lanes of one vector of the computation */
    SAMPLE_PAD_HELD = 16,           /* lanes of one fill: two vectors */
    SAMPLE_PAD_BLOCKS = 3,          /* bounce blocks one fill covers: 15 of its lanes */
    SAMPLE_REQUESTS_PER_BOUNCE = 5, /* requests of a bounce block */
    SAMPLE_PAD_KEPT = 4,            /* the fills from the first padded blocks, whose seeds are
                                        hashed once per pixel */
    SAMPLE_PAD_SPAN = SAMPLE_PAD_BLOCKS * SAMPLE_DIMS_PER_BOUNCE, /* dimensions a fill covers */
    SAMPLE_PAD_SPAN_STORED = 3 * SAMPLE_PAD_LANES                 /* the span in whole vectors */
};
enum {
    SAMPLE_BLOCK_REQUESTS = 1 << SAMPLE_BOUNCE_LIGHT_CHOICE | 1 << SAMPLE_BOUNCE_LIGHT_POS |
                            1 << SAMPLE_BOUNCE_BSDF_LOBE | 1 << SAMPLE_BOUNCE_BSDF_DIR |
                            1 << SAMPLE_BOUNCE_ROULETTE,
    /* bit k: dimension pad_dim0 + k is a request a fill holds */
    SAMPLE_PAD_REQUEST_MASK = SAMPLE_BLOCK_REQUESTS |
                              SAMPLE_BLOCK_REQUESTS << SAMPLE_DIMS_PER_BOUNCE |
                              SAMPLE_BLOCK_REQUESTS << 2 * SAMPLE_DIMS_PER_BOUNCE
};
/* The requests whose seeds the first SAMPLE_PAD_KEPT fills read (from the first one's start). */
enum {
    SAMPLE_PAD_KEPT_REQUESTS = (SAMPLE_PAD_KEPT - 1) * SAMPLE_REQUESTS_PER_BOUNCE + SAMPLE_PAD_HELD
};
_Static_assert(__builtin_popcount(SAMPLE_BLOCK_REQUESTS) == SAMPLE_REQUESTS_PER_BOUNCE &&
                   SAMPLE_BLOCK_REQUESTS >> SAMPLE_DIMS_PER_BOUNCE == 0 &&
                   (int)SAMPLE_PAD_BLOCKS == 3 &&
                   (int)SAMPLE_PAD_SPAN <= (int)SAMPLE_PAD_SPAN_STORED &&
                   (int)SAMPLE_PAD_BLOCKS * (int)SAMPLE_REQUESTS_PER_BOUNCE <=
                       (int)SAMPLE_PAD_HELD &&
                   (int)SAMPLE_PAD_HELD == 2 * (int)SAMPLE_PAD_LANES,
               "a fill is three bounce blocks' requests in two vectors");
/* pad_dim0 when nothing is held: dim - SAMPLE_PAD_NONE is past the span for any dimension in
 * use (all are below 2^28). */
#define SAMPLE_PAD_NONE 0xf0000000u

/* The sample generator for one (pixel, sample index), read dimension by dimension.
 * Independent: a PCG32 stream seeded by hashing (seed, pixel_idx, sample_idx).  Stratified and
 * Sobol': stateless hashes of (seed, pixel_idx, sample_idx, dim, set_spp).  What the samples of
 * one pixel share (the hashes of the pixel's seeds) is computed once by sample_start_pixel; each
 * sample then starts with sample_start_index, which for Sobol' also computes the whole joint
 * point and the path point at once (a lane per dimension) and the first padding fill (the first
 * three bounces' requests, their BSDF directions from the path point), so that reading those
 * dimensions is a load.  A sampler holds no pointer: copying one copies the sample. */
struct sampler {
    enum sampler_kind kind;
    uint64_t seed;
    uint32_t pixel_idx;
    uint32_t sample_idx;
    uint32_t dim; /* next dimension to be returned */
    struct pcg32 rng;
    uint32_t set_spp;    /* stratified: samples per stratified set (0 or 1: none) */
    uint32_t cmj_cols;   /* stratified: columns m of the m x n multi-jittered grid */
    uint64_t pixel_hash; /* hash of (seed, pixel_idx): root of every scrambling seed */
    /* Sobol', per pixel */
    uint32_t shuffle_seed;                         /* seed of the joint point's index shuffle */
    uint32_t joint_seed[SAMPLE_SOBOL_JOINT_LANES]; /* scramble seed of each joint dimension */
    /* the path point's index shuffle and the scramble seed of each of its dimensions */
    uint32_t path_shuffle_seed;
    uint32_t path_seed[SAMPLE_PAD_LANES];
    /* the seeds of the padding requests from the first padded block's start, request k at a
     * time (sample.c, pad_request_dim): the shuffle of the sample index, the scrambles of the
     * first and the second coordinate */
    uint32_t pad_seed_index[SAMPLE_PAD_KEPT_REQUESTS];
    uint32_t pad_seed_x[SAMPLE_PAD_KEPT_REQUESTS];
    uint32_t pad_seed_y[SAMPLE_PAD_KEPT_REQUESTS];
    /* Sobol', per sample */
    uint32_t sample_idx_rev;                 /* sample_idx bit-reversed: the padding's input */
    float joint_u[SAMPLE_SOBOL_JOINT_LANES]; /* the joint point, a value per dimension */
    float path_u[SAMPLE_PAD_LANES];          /* the path point, likewise */
    uint32_t pad_dim0;                       /* first dimension held, or SAMPLE_PAD_NONE */
    float pad_x[SAMPLE_PAD_SPAN_STORED];     /* the padding request at pad_dim0 + k, where */
    float pad_y[SAMPLE_PAD_SPAN_STORED];     /* sample_pad_holds: x, and y of a 2D request */
};                                           /* 776 bytes */

/* Starts the sample sample_idx of pixel pixel_idx at dimension 0, with set_spp = 0: the
 * stratified sampler then has no strata to fill and gives independent hashed uniforms. */
void sample_start(struct sampler *s, enum sampler_kind kind, uint64_t seed, uint32_t pixel_idx,
                  uint32_t sample_idx);
/* As sample_start, for a pixel whose samples come in stratified sets of set_spp (normally its
 * spp): sample indices k set_spp .. (k+1) set_spp - 1 form set k, whose points fill every
 * stratum once.  Only SAMPLER_STRATIFIED uses set_spp; Sobol' is stratified at every
 * power-of-two prefix without it.  The same as sample_start_pixel then sample_start_index. */
void sample_start_spp(struct sampler *s, enum sampler_kind kind, uint64_t seed, uint32_t pixel_idx,
                      uint32_t sample_idx, uint32_t set_spp);
/* The two halves of sample_start_spp, for a caller that takes many samples of one pixel:
 * sample_start_pixel computes what they share, then each sample_start_index(s, sample_idx)
 * starts one of them at dimension 0 (any order of indices; the values are those of
 * sample_start_spp with the same arguments). */
void sample_start_pixel(struct sampler *s, enum sampler_kind kind, uint64_t seed,
                        uint32_t pixel_idx, uint32_t set_spp);
void sample_start_index(struct sampler *s, uint32_t sample_idx);
/* Moves to dimension dim (>= the current one), skipping the values in between. */
void sample_set_dim(struct sampler *s, uint32_t dim);
/* The out-of-line parts of sample_1d and sample_2d: the value(s) at dimension dim, which the
 * caller has just passed (s->dim is already past them), for everything but the Sobol' values
 * the sampler holds. */
float sample_1d_compute(struct sampler *s, uint32_t dim);
vec2 sample_2d_compute(struct sampler *s, uint32_t dim);
/* The Sobol' sampler's request at dimension dim >= SAMPLE_SOBOL_JOINT_DIMS of its current sample
 * (a padded one, or a BSDF direction of the path point), computed alone (sample.c, "Padding"):
 * what sample_2d (and, for x, sample_1d) return there, however the sampler computed them. */
vec2 sample_sobol_request(const struct sampler *s, uint32_t dim);

/* Whether dimension dim is a request the Sobol' sampler holds from its last fill. */
static inline bool sample_pad_holds(const struct sampler *s, uint32_t dim)
{
    uint32_t k = dim - s->pad_dim0;
    return k < SAMPLE_PAD_SPAN && (SAMPLE_PAD_REQUEST_MASK >> k & 1u);
}

/* The value of the next dimension, in [0, 1).  Inline because a path reads a dozen or more per
 * sample: Sobol' values the sampler holds (the joint point, the current padded block) are one
 * load. */
static inline float sample_1d(struct sampler *s)
{
    uint32_t dim = s->dim++;
    if (s->kind == SAMPLER_SOBOL) {
        if (dim < SAMPLE_SOBOL_JOINT_DIMS)
            return s->joint_u[dim];
        if (sample_pad_holds(s, dim))
            return s->pad_x[dim - s->pad_dim0];
    }
    return sample_1d_compute(s, dim);
}

/* The next two dimensions as one 2D point in [0, 1)^2: stratified and Sobol' stratify the pair
 * jointly (in 2D), which two sample_1d calls would not. */
static inline vec2 sample_2d(struct sampler *s)
{
    uint32_t dim = s->dim;
    s->dim += 2;
    if (s->kind == SAMPLER_SOBOL) {
        if (dim + 1 < SAMPLE_SOBOL_JOINT_DIMS)
            return (vec2){s->joint_u[dim], s->joint_u[dim + 1]};
        if (dim >= SAMPLE_SOBOL_JOINT_DIMS && sample_pad_holds(s, dim))
            return (vec2){s->pad_x[dim - s->pad_dim0], s->pad_y[dim - s->pad_dim0]};
    }
    return sample_2d_compute(s, dim);
}

/* sample_1d_ahead and sample_2d_ahead's out-of-line part. */
vec2 sample_ahead_compute(struct sampler *s, uint32_t dim, bool is_2d);

/* The value(s) that sample_1d / sample_2d will return at dimension dim >= the current one,
 * read ahead: the current dimension does not move, so the reads before dim give what they
 * would have.  A path reads its BSDF sample this way before its light sample, whose dimensions
 * come first, so that the core overlaps the two (trace.c).  The independent sampler jumps a copy
 * of its stream ahead (sample_pcg32_advance); the others compute any dimension directly. */
static inline float sample_1d_ahead(struct sampler *s, uint32_t dim)
{
    if (s->kind == SAMPLER_SOBOL && dim >= SAMPLE_SOBOL_JOINT_DIMS && sample_pad_holds(s, dim))
        return s->pad_x[dim - s->pad_dim0];
    return sample_ahead_compute(s, dim, false).x;
}

static inline vec2 sample_2d_ahead(struct sampler *s, uint32_t dim)
{
    if (s->kind == SAMPLER_SOBOL && dim >= SAMPLE_SOBOL_JOINT_DIMS && sample_pad_holds(s, dim))
        return (vec2){s->pad_x[dim - s->pad_dim0], s->pad_y[dim - s->pad_dim0]};
    return sample_ahead_compute(s, dim, true);
}

/* 64-bit mixing hash (SplitMix64 finaliser, Steele et al. 2014). */
uint64_t sample_hash64(uint64_t x);

/* ---- warps: each takes uniforms u in [0,1)^2; its pdf sits beside it, and its inverse
 * (sample_invert_*: the u that maps to a given point) where one exists ---- */

/* Concentric disk, Shirley & Chiu 1997, "A Low Distortion Map Between Disk and Square";
 * pdf = 1 / pi per unit area. */
vec2 sample_concentric_disk(vec2 u);
vec2 sample_invert_concentric_disk(vec2 p);
/* Cosine-weighted hemisphere about +z (Malley's method: disk lifted to the hemisphere). */
vec3 sample_cosine_hemisphere(vec2 u);
float pdf_cosine_hemisphere(float cos_theta); /* cos_theta / pi, per steradian */
vec2 sample_invert_cosine_hemisphere(vec3 w);
/* Uniform hemisphere about +z. */
vec3 sample_uniform_hemisphere(vec2 u);
float pdf_uniform_hemisphere(void); /* 1 / (2 pi), per steradian */
vec2 sample_invert_uniform_hemisphere(vec3 w);
/* Uniform sphere. */
vec3 sample_uniform_sphere(vec2 u);
float pdf_uniform_sphere(void); /* 1 / (4 pi), per steradian */
vec2 sample_invert_uniform_sphere(vec3 w);
/* A cone of directions about +z with half-angle theta_max.  For a narrow cone 1 - cos theta_max
 * cancels in float, so a cone made from sin^2 theta_max below sin^2(1.5 deg) uses the Taylor
 * expansions 1 - cos theta_max = sin^2 theta_max / 2 and sin^2 theta = u0 sin^2 theta_max, as
 * PBRT 4e samples spheres (ch. 6, "Spheres"). */
struct sample_cone {
    float cos_theta_max;     /* cos theta_max, in [-1, 1) */
    float sin2_theta_max;    /* sin^2 theta_max */
    float one_minus_cos_max; /* 1 - cos theta_max; sin^2 theta_max / 2 for a narrow cone */
    bool is_narrow;          /* made from sin^2 theta_max < sin^2(1.5 deg): Taylor expansions */
};                           /* 16 bytes */
/* The cone of any half-angle, from cos_theta_max in [-1, 1). */
struct sample_cone sample_cone_from_cos(float cos_theta_max);
/* The cone of half-angle theta_max <= 90 deg from sin2_theta_max in (0, 1]: seen from a point at
 * distance d > r, a sphere of radius r fills the cone with sin^2 theta_max = r^2 / d^2. */
struct sample_cone sample_cone_from_sin2(float sin2_theta_max);
/* Uniform directions in the cone: cos theta uniform in [cos theta_max, 1] (solid angle is
 * linear in cos theta), phi = 2 pi u1; PBRT 4e, ch. A.5, "Sampling Multidimensional Functions".
 * sample_uniform_cone_theta is its polar part alone: cos theta and sin^2 theta from u0, for the
 * sphere sampler (shape.c), which turns theta into a point on the sphere. */
void sample_uniform_cone_theta(float u0, const struct sample_cone *cone, float *cos_theta,
                               float *sin2_theta);
vec3 sample_uniform_cone(vec2 u, const struct sample_cone *cone);
float pdf_uniform_cone(const struct sample_cone *cone); /* 1 / (2 pi (1 - cos theta_max)), per sr */
vec2 sample_invert_uniform_cone(vec3 w, const struct sample_cone *cone);
/* Uniform barycentrics (b0, b1) on a triangle by the square-root warp b0 = 1 - sqrt(u0),
 * b1 = u1 sqrt(u0) (b2 = 1 - b0 - b1): PBRT 3e, ch. 13, "Sampling a Triangle" (PBRT 4e's
 * SampleUniformTriangle, ch. 6, "Triangles", uses another map, which shifts points along the
 * diagonal); pdf = 1 / area per unit area. */
vec2 sample_uniform_triangle(vec2 u);
vec2 sample_invert_uniform_triangle(vec2 b);

/* A bilinear density on [0, 1]^2 with the weights w[0..3] >= 0 at its corners (0,0), (1,0),
 * (0,1), (1,1): pdf(p) = 4 bilerp(p, w) / sum w, per unit area; y from its marginal, then x
 * from its conditional, each a linear density (PBRT 4e, ch. A.5, "Sampling Multidimensional
 * Functions", SampleBilinear).  The light samplers warp their uniforms by it so that the
 * directions follow the cosine at the receiver (shape.c). */
vec2 sample_bilinear(vec2 u, const float w[4]);
float pdf_bilinear(vec2 p, const float w[4]);
vec2 sample_invert_bilinear(vec2 p, const float w[4]);

/* ---- spherical polygons: directions uniform in the solid angle that a triangle or a rectangle
 * subtends from a point (light sampling, shape.c) ---- */

/* Solid angle (sr) of the spherical triangle with unit vertices a, b, c: Van Oosterom & Strackee
 * 1983, "The Solid Angle of a Plane Triangle", tan(Omega / 2) = |a . (b x c)| /
 * (1 + a.b + b.c + c.a), which keeps its precision for small triangles where the angle excess
 * alpha + beta + gamma - pi cancels. */
float sample_spherical_triangle_area(vec3 a, vec3 b, vec3 c);

/* A spherical triangle prepared for Arvo's map (Arvo 1995, "Stratified Sampling of Spherical
 * Triangles", SIGGRAPH 95; PBRT 4e, ch. 6, "Triangles"): u0 picks the sub-triangle a, b, c' of
 * area u0 Omega (c' on the arc a -> c), u1 a point on the arc b -> c' with 1 - cos uniform. */
struct sample_sph_triangle {
    vec3 a; /* unit vertices */
    vec3 b;
    vec3 c;
    vec3 c_perp;     /* unit: c's part orthogonal to a, so the arc a -> c is a cos + c_perp sin */
    float area;      /* Omega, sr */
    float cos_alpha; /* cos and sin of the interior angle alpha at a */
    float sin_alpha;
    float cos_ab; /* a . b: cos of the arc a -> b */
};                /* 64 bytes */
/* Prepares the triangle of unit vertices a, b, c; false when it is degenerate (two vertices
 * equal or opposite, or a zero area). */
bool sample_sph_triangle_init(vec3 a, vec3 b, vec3 c, struct sample_sph_triangle *st);
/* A unit direction uniform in the spherical triangle, pdf 1 / Omega per steradian. */
vec3 sample_spherical_triangle(const struct sample_sph_triangle *st, vec2 u);
float pdf_spherical_triangle(const struct sample_sph_triangle *st);
/* The u that maps to the unit direction w inside the triangle (Arvo's inverse: c' where the
 * great circle through b and w meets the arc a -> c). */
vec2 sample_invert_spherical_triangle(const struct sample_sph_triangle *st, vec3 w);

/* A rectangle corner + s e1 + t e2 (s, t in [0, 1], e1 orthogonal to e2) seen from the point o,
 * prepared for the map of Urena, Fajardo & King 2013, "An Area-Preserving Parametrization for
 * Spherical Rectangles" (EGSR): u0 picks the sub-rectangle [x0, xu] x [y0, y1] of solid angle
 * u0 S, u1 the height along the line x = xu, uniform in solid angle. */
struct sample_sph_rect {
    vec3 o; /* the reference point */
    vec3 x; /* unit frame: x along e1, y along e2, z away from the rectangle's side */
    vec3 y;
    vec3 z;
    float x0; /* the rectangle in that frame: [x0, x1] x [y0, y1] at z = z0 < 0 */
    float x1;
    float y0;
    float y1;
    float z0;
    float b0; /* z components of the unit normals of the planes (o, v00, v10), (o, v11, v01) */
    float b1;
    float k;    /* gamma2 + gamma3: the sub-rectangle's angle is au = u0 S - k (mod 2 pi) */
    float area; /* S, sr */
};              /* 88 bytes */
/* Prepares the rectangle; false when o lies in its plane, the edges are not orthogonal (to
 * 1e-4 of their lengths' product) or the solid angle is 0. */
bool sample_sph_rect_init(vec3 o, vec3 corner, vec3 e1, vec3 e2, struct sample_sph_rect *sr);
/* The POINT on the rectangle whose direction from o is uniform in solid angle, pdf 1 / S per
 * steradian. */
vec3 sample_spherical_rectangle(const struct sample_sph_rect *sr, vec2 u);
float pdf_spherical_rectangle(const struct sample_sph_rect *sr);
/* The u that maps to the point p of the rectangle. */
vec2 sample_invert_spherical_rectangle(const struct sample_sph_rect *sr, vec3 p);

/* ---- discrete distributions ---- */

/* Walker's alias method with Vose's O(n) construction: O(1) picks of index i with probability
 * pmf_i = w_i / sum w (Walker 1977, "An Efficient Method for Generating Discrete Random Variables
 * with General Distributions"; Vose 1991, "A Linear Algorithm for Generating Random Numbers with
 * a Given Distribution"; PBRT 4e, ch. A.1, "The Alias Method").  Used to pick lights by power. */
struct sample_alias_bin {
    float q;        /* probability of keeping this bin's own index once the bin is chosen */
    uint32_t alias; /* the index returned otherwise */
    float pmf;      /* probability that a pick returns this bin's index */
};                  /* 12 bytes */

/* Fills bins[0 .. n-1] from the n weights (finite, >= 0; all zero means uniform).  A zero
 * weight is never picked.  Returns false when n == 0, a weight is negative or not finite, or
 * memory runs out (bins then unspecified). */
bool sample_alias_build(const double *weights, uint32_t n, struct sample_alias_bin *bins);
/* The index picked by u in [0, 1); *pmf (may be NULL) receives its probability.  One float u
 * carries 24 bits: floor(u n) takes log2(n) of them and the rest decide between a bin and its
 * alias, so the pick frequencies match the pmfs to about 2 n 2^-24 relative (1e-3 at 10^4
 * bins); scenes with far more emissive triangles would need a second uniform. */
uint32_t sample_alias_pick(const struct sample_alias_bin *bins, uint32_t n, float u, float *pmf);

/* Veach 1997, sec. 9.2.4: power heuristic, beta = 2, one sample from each of two strategies. */
float mis_power(float pdf_a, float pdf_b);

#endif
