/* sample.c - RNG, samplers, warps and MIS weights.
 * Seeding rule: the PCG32 stream of a sample is
 *   initstate = hash(seed, pixel_idx, sample_idx), initseq = hash(initstate),
 * so a sample's values depend on (seed, pixel, sample index, dimension) only.
 * References: O'Neill 2014 (PCG); Shirley & Chiu 1997 (concentric disk); PBRT 4e, ch. A.5,
 * "Sampling Multidimensional Functions"; Veach 1997, ch. 9 (MIS). */
#include "sample.h"

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

/* ---- samplers ---- */

void sample_start(struct sampler *s, enum sampler_kind kind, uint64_t seed, uint32_t pixel_idx,
                  uint32_t sample_idx)
{
    s->kind = kind;
    s->seed = seed;
    s->pixel_idx = pixel_idx;
    s->sample_idx = sample_idx;
    s->dim = 0;
    uint64_t h = sample_hash64(seed ^ sample_hash64(((uint64_t)pixel_idx << 32) | sample_idx));
    sample_pcg32_seed(&s->rng, h, sample_hash64(h));
}

void sample_set_dim(struct sampler *s, uint32_t dim)
{
    if (dim > s->dim) {
        sample_pcg32_advance(&s->rng, dim - s->dim);
        s->dim = dim;
    }
}

float sample_1d(struct sampler *s)
{
    s->dim++;
    return sample_pcg32_float(&s->rng);
}

vec2 sample_2d(struct sampler *s)
{
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

vec3 sample_cosine_hemisphere(vec2 u)
{
    /* Malley: a uniform disk point lifted to the hemisphere is cosine distributed */
    vec2 d = sample_concentric_disk(u);
    float z = sqrtf(fmaxf(0.0f, 1.0f - d.x * d.x - d.y * d.y));
    return (vec3){d.x, d.y, z};
}

float pdf_cosine_hemisphere(float cos_theta) { return cos_theta * MCPT_INV_PI; }

vec3 sample_uniform_hemisphere(vec2 u)
{
    /* z uniform in [0,1] gives uniform area on the hemisphere (Archimedes) */
    float z = u.x;
    float r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
    float phi = 2.0f * MCPT_PI * u.y;
    return (vec3){r * cosf(phi), r * sinf(phi), z};
}

float pdf_uniform_hemisphere(void) { return 0.5f * MCPT_INV_PI; }

vec2 sample_uniform_triangle(vec2 u)
{
    /* PBRT 4e, ch. 6, "Triangles": b0 = 1 - sqrt(u0), b1 = u1 sqrt(u0) */
    float su0 = sqrtf(u.x);
    return (vec2){1.0f - su0, u.y * su0};
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
