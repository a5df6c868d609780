/* sample.c - RNG, samplers, warps and MIS weights.
 * Seeding rule: the PCG32 stream of a sample is
 *   initstate = hash(seed, pixel_idx, sample_idx), initseq = hash(initstate),
 * so a sample's values depend on (seed, pixel, sample index, dimension) only; the stratified
 * and Sobol' samplers are stateless hashes of the same coordinates (docs/sampling.md).
 * References: O'Neill 2014 (PCG); Kensler 2013 (correlated multi-jittered sampling); Burley
 * 2020 and Joe & Kuo 2008 (Owen-scrambled Sobol'); Shirley & Chiu 1997 (concentric disk);
 * PBRT 4e, ch. A.5, "Sampling Multidimensional Functions"; Veach 1997, ch. 9 (MIS). */
#include "sample.h"

#include <assert.h>
#include <stdlib.h>
#include <string.h>

#include "sobol_matrices.h"

#if defined(__AVX2__)
#include <immintrin.h>
#endif

_Static_assert(SOBOL_N_DIMS == SAMPLE_SOBOL_MAX_DIMS, "sobol_matrices.h and sample.h disagree");
_Static_assert(SAMPLE_SOBOL_JOINT_DIMS <= SOBOL_N_DIMS, "joint dimensions beyond the table");

/* ---- PCG32 ---- */

static const uint64_t PCG32_MULT = 6364136223846793005ULL; /* O'Neill 2014, pcg32 multiplier */

void sample_pcg32_seed(struct pcg32 *rng, uint64_t initstate, uint64_t initseq)
{
    rng->state = 0u;
    rng->inc = (initseq << 1u) | 1u;
    sample_pcg32_next(rng);
    rng->state += initstate;
    sample_pcg32_next(rng);
}

uint32_t sample_pcg32_next(struct pcg32 *rng)
{
    uint64_t old = rng->state;
    rng->state = old * PCG32_MULT + rng->inc;
    uint32_t xorshifted = (uint32_t)(((old >> 18u) ^ old) >> 27u);
    uint32_t rot = (uint32_t)(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((-rot) & 31u));
}

float sample_pcg32_float(struct pcg32 *rng)
{
    return (float)(sample_pcg32_next(rng) >> 8) * 0x1p-24f; /* exactly representable, < 1 */
}

uint32_t sample_pcg32_bounded(struct pcg32 *rng, uint32_t bound)
{
    uint32_t threshold = (-bound) % bound;
    for (;;) {
        uint32_t r = sample_pcg32_next(rng);
        if (r >= threshold)
            return r % bound;
    }
}

void sample_pcg32_advance(struct pcg32 *rng, uint64_t delta)
{
    uint64_t cur_mult = PCG32_MULT, cur_plus = rng->inc;
    uint64_t acc_mult = 1u, acc_plus = 0u;
    while (delta > 0) {
        if (delta & 1u) {
            acc_mult *= cur_mult;
            acc_plus = acc_plus * cur_mult + cur_plus;
        }
        cur_plus = (cur_mult + 1u) * cur_plus;
        cur_mult *= cur_mult;
        delta >>= 1u;
    }
    rng->state = acc_mult * rng->state + acc_plus;
}

uint64_t sample_hash64(uint64_t x)
{
    x ^= x >> 30;
    x *= 0xbf58476d1ce4e5b9ULL;
    x ^= x >> 27;
    x *= 0x94d049bb133111ebULL;
    x ^= x >> 31;
    return x;
}

/* ---- samplers ----
 * Independent: the PCG32 stream of the seeding rule above, one output per dimension.
 * Stratified and Sobol' keep no stream: each value is a hash-driven function of (seed, pixel,
 * sample index, dimension), so sample_set_dim costs nothing and any dimension can be read in
 * any order. */

const char *sample_sampler_name(enum sampler_kind kind)
{
    switch (kind) {
    case SAMPLER_INDEPENDENT:
        return "independent";
    case SAMPLER_STRATIFIED:
        return "stratified";
    case SAMPLER_SOBOL:
        return "sobol";
    }
    return "?";
}

bool sample_sampler_parse(const char *name, enum sampler_kind *kind)
{
    for (int k = 0; k < SAMPLER_COUNT; k++)
        if (strcmp(name, sample_sampler_name((enum sampler_kind)k)) == 0) {
            *kind = (enum sampler_kind)k;
            return true;
        }
    return false;
}

/* Columns m of the multi-jittered grid for N samples: the largest divisor of N not above
 * sqrt(N), so that m x n = N exactly and every 1D projection is stratified into N intervals;
 * when that grid would be flatter than 1:4 (N prime, say), Kensler's m = floor(sqrt(N)) with a
 * ragged last row (Kensler 2013, cmj for arbitrary sample counts). */
static uint32_t cmj_columns(uint32_t n_samples)
{
    uint32_t root = 1;
    while ((uint64_t)(root + 1) * (root + 1) <= n_samples)
        root++;
    for (uint32_t m = root; m >= 1; m--)
        if (n_samples % m == 0) {
            if (4ull * m * m >= n_samples)
                return m;
            break;
        }
    return root;
}

static void sobol_pixel_seeds(struct sampler *s);
static void sobol_joint_point(struct sampler *s);
static void pad_block(struct sampler *s, uint32_t dim);

void sample_start_pixel(struct sampler *s, enum sampler_kind kind, uint64_t seed,
                        uint32_t pixel_idx, uint32_t set_spp)
{
    s->kind = kind;
    s->seed = seed;
    s->pixel_idx = pixel_idx;
    s->sample_idx = 0;
    s->dim = 0;
    s->set_spp = set_spp;
    s->cmj_cols = kind == SAMPLER_STRATIFIED && set_spp > 1 ? cmj_columns(set_spp) : 1;
    s->pixel_hash = sample_hash64(seed ^ sample_hash64(0x9e3779b97f4a7c15ULL + pixel_idx));
    s->rng = (struct pcg32){0, 1};
    s->pad_dim0 = SAMPLE_PAD_NONE;
    if (kind == SAMPLER_SOBOL)
        sobol_pixel_seeds(s);
}

void sample_start_index(struct sampler *s, uint32_t sample_idx)
{
    s->sample_idx = sample_idx;
    s->dim = 0;
    if (s->kind == SAMPLER_INDEPENDENT) {
        uint64_t h = sample_hash64(s->seed ^
                                   sample_hash64(((uint64_t)s->pixel_idx << 32) | sample_idx));
        sample_pcg32_seed(&s->rng, h, sample_hash64(h));
    } else if (s->kind == SAMPLER_SOBOL) {
        sobol_joint_point(s);
        /* the first fill now, not at the first bounce's request: its hashes are a chain of
         * dependent multiplies that the camera ray's traversal then hides, where on demand
         * the path waited for them (nearly every path reaches its first bounce) */
        pad_block(s, SAMPLE_DIM_BOUNCE0 + SAMPLE_BOUNCE_BSDF_LOBE);
    }
}

void sample_start_spp(struct sampler *s, enum sampler_kind kind, uint64_t seed, uint32_t pixel_idx,
                      uint32_t sample_idx, uint32_t set_spp)
{
    sample_start_pixel(s, kind, seed, pixel_idx, set_spp);
    sample_start_index(s, sample_idx);
}

void sample_start(struct sampler *s, enum sampler_kind kind, uint64_t seed, uint32_t pixel_idx,
                  uint32_t sample_idx)
{
    sample_start_spp(s, kind, seed, pixel_idx, sample_idx, 0);
}

void sample_set_dim(struct sampler *s, uint32_t dim)
{
    if (dim > s->dim) {
        if (s->kind == SAMPLER_INDEPENDENT)
            sample_pcg32_advance(&s->rng, dim - s->dim);
        s->dim = dim;
    }
}

/* A 32-bit seed for one use (tag) of one dimension of this pixel. */
static uint32_t dim_seed(const struct sampler *s, uint32_t dim, uint32_t tag)
{
    return (uint32_t)sample_hash64(s->pixel_hash ^ ((uint64_t)dim << 32 | tag));
}

/* A 32-bit fraction x / 2^32 as a float in [0, 1): its top 24 bits, exact (so truncation, not
 * rounding: a value never crosses up into the next stratum or up to 1). */
static float fraction_to_float(uint32_t x) { return (float)(x >> 8) * 0x1p-24f; }

/* -- stratified: correlated multi-jittered sampling, Kensler 2013, "Correlated Multi-Jittered
 * Sampling", Pixar Technical Memo 13-01 -- */

/* A pseudo-random permutation of [0, l), indexed by p: Kensler 2013, "permute"
 * (a hash restricted to the next power of two, cycle-walked back into [0, l)). */
static uint32_t kensler_permute(uint32_t i, uint32_t l, uint32_t p)
{
    assert(l > 0); /* the cycle walk ends only in a non-empty range */
    uint32_t w = l - 1;
    w |= w >> 1;
    w |= w >> 2;
    w |= w >> 4;
    w |= w >> 8;
    w |= w >> 16;
    do {
        i ^= p;
        i *= 0xe170893du;
        i ^= p >> 16;
        i ^= (i & w) >> 4;
        i ^= p >> 8;
        i *= 0x0929eb3fu;
        i ^= p >> 23;
        i ^= (i & w) >> 1;
        i *= 1u | p >> 27;
        i *= 0x6935fa69u;
        i ^= (i & w) >> 11;
        i *= 0x74dcb303u;
        i ^= (i & w) >> 2;
        i *= 0x9e501cc3u;
        i ^= (i & w) >> 2;
        i *= 0xc860a3dfu;
        i &= w;
        i ^= i >> 5;
    } while (i >= l);
    return (uint32_t)(((uint64_t)i + p) % l); /* 64-bit: Kensler's 32-bit (i + p) % l can wrap
                                                   and map two i to one value */
}

/* 32 hashed bits of (i, p): the jitter inside a stratum, as a 32-bit fraction. */
static uint32_t hash_jitter(uint32_t i, uint32_t p)
{
    return (uint32_t)(sample_hash64(((uint64_t)p << 32) | i) >> 32);
}

/* (k + j) / n for stratum k < n and the jitter j = jitter / 2^32, as a float: the 32-bit
 * fraction floor((k 2^32 + jitter) / n), then its top 24 bits.  Exact stratum boundaries
 * whenever n is a power of two up to 2^24. */
static float in_stratum(uint32_t k, uint32_t n, uint32_t jitter)
{
    return fraction_to_float((uint32_t)((((uint64_t)k << 32) | jitter) / n));
}

/* The sample's position s in its stratified set and the set's seed for dimension dim.  Set k of
 * N = set_spp holds sample indices kN .. kN + N - 1; each set has its own permutations. */
static uint32_t strat_position(const struct sampler *s, uint32_t dim, uint32_t *p)
{
    uint32_t n = s->set_spp > 1 ? s->set_spp : 1;
    *p = dim_seed(s, dim, s->sample_idx / n);
    return s->sample_idx % n;
}

/* 1D: x = (pi(s) + jitter) / N, pi a per-(pixel, dimension, set) permutation: every 1/N
 * interval holds one point of the set, and different dimensions pair strata at random
 * (Latin-hypercube padding, PBRT 4e, ch. 8, "Stratified Sampler"). */
static float stratified_1d(const struct sampler *s, uint32_t dim)
{
    uint32_t p;
    uint32_t i = strat_position(s, dim, &p);
    uint32_t n = s->set_spp > 1 ? s->set_spp : 1;
    uint32_t stratum = kensler_permute(i, n, p * 0x51633e2du);
    return in_stratum(stratum, n, hash_jitter(i, p * 0x967a889bu));
}

/* 2D: Kensler 2013, cmj(s, N, p) for arbitrary N, with an m x n grid (m = cmj_cols):
 *   s' = permute(s, N), sx = permute(s' mod m, m), sy = permute(s' div m, n),
 *   x = (sx + (sy + jx) / n) / m,  y = (s' + jy) / N.
 * Each cell of the m x n grid and each 1/N interval of x and of y holds one point when
 * N = m n (a multi-jittered set, Chiu, Shirley & Wang 1994). */
static vec2 stratified_2d(const struct sampler *s, uint32_t dim)
{
    uint32_t p;
    uint32_t i = strat_position(s, dim, &p);
    uint32_t n_set = s->set_spp > 1 ? s->set_spp : 1;
    /* rows n = ceil(N / m), written so that N near 2^32 cannot wrap (n = 0 would never end
     * kensler_permute's cycle walk) */
    uint32_t m = s->cmj_cols, n = n_set / m + (n_set % m != 0);
    uint32_t sp = kensler_permute(i, n_set, p * 0x51633e2du);
    uint32_t sx = kensler_permute(sp % m, m, p * 0x68bc21ebu);
    uint32_t sy = kensler_permute(sp / m, n, p * 0x02e5be93u);
    /* x = (sx + (sy + jx) / n) / m = (sx n + sy + jx) / (m n) */
    float x = in_stratum(sx * n + sy, m * n, hash_jitter(sp, p * 0x967a889bu));
    float y = in_stratum(sp, n_set, hash_jitter(sp, p * 0x368cc8b7u));
    return (vec2){x, y};
}

/* -- Sobol': Burley 2020, "Practical Hash-based Owen Scrambling", JCGT 9(4) -- */

/* Swaps halves, bytes, nibbles, pairs and bits: written with shifts and masks only (no
 * byte-swap builtin), so the compiler can also run it on a vector of lanes. */
static uint32_t reverse_bits32(uint32_t x)
{
    x = (x << 16) | (x >> 16);
    x = ((x & 0x00ff00ffu) << 8) | ((x & 0xff00ff00u) >> 8);
    x = ((x & 0x0f0f0f0fu) << 4) | ((x & 0xf0f0f0f0u) >> 4);
    x = ((x & 0x33333333u) << 2) | ((x & 0xccccccccu) >> 2);
    x = ((x & 0x55555555u) << 1) | ((x & 0xaaaaaaaau) >> 1);
    return x;
}

/* Sobol' dimension 1 in digit order (bit j = digit j + 1 of the fraction): Pascal's triangle
 * mod 2, digit j = XOR of the index bits k with binom(k, j) odd, i.e. (Lucas' theorem) with k
 * a bit-superset of j: a superset transform in 5 steps.  Dimension 0 (van der Corput) in digit
 * order is the index itself. */
static uint32_t pascal_digits(uint32_t index)
{
    uint32_t x = index;
    x ^= (x >> 1) & 0x55555555u;
    x ^= (x >> 2) & 0x33333333u;
    x ^= (x >> 4) & 0x0f0f0f0fu;
    x ^= (x >> 8) & 0x00ff00ffu;
    x ^= (x >> 16) & 0x0000ffffu;
    return x;
}

/* The padded block's requests run a lane each (pad_block): eight 32-bit lanes as a GNU C vector,
 * on which every operation above is written once more, lane by lane, to the same bits.  The
 * helpers work in place through pointers: a 32-byte vector passed by value has another ABI
 * without AVX, which gcc notes at every such definition. */
typedef uint32_t u32x8 __attribute__((vector_size(32)));
typedef int32_t i32x8 __attribute__((vector_size(32)));
typedef float f32x8 __attribute__((vector_size(32)));
_Static_assert(SAMPLE_PAD_LANES == 8, "pad_lanes runs eight lanes as one u32x8");

#if defined(__GFNI__) && defined(__AVX2__)
/* With GFNI the affine map whose matrix is 0x8040201008040201 reverses the bits of every byte
 * (Intel's GF2P8AFFINEQB), and a byte shuffle reverses each lane's bytes: two instructions for
 * reverse_bits32's fifteen. */
static ALWAYS_INLINE void reverse_bits_x8(u32x8 *x)
{
    __m256i v = _mm256_gf2p8affine_epi64_epi8((__m256i)*x,
                                              _mm256_set1_epi64x((long long)0x8040201008040201ull),
                                              0);
    const __m256i bytes = _mm256_setr_epi8(3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12, 3,
                                           2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12);
    *x = (u32x8)_mm256_shuffle_epi8(v, bytes);
}
#elif defined(__AVX2__)
/* Without GFNI, two nibble lookups (VPSHUFB) reverse the bits of every byte and a third
 * shuffle its lanes' bytes: seven instructions for reverse_bits32's fifteen. */
static ALWAYS_INLINE void reverse_bits_x8(u32x8 *x)
{
    /* byte k of rev_hi is k (a nibble) bit-reversed: 0, 8, 4, 12, 2, ...; rev_lo is it << 4 */
    const __m256i rev_hi = _mm256_broadcastsi128_si256(
        _mm_setr_epi32(0x0c040800, 0x0e060a02, 0x0d050901, 0x0f070b03));
    const __m256i rev_lo = _mm256_slli_epi16(rev_hi, 4);
    const __m256i low4 = _mm256_set1_epi8(0x0f);
    const __m256i bytes = _mm256_setr_epi8(3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12, 3,
                                           2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12);
    __m256i v = (__m256i)*x;
    __m256i lo = _mm256_and_si256(v, low4);
    __m256i hi = _mm256_and_si256(_mm256_srli_epi16(v, 4), low4);
    v = _mm256_or_si256(_mm256_shuffle_epi8(rev_lo, lo), _mm256_shuffle_epi8(rev_hi, hi));
    *x = (u32x8)_mm256_shuffle_epi8(v, bytes);
}
#else
static ALWAYS_INLINE void reverse_bits_x8(u32x8 *x)
{
    u32x8 v = *x;
    v = (v << 16) | (v >> 16);
    v = ((v & 0x00ff00ffu) << 8) | ((v & 0xff00ff00u) >> 8);
    v = ((v & 0x0f0f0f0fu) << 4) | ((v & 0xf0f0f0f0u) >> 4);
    v = ((v & 0x33333333u) << 2) | ((v & 0xccccccccu) >> 2);
    v = ((v & 0x55555555u) << 1) | ((v & 0xaaaaaaaau) >> 1);
    *x = v;
}
#endif

static ALWAYS_INLINE void pascal_digits_x8(u32x8 *x)
{
    u32x8 v = *x;
    v ^= (v >> 1) & 0x55555555u;
    v ^= (v >> 2) & 0x33333333u;
    v ^= (v >> 4) & 0x0f0f0f0fu;
    v ^= (v >> 8) & 0x00ff00ffu;
    v ^= (v >> 16) & 0x0000ffffu;
    *x = v;
}

/* fraction_to_float lane by lane: x >> 8 < 2^24 converts exactly through int32 */
static ALWAYS_INLINE void fraction_to_float_v8(const u32x8 *x, f32x8 *out)
{
    *out = __builtin_convertvector((i32x8)(*x >> 8), f32x8) * 0x1p-24f;
}

/* fraction_to_float_v8 into out[8] */
static ALWAYS_INLINE void fraction_to_float_x8(const u32x8 *x, float *out)
{
    f32x8 f;
    fraction_to_float_v8(x, &f);
    memcpy(out, &f, sizeof f);
}

uint32_t sample_sobol_u32(uint32_t index, uint32_t dim)
{
    /* x = C_dim * bits(index) over GF(2), the columns C_dim from Joe & Kuo 2008 */
    if (dim == 0)
        return reverse_bits32(index);
    if (dim == 1)
        return reverse_bits32(pascal_digits(index));
    uint32_t x = 0;
    for (int k = 0; k < 32; k++) /* branch-free: shuffled indices have random bits */
        x ^= SOBOL_MATRICES[dim][k] & (0u - (index >> k & 1u));
    return x;
}

/* A hash in which each output bit depends only on that bit and lower bits of x (Laine &
 * Karras 2011, "Stratified sampling for stochastic transparency"), with the stronger
 * constants of Vegdahl 2021, "Building a Better LK Hash" in place of Burley 2020's. */
static uint32_t laine_karras_permutation(uint32_t x, uint32_t seed)
{
    x ^= x * 0x3d20adeau;
    x += seed;
    x *= (seed >> 16) | 1u;
    x ^= x * 0x05526c56u;
    x ^= x * 0x53a22864u;
    return x;
}

static ALWAYS_INLINE void laine_karras_permutation_x8(u32x8 *x, const u32x8 *seed)
{
    u32x8 v = *x;
    v ^= v * 0x3d20adeau;
    v += *seed;
    v *= (*seed >> 16) | 1u;
    v ^= v * 0x05526c56u;
    v ^= v * 0x53a22864u;
    *x = v;
}

/* Nested uniform (Owen 1995) scrambling of a 32-bit fraction, as in Burley 2020: after the bit
 * reversal the LK hash flips each digit as a function of the more significant digits only.  A
 * bijection that maps every aligned block of 2^k values onto another, so it keeps every
 * elementary-interval property of the points it scrambles.  Eight lanes at once, each with its
 * own seed: reverse_bits32(laine_karras_permutation(reverse_bits32(x), seed)) lane by lane. */
static ALWAYS_INLINE void nested_uniform_scramble_x8(u32x8 *x, const u32x8 *seed)
{
    reverse_bits_x8(x);
    laine_karras_permutation_x8(x, seed);
    reverse_bits_x8(x);
}

static void pad_seeds(const struct sampler *s, uint32_t dim0, uint32_t *index, uint32_t *x,
                      uint32_t *y, uint32_t n);

/* The first bounce block with a padded dimension: the fills whose seeds a sampler keeps per
 * pixel are those from this block and from the next SAMPLE_PAD_KEPT - 1. */
static const uint32_t PAD_FIRST_KEPT = SAMPLE_SOBOL_JOINT_DIMS <= SAMPLE_DIM_BOUNCE0
                                           ? 0
                                           : (SAMPLE_SOBOL_JOINT_DIMS - SAMPLE_DIM_BOUNCE0) /
                                                 SAMPLE_DIMS_PER_BOUNCE;

/* The per-pixel seeds: the joint point's index shuffle, one scramble seed per dimension of the
 * joint lane (those past SAMPLE_SOBOL_JOINT_DIMS are computed for the lanes' sake, never read),
 * and the padding seeds of the bounce blocks every path reaches first. */
static void sobol_pixel_seeds(struct sampler *s)
{
    s->shuffle_seed = dim_seed(s, UINT32_MAX, 0);
    for (uint32_t d = 0; d < SAMPLE_SOBOL_JOINT_LANES; d++)
        s->joint_seed[d] = dim_seed(s, d, 1);
    s->path_shuffle_seed = dim_seed(s, UINT32_MAX, 3);
    for (uint32_t d = 0; d < SAMPLE_PAD_LANES; d++)
        s->path_seed[d] = dim_seed(s, d, 4);
    pad_seeds(s, SAMPLE_DIM_BOUNCE0 + PAD_FIRST_KEPT * SAMPLE_DIMS_PER_BOUNCE, s->pad_seed_index,
              s->pad_seed_x, s->pad_seed_y, SAMPLE_PAD_KEPT_REQUESTS);
}

/* A shuffled, scrambled Sobol' point of the sample, n_lanes (a multiple of 8) dimensions at once
 * (Burley 2020: shuffled_scrambled_sobol4d for n_lanes dimensions):
 *   index = nested_uniform_scramble(sample_idx, shuffle_seed)   (the per-pixel shuffle: power-
 *           of-two prefixes of a pixel's samples map to aligned blocks of the sequence, which
 *           are (t, m, s)-nets)
 *   x_d = C_d * bits(index) over GF(2), as the XOR of one table row per 4-bit digit of index
 *   u_d = nested_uniform_scramble(x_d, seed_d),
 * nested_uniform_scramble(x, seed) being Burley's reverse_bits32(laine_karras_permutation(
 * reverse_bits32(x), seed)), computed a vector of lanes at a time (nested_uniform_scramble_x8).
 * The loops over d run a lane per dimension with no branch; u_d is the scramble of
 * sample_sobol_u32(index, d) to the bit. */
static ALWAYS_INLINE void sobol_point(uint32_t sample_idx_rev, uint32_t shuffle_seed,
                                      const uint32_t *seed, int n_lanes, float *u)
{
    uint32_t index = reverse_bits32(laine_karras_permutation(sample_idx_rev, shuffle_seed));
    uint32_t x[SAMPLE_SOBOL_MAX_DIMS] = {0};
    for (int p = 0; p < 8; p++) {
        const uint32_t *row = SOBOL_NIBBLES[p][index >> 4 * p & 15u];
        for (int d = 0; d < n_lanes; d++)
            x[d] ^= row[d];
    }
    for (int l = 0; l < n_lanes; l += SAMPLE_PAD_LANES) {
        u32x8 v, sd;
        memcpy(&v, x + l, sizeof v);
        memcpy(&sd, seed + l, sizeof sd);
        nested_uniform_scramble_x8(&v, &sd);
        fraction_to_float_x8(&v, u + l);
    }
}

static void sobol_path_point(const struct sampler *s, float u[SAMPLE_PAD_LANES]);

/* The joint point: SAMPLE_SOBOL_JOINT_DIMS dimensions (rounded up to whole vectors), and the
 * path point beside it for the first fill: two independent chains of dependent multiplies and
 * table loads that the core overlaps, where the path point computed in the fill was the fill's
 * longest chain (the sampler 5.5% of a Cornell profile with it there, 4.4% here: medians of 5,
 * docs/performance.md). */
static void sobol_joint_point(struct sampler *s)
{
    s->sample_idx_rev = reverse_bits32(s->sample_idx);
    sobol_point(s->sample_idx_rev, s->shuffle_seed, s->joint_seed, SAMPLE_SOBOL_JOINT_LANES,
                s->joint_u);
    if (SAMPLE_SOBOL_PATH_DIRS > 0)
        sobol_path_point(s, s->path_u);
}

/* The path point (sample.h, SAMPLE_SOBOL_PATH_DIRS): the BSDF directions of the first bounces
 * as one Sobol' point, computed as the joint point is, with its own index shuffle and scrambles.
 * path_dir_slot gives the slot j of a padded direction's dimension (its values are the point's
 * dimensions PATH_DIMS[j]), or -1 for every other dimension. */
_Static_assert(SAMPLE_SOBOL_PATH_DIRS <= 3 && SAMPLE_SOBOL_PATH_DIRS <= SAMPLE_PAD_BLOCKS,
               "the path point is one vector, its directions within the first fill");

/* The path point's dimension pairs, from its first eight: (0, 1) a (0,2)-sequence, (2, 3) and
 * (4, 6) (t, 2)-sequences with t = 2 ((4, 5) has t = 3: every (t, m, 2)-net property checked
 * to 2^12 points), and the six top digits independent, so that any aligned 64 samples put one
 * point in each of the 64 cells that halving every coordinate makes. */
static const uint8_t PATH_DIMS[3][2] = {{0, 1}, {2, 3}, {4, 6}};

static int path_dir_slot(uint32_t dim)
{
    int j = 0;
    for (uint32_t b = 0; b < SAMPLE_SOBOL_PATH_DIRS; b++) {
        uint32_t d = SAMPLE_DIM_BOUNCE0 + b * SAMPLE_DIMS_PER_BOUNCE + SAMPLE_BOUNCE_BSDF_DIR;
        if (d < SAMPLE_SOBOL_JOINT_DIMS)
            continue; /* a direction in the joint point */
        if (d == dim)
            return j;
        j++;
    }
    return -1;
}

/* The path point's SAMPLE_PAD_LANES dimensions (those past 2 SAMPLE_SOBOL_PATH_DIRS unread). */
static void sobol_path_point(const struct sampler *s, float u[SAMPLE_PAD_LANES])
{
    sobol_point(s->sample_idx_rev, s->path_shuffle_seed, s->path_seed, SAMPLE_PAD_LANES, u);
}

/* The path point's slot j alone, to the bit what sobol_path_point gives there. */
static vec2 sobol_path_dir(const struct sampler *s, int j)
{
    uint32_t index = reverse_bits32(
        laine_karras_permutation(s->sample_idx_rev, s->path_shuffle_seed));
    float u[2];
    for (int c = 0; c < 2; c++) {
        uint32_t d = PATH_DIMS[j][c];
        uint32_t x = reverse_bits32(sample_sobol_u32(index, d));
        u[c] = fraction_to_float(reverse_bits32(laine_karras_permutation(x, s->path_seed[d])));
    }
    return (vec2){u[0], u[1]};
}

/* Padding (Burley 2020): a request at dimension dim >= the joint ones reads Sobol' dimensions
 * 0 (and 1), a (0,2)-sequence, with its own index shuffle and its own scrambles, so requests
 * are mutually independent and each is stratified in itself:
 *   index = nested_uniform_scramble(sample_idx, seed_index)
 *   x = scrambled_sobol(index, 0, seed_x),  y = scrambled_sobol(index, 1, seed_y)   (2D only)
 * The three seeds of the request at dim come from one 64-bit hash h of (pixel, dim): its halves
 * lo and hi, and lo ^ mix(hi); each uniform, and pairwise independent for a uniform hash. */
static void request_seeds(const struct sampler *s, uint32_t dim, uint32_t *seed_index,
                          uint32_t *seed_x, uint32_t *seed_y)
{
    uint64_t h = sample_hash64(s->pixel_hash ^ ((uint64_t)dim << 32 | 2u));
    uint32_t lo = (uint32_t)h, hi = (uint32_t)(h >> 32);
    *seed_index = lo;
    *seed_x = hi;
    *seed_y = lo ^ (hi * 0x9e3779b9u + 0x7f4a7c15u);
}

/* The request with these seeds, 1D (x) and 2D (x, y) alike: the x of a 2D request is the 1D
 * request's value.  sample_idx_rev is sample_idx bit-reversed, the first step of the index
 * shuffle.  x = nested_uniform_scramble(sample_sobol_u32(index, 0), seed_x), in which the
 * scramble's first reversal undoes the one that puts dimension 0's digits in fraction order, so
 * both are skipped; y likewise for dimension 1. */
static inline vec2 pad_request(uint32_t sample_idx_rev, uint32_t seed_index, uint32_t seed_x,
                               uint32_t seed_y)
{
    uint32_t index = reverse_bits32(laine_karras_permutation(sample_idx_rev, seed_index));
    uint32_t x = reverse_bits32(laine_karras_permutation(index, seed_x));
    uint32_t y = reverse_bits32(laine_karras_permutation(pascal_digits(index), seed_y));
    return (vec2){fraction_to_float(x), fraction_to_float(y)};
}

/* The padded dimensions of the bounce blocks (sample.h: SAMPLE_DIMS_PER_BOUNCE dimensions from
 * SAMPLE_DIM_BOUNCE0 on) are computed a fill at a time: from the start of a block, the requests
 * of SAMPLE_PAD_BLOCKS blocks at once, a lane each (two vectors), kept until the sample passes
 * them: pad_x[k] and pad_y[k] hold x and y of the request at dimension pad_dim0 + k.  A fill
 * costs its two vectors whatever they hold, so they hold requests only, not the places of
 * second coordinates: one fill serves the first three bounces of a path, which with the
 * roulette threshold most paths reach (a fill per two bounces before).  Other dimensions (the
 * light-sample block, any dimension below the first bounce, a second coordinate read alone)
 * are requested one at a time. */
static bool pad_in_blocks(uint32_t dim)
{
    return dim >= SAMPLE_DIM_BOUNCE0 && dim < SAMPLE_DIM_LIGHT_EXTRA &&
           (SAMPLE_BLOCK_REQUESTS >> (dim - SAMPLE_DIM_BOUNCE0) % SAMPLE_DIMS_PER_BOUNCE & 1u);
}

/* The dimension of request k of the blocks from dimension dim0 (a block's start): request
 * r = k % 5 of block k / 5 is at the block's offset r + (r >= 2) + (r >= 4), the r-th of the
 * offsets 0, 1, 3, 4, 6 of SAMPLE_BLOCK_REQUESTS. */
static uint32_t pad_request_dim(uint32_t dim0, uint32_t k)
{
    _Static_assert(SAMPLE_BLOCK_REQUESTS == 0x5b, "requests at block offsets 0, 1, 3, 4, 6");
    uint32_t r = k % SAMPLE_REQUESTS_PER_BOUNCE;
    return dim0 + k / SAMPLE_REQUESTS_PER_BOUNCE * SAMPLE_DIMS_PER_BOUNCE + r + (r >= 2) + (r >= 4);
}

/* The seeds of requests k < n of the blocks from dimension dim0. */
static void pad_seeds(const struct sampler *s, uint32_t dim0, uint32_t *index, uint32_t *x,
                      uint32_t *y, uint32_t n)
{
    for (uint32_t k = 0; k < n; k++)
        request_seeds(s, pad_request_dim(dim0, k), &index[k], &x[k], &y[k]);
}

/* pad_request on eight lanes at once: the requests with seeds index[l], x[l], y[l] into
 * x[l], y[l]. */
static ALWAYS_INLINE void pad_lanes(uint32_t sample_idx_rev, const uint32_t *seeds_index,
                                    const uint32_t *seeds_x, const uint32_t *seeds_y, f32x8 *out_x,
                                    f32x8 *out_y)
{
    u32x8 seed_index, seed_x, seed_y;
    memcpy(&seed_index, seeds_index, sizeof seed_index);
    memcpy(&seed_x, seeds_x, sizeof seed_x);
    memcpy(&seed_y, seeds_y, sizeof seed_y);
    u32x8 index = (u32x8){0} + sample_idx_rev;
    laine_karras_permutation_x8(&index, &seed_index);
    reverse_bits_x8(&index);
    u32x8 x = index, y = index;
    laine_karras_permutation_x8(&x, &seed_x);
    reverse_bits_x8(&x);
    pascal_digits_x8(&y);
    laine_karras_permutation_x8(&y, &seed_y);
    reverse_bits_x8(&y);
    fraction_to_float_v8(&x, out_x);
    fraction_to_float_v8(&y, out_y);
}

/* The 15 requests of lanes *lo (0-7) and *hi (8-15) in dimension order: request k to
 * out[pad_request_dim(0, k)] of out[SAMPLE_PAD_SPAN_STORED], the places of the second
 * coordinates (never read) filled with copies.  Three shuffles in registers: copying lane by
 * lane from a stored vector stalls each load on store forwarding (measured on Zen 3). */
static ALWAYS_INLINE void pad_spread(const f32x8 *lo, const f32x8 *hi, float *out)
{
    f32x8 v0 = __builtin_shufflevector(*lo, *hi, 0, 1, 1, 2, 3, 3, 4, 5);
    f32x8 v1 = __builtin_shufflevector(*lo, *hi, 6, 6, 7, 8, 8, 9, 10, 11);
    f32x8 v2 = __builtin_shufflevector(*hi, *hi, 3, 4, 5, 5, 6, 6, 6, 6);
    memcpy(out, &v0, sizeof v0);
    memcpy(out + 8, &v1, sizeof v1);
    memcpy(out + 16, &v2, sizeof v2);
}

/* Fills the held requests from the start of the block of dimension dim (pad_in_blocks(dim)).
 * Out of line, as gcc left it before the path point moved to sobol_joint_point: inlined into
 * render_pixel and sobol_pad it saved nothing measurable and hid the sampler in its callers. */
static NOINLINE void pad_block(struct sampler *s, uint32_t dim)
{
    uint32_t block = (dim - SAMPLE_DIM_BOUNCE0) / SAMPLE_DIMS_PER_BOUNCE;
    uint32_t dim0 = SAMPLE_DIM_BOUNCE0 + block * SAMPLE_DIMS_PER_BOUNCE;
    uint32_t computed_index[SAMPLE_PAD_HELD], computed_x[SAMPLE_PAD_HELD],
        computed_y[SAMPLE_PAD_HELD];
    const uint32_t *seed_index = computed_index, *seed_x = computed_x, *seed_y = computed_y;
    if (block - PAD_FIRST_KEPT < SAMPLE_PAD_KEPT) {
        uint32_t k = (block - PAD_FIRST_KEPT) * SAMPLE_REQUESTS_PER_BOUNCE;
        seed_index = s->pad_seed_index + k;
        seed_x = s->pad_seed_x + k;
        seed_y = s->pad_seed_y + k;
    } else {
        pad_seeds(s, dim0, computed_index, computed_x, computed_y, SAMPLE_PAD_HELD);
    }
    f32x8 x_lo, y_lo, x_hi, y_hi;
    pad_lanes(s->sample_idx_rev, seed_index, seed_x, seed_y, &x_lo, &y_lo);
    pad_lanes(s->sample_idx_rev, seed_index + SAMPLE_PAD_LANES, seed_x + SAMPLE_PAD_LANES,
              seed_y + SAMPLE_PAD_LANES, &x_hi, &y_hi);
    pad_spread(&x_lo, &x_hi, s->pad_x);
    pad_spread(&y_lo, &y_hi, s->pad_y);
    s->pad_dim0 = dim0;
    /* the BSDF directions of the path point, where the fill holds them (the first fill always:
     * sample_start_index makes it) */
    if (SAMPLE_SOBOL_PATH_DIRS > 0 && block < SAMPLE_SOBOL_PATH_DIRS) {
        const float *u = s->path_u;
        for (uint32_t b = block; b < SAMPLE_SOBOL_PATH_DIRS; b++) {
            uint32_t d = SAMPLE_DIM_BOUNCE0 + b * SAMPLE_DIMS_PER_BOUNCE + SAMPLE_BOUNCE_BSDF_DIR;
            int j = path_dir_slot(d);
            if (j >= 0) {
                s->pad_x[d - dim0] = u[PATH_DIMS[j][0]];
                s->pad_y[d - dim0] = u[PATH_DIMS[j][1]];
            }
        }
    }
}

/* The Sobol' request at dimension dim >= SAMPLE_SOBOL_JOINT_DIMS: x, and y for a 2D request. */
static vec2 sobol_pad(struct sampler *s, uint32_t dim)
{
    if (pad_in_blocks(dim)) {
        if (!sample_pad_holds(s, dim))
            pad_block(s, dim);
        uint32_t k = dim - s->pad_dim0;
        return (vec2){s->pad_x[k], s->pad_y[k]};
    }
    return sample_sobol_request(s, dim);
}

vec2 sample_sobol_request(const struct sampler *s, uint32_t dim)
{
    int slot = path_dir_slot(dim);
    if (slot >= 0)
        return sobol_path_dir(s, slot);
    uint32_t seed_index, seed_x, seed_y;
    request_seeds(s, dim, &seed_index, &seed_x, &seed_y);
    return pad_request(s->sample_idx_rev, seed_index, seed_x, seed_y);
}

float sample_1d_compute(struct sampler *s, uint32_t dim)
{
    switch (s->kind) {
    case SAMPLER_STRATIFIED:
        return stratified_1d(s, dim);
    case SAMPLER_SOBOL:
        return dim < SAMPLE_SOBOL_JOINT_DIMS ? s->joint_u[dim] : sobol_pad(s, dim).x;
    case SAMPLER_INDEPENDENT:
        break;
    }
    return sample_pcg32_float(&s->rng);
}

vec2 sample_2d_compute(struct sampler *s, uint32_t dim)
{
    if (s->kind == SAMPLER_STRATIFIED)
        return stratified_2d(s, dim);
    if (s->kind == SAMPLER_SOBOL && dim >= SAMPLE_SOBOL_JOINT_DIMS)
        return sobol_pad(s, dim);
    /* independent, and Sobol' across the end of the joint dimensions: two consecutive
     * dimensions */
    float x = sample_1d_compute(s, dim);
    float y = sample_1d_compute(s, dim + 1);
    return (vec2){x, y};
}

vec2 sample_ahead_compute(struct sampler *s, uint32_t dim, bool is_2d)
{
    if (s->kind == SAMPLER_INDEPENDENT) {
        /* the stream from the current dimension on, one value per dimension */
        struct pcg32 ahead = s->rng;
        sample_pcg32_advance(&ahead, dim - s->dim);
        float x = sample_pcg32_float(&ahead);
        return (vec2){x, is_2d ? sample_pcg32_float(&ahead) : 0.0f};
    }
    /* stratified and Sobol' values are functions of the dimension alone */
    return is_2d ? sample_2d_compute(s, dim) : (vec2){sample_1d_compute(s, dim), 0.0f};
}

/* ---- warps ---- */

/* cos and sin of phi in [-pi/4, pi/4] by the minimax polynomials of the Cephes library's cosf
 * and sinf on that interval (Moshier 1989, "Methods and Programs for Mathematical Functions";
 * relative error about 3e-8): the concentric map needs no argument reduction, so it is cheaper
 * than the library's sincosf. */
static vec2 cos_sin_quarter(float phi)
{
    float z = phi * phi;
    float c = ((2.443315711809948e-5f * z - 1.388731625493765e-3f) * z + 4.166664568298827e-2f) *
                  z * z -
              0.5f * z + 1.0f;
    float sn = ((-1.9515295891e-4f * z + 8.3321608736e-3f) * z - 1.6666654611e-1f) * z * phi + phi;
    return (vec2){c, sn};
}

/* sample_concentric_disk, with the point's radius |r| in *radius. */
static ALWAYS_INLINE vec2 concentric_disk(vec2 u, float *radius)
{
    /* map u to [-1,1]^2, then squares to concentric rings (Shirley & Chiu 1997):
     * r = ox, theta = pi/4 oy/ox when |ox| > |oy|, else r = oy, theta = pi/2 - pi/4 ox/oy, whose
     * cos and sin are the sin and cos of pi/4 ox/oy */
    float ox = 2.0f * u.x - 1.0f, oy = 2.0f * u.y - 1.0f;
    *radius = 0.0f;
    if (ox == 0.0f && oy == 0.0f)
        return (vec2){0.0f, 0.0f};
    /* the two wedges as selects, not a branch: which one u falls in is a coin toss, and a
     * mispredicted branch cost more than the map (perf annotate) */
    bool x_wedge = fabsf(ox) > fabsf(oy);
    float r = x_wedge ? ox : oy;
    float other = x_wedge ? oy : ox;
    *radius = fabsf(r);
    vec2 cs = cos_sin_quarter((MCPT_PI / 4.0f) * (other / r));
    return x_wedge ? (vec2){r * cs.x, r * cs.y} : (vec2){r * cs.y, r * cs.x};
}

vec2 sample_concentric_disk(vec2 u)
{
    float r;
    return concentric_disk(u, &r);
}

vec2 sample_invert_concentric_disk(vec2 p)
{
    /* PBRT 4e, ch. A.5, "Sampling Multidimensional Functions": the wedge of p gives which of
     * ox, oy was the (signed) radius; the angle inside the wedge gives the other */
    float theta = atan2f(p.y, p.x); /* (-pi, pi] */
    float r = sqrtf(p.x * p.x + p.y * p.y);
    float ox, oy;
    if (fabsf(theta) < MCPT_PI / 4.0f || fabsf(theta) > 3.0f * MCPT_PI / 4.0f) {
        ox = r = copysignf(r, p.x);
        if (p.x < 0.0f)
            oy = (p.y < 0.0f ? MCPT_PI + theta : theta - MCPT_PI) * r / (MCPT_PI / 4.0f);
        else
            oy = theta * r / (MCPT_PI / 4.0f);
    } else {
        oy = r = copysignf(r, p.y);
        if (p.y < 0.0f)
            ox = -(MCPT_PI / 2.0f + theta) * r / (MCPT_PI / 4.0f);
        else
            ox = (MCPT_PI / 2.0f - theta) * r / (MCPT_PI / 4.0f);
    }
    return (vec2){0.5f * (ox + 1.0f), 0.5f * (oy + 1.0f)};
}

vec3 sample_cosine_hemisphere(vec2 u)
{
    /* Malley: a uniform disk point lifted to the hemisphere is cosine distributed; z from the
     * ring's radius r, |d| in exact arithmetic, which is known before the angle's division and
     * polynomial, so that the square root runs beside them instead of after */
    float r;
    vec2 d = concentric_disk(u, &r);
    float z = sqrtf(max_f(0.0f, 1.0f - r * r));
    return (vec3){d.x, d.y, z};
}

float pdf_cosine_hemisphere(float cos_theta) { return cos_theta * MCPT_INV_PI; }

vec2 sample_invert_cosine_hemisphere(vec3 w)
{
    return sample_invert_concentric_disk((vec2){w.x, w.y});
}

/* Azimuth phi / (2 pi) of (x, y) in [0, 1). */
static float azimuth_fraction(float x, float y)
{
    float f = atan2f(y, x) * (0.5f * MCPT_INV_PI);
    f = f < 0.0f ? f + 1.0f : f;
    return f < 1.0f ? f : 0.0f;
}

vec3 sample_uniform_hemisphere(vec2 u)
{
    /* z uniform in [0,1] gives uniform area on the hemisphere (Archimedes) */
    float z = u.x;
    float r = sqrtf(max_f(0.0f, 1.0f - z * z));
    float phi = 2.0f * MCPT_PI * u.y;
    return (vec3){r * cosf(phi), r * sinf(phi), z};
}

float pdf_uniform_hemisphere(void) { return 0.5f * MCPT_INV_PI; }

vec2 sample_invert_uniform_hemisphere(vec3 w) { return (vec2){w.z, azimuth_fraction(w.x, w.y)}; }

vec3 sample_uniform_sphere(vec2 u)
{
    /* z uniform in [-1, 1], phi uniform (Archimedes' hat-box theorem).  Some tutorials normalise
     * a vector of three standard normal deviates instead (Muller 1959): correct, since the
     * Gaussian is rotation invariant, but it costs three normal deviates (four uniforms by
     * Box-Muller) and a sqrt, and has no simple inverse: a stratified 2D point does not carry
     * over to the sphere. */
    float z = 1.0f - 2.0f * u.x;
    float r = sqrtf(max_f(0.0f, 1.0f - z * z));
    float phi = 2.0f * MCPT_PI * u.y;
    return (vec3){r * cosf(phi), r * sinf(phi), z};
}

float pdf_uniform_sphere(void) { return 0.25f * MCPT_INV_PI; }

vec2 sample_invert_uniform_sphere(vec3 w)
{
    return (vec2){0.5f * (1.0f - w.z), azimuth_fraction(w.x, w.y)};
}

/* sin^2(1.5 deg): below it a cone counts as narrow (PBRT 4e, ch. 6, "Spheres") */
static const float CONE_NARROW_SIN2 = 0.00068523f;

struct sample_cone sample_cone_from_cos(float cos_theta_max)
{
    struct sample_cone c;
    c.cos_theta_max = cos_theta_max;
    c.sin2_theta_max = max_f(0.0f, 1.0f - cos_theta_max * cos_theta_max);
    c.one_minus_cos_max = 1.0f - cos_theta_max;
    c.is_narrow = false; /* the digits 1 - cos theta_max lost are gone already */
    return c;
}

struct sample_cone sample_cone_from_sin2(float sin2_theta_max)
{
    struct sample_cone c;
    c.sin2_theta_max = sin2_theta_max;
    c.cos_theta_max = sqrtf(max_f(0.0f, 1.0f - sin2_theta_max));
    c.is_narrow = sin2_theta_max < CONE_NARROW_SIN2;
    /* Taylor: 1 - cos theta_max = 1 - sqrt(1 - s) ~ s / 2 */
    c.one_minus_cos_max = c.is_narrow ? sin2_theta_max / 2.0f : 1.0f - c.cos_theta_max;
    return c;
}

void sample_uniform_cone_theta(float u0, const struct sample_cone *cone, float *cos_theta,
                               float *sin2_theta)
{
    if (cone->is_narrow) {
        /* Taylor: sin^2 theta = 1 - cos^2 theta ~ 2 (1 - cos theta) = u0 sin^2 theta_max */
        *sin2_theta = cone->sin2_theta_max * u0;
        *cos_theta = sqrtf(1.0f - *sin2_theta);
    } else {
        /* cos theta uniform in [cos theta_max, 1]: solid angle is linear in cos theta */
        *cos_theta = (cone->cos_theta_max - 1.0f) * u0 + 1.0f;
        *sin2_theta = 1.0f - *cos_theta * *cos_theta;
    }
}

vec3 sample_uniform_cone(vec2 u, const struct sample_cone *cone)
{
    float cos_theta, sin2_theta;
    sample_uniform_cone_theta(u.x, cone, &cos_theta, &sin2_theta);
    float sin_theta = sqrtf(max_f(0.0f, sin2_theta));
    float phi = 2.0f * MCPT_PI * u.y;
    return (vec3){sin_theta * cosf(phi), sin_theta * sinf(phi), cos_theta};
}

float pdf_uniform_cone(const struct sample_cone *cone)
{
    return 1.0f / (2.0f * MCPT_PI * cone->one_minus_cos_max);
}

vec2 sample_invert_uniform_cone(vec3 w, const struct sample_cone *cone)
{
    /* u0 = (1 - cos theta) / (1 - cos theta_max); a narrow cone reads sin^2 theta = x^2 + y^2 */
    float u0 = cone->is_narrow ? (w.x * w.x + w.y * w.y) / cone->sin2_theta_max
                               : (1.0f - w.z) / cone->one_minus_cos_max;
    return (vec2){u0, azimuth_fraction(w.x, w.y)};
}

vec2 sample_uniform_triangle(vec2 u)
{
    /* PBRT 3e, ch. 13, "Sampling a Triangle": b0 = 1 - sqrt(u0), b1 = u1 sqrt(u0) */
    float su0 = sqrtf(u.x);
    return (vec2){1.0f - su0, u.y * su0};
}

vec2 sample_invert_uniform_triangle(vec2 b)
{
    /* sqrt(u0) = 1 - b0, u1 = b1 / sqrt(u0) */
    float su0 = 1.0f - b.x;
    return (vec2){su0 * su0, su0 > 0.0f ? b.y / su0 : 0.0f};
}

/* ---- bilinear and linear densities on [0, 1] ---- */

static float lerpf(float t, float a, float b) { return (1.0f - t) * a + t * b; }

/* x in [0, 1) with density 2 lerp(x, a, b) / (a + b): the root of the quadratic CDF
 * (a x + (b - a) x^2 / 2) 2 / (a + b) = u in the form that does not cancel,
 * x = u (a + b) / (a + sqrt(lerp(u, a^2, b^2))) (PBRT 4e, ch. A.5, SampleLinear). */
static float sample_linear(float u, float a, float b)
{
    if (u == 0.0f && a == 0.0f)
        return 0.0f;
    float x = u * (a + b) / (a + sqrtf(lerpf(u, a * a, b * b)));
    return min_f(x, 0x1.fffffep-1f);
}

/* The CDF of sample_linear at x: u = x (a (2 - x) + b x) / (a + b). */
static float invert_linear(float x, float a, float b)
{
    return x * (a * (2.0f - x) + b * x) / (a + b);
}

vec2 sample_bilinear(vec2 u, const float w[4])
{
    /* y by its marginal (w0 + w1 at y = 0, w2 + w3 at y = 1), then x given y */
    float y = sample_linear(u.y, w[0] + w[1], w[2] + w[3]);
    float x = sample_linear(u.x, lerpf(y, w[0], w[2]), lerpf(y, w[1], w[3]));
    return (vec2){x, y};
}

float pdf_bilinear(vec2 p, const float w[4])
{
    if (p.x < 0.0f || p.x > 1.0f || p.y < 0.0f || p.y > 1.0f)
        return 0.0f;
    float sum = w[0] + w[1] + w[2] + w[3];
    if (sum == 0.0f)
        return 1.0f; /* all weights 0: sample_linear is the identity */
    /* pdf = 4 bilerp(p, w) / sum w: the bilinear function over its integral sum w / 4 */
    float bilerp = (1.0f - p.x) * (1.0f - p.y) * w[0] + p.x * (1.0f - p.y) * w[1] +
                   (1.0f - p.x) * p.y * w[2] + p.x * p.y * w[3];
    return 4.0f * bilerp / sum;
}

vec2 sample_invert_bilinear(vec2 p, const float w[4])
{
    return (vec2){invert_linear(p.x, lerpf(p.y, w[0], w[2]), lerpf(p.y, w[1], w[3])),
                  invert_linear(p.y, w[0] + w[1], w[2] + w[3])};
}

/* ---- spherical triangles (Arvo 1995) ---- */

/* The angle between unit vectors a and b, precise near 0 and pi (PBRT 4e, ch. 3, "Vectors",
 * AngleBetween): 2 asin(|b - a| / 2), or pi - 2 asin(|a + b| / 2) past 90 degrees. */
static float angle_between(vec3 a, vec3 b)
{
    if (v3_dot(a, b) < 0.0f)
        return MCPT_PI - 2.0f * asinf(min_f(1.0f, 0.5f * v3_length(v3_add(a, b))));
    return 2.0f * asinf(min_f(1.0f, 0.5f * v3_length(v3_sub(b, a))));
}

/* normalize(v), or false when v is 0 (or not finite). */
static bool normalize_to(vec3 v, vec3 *out)
{
    float len = v3_length(v);
    if (!(len > 0.0f) || !isfinite(len))
        return false;
    *out = v3_scale(v, 1.0f / len);
    return true;
}

float sample_spherical_triangle_area(vec3 a, vec3 b, vec3 c)
{
    /* Omega = 2 atan2(|a . (b x c)|, 1 + a.b + b.c + c.a) */
    float num = fabsf(v3_dot(a, v3_cross(b, c)));
    float den = 1.0f + v3_dot(a, b) + v3_dot(b, c) + v3_dot(c, a);
    return 2.0f * atan2f(num, den);
}

bool sample_sph_triangle_init(vec3 a, vec3 b, vec3 c, struct sample_sph_triangle *st)
{
    /* the unit normals of the planes of the edges through a: the angle between them is the
     * interior angle alpha, so cos alpha = n_ab . n_ac and sin alpha = |n_ab x n_ac|, without
     * a trigonometric function */
    vec3 n_ab, n_ac;
    if (!normalize_to(v3_cross(a, b), &n_ab) || !normalize_to(v3_cross(a, c), &n_ac) ||
        !normalize_to(v3_sub(c, v3_scale(a, v3_dot(c, a))), &st->c_perp))
        return false;
    st->a = a;
    st->b = b;
    st->c = c;
    st->cos_alpha = v3_dot(n_ab, n_ac);
    st->sin_alpha = v3_length(v3_cross(n_ab, n_ac));
    st->cos_ab = v3_dot(a, b);
    st->area = sample_spherical_triangle_area(a, b, c);
    return st->area > 0.0f && st->sin_alpha > 0.0f;
}

vec3 sample_spherical_triangle(const struct sample_sph_triangle *st, vec2 u)
{
    /* Arvo 1995, sec. 3: the sub-triangle a, b, c' of area A' = u0 Omega has
     *   cos |a c'| = q = ((v t - w s) cos alpha - v) / ((v s + w t) sin alpha),
     * s = sin(A' - alpha), t = cos(A' - alpha), w = t - cos alpha, v = s + sin alpha cos |a b|;
     * s and t by the angle-difference formulas, so only A' needs a sine and a cosine */
    float a_sub = u.x * st->area;
    float sin_a = sinf(a_sub), cos_a = cosf(a_sub);
    float s = sin_a * st->cos_alpha - cos_a * st->sin_alpha;
    float t = cos_a * st->cos_alpha + sin_a * st->sin_alpha;
    float w = t - st->cos_alpha;
    float v = s + st->sin_alpha * st->cos_ab;
    float q = ((v * t - w * s) * st->cos_alpha - v) / ((v * s + w * t) * st->sin_alpha);
    q = min_f(1.0f, max_f(-1.0f, q));
    vec3 c_sub = v3_add(v3_scale(st->a, q), v3_scale(st->c_perp, sqrtf(max_f(0.0f, 1.0f - q * q))));
    /* on the arc b -> c', 1 - cos theta uniform in [0, 1 - cos |b c'|]; 1 - cos = |x - b|^2 / 2
     * keeps its digits for a small arc */
    vec3 d = v3_sub(c_sub, st->b);
    float one_minus_z = u.y * 0.5f * v3_dot(d, d);
    float z = 1.0f - one_minus_z;
    vec3 perp;
    if (!normalize_to(v3_sub(c_sub, v3_scale(st->b, v3_dot(c_sub, st->b))), &perp))
        return st->b; /* c' = b: the arc has no length */
    float sin_theta = sqrtf(max_f(0.0f, one_minus_z * (2.0f - one_minus_z)));
    return v3_normalize(v3_add(v3_scale(st->b, z), v3_scale(perp, sin_theta)));
}

float pdf_spherical_triangle(const struct sample_sph_triangle *st) { return 1.0f / st->area; }

vec2 sample_invert_spherical_triangle(const struct sample_sph_triangle *st, vec3 w)
{
    /* c' lies on the great circle through b and w and on the arc a -> c: along the line where
     * their planes meet, (b x w) x (c x a), on the side of a + c */
    vec3 c_sub;
    if (!normalize_to(v3_cross(v3_cross(st->b, w), v3_cross(st->c, st->a)), &c_sub))
        return (vec2){0.0f, 0.0f}; /* w = b: every u0 maps there */
    if (v3_dot(c_sub, v3_add(st->a, st->c)) < 0.0f)
        c_sub = v3_neg(c_sub);
    /* u0 = area(a, b, c') / Omega; u1 = (1 - w.b) / (1 - c'.b) = |w - b|^2 / |c' - b|^2 */
    float u0 = sample_spherical_triangle_area(st->a, st->b, c_sub) / st->area;
    vec3 dw = v3_sub(w, st->b), dc = v3_sub(c_sub, st->b);
    float dc2 = v3_dot(dc, dc);
    float u1 = dc2 > 0.0f ? v3_dot(dw, dw) / dc2 : 0.0f;
    return (vec2){min_f(1.0f, max_f(0.0f, u0)), min_f(1.0f, max_f(0.0f, u1))};
}

/* ---- spherical rectangles (Urena, Fajardo & King 2013) ---- */

/* Solid angle of the rectangle [x0, xa] x [y0, y1] at z = z0 seen from the origin: two
 * spherical triangles (Van Oosterom & Strackee 1983). */
static float rect_solid_angle(float x0, float xa, float y0, float y1, float z0)
{
    vec3 v00 = v3_normalize(v3(x0, y0, z0)), v10 = v3_normalize(v3(xa, y0, z0));
    vec3 v11 = v3_normalize(v3(xa, y1, z0)), v01 = v3_normalize(v3(x0, y1, z0));
    return sample_spherical_triangle_area(v00, v10, v11) +
           sample_spherical_triangle_area(v00, v11, v01);
}

bool sample_sph_rect_init(vec3 o, vec3 corner, vec3 e1, vec3 e2, struct sample_sph_rect *sr)
{
    float len1 = v3_length(e1), len2 = v3_length(e2);
    if (!(len1 > 0.0f && len2 > 0.0f) || fabsf(v3_dot(e1, e2)) > 1e-5f * len1 * len2)
        return false;
    /* the frame of the paper, sec. 3: x, y along the edges, the rectangle at z0 < 0 */
    sr->o = o;
    sr->x = v3_scale(e1, 1.0f / len1);
    sr->y = v3_normalize(v3_sub(e2, v3_scale(sr->x, v3_dot(e2, sr->x))));
    sr->z = v3_cross(sr->x, sr->y);
    vec3 d = v3_sub(corner, o);
    sr->z0 = v3_dot(d, sr->z);
    if (sr->z0 > 0.0f) {
        sr->z = v3_neg(sr->z);
        sr->z0 = -sr->z0;
    }
    if (!(sr->z0 < 0.0f))
        return false; /* o lies in the rectangle's plane */
    sr->x0 = v3_dot(d, sr->x);
    sr->y0 = v3_dot(d, sr->y);
    sr->x1 = sr->x0 + len1;
    sr->y1 = sr->y0 + len2;
    /* the planes through o and each edge, and the interior angles gamma_i between them */
    vec3 v00 = v3(sr->x0, sr->y0, sr->z0), v10 = v3(sr->x1, sr->y0, sr->z0);
    vec3 v11 = v3(sr->x1, sr->y1, sr->z0), v01 = v3(sr->x0, sr->y1, sr->z0);
    vec3 n0, n1, n2, n3;
    if (!normalize_to(v3_cross(v00, v10), &n0) || !normalize_to(v3_cross(v10, v11), &n1) ||
        !normalize_to(v3_cross(v11, v01), &n2) || !normalize_to(v3_cross(v01, v00), &n3))
        return false;
    float g2 = angle_between(v3_neg(n2), n3), g3 = angle_between(v3_neg(n3), n0);
    sr->b0 = n0.z;
    sr->b1 = n2.z;
    sr->k = g2 + g3;
    /* S = g0 + g1 + g2 + g3 - 2 pi cancels for a small rectangle: two triangles instead */
    sr->area = rect_solid_angle(sr->x0, sr->x1, sr->y0, sr->y1, sr->z0);
    return sr->area > 0.0f && isfinite(sr->area);
}

vec3 sample_spherical_rectangle(const struct sample_sph_rect *sr, vec2 u)
{
    /* Urena et al. 2013, sec. 4.1: the sub-rectangle angle au = u0 S - gamma2 - gamma3 gives
     * fu = (cos au b0 - b1) / sin au, cu = sign(fu) / sqrt(fu^2 + b0^2) (the cosine of the
     * angle of the plane x = xu), xu = -cu z0 / sqrt(1 - cu^2) */
    float au = u.x * sr->area - sr->k;
    float fu = (cosf(au) * sr->b0 - sr->b1) / sinf(au);
    float cu = copysignf(1.0f / sqrtf(fu * fu + sr->b0 * sr->b0), fu);
    cu = min_f(0x1.fffffep-1f, max_f(-0x1.fffffep-1f, cu));
    float xu = -(cu * sr->z0) / sqrtf(max_f(0.0f, 1.0f - cu * cu));
    xu = min_f(sr->x1, max_f(sr->x0, xu));
    /* sec. 4.2: along x = xu, h = y / sqrt(d^2 + y^2) (the sine of the elevation) is uniform
     * in solid angle, d = sqrt(xu^2 + z0^2) */
    float dd = sqrtf(xu * xu + sr->z0 * sr->z0);
    float h0 = sr->y0 / sqrtf(dd * dd + sr->y0 * sr->y0);
    float h1 = sr->y1 / sqrtf(dd * dd + sr->y1 * sr->y1);
    float hv = lerpf(u.y, h0, h1), hv2 = hv * hv;
    float yv = hv2 < 1.0f - 1e-6f ? hv * dd / sqrtf(1.0f - hv2) : sr->y1;
    yv = min_f(sr->y1, max_f(sr->y0, yv));
    return v3_add(sr->o, v3_add(v3_add(v3_scale(sr->x, xu), v3_scale(sr->y, yv)),
                                v3_scale(sr->z, sr->z0)));
}

float pdf_spherical_rectangle(const struct sample_sph_rect *sr) { return 1.0f / sr->area; }

vec2 sample_invert_spherical_rectangle(const struct sample_sph_rect *sr, vec3 p)
{
    /* u0 = S(x0 .. xu) / S, the sub-rectangle's share; u1 = (h - h0) / (h1 - h0) */
    vec3 d = v3_sub(p, sr->o);
    float xu = min_f(sr->x1, max_f(sr->x0, v3_dot(d, sr->x)));
    float yv = min_f(sr->y1, max_f(sr->y0, v3_dot(d, sr->y)));
    float u0 = xu > sr->x0 ? rect_solid_angle(sr->x0, xu, sr->y0, sr->y1, sr->z0) / sr->area : 0.0f;
    float dd2 = xu * xu + sr->z0 * sr->z0;
    float h0 = sr->y0 / sqrtf(dd2 + sr->y0 * sr->y0);
    float h1 = sr->y1 / sqrtf(dd2 + sr->y1 * sr->y1);
    float h = yv / sqrtf(dd2 + yv * yv);
    float u1 = h1 != h0 ? (h - h0) / (h1 - h0) : 0.0f;
    return (vec2){min_f(1.0f, max_f(0.0f, u0)), min_f(1.0f, max_f(0.0f, u1))};
}

/* ---- discrete distributions: the alias method ---- */

bool sample_alias_build(const double *weights, uint32_t n, struct sample_alias_bin *bins)
{
    if (n == 0)
        return false;
    double total = 0.0;
    for (uint32_t i = 0; i < n; i++) {
        if (!(weights[i] >= 0.0) || !isfinite(weights[i]))
            return false;
        total += weights[i];
    }
    uint32_t *small = malloc(sizeof(uint32_t) * n), *large = malloc(sizeof(uint32_t) * n);
    double *p = malloc(sizeof(double) * n);
    if (!small || !large || !p) {
        free(small);
        free(large);
        free(p);
        return false;
    }
    /* scaled probabilities p_i = n pmf_i: bins below 1 are topped up from bins above 1 */
    uint32_t n_small = 0, n_large = 0, any_positive = 0;
    for (uint32_t i = 0; i < n; i++) {
        double pmf = total > 0.0 ? weights[i] / total : 1.0 / n;
        bins[i].pmf = (float)pmf;
        bins[i].alias = i;
        p[i] = pmf * n;
        if (p[i] > 0.0)
            any_positive = i;
        if (p[i] < 1.0)
            small[n_small++] = i;
        else
            large[n_large++] = i;
    }
    /* Vose: pair each under-full bin with an over-full one, which gives away 1 - p_small */
    while (n_small > 0 && n_large > 0) {
        uint32_t s = small[--n_small], l = large[--n_large];
        bins[s].q = (float)p[s];
        bins[s].alias = l;
        p[l] = (p[l] + p[s]) - 1.0;
        if (p[l] < 1.0)
            small[n_small++] = l;
        else
            large[n_large++] = l;
    }
    /* what is left is full up to rounding; a zero weight left over by rounding keeps q = 0 */
    while (n_large > 0) {
        uint32_t l = large[--n_large];
        bins[l].q = 1.0f;
    }
    while (n_small > 0) {
        uint32_t s = small[--n_small];
        bool is_zero = total > 0.0 && weights[s] == 0.0;
        bins[s].q = is_zero ? 0.0f : 1.0f;
        bins[s].alias = is_zero ? any_positive : s;
    }
    free(small);
    free(large);
    free(p);
    return true;
}

uint32_t sample_alias_pick(const struct sample_alias_bin *bins, uint32_t n, float u, float *pmf)
{
    /* bin i = floor(u n); the fraction u n - i decides between i and its alias */
    double un = (double)u * n;
    uint32_t i = un < (double)n ? (uint32_t)un : n - 1;
    float up = (float)(un - i);
    uint32_t picked = up < bins[i].q ? i : bins[i].alias;
    if (pmf)
        *pmf = bins[picked].pmf;
    return picked;
}

/* ---- MIS ---- */

float mis_power(float pdf_a, float pdf_b)
{
    /* w_a = pdf_a^2 / (pdf_a^2 + pdf_b^2); inf/inf guarded for extreme pdfs */
    if (isinf(pdf_a * pdf_a))
        return 1.0f;
    float a2 = pdf_a * pdf_a, b2 = pdf_b * pdf_b;
    return a2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}
