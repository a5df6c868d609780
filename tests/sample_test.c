/* tests/sample_test.c - sample.c: PCG32 against O'Neill's reference output, stream jumps,
 * the seeding rule (values depend on seed, pixel, sample and dimension only), warps' moments
 * against their analytic values, and the power heuristic (Veach 1997, sec. 9.2.4). */
#include <criterion/criterion.h>

#include "sample.h"

/* pcg32-demo of the PCG C reference (pcg32_srandom_r(42, 54)) prints these first six values. */
Test(sample, pcg32_reference_output)
{
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 42u, 54u);
    const uint32_t expect[6] = {0xa15c02b7u, 0x7b47f409u, 0xba1d3330u,
                                0x83d2f293u, 0xbfa4784bu, 0xcbed606eu};
    for (int i = 0; i < 6; i++)
        cr_assert_eq(sample_pcg32_next(&rng), expect[i], "output %d", i);
}

/* advance(k) equals k calls of next (Brown 1994 jump-ahead). */
Test(sample, pcg32_advance)
{
    struct pcg32 a, b;
    sample_pcg32_seed(&a, 7u, 9u);
    b = a;
    for (int i = 0; i < 12345; i++)
        sample_pcg32_next(&a);
    sample_pcg32_advance(&b, 12345u);
    cr_assert_eq(sample_pcg32_next(&a), sample_pcg32_next(&b));
}

/* A dimension's value depends on (seed, pixel, sample, dim) alone, however it was reached. */
Test(sample, dimension_addressing)
{
    struct sampler s1, s2;
    sample_start(&s1, SAMPLER_INDEPENDENT, 3u, 1000u, 17u);
    float seq[20];
    for (int i = 0; i < 20; i++)
        seq[i] = sample_1d(&s1);
    sample_start(&s2, SAMPLER_INDEPENDENT, 3u, 1000u, 17u);
    sample_set_dim(&s2, 13u);
    cr_assert_eq(sample_1d(&s2), seq[13]);
    sample_start(&s2, SAMPLER_INDEPENDENT, 3u, 1000u, 18u);
    cr_assert_neq(sample_1d(&s2), seq[0], "another sample index gives another stream");
    sample_start(&s2, SAMPLER_INDEPENDENT, 4u, 1000u, 17u);
    cr_assert_neq(sample_1d(&s2), seq[0], "another seed gives another stream");
}

/* Uniforms are in [0, 1) with mean 1/2 and variance 1/12 (within 5 standard errors). */
Test(sample, uniform_moments)
{
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 1u, 1u);
    const int n = 200000;
    double s = 0, s2 = 0;
    for (int i = 0; i < n; i++) {
        float u = sample_pcg32_float(&rng);
        cr_assert(u >= 0.0f && u < 1.0f);
        s += u;
        s2 += (double)u * u;
    }
    double mean = s / n, var = s2 / n - mean * mean;
    cr_assert(fabs(mean - 0.5) < 5.0 * sqrt(1.0 / 12.0 / n), "mean %f", mean);
    cr_assert(fabs(var - 1.0 / 12.0) < 0.002, "variance %f", var);
}

/* Moments of the warps: concentric disk E[r^2] = 1/2; cosine hemisphere E[cos] = 2/3;
 * uniform hemisphere E[cos] = 1/2; uniform triangle E[b0] = E[b1] = 1/3. 5-sigma bounds. */
Test(sample, warp_moments)
{
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 5u, 11u);
    const int n = 100000;
    double r2 = 0, cz = 0, uz = 0, b0 = 0, b1 = 0;
    for (int i = 0; i < n; i++) {
        vec2 u = {sample_pcg32_float(&rng), sample_pcg32_float(&rng)};
        vec2 d = sample_concentric_disk(u);
        r2 += d.x * d.x + d.y * d.y;
        vec3 c = sample_cosine_hemisphere(u);
        cr_assert(c.z >= 0.0f && fabsf(v3_length(c) - 1.0f) < 1e-5f);
        cz += c.z;
        uz += sample_uniform_hemisphere(u).z;
        vec2 b = sample_uniform_triangle(u);
        cr_assert(b.x >= 0.0f && b.y >= 0.0f && b.x + b.y <= 1.0f);
        b0 += b.x;
        b1 += b.y;
    }
    /* standard deviations: r^2 ~ U(0,1): 1/sqrt(12); cos under cosine pdf: sqrt(1/2-4/9);
     * cos under uniform: 1/sqrt(12); barycentric: sqrt(1/18) */
    double k = 5.0 / sqrt((double)n);
    cr_assert(fabs(r2 / n - 0.5) < k * sqrt(1.0 / 12.0), "disk E[r^2] %f", r2 / n);
    cr_assert(fabs(cz / n - 2.0 / 3.0) < k * sqrt(0.5 - 4.0 / 9.0), "E[cos] %f", cz / n);
    cr_assert(fabs(uz / n - 0.5) < k * sqrt(1.0 / 12.0), "uniform E[cos] %f", uz / n);
    cr_assert(fabs(b0 / n - 1.0 / 3.0) < k * sqrt(1.0 / 18.0), "E[b0] %f", b0 / n);
    cr_assert(fabs(b1 / n - 1.0 / 3.0) < k * sqrt(1.0 / 18.0), "E[b1] %f", b1 / n);
}

/* Power heuristic weights of two strategies sum to one; a zero pdf gets zero weight. */
Test(sample, mis_power)
{
    cr_assert_float_eq(mis_power(0.3f, 0.7f) + mis_power(0.7f, 0.3f), 1.0f, 1e-6f);
    cr_assert_float_eq(mis_power(2.0f, 1.0f), 0.8f, 1e-6f);
    cr_assert_eq(mis_power(0.0f, 1.0f), 0.0f);
    cr_assert_eq(mis_power(1.0f, 0.0f), 1.0f);
}
