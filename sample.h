/* sample.h - random numbers, samplers, warps with their pdfs, and MIS weights.
 * RNG: PCG32 (O'Neill 2014).  Every sample value is a function of (seed, pixel, sample index,
 * dimension) alone, never of thread state, so images are identical for any thread count.
 * Dimension order of one camera sample (SAMPLE_DIM_*): pixel 2D, lens 2D, then per bounce:
 * light choice 1D, light position 2D, BSDF lobe 1D, BSDF direction 2D, roulette 1D. */
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

enum sampler_kind {
    SAMPLER_INDEPENDENT, /* every dimension an independent uniform */
};

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

/* The sample generator for one (pixel, sample index): a PCG32 stream seeded by hashing
 * (seed, pixel_idx, sample_idx), read dimension by dimension. */
struct sampler {
    enum sampler_kind kind;
    uint64_t seed;
    uint32_t pixel_idx;
    uint32_t sample_idx;
    uint32_t dim; /* next dimension to be returned */
    struct pcg32 rng;
};

/* Starts the sample sample_idx of pixel pixel_idx at dimension 0. */
void sample_start(struct sampler *s, enum sampler_kind kind, uint64_t seed, uint32_t pixel_idx,
                  uint32_t sample_idx);
/* Moves to dimension dim (>= the current one), skipping the values in between. */
void sample_set_dim(struct sampler *s, uint32_t dim);
float sample_1d(struct sampler *s);
vec2 sample_2d(struct sampler *s);

/* 64-bit mixing hash (SplitMix64 finaliser, Steele et al. 2014). */
uint64_t sample_hash64(uint64_t x);

/* ---- warps: each takes uniforms u in [0,1)^2; its pdf sits beside it ---- */

/* Concentric disk, Shirley & Chiu 1997, "A Low Distortion Map Between Disk and Square". */
vec2 sample_concentric_disk(vec2 u);
/* Cosine-weighted hemisphere about +z (Malley's method: disk lifted to the hemisphere). */
vec3 sample_cosine_hemisphere(vec2 u);
float pdf_cosine_hemisphere(float cos_theta); /* cos_theta / pi, per steradian */
/* Uniform hemisphere about +z. */
vec3 sample_uniform_hemisphere(vec2 u);
float pdf_uniform_hemisphere(void); /* 1 / (2 pi), per steradian */
/* Uniform barycentrics (b0, b1) on a triangle, square-root warp, PBRT 4e, ch. 6, "Triangles"
 * (b2 = 1 - b0 - b1); pdf = 1 / area per unit area. */
vec2 sample_uniform_triangle(vec2 u);

/* Veach 1997, sec. 9.2.4: power heuristic, beta = 2, one sample from each of two strategies. */
float mis_power(float pdf_a, float pdf_b);

#endif
