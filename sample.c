/* sample.c - RNG, samplers, warps and MIS weights.
 * Seeding rule: the PCG32 stream of a sample is
 *   initstate = hash(seed, pixel_idx, sample_idx), initseq = hash(initstate),
 * so a sample's values depend on (seed, pixel, sample index, dimension) only; the stratified
 * and Sobol' samplers are stateless hashes of the same coordinates (docs/sampling.md).
 * References: O'Neill 2014 (PCG); Kensler 2013 (correlated multi-jittered sampling); Burley
 * 2020 and Joe & Kuo 2008 (Owen-scrambled Sobol'); Shirley & Chiu 1997 (concentric disk);
 * PBRT 4e, ch. A.5, "Sampling Multidimensional Functions"; Veach 1997, ch. 9 (MIS). */
#include "sample.h"

#include <stdlib.h>
#include <string.h>

#include "sobol_matrices.h"

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

static uint32_t sobol_joint_index(const struct sampler *s);

void sample_start_spp(struct sampler *s, enum sampler_kind kind, uint64_t seed, uint32_t pixel_idx,
                      uint32_t sample_idx, uint32_t set_spp)
{
    s->kind = kind;
    s->seed = seed;
    s->pixel_idx = pixel_idx;
    s->sample_idx = sample_idx;
    s->dim = 0;
    s->set_spp = set_spp;
    s->cmj_cols = 1;
    s->pixel_hash = sample_hash64(seed ^ sample_hash64(0x9e3779b97f4a7c15ULL + pixel_idx));
    if (kind == SAMPLER_INDEPENDENT) {
        uint64_t h = sample_hash64(seed ^ sample_hash64(((uint64_t)pixel_idx << 32) | sample_idx));
        sample_pcg32_seed(&s->rng, h, sample_hash64(h));
    } else {
        s->rng = (struct pcg32){0, 1};
        if (kind == SAMPLER_STRATIFIED && set_spp > 1)
            s->cmj_cols = cmj_columns(set_spp);
    }
    s->sobol_index = kind == SAMPLER_SOBOL ? sobol_joint_index(s) : 0;
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
    uint32_t m = s->cmj_cols, n = (n_set + m - 1) / m;
    uint32_t sp = kensler_permute(i, n_set, p * 0x51633e2du);
    uint32_t sx = kensler_permute(sp % m, m, p * 0x68bc21ebu);
    uint32_t sy = kensler_permute(sp / m, n, p * 0x02e5be93u);
    /* x = (sx + (sy + jx) / n) / m = (sx n + sy + jx) / (m n) */
    float x = in_stratum(sx * n + sy, m * n, hash_jitter(sp, p * 0x967a889bu));
    float y = in_stratum(sp, n_set, hash_jitter(sp, p * 0x368cc8b7u));
    return (vec2){x, y};
}

/* -- Sobol': Burley 2020, "Practical Hash-based Owen Scrambling", JCGT 9(4) -- */

static uint32_t reverse_bits32(uint32_t x)
{
    x = __builtin_bswap32(x); /* GCC and Clang builtin: the bytes reversed */
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

/* Nested uniform (Owen 1995) scrambling of a 32-bit fraction, as in Burley 2020: after the bit
 * reversal the LK hash flips each digit as a function of the more significant digits only.  A
 * bijection that maps every aligned block of 2^k values onto another, so it keeps every
 * elementary-interval property of the points it scrambles. */
static uint32_t nested_uniform_scramble(uint32_t x, uint32_t seed)
{
    return reverse_bits32(laine_karras_permutation(reverse_bits32(x), seed));
}

/* nested_uniform_scramble(sample_sobol_u32(index, dim), seed).  For dimensions 0 and 1 the
 * scramble's first reversal undoes the one that puts the digits in fraction order, so both are
 * skipped: the hot path of every padding request. */
static uint32_t scrambled_sobol(uint32_t index, uint32_t dim, uint32_t seed)
{
    if (dim == 0)
        return reverse_bits32(laine_karras_permutation(index, seed));
    if (dim == 1)
        return reverse_bits32(laine_karras_permutation(pascal_digits(index), seed));
    return nested_uniform_scramble(sample_sobol_u32(index, dim), seed);
}

/* The per-pixel shuffle of the sample index: Owen-scrambled, so power-of-two prefixes of a
 * pixel's samples map to aligned blocks of the sequence, which are (t, m, s)-nets. */
static uint32_t sobol_joint_index(const struct sampler *s)
{
    return nested_uniform_scramble(s->sample_idx, dim_seed(s, UINT32_MAX, 0));
}

/* Dimension dim < SAMPLE_SOBOL_JOINT_DIMS: one shuffled Sobol' point per sample for all the
 * joint dimensions (Burley 2020: shuffled_scrambled_sobol4d, the index Owen-scrambled too);
 * its index, sobol_joint_index, is computed once in sample_start_spp. */
static float sobol_joint_1d(const struct sampler *s, uint32_t dim)
{
    return fraction_to_float(scrambled_sobol(s->sobol_index, dim, dim_seed(s, dim, 1)));
}

/* Padding (Burley 2020): a request at dimension dim >= the joint ones reads Sobol' dimensions
 * 0 (and 1), a (0,2)-sequence, with its own index shuffle and its own scrambles, so requests
 * are mutually independent and each is stratified in itself. */
struct pad_seeds {
    uint32_t index; /* shuffle of the sample index */
    uint32_t x;     /* scramble of the first coordinate */
    uint32_t y;     /* scramble of the second */
};

/* The three seeds of a padding request from one 64-bit hash: its halves lo and hi, and
 * lo ^ mix(hi); each uniform, and pairwise independent for a uniform hash. */
static struct pad_seeds pad_seeds(const struct sampler *s, uint32_t dim)
{
    uint64_t h = sample_hash64(s->pixel_hash ^ ((uint64_t)dim << 32 | 2u));
    uint32_t lo = (uint32_t)h, hi = (uint32_t)(h >> 32);
    return (struct pad_seeds){lo, hi, lo ^ (hi * 0x9e3779b9u + 0x7f4a7c15u)};
}

static float sobol_pad_1d(const struct sampler *s, uint32_t dim)
{
    struct pad_seeds seed = pad_seeds(s, dim);
    uint32_t index = nested_uniform_scramble(s->sample_idx, seed.index);
    return fraction_to_float(scrambled_sobol(index, 0, seed.x));
}

static vec2 sobol_pad_2d(const struct sampler *s, uint32_t dim)
{
    struct pad_seeds seed = pad_seeds(s, dim);
    uint32_t index = nested_uniform_scramble(s->sample_idx, seed.index);
    uint32_t x = scrambled_sobol(index, 0, seed.x);
    uint32_t y = scrambled_sobol(index, 1, seed.y);
    return (vec2){fraction_to_float(x), fraction_to_float(y)};
}

float sample_1d(struct sampler *s)
{
    uint32_t dim = s->dim++;
    switch (s->kind) {
    case SAMPLER_STRATIFIED:
        return stratified_1d(s, dim);
    case SAMPLER_SOBOL:
        return dim < SAMPLE_SOBOL_JOINT_DIMS ? sobol_joint_1d(s, dim) : sobol_pad_1d(s, dim);
    case SAMPLER_INDEPENDENT:
        break;
    }
    return sample_pcg32_float(&s->rng);
}

vec2 sample_2d(struct sampler *s)
{
    uint32_t dim = s->dim;
    if (s->kind == SAMPLER_STRATIFIED) {
        s->dim += 2;
        return stratified_2d(s, dim);
    }
    if (s->kind == SAMPLER_SOBOL && dim >= SAMPLE_SOBOL_JOINT_DIMS) {
        s->dim += 2;
        return sobol_pad_2d(s, dim);
    }
    /* independent, and Sobol' inside the joint dimensions: two consecutive dimensions */
    float x = sample_1d(s);
    float y = sample_1d(s);
    return (vec2){x, y};
}

/* ---- warps ---- */

vec2 sample_concentric_disk(vec2 u)
{
    /* map u to [-1,1]^2, then squares to concentric rings (Shirley & Chiu 1997) */
    float ox = 2.0f * u.x - 1.0f, oy = 2.0f * u.y - 1.0f;
    if (ox == 0.0f && oy == 0.0f)
        return (vec2){0.0f, 0.0f};
    float r, theta;
    if (fabsf(ox) > fabsf(oy)) {
        r = ox;
        theta = (MCPT_PI / 4.0f) * (oy / ox);
    } else {
        r = oy;
        theta = (MCPT_PI / 2.0f) - (MCPT_PI / 4.0f) * (ox / oy);
    }
    return (vec2){r * cosf(theta), r * sinf(theta)};
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
    /* Malley: a uniform disk point lifted to the hemisphere is cosine distributed */
    vec2 d = sample_concentric_disk(u);
    float z = sqrtf(fmaxf(0.0f, 1.0f - d.x * d.x - d.y * d.y));
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
    float r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
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
    float r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
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
    c.sin2_theta_max = fmaxf(0.0f, 1.0f - cos_theta_max * cos_theta_max);
    c.one_minus_cos_max = 1.0f - cos_theta_max;
    c.is_narrow = false; /* the digits 1 - cos theta_max lost are gone already */
    return c;
}

struct sample_cone sample_cone_from_sin2(float sin2_theta_max)
{
    struct sample_cone c;
    c.sin2_theta_max = sin2_theta_max;
    c.cos_theta_max = sqrtf(fmaxf(0.0f, 1.0f - sin2_theta_max));
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
    float sin_theta = sqrtf(fmaxf(0.0f, sin2_theta));
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
