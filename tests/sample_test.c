/* tests/sample_test.c - sample.c: PCG32 against O'Neill's reference output, stream jumps,
 * the seeding rule (values depend on seed, pixel, sample and dimension only), warps' moments,
 * chi-square fits (tests/chi2.h) and inverses, narrow cones (PBRT 4e, ch. 6, "Spheres"), the
 * alias method (Walker 1977; Vose 1991), the power heuristic (Veach 1997, sec. 9.2.4);
 * the samplers: Sobol' closed forms against Joe & Kuo's matrices, (0,m,2)-nets and 1D strata
 * of power-of-two prefixes kept by Owen scrambling (Burley 2020), multi-jittered sets (Kensler
 * 2013), decorrelated padding; and, through trace.c, the adaptive stopping rule on synthetic
 * streams, thread-count determinism of every sampler and of adaptive sampling, and equal-spp
 * error of the samplers on scenes/direct-plane.txt. */
#include <criterion/criterion.h>
#include <criterion/logging.h>

#include <stdlib.h>

#include "chi2.h"
#include "film.h"
#include "sample.h"
#include "scene.h"
#include "sobol_matrices.h"
#include "trace.h"
#include "test_util.h"

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

/* ---- samplers ---- */

static const enum sampler_kind KINDS[SAMPLER_COUNT] = {SAMPLER_INDEPENDENT, SAMPLER_STRATIFIED,
                                                       SAMPLER_SOBOL};

/* Names and parsing agree, and an unknown name is refused. */
Test(sample, sampler_names)
{
    for (int k = 0; k < SAMPLER_COUNT; k++) {
        enum sampler_kind kind = SAMPLER_INDEPENDENT;
        cr_assert(sample_sampler_parse(sample_sampler_name(KINDS[k]), &kind));
        cr_assert_eq(kind, KINDS[k]);
    }
    enum sampler_kind kind = SAMPLER_SOBOL;
    cr_assert_not(sample_sampler_parse("halton", &kind));
    cr_assert_eq(kind, SAMPLER_SOBOL, "untouched on failure");
}

/* sample_sobol_u32's closed forms for dimensions 0 (radical inverse) and 1 (Pascal's triangle
 * mod 2) and its matrix product for the others equal C_d * bits(index) over GF(2) with the
 * generator matrices built from Joe & Kuo 2008 (sobol_matrices.h). */
Test(sample, sobol_matches_generator_matrices)
{
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 3u, 5u);
    for (int t = 0; t < 20000; t++) {
        uint32_t index = t < 4096 ? (uint32_t)t : sample_pcg32_next(&rng);
        for (uint32_t dim = 0; dim < SAMPLE_SOBOL_MAX_DIMS; dim++) {
            uint32_t x = 0;
            for (int k = 0; k < 32; k++)
                if (index >> k & 1u)
                    x ^= SOBOL_MATRICES[dim][k];
            cr_assert_eq(sample_sobol_u32(index, dim), x, "index %u dim %u", index, dim);
        }
    }
}

/* The nibble table the joint point is computed from is the generator matrices' product with
 * every 4-bit digit: SOBOL_NIBBLES[p][v][d] = C_d * (v << 4p) over GF(2). */
Test(sample, sobol_nibbles_match_generator_matrices)
{
    for (int p = 0; p < 8; p++)
        for (uint32_t v = 0; v < 16; v++)
            for (int d = 0; d < SOBOL_N_DIMS; d++) {
                uint32_t x = 0;
                for (int b = 0; b < 4; b++)
                    if (v >> b & 1u)
                        x ^= SOBOL_MATRICES[d][4 * p + b];
                cr_assert_eq(SOBOL_NIBBLES[p][v][d], x, "digit %d value %u dim %d", p, v, d);
            }
}

/* A sampler started once per pixel (sample_start_pixel) and then per sample
 * (sample_start_index), in any order of sample indices, gives the values of a sampler started
 * afresh for each sample: what it keeps between samples (the pixel's seeds, the joint point,
 * the padded block) is a cache of a function of (seed, pixel, sample, dimension).  Requests of
 * both sizes at every offset of the bounce blocks, in the extra light-sample block, and a sample
 * that starts in the block where the last one ended. */
Test(sample, pixel_start_matches_sample_start)
{
    static const uint32_t order[] = {5, 0, 1, 1000, 3, 5, 77, 2, 4096, 0};
    for (int k = 0; k < SAMPLER_COUNT; k++) {
        struct sampler px;
        sample_start_pixel(&px, KINDS[k], 21u, 4242u, 16u);
        for (size_t i = 0; i < sizeof order / sizeof order[0]; i++) {
            sample_start_index(&px, order[i]);
            /* odd samples start in the block where the previous one ended */
            for (uint32_t dim = i % 2 ? 95 : 0; dim < 100;) {
                bool is_2d = (dim * 7 + order[i]) % 3 == 0;
                struct sampler fresh;
                sample_start_spp(&fresh, KINDS[k], 21u, 4242u, order[i], 16u);
                sample_set_dim(&fresh, dim);
                sample_set_dim(&px, dim);
                if (is_2d) {
                    vec2 a = sample_2d(&px), b = sample_2d(&fresh);
                    cr_assert(a.x == b.x && a.y == b.y, "%s sample %u dim %u (2D)",
                              sample_sampler_name(KINDS[k]), order[i], dim);
                } else {
                    cr_assert(sample_1d(&px) == sample_1d(&fresh), "%s sample %u dim %u",
                              sample_sampler_name(KINDS[k]), order[i], dim);
                }
                dim += is_2d ? 2 + dim % 2 : 1;
            }
            struct sampler fresh;
            sample_start_spp(&fresh, KINDS[k], 21u, 4242u, order[i], 16u);
            sample_set_dim(&fresh, SAMPLE_DIM_LIGHT_EXTRA + 4);
            sample_set_dim(&px, SAMPLE_DIM_LIGHT_EXTRA + 4);
            vec2 a = sample_2d(&px), b = sample_2d(&fresh);
            cr_assert(a.x == b.x && a.y == b.y, "%s sample %u light-sample block",
                      sample_sampler_name(KINDS[k]), order[i]);
        }
    }
}

/* Reading ahead (sample_1d_ahead, sample_2d_ahead: the path loop's BSDF sample before its light
 * sample) gives the values the reads in dimension order give, and leaves the reads before it,
 * and after a jump past it, as they were: bounce after bounce, for every sampler, with a sample
 * that ends its path at a deep bounce (Sobol' fills past the kept ones) and one stratified set
 * size. */
Test(sample, reads_ahead_match_reads_in_order)
{
    static const uint32_t samples[] = {0, 3, 255, 4099};
    for (int k = 0; k < SAMPLER_COUNT; k++) {
        for (size_t i = 0; i < sizeof samples / sizeof samples[0]; i++) {
            struct sampler ahead, in_order;
            sample_start_spp(&ahead, KINDS[k], 7u, 1234u, samples[i], 16u);
            sample_start_spp(&in_order, KINDS[k], 7u, 1234u, samples[i], 16u);
            for (uint32_t b = 0; b < 20; b++) {
                uint32_t dim0 = SAMPLE_DIM_BOUNCE0 + b * SAMPLE_DIMS_PER_BOUNCE;
                float lobe = sample_1d_ahead(&ahead, dim0 + SAMPLE_BOUNCE_BSDF_LOBE);
                vec2 dir = sample_2d_ahead(&ahead, dim0 + SAMPLE_BOUNCE_BSDF_DIR);
                sample_set_dim(&ahead, dim0 + SAMPLE_BOUNCE_LIGHT_CHOICE);
                sample_set_dim(&in_order, dim0 + SAMPLE_BOUNCE_LIGHT_CHOICE);
                float choice_a = sample_1d(&ahead), choice_b = sample_1d(&in_order);
                vec2 light_a = sample_2d(&ahead), light_b = sample_2d(&in_order);
                float lobe_b = sample_1d(&in_order);
                vec2 dir_b = sample_2d(&in_order);
                sample_set_dim(&ahead, dim0 + SAMPLE_BOUNCE_BSDF_DIR + 2);
                float rr_a = sample_1d(&ahead), rr_b = sample_1d(&in_order);
                const char *name = sample_sampler_name(KINDS[k]);
                cr_assert(choice_a == choice_b && light_a.x == light_b.x && light_a.y == light_b.y,
                          "%s sample %u bounce %u: the light sample", name, samples[i], b);
                cr_assert(lobe == lobe_b && dir.x == dir_b.x && dir.y == dir_b.y,
                          "%s sample %u bounce %u: the BSDF sample read ahead", name, samples[i],
                          b);
                cr_assert(rr_a == rr_b, "%s sample %u bounce %u: the roulette", name, samples[i],
                          b);
            }
        }
    }
}

/* The Sobol' sampler computes its padded requests many at a time (sample.c, pad_block: three
 * bounce blocks' requests a fill, as lanes placed by shuffles), and per pixel keeps the seeds
 * of the first fills.  Whatever the order of reads (every bounce block in turn, 1D and 2D reads
 * at every offset of a block, jumps across blocks, the kept fills and those past them), each
 * value must be the request at its dimension computed alone. */
Test(sample, sobol_held_requests_match_requests_alone)
{
    static const uint32_t samples[] = {0, 1, 7, 255, 4097};
    for (uint32_t pixel = 0; pixel < 3; pixel++) {
        struct sampler px;
        sample_start_pixel(&px, SAMPLER_SOBOL, 5u + pixel, 9000u + pixel, 0u);
        for (size_t i = 0; i < sizeof samples / sizeof samples[0]; i++) {
            for (uint32_t pattern = 0; pattern < 4; pattern++) {
                sample_start_index(&px, samples[i]);
                uint32_t dim = SAMPLE_SOBOL_JOINT_DIMS + pattern;
                sample_set_dim(&px, dim);
                while (dim < SAMPLE_DIM_BOUNCE0 + 30 * SAMPLE_DIMS_PER_BOUNCE) {
                    vec2 want = sample_sobol_request(&px, dim);
                    /* patterns: 2D reads, 1D reads, both alternately, and 1D reads that jump */
                    bool is_2d = pattern == 0 || (pattern == 2 && dim % 2 == 0);
                    if (is_2d) {
                        vec2 got = sample_2d(&px);
                        cr_assert(got.x == want.x && got.y == want.y,
                                  "pixel %u sample %u dim %u (2D, pattern %u)", pixel, samples[i],
                                  dim, pattern);
                    } else {
                        cr_assert(sample_1d(&px) == want.x,
                                  "pixel %u sample %u dim %u (pattern %u)", pixel, samples[i], dim,
                                  pattern);
                    }
                    dim += is_2d ? 2 : 1;
                    if (pattern == 3 && dim % 5 == 0) {
                        dim += 2 * SAMPLE_DIMS_PER_BOUNCE + 1;
                        sample_set_dim(&px, dim);
                    }
                }
            }
        }
    }
}

/* Is every elementary interval [a 2^-j, (a+1) 2^-j) x [b 2^-(m-j), (b+1) 2^-(m-j)) hit exactly
 * once by the 2^m points (x, y) (fractions of 2^32)?  That is a (0,m,2)-net in base 2. */
static bool is_02_net(const uint32_t *x, const uint32_t *y, int m)
{
    uint32_t n = 1u << m;
    char *hit = malloc(n);
    cr_assert(hit);
    bool ok = true;
    for (int j = 0; j <= m && ok; j++) {
        memset(hit, 0, n);
        for (uint32_t i = 0; i < n && ok; i++) {
            uint32_t a = j ? x[i] >> (32 - j) : 0, b = m - j ? y[i] >> (32 - (m - j)) : 0;
            uint32_t cell = (a << (m - j)) | b;
            ok = !hit[cell];
            hit[cell] = 1;
        }
    }
    free(hit);
    return ok;
}

/* Sobol' dimensions 0 and 1 form a (0,2)-sequence: the first 2^m points are a (0,m,2)-net
 * (Sobol' 1967; the property padding relies on, Burley 2020). */
Test(sample, sobol_dims_0_1_are_02_nets)
{
    static uint32_t x[1024], y[1024];
    for (int m = 0; m <= 10; m++) {
        for (uint32_t i = 0; i < (1u << m); i++) {
            x[i] = sample_sobol_u32(i + (3u << m), 0); /* an aligned block, not only the first */
            y[i] = sample_sobol_u32(i + (3u << m), 1);
        }
        cr_assert(is_02_net(x, y, m), "m = %d", m);
    }
}

/* Do the values at dimension dim of sample indices first .. first + n - 1 of a pixel put
 * exactly one point in each interval [k/n, (k+1)/n)? */
static bool strata_1d(enum sampler_kind kind, uint32_t pixel, uint32_t first, uint32_t n,
                      uint32_t set_spp, uint32_t dim)
{
    char *hit = calloc(n, 1);
    cr_assert(hit);
    bool ok = true;
    for (uint32_t i = 0; i < n && ok; i++) {
        struct sampler s;
        sample_start_spp(&s, kind, 11u, pixel, first + i, set_spp);
        sample_set_dim(&s, dim);
        float u = sample_1d(&s);
        cr_assert(u >= 0.0f && u < 1.0f);
        uint32_t k = (uint32_t)((double)u * n);
        ok = !hit[k];
        hit[k] = 1;
    }
    free(hit);
    return ok;
}

/* Owen-scrambled Sobol' with per-pixel shuffled indices keeps the strata of every aligned
 * power-of-two block of a pixel's samples (the first 2^m, or samples 3 2^m .. 4 2^m - 1), in
 * every dimension: joint ones (0-3), padded ones, and the extra light-sample block.  Nested
 * uniform scrambling maps aligned blocks onto aligned blocks (Owen 1995; Burley 2020). */
Test(sample, sobol_power_of_two_prefixes_stratified)
{
    static const uint32_t dims[] = {0, 1, 2, 3, 4, 5, 6, 7, 10, 33, SAMPLE_DIM_LIGHT_EXTRA + 1};
    static const uint32_t pixels[] = {0, 77, 123456};
    for (size_t p = 0; p < 3; p++)
        for (size_t d = 0; d < sizeof dims / sizeof dims[0]; d++)
            for (int m = 0; m <= 12; m++)
                for (uint32_t block = 0; block < 4; block += 3)
                    cr_assert(strata_1d(SAMPLER_SOBOL, pixels[p], block << m, 1u << m, 0, dims[d]),
                              "pixel %u dim %u 2^%d block %u", pixels[p], dims[d], m, block);
}

/* sample_2d of the Sobol' sampler gives (0,m,2)-nets for the first 2^m samples, at the joint
 * pixel dimensions (Sobol' dimensions 0 and 1) and at padded pairs (the first bounce's BSDF
 * direction on): scrambling and shuffling keep Sobol's 2D nets. */
Test(sample, sobol_2d_requests_are_02_nets)
{
    cr_assert(SAMPLE_SOBOL_JOINT_DIMS <= SAMPLE_DIM_BOUNCE0 + SAMPLE_BOUNCE_BSDF_DIR,
              "dims below are padded");
    static const uint32_t dims[] = {0, SAMPLE_DIM_BOUNCE0 + SAMPLE_BOUNCE_BSDF_DIR, 11, 14,
                                    SAMPLE_DIM_LIGHT_EXTRA + 1};
    static uint32_t x[1024], y[1024];
    for (size_t d = 0; d < sizeof dims / sizeof dims[0]; d++)
        for (int m = 1; m <= 10; m++) {
            for (uint32_t i = 0; i < (1u << m); i++) {
                struct sampler s;
                sample_start(&s, SAMPLER_SOBOL, 5u, 4242u, i);
                sample_set_dim(&s, dims[d]);
                vec2 u = sample_2d(&s);
                x[i] = (uint32_t)((double)u.x * 0x1p32); /* exact: 24-bit floats */
                y[i] = (uint32_t)((double)u.y * 0x1p32);
            }
            cr_assert(is_02_net(x, y, m), "dim %u m %d", dims[d], m);
        }
}

/* The path point (sample.h, SAMPLE_SOBOL_PATH_DIRS) stratifies a path's first BSDF directions
 * together: over any aligned block of 4^k samples of a pixel, the k directions' 2k coordinates
 * fall one point in each of the 4^k cells that halving every coordinate makes (the top digits
 * of Sobol' dimensions 0 .. 2k - 1 are independent; shuffle and scrambles map aligned blocks and
 * halves onto aligned blocks and halves).  Independently padded directions would do so with
 * probability (4^k)! / (4^k)^(4^k), 1e-26 for k = 3. */
Test(sample, sobol_path_directions_stratified_together)
{
    const uint32_t k = SAMPLE_SOBOL_PATH_DIRS;
    const uint32_t dir0 = SAMPLE_DIM_BOUNCE0 + SAMPLE_BOUNCE_BSDF_DIR;
    cr_assert(k >= 2 && SAMPLE_SOBOL_JOINT_DIMS <= dir0, "the directions are padded");
    const uint32_t n = 1u << 2 * k;
    static const uint32_t pixels[] = {0, 77, 123456};
    for (size_t p = 0; p < 3; p++)
        for (uint32_t block = 0; block < 6; block += 5) {
            bool cell[1u << 2 * SAMPLE_SOBOL_PATH_DIRS] = {false};
            for (uint32_t i = 0; i < n; i++) {
                struct sampler s;
                sample_start(&s, SAMPLER_SOBOL, 5u, pixels[p], block * n + i);
                uint32_t c = 0;
                for (uint32_t b = 0; b < k; b++) {
                    sample_set_dim(&s, dir0 + b * SAMPLE_DIMS_PER_BOUNCE);
                    vec2 u = sample_2d(&s);
                    c |= (uint32_t)(u.x >= 0.5f) << 2 * b | (uint32_t)(u.y >= 0.5f) << (2 * b + 1);
                }
                cr_assert(!cell[c], "pixel %u block %u: two samples in cell %u", pixels[p], block,
                          c);
                cell[c] = true;
            }
        }
}

/* The stratified sampler's sets of N = set_spp samples (Kensler 2013, correlated
 * multi-jittered): in 1D every 1/N interval holds one point of a set; in 2D every 1/N interval
 * of x and of y, and every cell of the m x n grid, holds one point when N = m n; for N = 7 (a
 * ragged 2 x 4 grid) y keeps its N strata and each x stratum 1/8 at most one point.  Sets 0
 * and 2 (sample indices 2N .. 3N - 1) alike. */
Test(sample, stratified_sets_fill_every_stratum)
{
    static const uint32_t ns[] = {1, 2, 3, 4, 7, 12, 16, 64, 100, 256};
    for (size_t t = 0; t < sizeof ns / sizeof ns[0]; t++) {
        uint32_t n = ns[t];
        for (uint32_t set = 0; set < 3; set += 2) {
            for (uint32_t dim = 0; dim < 12; dim += 3)
                cr_assert(strata_1d(SAMPLER_STRATIFIED, 9u, set * n, n, n, dim),
                          "1D N %u set %u dim %u", n, set, dim);
            /* 2D: grid m x rows as sample.c chooses it; recovered from the test's own rule */
            uint32_t m = 1, rows;
            for (uint32_t c = 1; c * c <= n; c++)
                if (n % c == 0)
                    m = c;
            bool exact = 4 * m * m >= n;
            if (!exact)
                for (m = 1; (m + 1) * (m + 1) <= n; m++)
                    ;
            rows = (n + m - 1) / m;
            char *hx = calloc(m * rows, 1), *hy = calloc(n, 1), *cell = calloc(m * rows, 1);
            cr_assert(hx && hy && cell);
            for (uint32_t i = 0; i < n; i++) {
                struct sampler s;
                sample_start_spp(&s, SAMPLER_STRATIFIED, 3u, 17u, set * n + i, n);
                sample_set_dim(&s, 5);
                vec2 u = sample_2d(&s);
                uint32_t kx = (uint32_t)((double)u.x * m * rows), ky = (uint32_t)((double)u.y * n);
                uint32_t c = (uint32_t)((double)u.y * rows) * m + (uint32_t)((double)u.x * m);
                cr_assert(!hx[kx] && !hy[ky], "2D N %u: x or y stratum hit twice", n);
                cr_assert(!exact || !cell[c], "2D N %u: grid cell %u hit twice", n, c);
                hx[kx] = hy[ky] = cell[c] = 1;
            }
            free(hx);
            free(hy);
            free(cell);
        }
    }
}

/* Stratified sets as large as a uint32_t holds (--spp 4294967295, or --batch 4294967295 with
 * --adaptive): the m x n grid's rows ceil(N / m) must not wrap to 0 (issue 15: the sample never
 * ended); the points lie in [0, 1). */
Test(sample, stratified_set_of_2_32_minus_1)
{
    static const uint32_t ns[] = {UINT32_MAX, UINT32_MAX - 1, 4294836225u /* 65535^2 */};
    for (size_t t = 0; t < sizeof ns / sizeof ns[0]; t++) {
        for (uint32_t i = 0; i < 64; i++) {
            struct sampler s;
            sample_start_spp(&s, SAMPLER_STRATIFIED, 1u, 5u, i, ns[t]);
            float u1 = sample_1d(&s);
            vec2 u2 = sample_2d(&s);
            cr_assert(u1 >= 0.0f && u1 < 1.0f && u2.x >= 0.0f && u2.x < 1.0f && u2.y >= 0.0f &&
                          u2.y < 1.0f,
                      "N %u sample %u: %g %g %g", ns[t], i, u1, u2.x, u2.y);
        }
    }
}

/* Every sampler: a dimension's value depends on (seed, pixel, sample, dimension) alone, not on
 * how it was reached (sequential reads, 2D reads, sample_set_dim jumps); another seed or pixel
 * gives other values. */
Test(sample, samplers_are_addressable_and_deterministic)
{
    for (int k = 0; k < SAMPLER_COUNT; k++) {
        struct sampler a, b;
        float seq[40];
        sample_start_spp(&a, KINDS[k], 9u, 321u, 5u, 16u);
        for (int i = 0; i < 40; i += 2) {
            vec2 u = sample_2d(&a);
            seq[i] = u.x;
            seq[i + 1] = u.y;
        }
        for (uint32_t d = 0; d < 40; d += 2) {
            sample_start_spp(&b, KINDS[k], 9u, 321u, 5u, 16u);
            sample_set_dim(&b, d);
            vec2 u = sample_2d(&b);
            cr_assert(u.x == seq[d] && u.y == seq[d + 1], "%s dim %u",
                      sample_sampler_name(KINDS[k]), d);
        }
        sample_start_spp(&b, KINDS[k], 10u, 321u, 5u, 16u);
        vec2 u = sample_2d(&b);
        cr_assert(u.x != seq[0] || u.y != seq[1], "%s: another seed",
                  sample_sampler_name(KINDS[k]));
        sample_start_spp(&b, KINDS[k], 9u, 322u, 5u, 16u);
        u = sample_2d(&b);
        cr_assert(u.x != seq[0] || u.y != seq[1], "%s: another pixel",
                  sample_sampler_name(KINDS[k]));
    }
}

/* Every sampler is uniform and its dimensions independent in expectation: over many pixels,
 * E[u] = 1/2, E[u^2] = 1/3, and E[u_a u_b] = 1/4 for the two halves of a 2D request, for two
 * padded requests, and for a joint and a padded dimension (5 standard errors; the pixels are
 * independent, so the standard error of iid uniforms bounds that of stratified ones). */
Test(sample, samplers_uniform_and_independent_in_expectation)
{
    const int n_pixels = 4000, spp = 16;
    const double n = (double)n_pixels * spp;
    for (int k = 0; k < SAMPLER_COUNT; k++) {
        double s1 = 0, s2 = 0, sxy = 0, spad = 0, sjp = 0;
        for (int p = 0; p < n_pixels; p++)
            for (int i = 0; i < spp; i++) {
                struct sampler s;
                sample_start_spp(&s, KINDS[k], 1u, (uint32_t)p, (uint32_t)i, (uint32_t)spp);
                float u0 = sample_1d(&s);
                sample_set_dim(&s, 5);
                vec2 a = sample_2d(&s);
                sample_set_dim(&s, 8);
                vec2 b = sample_2d(&s);
                s1 += a.x;
                s2 += (double)a.x * a.x;
                sxy += (double)a.x * a.y;
                spad += (double)a.x * b.x;
                sjp += (double)u0 * b.y;
            }
        const char *name = sample_sampler_name(KINDS[k]);
        cr_assert(fabs(s1 / n - 0.5) < 5 * sqrt(1.0 / 12 / n), "%s E[u] %f", name, s1 / n);
        cr_assert(fabs(s2 / n - 1.0 / 3) < 5 * sqrt(4.0 / 45 / n), "%s E[u^2] %f", name, s2 / n);
        double se_xy = 5 * sqrt(7.0 / 144 / n); /* Var(u v) = 1/9 - 1/16 */
        cr_assert(fabs(sxy / n - 0.25) < se_xy, "%s E[x y] %f", name, sxy / n);
        cr_assert(fabs(spad / n - 0.25) < se_xy, "%s padded E[a b] %f", name, spad / n);
        cr_assert(fabs(sjp / n - 0.25) < se_xy, "%s joint-padded E[a b] %f", name, sjp / n);
    }
}

/* Dimensions within a pixel are decorrelated: over one pixel's first 1024 samples the
 * correlation of two joint dimensions (2 and 5), of a joint and a padded one (0 and 12) and of
 * two padded requests (11 and 14) is at most that of a random pairing, |r| < 4 / sqrt(n - 1).
 * Sobol' without its per-request shuffle, or strata paired identically, would give r near 1. */
Test(sample, padding_decorrelates_dimensions)
{
    const int n = 1024;
    for (int k = 1; k < SAMPLER_COUNT; k++) {
        const uint32_t pairs[3][2] = {{2, 5}, {0, 12}, {11, 14}};
        for (int q = 0; q < 3; q++) {
            double sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0;
            for (int i = 0; i < n; i++) {
                struct sampler s;
                sample_start_spp(&s, KINDS[k], 2u, 99u, (uint32_t)i, (uint32_t)n);
                sample_set_dim(&s, pairs[q][0]);
                double a = sample_1d(&s);
                sample_set_dim(&s, pairs[q][1]);
                double b = sample_1d(&s);
                sa += a;
                sb += b;
                saa += a * a;
                sbb += b * b;
                sab += a * b;
            }
            double cov = sab / n - sa / n * sb / n;
            double r = cov / sqrt((saa / n - sa / n * sa / n) * (sbb / n - sb / n * sb / n));
            cr_assert(fabs(r) < 4.0 / sqrt(n - 1.0), "%s dims %u, %u: r = %f",
                      sample_sampler_name(KINDS[k]), pairs[q][0], pairs[q][1], r);
        }
    }
}

/* ---- warps: chi-square fits against their pdfs, inverses ---- */

#define N_WARP_CHI2_TESTS 8 /* Bonferroni: the chi-square tests of this file */

static bool draw_uniform_sphere(void *ctx, const float u[3], vec3 *w)
{
    (void)ctx;
    *w = sample_uniform_sphere((vec2){u[0], u[1]});
    return true;
}
static double pdf_sphere_at(void *ctx, vec3 w)
{
    (void)ctx;
    (void)w;
    return pdf_uniform_sphere();
}
static bool draw_uniform_hemisphere(void *ctx, const float u[3], vec3 *w)
{
    (void)ctx;
    *w = sample_uniform_hemisphere((vec2){u[0], u[1]});
    return true;
}
static double pdf_hemisphere_at(void *ctx, vec3 w)
{
    (void)ctx;
    return w.z >= 0.0f ? pdf_uniform_hemisphere() : 0.0;
}
static bool draw_cosine_hemisphere(void *ctx, const float u[3], vec3 *w)
{
    (void)ctx;
    *w = sample_cosine_hemisphere((vec2){u[0], u[1]});
    return true;
}
static double pdf_cosine_at(void *ctx, vec3 w)
{
    (void)ctx;
    return w.z >= 0.0f ? pdf_cosine_hemisphere(w.z) : 0.0;
}
static bool draw_cone(void *ctx, const float u[3], vec3 *w)
{
    *w = sample_uniform_cone((vec2){u[0], u[1]}, ctx);
    return true;
}
static double pdf_cone_at(void *ctx, vec3 w)
{
    const struct sample_cone *cone = ctx;
    return w.z >= cone->cos_theta_max ? pdf_uniform_cone(cone) : 0.0;
}
static bool draw_disk(void *ctx, const float u[3], vec3 *w)
{
    (void)ctx;
    vec2 p = sample_concentric_disk((vec2){u[0], u[1]});
    *w = v3(p.x, p.y, 0.0f);
    return true;
}
static double pdf_disk_at(void *ctx, vec3 w)
{
    (void)ctx;
    return w.x * w.x + w.y * w.y <= 1.0f ? MCPT_INV_PI : 0.0; /* 1 / area */
}
static bool draw_triangle(void *ctx, const float u[3], vec3 *w)
{
    (void)ctx;
    vec2 b = sample_uniform_triangle((vec2){u[0], u[1]});
    *w = v3(b.x, b.y, 0.0f);
    return true;
}
static double pdf_triangle_at(void *ctx, vec3 w)
{
    (void)ctx;
    return w.x + w.y <= 1.0f ? 2.0 : 0.0; /* (b0, b1) uniform on the half square: 1 / (1/2) */
}

static void check_chi2(struct chi2_spec spec, const char *name)
{
    spec.n_samples = 200000;
    struct chi2_result r;
    chi2_run(&spec, &r);
    cr_assert(chi2_accept(&r, N_WARP_CHI2_TESTS), "%s: %s", name, r.msg);
    cr_assert(fabs(r.pdf_integral - 1.0) < 2e-3, "%s: pdf integrates to %f", name, r.pdf_integral);
}

/* Each warp's samples fit its pdf (Pearson's chi-square on a 2D histogram against the pdf
 * integrated over each cell, significance 0.01 / 8, as Mitsuba's chi2 tests), and each pdf
 * integrates to 1 over its domain. */
Test(sample, warps_chi2, .timeout = TEST_TIMEOUT_S(60))
{
    check_chi2(chi2_sphere(draw_uniform_sphere, pdf_sphere_at, NULL), "uniform sphere");
    check_chi2(chi2_sphere(draw_uniform_hemisphere, pdf_hemisphere_at, NULL), "uniform hemisphere");
    check_chi2(chi2_sphere(draw_cosine_hemisphere, pdf_cosine_at, NULL), "cosine hemisphere");
    struct sample_cone narrow = sample_cone_from_cos(0.95f), wide = sample_cone_from_cos(-0.3f);
    struct sample_cone sphere = sample_cone_from_sin2(0.25f); /* a sphere at twice its radius */
    check_chi2(chi2_sphere(draw_cone, pdf_cone_at, &narrow), "cone 18 deg");
    check_chi2(chi2_sphere(draw_cone, pdf_cone_at, &wide), "cone 107 deg");
    check_chi2(chi2_sphere(draw_cone, pdf_cone_at, &sphere), "cone 30 deg from sin^2");
    check_chi2(chi2_plane(draw_disk, pdf_disk_at, NULL, -1, 1, -1, 1), "concentric disk");
    check_chi2(chi2_plane(draw_triangle, pdf_triangle_at, NULL, 0, 1, 0, 1), "triangle");
}

/* Inverse warps round-trip: sample_invert_X(sample_X(u)) = u up to float rounding (azimuths
 * compared modulo 1). */
Test(sample, warp_inverses_round_trip)
{
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 8u, 13u);
    for (int i = 0; i < 100000; i++) {
        vec2 u = {sample_pcg32_float(&rng), sample_pcg32_float(&rng)};
        if (u.x < 1e-3f || u.x > 1.0f - 1e-3f || u.y < 1e-3f || u.y > 1.0f - 1e-3f)
            continue; /* poles and seams, where the inverse is ill-conditioned in float */
        vec2 got[6];
        got[0] = sample_invert_concentric_disk(sample_concentric_disk(u));
        got[1] = sample_invert_cosine_hemisphere(sample_cosine_hemisphere(u));
        got[2] = sample_invert_uniform_hemisphere(sample_uniform_hemisphere(u));
        got[3] = sample_invert_uniform_sphere(sample_uniform_sphere(u));
        struct sample_cone cone = sample_cone_from_cos(0.3f);
        got[4] = sample_invert_uniform_cone(sample_uniform_cone(u, &cone), &cone);
        got[5] = sample_invert_uniform_triangle(sample_uniform_triangle(u));
        for (int k = 0; k < 6; k++) {
            float dy = fabsf(got[k].y - u.y);
            dy = fminf(dy, 1.0f - dy);
            cr_assert(fabsf(got[k].x - u.x) < 2e-3f && dy < 2e-3f,
                      "warp %d: u (%f, %f) -> (%f, %f)", k, u.x, u.y, got[k].x, got[k].y);
        }
    }
}

/* A narrow cone (a sphere far away: sin^2 theta_max = 1e-6, theta_max = 0.057 deg) made from
 * sin^2 theta_max keeps its precision by the Taylor expansions of PBRT 4e, ch. 6, "Spheres": the
 * pdf 1 / (2 pi (1 - cos theta_max)) and the sampled sin^2 theta = 1 - (1 - u0 (1 - cos
 * theta_max))^2 agree with double precision to 1e-5 relative, where the same cone made from
 * cos theta_max in float is 7% off; its inverse round-trips.  Cones just above sin^2(1.5 deg)
 * give the same pdf either way. */
Test(sample, narrow_cone_keeps_precision)
{
    const double s2 = 1e-6;
    const double om = s2 / (1.0 + sqrt(1.0 - s2)); /* 1 - sqrt(1 - s2) without cancellation */
    struct sample_cone cone = sample_cone_from_sin2((float)s2);
    cr_assert(cone.is_narrow);
    double pdf_exact = 1.0 / (2.0 * MCPT_PI * om);
    cr_assert(fabs(pdf_uniform_cone(&cone) / pdf_exact - 1.0) < 1e-5, "pdf %g, exact %g",
              pdf_uniform_cone(&cone), pdf_exact);
    struct sample_cone naive = sample_cone_from_cos(sqrtf(1.0f - (float)s2));
    cr_assert(fabs(pdf_uniform_cone(&naive) / pdf_exact - 1.0) > 0.05, "float cancellation");
    for (int i = 1; i < 100; i++) {
        float u0 = (float)i / 100.0f;
        float cos_theta, sin2_theta;
        sample_uniform_cone_theta(u0, &cone, &cos_theta, &sin2_theta);
        double c = 1.0 - u0 * om;
        double sin2_exact = (1.0 - c) * (1.0 + c);
        cr_assert(fabs(sin2_theta / sin2_exact - 1.0) < 1e-5, "u0 %f: sin^2 %g, exact %g", u0,
                  sin2_theta, sin2_exact);
        vec2 u = {u0, 0.37f};
        vec2 back = sample_invert_uniform_cone(sample_uniform_cone(u, &cone), &cone);
        cr_assert(fabsf(back.x - u.x) < 1e-5f && fabsf(back.y - u.y) < 1e-5f,
                  "u (%f, %f) -> (%f, %f)", u.x, u.y, back.x, back.y);
    }
    struct sample_cone wide_sin2 = sample_cone_from_sin2(0.001f);
    struct sample_cone wide_cos = sample_cone_from_cos(sqrtf(1.0f - 0.001f));
    cr_assert(!wide_sin2.is_narrow);
    cr_assert_eq(pdf_uniform_cone(&wide_sin2), pdf_uniform_cone(&wide_cos));
}

/* ---- the spherical polygons and the bilinear warp ---- */

/* Whether unit w lies inside the spherical triangle (a, b, c): on the inner side of each edge's
 * great circle. */
static bool in_sph_triangle(vec3 a, vec3 b, vec3 c, vec3 w)
{
    float o = v3_dot(a, v3_cross(b, c));
    return v3_dot(w, v3_cross(a, b)) * o >= 0.0f && v3_dot(w, v3_cross(b, c)) * o >= 0.0f &&
           v3_dot(w, v3_cross(c, a)) * o >= 0.0f;
}

static bool draw_sph_triangle(void *ctx, const float u[3], vec3 *w)
{
    *w = sample_spherical_triangle(ctx, (vec2){u[0], u[1]});
    return true;
}
static double pdf_sph_triangle_at(void *ctx, vec3 w)
{
    const struct sample_sph_triangle *st = ctx;
    return in_sph_triangle(st->a, st->b, st->c, w) ? pdf_spherical_triangle(st) : 0.0;
}

struct rect_ctx {
    struct sample_sph_rect sr;
    vec3 corner, e1, e2;
};
static bool draw_sph_rect(void *ctx, const float u[3], vec3 *w)
{
    struct rect_ctx *c = ctx;
    *w = v3_normalize(v3_sub(sample_spherical_rectangle(&c->sr, (vec2){u[0], u[1]}), c->sr.o));
    return true;
}
/* 1 / S where the ray from o along w meets the rectangle (a ray-plane test in its frame). */
static double pdf_sph_rect_at(void *ctx, vec3 w)
{
    struct rect_ctx *c = ctx;
    vec3 n = v3_cross(c->e1, c->e2);
    float t = v3_dot(n, v3_sub(c->corner, c->sr.o)) / v3_dot(n, w);
    if (!(t > 0.0f))
        return 0.0;
    vec3 d = v3_sub(v3_add(c->sr.o, v3_scale(w, t)), c->corner);
    float s1 = v3_dot(d, c->e1) / v3_dot(c->e1, c->e1),
          s2 = v3_dot(d, c->e2) / v3_dot(c->e2, c->e2);
    return s1 >= 0.0f && s1 <= 1.0f && s2 >= 0.0f && s2 <= 1.0f ? pdf_spherical_rectangle(&c->sr)
                                                                : 0.0;
}

static const float BILINEAR_W[4] = {0.2f, 1.0f, 0.6f, 0.05f};
static bool draw_bilinear(void *ctx, const float u[3], vec3 *w)
{
    (void)ctx;
    vec2 p = sample_bilinear((vec2){u[0], u[1]}, BILINEAR_W);
    *w = v3(p.x, p.y, 0.0f);
    return true;
}
static double pdf_bilinear_at(void *ctx, vec3 w)
{
    (void)ctx;
    return pdf_bilinear((vec2){w.x, w.y}, BILINEAR_W);
}

/* A rectangle seen from o with corner + s e1 + t e2; the frame it is given in is rotated. */
static struct rect_ctx rect_case(vec3 o, vec3 corner, vec3 e1, vec3 e2)
{
    struct rect_ctx c = {.corner = corner, .e1 = e1, .e2 = e2};
    cr_assert(sample_sph_rect_init(o, corner, e1, e2, &c.sr));
    return c;
}

/* Arvo's spherical-triangle map (Arvo 1995) and the spherical-rectangle map (Urena et al. 2013)
 * are uniform in solid angle: chi-square against 1 / Omega inside the polygon (significance
 * 0.01 / 5), the pdf integrating to 1 (so Omega is right); the bilinear warp fits its pdf
 * (PBRT 4e, ch. A.5, SampleBilinear).  A large and a small triangle, a rectangle seen
 * off-centre, and one seen from beside its edge (a grazing view). */
Test(sample, spherical_polygons_chi2, .timeout = TEST_TIMEOUT_S(60))
{
    const int n_tests = 5;
    struct sample_sph_triangle big, small;
    cr_assert(sample_sph_triangle_init(v3_normalize(v3(0.1f, 0.2f, 1.0f)),
                                       v3_normalize(v3(1.0f, -0.3f, 0.4f)),
                                       v3_normalize(v3(-0.6f, 0.9f, 0.5f)), &big));
    cr_assert(sample_sph_triangle_init(v3_normalize(v3(0.1f, 0.2f, 1.0f)),
                                       v3_normalize(v3(0.3f, 0.1f, 1.0f)),
                                       v3_normalize(v3(0.15f, 0.45f, 1.0f)), &small));
    struct rect_ctx off = rect_case(v3(0.3f, -0.2f, 0.1f), v3(-1.0f, -0.5f, 1.0f),
                                    v3(1.6f, 0.0f, 0.0f), v3(0.0f, 1.2f, 0.4f));
    struct rect_ctx grazing = rect_case(v3(0.0f, 0.0f, 0.0f), v3(0.2f, -1.0f, 0.05f),
                                        v3(0.0f, 2.0f, 0.0f), v3(1.5f, 0.0f, 0.0f));
    struct {
        struct chi2_spec spec;
        const char *name;
    } cases[] = {
        {chi2_sphere(draw_sph_triangle, pdf_sph_triangle_at, &big), "spherical triangle 1 sr"},
        {chi2_sphere(draw_sph_triangle, pdf_sph_triangle_at, &small), "spherical triangle small"},
        {chi2_sphere(draw_sph_rect, pdf_sph_rect_at, &off), "spherical rectangle"},
        {chi2_sphere(draw_sph_rect, pdf_sph_rect_at, &grazing), "spherical rectangle, grazing"},
        {chi2_plane(draw_bilinear, pdf_bilinear_at, NULL, 0, 1, 0, 1), "bilinear"},
    };
    for (int k = 0; k < n_tests; k++) {
        cases[k].spec.n_samples = 300000;
        if (k == 1) /* a small triangle: a finer grid, so that cells resolve it */
            cases[k].spec.n_rows = cases[k].spec.n_cols = 256;
        struct chi2_result r;
        chi2_run(&cases[k].spec, &r);
        cr_assert(chi2_accept(&r, n_tests), "%s: %s", cases[k].name, r.msg);
        cr_assert(fabs(r.pdf_integral - 1.0) < 3e-3, "%s: pdf integrates to %f", cases[k].name,
                  r.pdf_integral);
    }
}

/* The solid angles against closed forms: an octant triangle is pi / 2 sr; a square of side 2
 * at distance 1 seen from its centre's normal is 4 asin(1/3) = 2 pi / 3 sr (a cube face). */
Test(sample, spherical_polygon_areas)
{
    float octant = sample_spherical_triangle_area(v3(1, 0, 0), v3(0, 1, 0), v3(0, 0, 1));
    cr_assert(fabsf(octant - MCPT_PI / 2.0f) < 1e-6f, "octant %.9g", octant);
    struct sample_sph_rect sr;
    cr_assert(sample_sph_rect_init(v3(0, 0, 0), v3(-1, -1, -1), v3(2, 0, 0), v3(0, 2, 0), &sr));
    cr_assert(fabsf(sr.area - 2.0f * MCPT_PI / 3.0f) < 1e-6f, "cube face %.9g", sr.area);
    /* a tiny triangle keeps its relative precision (the angle excess would lose it) */
    double h = 1e-3;
    float tiny = sample_spherical_triangle_area(v3(0, 0, 1), v3_normalize(v3((float)h, 0, 1)),
                                                v3_normalize(v3(0, (float)h, 1)));
    cr_assert(fabs(tiny / (0.5 * h * h) - 1.0) < 2e-3, "tiny %.9g vs %.9g", tiny, 0.5 * h * h);
    /* refused: a degenerate triangle, a non-rectangular parallelogram, a point in the plane */
    struct sample_sph_triangle st;
    cr_assert(!sample_sph_triangle_init(v3(1, 0, 0), v3(1, 0, 0), v3(0, 1, 0), &st));
    cr_assert(!sample_sph_rect_init(v3(0, 0, 0), v3(-1, -1, -1), v3(2, 0, 0), v3(1, 2, 0), &sr));
    cr_assert(!sample_sph_rect_init(v3(0, 0, -1), v3(-1, -1, -1), v3(2, 0, 0), v3(0, 2, 0), &sr));
}

/* The inverses round-trip: sample_invert_X(sample_X(u)) = u, for the triangles and rectangles of
 * the chi-square test and for the bilinear warp. */
Test(sample, spherical_polygon_inverses_round_trip)
{
    struct sample_sph_triangle st;
    cr_assert(sample_sph_triangle_init(v3_normalize(v3(0.1f, 0.2f, 1.0f)),
                                       v3_normalize(v3(1.0f, -0.3f, 0.4f)),
                                       v3_normalize(v3(-0.6f, 0.9f, 0.5f)), &st));
    struct rect_ctx rc = rect_case(v3(0.3f, -0.2f, 0.1f), v3(-1.0f, -0.5f, 1.0f),
                                   v3(1.6f, 0.0f, 0.0f), v3(0.0f, 1.2f, 0.4f));
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 21u, 5u);
    for (int i = 0; i < 100000; i++) {
        vec2 u = {sample_pcg32_float(&rng), sample_pcg32_float(&rng)};
        if (u.x < 1e-3f || u.x > 1.0f - 1e-3f || u.y < 1e-3f || u.y > 1.0f - 1e-3f)
            continue; /* the corners, where a vertex has every u0 and the inverse no answer */
        vec2 got[3];
        got[0] = sample_invert_spherical_triangle(&st, sample_spherical_triangle(&st, u));
        got[1] = sample_invert_spherical_rectangle(&rc.sr, sample_spherical_rectangle(&rc.sr, u));
        got[2] = sample_invert_bilinear(sample_bilinear(u, BILINEAR_W), BILINEAR_W);
        for (int k = 0; k < 3; k++)
            cr_assert(fabsf(got[k].x - u.x) < 1e-3f && fabsf(got[k].y - u.y) < 1e-3f,
                      "warp %d: u (%f, %f) -> (%f, %f)", k, u.x, u.y, got[k].x, got[k].y);
    }
}

/* ---- discrete distributions: the alias method ---- */

/* The alias table (Walker 1977; Vose 1991) picks index i with probability w_i / sum w: over a
 * uniform grid of M values of u the frequencies match the pmfs to within n / M (the picks are
 * unions of intervals of u), zero weights are never picked, and random u pass a chi-square
 * test; all-zero weights give the uniform distribution. */
Test(sample, alias_table_frequencies)
{
    const double w[7] = {1.0, 0.0, 3.0, 0.5, 2.5, 0.0, 1e-3};
    const uint32_t n = 7;
    struct sample_alias_bin bins[7];
    cr_assert(sample_alias_build(w, n, bins));
    const uint32_t M = 1u << 20;
    uint64_t count[7] = {0};
    for (uint32_t k = 0; k < M; k++) {
        float pmf;
        uint32_t i = sample_alias_pick(bins, n, ((float)k + 0.5f) / (float)M, &pmf);
        cr_assert(i < n);
        cr_assert_eq(pmf, bins[i].pmf);
        count[i]++;
    }
    double total = 7.001;
    for (uint32_t i = 0; i < n; i++) {
        cr_assert_float_eq(bins[i].pmf, w[i] / total, 1e-7);
        cr_assert(fabs((double)count[i] / M - w[i] / total) <= (double)n / M + 1e-6,
                  "bin %u: frequency %f, pmf %f", i, (double)count[i] / M, w[i] / total);
        if (w[i] == 0.0)
            cr_assert_eq(count[i], 0u);
    }
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 17, 4);
    uint64_t observed[7] = {0};
    double expected[7];
    const int draws = 1000000;
    for (int k = 0; k < draws; k++)
        observed[sample_alias_pick(bins, n, sample_pcg32_float(&rng), NULL)]++;
    for (uint32_t i = 0; i < n; i++)
        expected[i] = draws * w[i] / total;
    struct chi2_result r;
    chi2_counts(expected, observed, n, &r);
    cr_assert(chi2_accept(&r, 1), "%s", r.msg);
    const double zeros[3] = {0.0, 0.0, 0.0};
    cr_assert(sample_alias_build(zeros, 3, bins));
    for (int i = 0; i < 3; i++)
        cr_assert_float_eq(bins[i].pmf, 1.0f / 3.0f, 1e-7f);
    const double negative[2] = {1.0, -1.0};
    cr_assert(!sample_alias_build(negative, 2, bins), "negative weights are refused");
}

/* ---- adaptive sampling: the stopping rule ---- */

/* Feeds the stream next() to the stopping rule, testing at min_spp + k batch as trace.c does;
 * returns the sample count at which it stops, or max_spp. */
static uint32_t stop_count(double (*next)(void *, uint32_t), void *ctx, uint32_t min_spp,
                           uint32_t batch, uint32_t max_spp, double tol, double floor_lum)
{
    double s1 = 0, s2 = 0;
    for (uint32_t n = 0; n < max_spp; n++) {
        if (n >= min_spp && (n - min_spp) % batch == 0 &&
            trace_adaptive_stop(s1, s2, n, tol, floor_lum))
            return n;
        double x = next(ctx, n);
        s1 += x;
        s2 += x * x;
    }
    return max_spp;
}

/* The test point at which the rule stops a stream of exact mean mu and spread sigma: the first
 * n = min_spp + k batch with 1.96 sigma / sqrt(n) <= T max(mu, floor). */
static uint32_t predicted_stop(double mu, double sigma, uint32_t min_spp, uint32_t batch,
                               uint32_t max_spp, double tol, double floor_lum)
{
    double n_star = pow(1.96 * sigma / (tol * fmax(mu, floor_lum)), 2.0);
    uint32_t n = min_spp;
    while (n < max_spp && (double)n < n_star)
        n += batch;
    return n < max_spp ? n : max_spp;
}

struct stream {
    double mu, sigma;
    struct pcg32 rng;
};

/* mu + sigma, mu - sigma, ...: at every even count the mean is mu and s2/n - mu^2 = sigma^2. */
static double alternating(void *ctx, uint32_t i)
{
    const struct stream *st = ctx;
    return i % 2 ? st->mu - st->sigma : st->mu + st->sigma;
}

static double gaussian(void *ctx, uint32_t i)
{
    (void)i;
    struct stream *st = ctx;
    /* Box-Muller */
    double u1 = 1.0 - sample_pcg32_float(&st->rng), u2 = sample_pcg32_float(&st->rng);
    return st->mu + st->sigma * sqrt(-2.0 * log(u1)) * cos(2.0 * MCPT_PI * u2);
}

/* With exact moments the rule stops exactly at the predicted test point, for relative
 * (mu above the floor) and absolute (dark: mu below the floor) cases; an all-zero stream
 * stops at the first test, and no stream stops before min_spp or beyond max_spp. */
Test(adaptive, rule_on_exact_streams)
{
    const struct {
        double mu, sigma, tol, floor_lum;
        uint32_t min_spp, batch, max_spp;
    } cases[] = {
        {1.0, 0.5, 0.05, 0.01, 64, 32, 4096},     /* n* = 384.2 -> 416 */
        {1.0, 2.0, 0.05, 0.01, 64, 32, 4096},     /* n* = 6147 -> the maximum */
        {0.2, 0.1, 0.10, 0.01, 16, 8, 1024},      /* n* = 96.04 -> 104 */
        {1e-3, 1e-2, 0.05, 0.01, 64, 32, 4096},   /* dark: n* = 1536.6 with the floor */
        {1e-3, 1e-2, 0.05, 0.0, 64, 32, 1 << 20}, /* no floor: n* = 153664 */
        {0.0, 0.0, 0.05, 0.01, 64, 32, 4096},     /* black: stops at the first test */
        {5.0, 0.01, 0.05, 0.01, 64, 32, 4096},    /* converged at once: min_spp */
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        struct stream st = {cases[c].mu, cases[c].sigma, {0, 1}};
        uint32_t got = stop_count(alternating, &st, cases[c].min_spp, cases[c].batch,
                                  cases[c].max_spp, cases[c].tol, cases[c].floor_lum);
        uint32_t want = predicted_stop(cases[c].mu, cases[c].sigma, cases[c].min_spp,
                                       cases[c].batch, cases[c].max_spp, cases[c].tol,
                                       cases[c].floor_lum);
        cr_assert_eq(got, want, "case %zu: stopped at %u, predicted %u", c, got, want);
    }
    cr_assert_not(trace_adaptive_stop(0.0, 0.0, 0, 0.05, 0.01), "n = 0 never stops");
}

/* On Gaussian streams with known mu and sigma the rule stops within one batch of the
 * predicted test point (the estimates of mu and sigma wander by about sqrt(2 n*) samples of
 * n*, well inside the batch of 128 used here), for 10 streams each of three (mu, sigma). */
Test(adaptive, rule_on_gaussian_streams)
{
    const double params[3][2] = {{1.0, 0.5}, {2.0, 0.6}, {0.5, 0.3}};
    for (int p = 0; p < 3; p++)
        for (uint64_t seed = 1; seed <= 10; seed++) {
            struct stream st = {params[p][0], params[p][1], {0, 1}};
            sample_pcg32_seed(&st.rng, seed, 77u + (uint64_t)p);
            uint32_t got = stop_count(gaussian, &st, 128, 128, 1u << 16, 0.05, 0.01);
            uint32_t want = predicted_stop(st.mu, st.sigma, 128, 128, 1u << 16, 0.05, 0.01);
            cr_assert(got + 128 >= want && got <= want + 128,
                      "mu %g sigma %g seed %llu: stopped at %u, predicted %u", st.mu, st.sigma,
                      (unsigned long long)seed, got, want);
        }
}

/* The pilot rule's count is the stop rule's predicted stop: with exact moments of the pilot
 * (an alternating stream of an even count has mean mu and spread sigma) it is the N with
 * 1.96 sigma / sqrt(N) = T max(mu, floor), rounded up to whole batches and clamped to
 * [min_spp, max_spp]; no pilot (n = 0) gives the maximum. */
Test(adaptive, pilot_count_on_exact_moments)
{
    const struct {
        double mu, sigma, tol, floor_lum;
        uint32_t min_spp, batch, max_spp;
    } cases[] = {
        {1.0, 0.5, 0.05, 0.01, 64, 32, 4096},   /* N* = 384.2 -> 416 */
        {1.0, 2.0, 0.05, 0.01, 64, 32, 4096},   /* N* = 6147 -> the maximum */
        {0.2, 0.1, 0.10, 0.01, 16, 8, 1024},    /* N* = 96.04 -> 104 */
        {1e-3, 1e-2, 0.05, 0.01, 64, 32, 4096}, /* dark: N* = 1536.6 with the floor */
        {0.0, 0.0, 0.05, 0.01, 64, 32, 4096},   /* black: the least */
        {5.0, 0.01, 0.05, 0.01, 64, 32, 4096},  /* converged at once: the least */
        {1.0, 0.5, 0.05, 0.01, 64, 1, 4096},    /* batch 1: N* rounded up, 385 */
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        struct stream st = {cases[c].mu, cases[c].sigma, {0, 1}};
        double s1 = 0.0, s2 = 0.0;
        for (uint32_t i = 0; i < 16; i++) {
            double x = alternating(&st, i);
            s1 += x;
            s2 += x * x;
        }
        uint32_t got = trace_pilot_spp(s1, s2, 16, cases[c].tol, cases[c].floor_lum,
                                       cases[c].min_spp, cases[c].max_spp, cases[c].batch);
        uint32_t want = predicted_stop(cases[c].mu, cases[c].sigma, cases[c].min_spp,
                                       cases[c].batch, cases[c].max_spp, cases[c].tol,
                                       cases[c].floor_lum);
        cr_assert_eq(got, want, "case %zu: pilot count %u, predicted %u", c, got, want);
    }
    cr_assert_eq(trace_pilot_spp(0.0, 0.0, 0, 0.05, 0.01, 64, 4096, 32), 4096u, "no pilot");
}

static bool is_pow2(uint32_t n) { return n && !(n & (n - 1)); }

/* The budget rule's counts (trace_budget_counts): powers of two between the bounds that spend
 * at most the budget and less than double it would; a larger weight never gets fewer samples,
 * a costlier pixel of the same weight never more; weights four times larger get four times the
 * samples; a zero weight gets the least; a budget below the least counts gives the least. */
Test(adaptive, budget_counts)
{
    enum { N = 1000 };
    static double log2w[N], cost[N];
    static uint32_t count[N];
    uint64_t rng = 7;
    for (int i = 0; i < N; i++) {
        rng = rng * 6364136223846793005ull + 1442695040888963407ull;
        log2w[i] = (double)(rng >> 40) / (double)(1u << 24) * 12.0 - 6.0; /* w in 1/64..64 */
        cost[i] = 1.0 + (double)(rng >> 60);                              /* 1..16 rays */
    }
    log2w[0] = -INFINITY;
    double costs = 0.0;
    for (int i = 0; i < N; i++)
        costs += cost[i];
    for (double spp = 16.0; spp <= 1024.0; spp *= 4.0) {
        trace_budget_counts(log2w, cost, N, spp * costs, 4, 8192, count);
        double spent = 0.0;
        for (int i = 0; i < N; i++) {
            cr_assert(is_pow2(count[i]) && count[i] >= 4 && count[i] <= 8192,
                      "spp %g: pixel %d count %u", spp, i, count[i]);
            spent += count[i] * cost[i];
        }
        cr_assert_eq(count[0], 4u, "a zero weight gets the least");
        cr_assert(spent <= spp * costs, "spp %g: spent %g of %g", spp, spent, spp * costs);
        cr_assert(spent > 0.5 * spp * costs, "spp %g: spent only %g of %g", spp, spent,
                  spp * costs);
        for (int i = 1; i < N; i++)
            for (int j = 1; j < N; j++)
                if (cost[i] == cost[j] && log2w[i] > log2w[j])
                    cr_assert(count[i] >= count[j], "spp %g: weights 2^%g > 2^%g, counts %u < %u",
                              spp, log2w[i], log2w[j], count[i], count[j]);
                else if (log2w[i] == log2w[j] && cost[i] > cost[j])
                    cr_assert(count[i] <= count[j]);
    }
    /* equal costs: weights 1, 4, 16 of four pixels each and a total of 4 (1 + 4 + 16) 16 */
    const double lw[12] = {0, 0, 0, 0, 2, 2, 2, 2, 4, 4, 4, 4};
    trace_budget_counts(lw, NULL, 12, 4.0 * 21.0 * 16.0, 1, 1u << 20, count);
    for (int i = 0; i < 12; i++)
        cr_assert_eq(count[i], 16u << (int)lw[i], "pixel %d: %u", i, count[i]);
    trace_budget_counts(lw, NULL, 12, 11.0, 1, 1u << 20, count);
    for (int i = 0; i < 12; i++)
        cr_assert_eq(count[i], 1u, "too small a budget: the least, got %u", count[i]);
}

/* A pixel with a rare bright path: x = 0.5, or 50 with probability 1/100 (mean 0.995).  Over
 * 20000 pixels: the stop rule (its own samples decide and estimate) returns a mean far below
 * the truth (a pixel that has not met the bright path shows a mean of 0.5 and no spread, and
 * stops at min_spp, 52% of them); the pilot rule (Kirk & Arvo 1991: 16 pilot samples decide,
 * then N fresh samples estimate) returns the truth within 4 standard errors. */
Test(adaptive, pilot_unbiased_where_stop_rule_is_not)
{
    enum { PIXELS = 20000, MIN_SPP = 64, BATCH = 32, MAX_SPP = 1024, PILOT = 16 };
    const double tol = 0.1, floor_lum = 0.01, truth = 0.99 * 0.5 + 0.01 * 50.0;
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 2024u, 5u);
#define DRAW() (sample_pcg32_float(&rng) < 0.01f ? 50.0 : 0.5)
    double sum[2] = {0.0, 0.0}, sum_sq[2] = {0.0, 0.0};
    for (int i = 0; i < PIXELS; i++) {
        /* the stop rule: test at MIN_SPP + k BATCH, estimate from the same samples */
        double s1 = 0.0, s2 = 0.0;
        uint32_t n = 0;
        while (n < MAX_SPP && !(n >= MIN_SPP && (n - MIN_SPP) % BATCH == 0 &&
                                trace_adaptive_stop(s1, s2, n, tol, floor_lum))) {
            double x = DRAW();
            s1 += x;
            s2 += x * x;
            n++;
        }
        double est = s1 / n;
        sum[0] += est;
        sum_sq[0] += est * est;
        /* the pilot rule: PILOT samples decide N, N fresh samples estimate */
        double p1 = 0.0, p2 = 0.0;
        for (int k = 0; k < PILOT; k++) {
            double x = DRAW();
            p1 += x;
            p2 += x * x;
        }
        uint32_t n_spp = trace_pilot_spp(p1, p2, PILOT, tol, floor_lum, MIN_SPP, MAX_SPP, BATCH);
        double e1 = 0.0;
        for (uint32_t k = 0; k < n_spp; k++)
            e1 += DRAW();
        est = e1 / n_spp;
        sum[1] += est;
        sum_sq[1] += est * est;
    }
#undef DRAW
    double mean[2], se[2];
    for (int r = 0; r < 2; r++) {
        mean[r] = sum[r] / PIXELS;
        se[r] = sqrt((sum_sq[r] / PIXELS - mean[r] * mean[r]) / (PIXELS - 1));
    }
    cr_log_info("stop rule %.5f +- %.5f, pilot rule %.5f +- %.5f, truth %.5f", mean[0], se[0],
                mean[1], se[1], truth);
    cr_assert(mean[0] < truth - 10.0 * se[0], "stop rule %g +- %g: expected its bias, truth %g",
              mean[0], se[0], truth);
    cr_assert(fabs(mean[1] - truth) < 4.0 * se[1], "pilot rule %g +- %g, truth %g", mean[1], se[1],
              truth);
}

/* ---- samplers in the renderer ---- */

static struct trace_scene *load_scene(const char *path, int width, int height, struct scene *s)
{
    struct mcpt_error err;
    cr_assert(scene_load(path, s, &err), "%s", err.msg);
    s->width = width;
    s->height = height;
    struct trace_scene *ts = trace_prepare(s, 1, &err);
    cr_assert(ts, "%s", err.msg);
    return ts;
}

static void render_film(const struct trace_scene *ts, const struct trace_options *opt,
                        struct film *film)
{
    struct trace_result res;
    struct mcpt_error err;
    cr_assert(trace_render(ts, opt, film, &res, &err), "%s", err.msg);
    cr_assert_eq(res.n_nonfinite, 0u);
}

/* New films a and b of width x height rendered with opt on 1 and on 3 threads. */
static void render_1_and_3_threads(const struct trace_scene *ts, const struct trace_options *opt,
                                   int width, int height, struct film *a, struct film *b)
{
    struct mcpt_error err;
    cr_assert(film_init(a, width, height, &err));
    cr_assert(film_init(b, width, height, &err));
    struct trace_options o = *opt;
    o.n_threads = 1;
    render_film(ts, &o, a);
    o.n_threads = 3;
    render_film(ts, &o, b);
}

/* Every sampler, and adaptive sampling by either rule, renders bit-identical films with 1 and
 * 3 threads; an adaptive render split into two calls (maximum 16, then 48) equals one call; and
 * adaptive sampling does stop some pixels early and run others on. */
Test(sampling, deterministic_for_any_thread_count, .timeout = TEST_TIMEOUT_S(120))
{
    struct scene s;
    struct trace_scene *ts = load_scene("scenes/cornell-box.txt", 24, 20, &s);
    size_t n_pixels = (size_t)s.width * (size_t)s.height;
    size_t bytes = sizeof(struct film_pixel) * n_pixels;
    struct mcpt_error err;
    for (int k = 0; k < SAMPLER_COUNT; k++)
        for (int adaptive = 0; adaptive < 3; adaptive++) {
            struct trace_options opt = {.spp = adaptive ? 48 : 8,
                                        .max_depth = 5,
                                        .seed = 42,
                                        .sampler = KINDS[k],
                                        .adaptive = adaptive > 0,
                                        .adaptive_rule = adaptive == 1 ? RENDER_ADAPTIVE_STOP
                                                                       : RENDER_ADAPTIVE_PILOT,
                                        .tolerance = 0.3f,
                                        .adaptive_floor = 0.01f,
                                        .min_spp = 8,
                                        .batch = 8,
                                        .pilot_spp = 8,
                                        .max_spp = 48};
            struct film a, b, c;
            cr_assert(film_init(&c, s.width, s.height, &err));
            render_1_and_3_threads(ts, &opt, s.width, s.height, &a, &b);
            cr_assert(memcmp(a.pixels, b.pixels, bytes) == 0, "%s%s: 1 vs 3 threads",
                      sample_sampler_name(KINDS[k]), adaptive ? " adaptive" : "");
            if (adaptive) {
                opt.spp = 16;
                render_film(ts, &opt, &c);
                opt.spp = 48;
                opt.n_threads = 2;
                render_film(ts, &opt, &c);
                cr_assert(memcmp(a.pixels, c.pixels, bytes) == 0, "%s adaptive: split render",
                          sample_sampler_name(KINDS[k]));
                uint32_t lo = UINT32_MAX, hi = 0;
                for (size_t i = 0; i < n_pixels; i++) {
                    lo = a.pixels[i].n < lo ? a.pixels[i].n : lo;
                    hi = a.pixels[i].n > hi ? a.pixels[i].n : hi;
                }
                cr_assert(lo == 8 && hi == 48, "%s adaptive: counts %u..%u",
                          sample_sampler_name(KINDS[k]), lo, hi);
            }
            film_free(&a);
            film_free(&b);
            film_free(&c);
        }
    trace_free(ts);
    scene_free(&s);
}

/* The budget rule renders bit-identical films with 1 and 3 threads and in two calls (maximum 64,
 * then 256); its counts are powers of two from min-spp to max-spp, at least three of them; and
 * a pixel's estimate is the one a uniform render of its count gives it (its Sobol' prefix). */
Test(sampling, budget_rule_deterministic_and_prefix, .timeout = TEST_TIMEOUT_S(120))
{
    struct scene s;
    struct trace_scene *ts = load_scene("scenes/cornell-box.txt", 24, 20, &s);
    size_t n_pixels = (size_t)s.width * (size_t)s.height;
    size_t bytes = sizeof(struct film_pixel) * n_pixels;
    struct mcpt_error err;
    struct trace_options opt = {.spp = 256,
                                .max_depth = 5,
                                .seed = 42,
                                .sampler = SAMPLER_SOBOL,
                                .adaptive = true,
                                .adaptive_rule = RENDER_ADAPTIVE_BUDGET,
                                .budget_spp = 32,
                                .min_spp = 4,
                                .batch = 1,
                                .pilot_spp = 8,
                                .max_spp = 256};
    struct film a, b, c;
    cr_assert(film_init(&c, s.width, s.height, &err));
    render_1_and_3_threads(ts, &opt, s.width, s.height, &a, &b);
    cr_assert(memcmp(a.pixels, b.pixels, bytes) == 0, "1 vs 3 threads");
    static uint32_t kept[24 * 20];
    opt.pilot_target = kept; /* as main.c keeps them between the calls of one render */
    opt.spp = 64;
    render_film(ts, &opt, &c);
    opt.spp = 256;
    render_film(ts, &opt, &c);
    cr_assert(memcmp(a.pixels, c.pixels, bytes) == 0, "split render");
    bool has[9] = {false};
    for (size_t i = 0; i < n_pixels; i++) {
        uint32_t n = a.pixels[i].n;
        cr_assert(is_pow2(n) && n >= 4 && n <= 256, "pixel %zu: %u samples", i, n);
        has[__builtin_ctz(n)] = true;
    }
    int n_counts = 0;
    for (int e = 0; e <= 8; e++)
        n_counts += has[e];
    cr_assert(n_counts >= 3, "the counts adapt: %d distinct", n_counts);
    for (int e = 2; e <= 8; e++) {
        if (!has[e])
            continue;
        struct film u;
        cr_assert(film_init(&u, s.width, s.height, &err));
        struct trace_options uo = {.spp = 1u << e,
                                   .max_depth = 5,
                                   .seed = 42,
                                   .sampler = SAMPLER_SOBOL,
                                   .n_threads = 2};
        render_film(ts, &uo, &u);
        for (size_t i = 0; i < n_pixels; i++)
            if (a.pixels[i].n == 1u << e)
                cr_assert(memcmp(&a.pixels[i], &u.pixels[i], sizeof u.pixels[i]) == 0,
                          "pixel %zu: %u samples differ from the uniform render's", i, 1u << e);
        film_free(&u);
    }
    film_free(&a);
    film_free(&b);
    film_free(&c);
    trace_free(ts);
    scene_free(&s);
}

/* The budget rule lowers the image's error at equal cost: the Cornell box at 32 x 32, a budget
 * of 128 spp against uniform 128-spp renders, 8 seeds each (the rule's of other seeds); each
 * pixel's variance across the seeds estimates its MSE (both estimators are unbiased), and the
 * image's is their mean over pixels and channels.  Measured: ratio 0.29 over 16 seeds (0.24-0.35
 * in groups of 4; 0.31 in the run that added it).  Asserted: at most 0.6, 2x the
 * measured mean (a rule that stopped helping gives 1), with the rule's rays, its pilot's
 * included, at most 1.1x the uniform renders' (its counts are sized to trace as many). */
Test(sampling, budget_rule_lowers_mse_at_equal_cost, .timeout = TEST_TIMEOUT_S(120))
{
    enum { W = 32, H = 32, SEEDS = 8 };
    struct scene s;
    struct trace_scene *ts = load_scene("scenes/cornell-box.txt", W, H, &s);
    static double v[2][SEEDS][W * H][3];
    uint64_t rays[2] = {0, 0};
    struct mcpt_error err;
    for (int rule = 0; rule < 2; rule++)
        for (int k = 0; k < SEEDS; k++) {
            struct trace_options opt = {.spp = 128,
                                        .max_depth = TRACE_DEPTH_INFINITE,
                                        .seed = 500u + 100u * (uint64_t)rule + (uint64_t)k,
                                        .sampler = SAMPLER_SOBOL,
                                        .n_threads = 2};
            if (rule) {
                opt.adaptive = true;
                opt.adaptive_rule = RENDER_ADAPTIVE_BUDGET;
                opt.budget_spp = 128;
                opt.spp = opt.max_spp = 1024;
                opt.min_spp = 32;
                opt.pilot_spp = TRACE_BUDGET_PILOT_SPP;
            }
            struct film film;
            cr_assert(film_init(&film, W, H, &err));
            struct trace_result res;
            cr_assert(trace_render(ts, &opt, &film, &res, &err), "%s", err.msg);
            rays[rule] += res.n_rays;
            for (int i = 0; i < W * H; i++)
                for (int c = 0; c < 3; c++)
                    v[rule][k][i][c] = film_mean(&film.pixels[i], c);
            film_free(&film);
        }
    double mse[2] = {0.0, 0.0};
    for (int rule = 0; rule < 2; rule++)
        for (int i = 0; i < W * H; i++)
            for (int c = 0; c < 3; c++) {
                double m = 0.0, q = 0.0;
                for (int k = 0; k < SEEDS; k++)
                    m += v[rule][k][i][c] / SEEDS;
                for (int k = 0; k < SEEDS; k++)
                    q += (v[rule][k][i][c] - m) * (v[rule][k][i][c] - m);
                mse[rule] += q / (SEEDS - 1) / (3.0 * W * H);
            }
    double ratio = mse[1] / mse[0], ray_ratio = (double)rays[1] / (double)rays[0];
    cr_log_info("budget rule / uniform: MSE %.3g / %.3g = %.3f, rays %.3f", mse[1], mse[0], ratio,
                ray_ratio);
    cr_assert(ratio <= 0.6, "MSE ratio %.3f, expected <= 0.6 (measured 0.29)", ratio);
    cr_assert(ray_ratio <= 1.1, "rays ratio %.3f, expected <= 1.1", ray_ratio);
    trace_free(ts);
    scene_free(&s);
}

/* The image mean of pixels' estimates (film means) of a 32 x 32 render of the glass Cornell box
 * with options opt, channel by channel. */
static void glass_image_mean(const struct trace_scene *ts, const struct trace_options *opt,
                             int width, int height, double mean[3], uint64_t *n_samples)
{
    struct film film;
    struct mcpt_error err;
    cr_assert(film_init(&film, width, height, &err));
    struct trace_result res;
    cr_assert(trace_render(ts, opt, &film, &res, &err), "%s", err.msg);
    *n_samples = res.n_samples + res.n_pilot;
    for (int c = 0; c < 3; c++) {
        double sum = 0.0;
        for (int i = 0; i < width * height; i++)
            sum += film_mean(&film.pixels[i], c);
        mean[c] = sum / (width * height);
    }
    film_free(&film);
}

/* Adaptive sampling by the pilot rule is unbiased on the glass Cornell box, whose caustic the
 * stop rule misses (docs/sampling.md): over 24 seeds, the image mean of adaptive renders (T
 * 0.2, pilot 8, 8..256 spp) minus that of uniform 64-spp renders of other seeds is within 4
 * standard errors of 0 (the seeds' scatter) in each channel, while the stop rule with the same
 * T, min-spp and batch is below by more than 4.  So is the budget rule's (a budget of 64 spp,
 * pilot 8, 16..512 spp), within 4. */
Test(sampling, adaptive_pilot_unbiased_on_glass, .timeout = TEST_TIMEOUT_S(240))
{
    enum { W = 32, H = 32, SEEDS = 24 };
    struct scene s;
    struct trace_scene *ts = load_scene("scenes/cornell-glass.txt", W, H, &s);
    struct trace_options base = {.max_depth = TRACE_DEPTH_INFINITE,
                                 .sampler = SAMPLER_SOBOL,
                                 .n_threads = 2,
                                 .tolerance = 0.2f,
                                 .adaptive_floor = 0.01f,
                                 .min_spp = 8,
                                 .batch = 8,
                                 .pilot_spp = 8};
    double sum[3][3] = {{0}}, sum_sq[3][3] = {{0}};
    uint64_t n_adaptive = 0;
    for (uint64_t k = 0; k < SEEDS; k++) {
        double uniform[3], pilot[3], stop[3], budget[3];
        uint64_t n;
        struct trace_options opt = base;
        opt.seed = 1000 + k;
        opt.spp = 64;
        glass_image_mean(ts, &opt, W, H, uniform, &n);
        opt.seed = 2000 + k;
        opt.spp = 256;
        opt.adaptive = true;
        opt.adaptive_rule = RENDER_ADAPTIVE_PILOT;
        glass_image_mean(ts, &opt, W, H, pilot, &n);
        n_adaptive += n;
        opt.adaptive_rule = RENDER_ADAPTIVE_STOP;
        glass_image_mean(ts, &opt, W, H, stop, &n);
        opt.adaptive_rule = RENDER_ADAPTIVE_BUDGET;
        opt.seed = 3000 + k;
        opt.budget_spp = 64;
        opt.spp = opt.max_spp = 512;
        opt.min_spp = 16;
        glass_image_mean(ts, &opt, W, H, budget, &n);
        for (int c = 0; c < 3; c++) {
            double d[3] = {pilot[c] - uniform[c], stop[c] - uniform[c], budget[c] - uniform[c]};
            for (int r = 0; r < 3; r++) {
                sum[r][c] += d[r];
                sum_sq[r][c] += d[r] * d[r];
            }
        }
    }
    for (int c = 0; c < 3; c++) {
        double z[3];
        for (int r = 0; r < 3; r++) {
            double m = sum[r][c] / SEEDS;
            double se = sqrt((sum_sq[r][c] / SEEDS - m * m) / (SEEDS - 1));
            z[r] = m / se;
        }
        cr_log_info("channel %d: pilot - uniform %.2f SE, stop - uniform %.2f SE, budget - "
                    "uniform %.2f SE (pilot %.1f spp a pixel with its pilot)",
                    c, z[0], z[1], z[2], (double)n_adaptive / SEEDS / (W * H));
        cr_assert(fabs(z[0]) < 4.0, "channel %d: pilot rule off by %.2f SE", c, z[0]);
        cr_assert(fabs(z[2]) < 4.0, "channel %d: budget rule off by %.2f SE", c, z[2]);
        cr_assert(z[1] < -4.0, "channel %d: the stop rule's bias, %.2f SE, not seen", c, z[1]);
    }
    trace_free(ts);
    scene_free(&s);
}

/* Equal-spp error on direct lighting (scenes/direct-plane.txt, 16x16, 16 spp): for each pixel
 * the variance of its value across 8 seeds estimates its MSE (every sampler is unbiased).  The
 * statistic is the geometric mean over pixels of v_sampler / v_independent (pixels with a
 * nonzero variance under both: the lamp and the black background have none).  Measured over 200
 * other sets of 8 seeds: stratified 0.0280 (sd 0.0015, ln sd 0.052, range 0.024-0.032), Sobol'
 * 0.0615 (sd 0.0031, ln sd 0.051, range 0.053-0.070): 36x and 16x less MSE per pixel.  The test
 * asserts ratio <= 2 x the measured mean (0.056 and 0.123), at least 18x and 8x less: ln 2 =
 * 13 sd above the measured mean, so chance does not fail it, and 40 sd below no advantage
 * (ratio 1), so a sampler that loses its stratification, or half its gain, fails it.  (The
 * ratio of image MSEs, 0.21 and 0.65, is dominated by a few pixels and too noisy at 8 seeds
 * to test: Sobol' ranged 0.39-1.00.) */
Test(sampling, stratified_and_sobol_beat_independent, .timeout = TEST_TIMEOUT_S(120))
{
    enum { W = 16, H = 16, SEEDS = 8, SPP = 16 };
    const double ratio_max[SAMPLER_COUNT] = {1.0, 2.0 * 0.0280, 2.0 * 0.0615}; /* by KINDS */
    struct scene s;
    struct trace_scene *ts = load_scene("scenes/direct-plane.txt", W, H, &s);
    struct mcpt_error err;
    static double lum[SAMPLER_COUNT][SEEDS][W * H];
    for (int k = 0; k < SAMPLER_COUNT; k++)
        for (int seed = 0; seed < SEEDS; seed++) {
            struct film film;
            cr_assert(film_init(&film, W, H, &err));
            struct trace_options opt = {.spp = SPP,
                                        .max_depth = s.render.max_depth,
                                        .seed = 1000u + (uint64_t)seed,
                                        .sampler = KINDS[k],
                                        .n_threads = 2};
            render_film(ts, &opt, &film);
            for (int i = 0; i < W * H; i++)
                lum[k][seed][i] = film_sum_lum(&film.pixels[i]) / film.pixels[i].n;
            film_free(&film);
        }
    static double v[SAMPLER_COUNT][W * H]; /* per-pixel variance across seeds */
    double v_mean[SAMPLER_COUNT] = {0};
    for (int k = 0; k < SAMPLER_COUNT; k++)
        for (int i = 0; i < W * H; i++) {
            double m = 0, q = 0;
            for (int seed = 0; seed < SEEDS; seed++)
                m += lum[k][seed][i] / SEEDS;
            for (int seed = 0; seed < SEEDS; seed++)
                q += (lum[k][seed][i] - m) * (lum[k][seed][i] - m);
            v[k][i] = q / (SEEDS - 1);
            v_mean[k] += v[k][i] / (W * H);
        }
    cr_assert(v_mean[0] > 0.0, "the scene has noise to reduce");
    int n_noisy = 0; /* pixels with noise under independent sampling */
    for (int i = 0; i < W * H; i++)
        n_noisy += v[0][i] > 0.0;
    for (int k = 1; k < SAMPLER_COUNT; k++) {
        double sum_ln = 0.0;
        int n = 0;
        for (int i = 0; i < W * H; i++)
            if (v[0][i] > 0.0 && v[k][i] > 0.0) {
                sum_ln += log(v[k][i] / v[0][i]);
                n++;
            }
        double ratio = exp(sum_ln / n);
        cr_log_info("%s: per-pixel MSE ratio %.4f (geometric mean of %d pixels), image MSE %.3g "
                    "vs independent %.3g (ratio %.3f)\n",
                    sample_sampler_name(KINDS[k]), ratio, n, v_mean[k], v_mean[0],
                    v_mean[k] / v_mean[0]);
        /* a sampler whose points ignore the seed would show no variance at all (measured: at
         * most 2 of the 222-224 noisy pixels are noise-free under stratified or Sobol') */
        cr_assert(n >= n_noisy * 9 / 10, "%s: only %d of %d noisy pixels vary with the seed",
                  sample_sampler_name(KINDS[k]), n, n_noisy);
        cr_assert(ratio <= ratio_max[k],
                  "%s: per-pixel MSE ratio to independent %.4f, expected at most %.4f (measured "
                  "%.4f)",
                  sample_sampler_name(KINDS[k]), ratio, ratio_max[k], ratio_max[k] / 2.0);
    }
    trace_free(ts);
    scene_free(&s);
}

/* ---- the render statement's sampling parameters (scene.c, docs/scene-format.md) ---- */

/* Writes text to a temporary scene file and loads it; returns scene_load's result. */
static bool load_text(const char *text, struct scene *s, struct mcpt_error *err)
{
    char path[] = "/tmp/mcpt_sample_scene_XXXXXX";
    int fd = mkstemp(path);
    cr_assert(fd >= 0);
    FILE *f = fdopen(fd, "w");
    cr_assert(f);
    fputs(text, f);
    fclose(f);
    bool ok = scene_load(path, s, err);
    remove(path);
    return ok;
}

#define CAM "camera eye=0,0,1 look-at=0,0,0 up=0,1,0 fov=40\n"

/* sampler= and the adaptive settings are read into struct render_settings; without them the
 * defaults are SAMPLER_DEFAULT, not adaptive, and "not given" (0, floor < 0). */
Test(sampling, render_statement_parameters)
{
    struct scene s;
    struct mcpt_error err;
    cr_assert(load_text(CAM "render spp=8 sampler=stratified adaptive=true tolerance=0.1 "
                            "adaptive-floor=0.002 batch=16 min-spp=32 max-spp=512 "
                            "adaptive-rule=stop pilot-spp=8 light-sampling=solid-angle\n",
                        &s, &err),
              "%s", err.msg);
    cr_assert_eq(s.render.sampler, SAMPLER_STRATIFIED);
    cr_assert(s.render.adaptive);
    cr_assert(s.render.has_adaptive_rule && s.render.adaptive_rule == RENDER_ADAPTIVE_STOP);
    cr_assert_eq(s.render.pilot_spp, 8u);
    cr_assert_eq(s.render.light_sampling, RENDER_LIGHT_SOLID_ANGLE);
    cr_assert_float_eq(s.render.tolerance, 0.1f, 1e-7f);
    cr_assert_float_eq(s.render.adaptive_floor, 0.002f, 1e-9f);
    cr_assert_eq(s.render.batch, 16u);
    cr_assert_eq(s.render.min_spp, 32u);
    cr_assert_eq(s.render.max_spp, 512u);
    scene_free(&s);
    cr_assert(load_text(CAM, &s, &err), "%s", err.msg);
    cr_assert_eq(s.render.sampler, SAMPLER_DEFAULT);
    cr_assert_not(s.render.adaptive);
    cr_assert(s.render.tolerance == 0.0f && s.render.batch == 0 && s.render.min_spp == 0 &&
              s.render.max_spp == 0 && s.render.adaptive_floor < 0.0f);
    cr_assert(!s.render.has_adaptive_rule && s.render.pilot_spp == 0);
    cr_assert_eq(s.render.light_sampling, RENDER_LIGHT_AREA);
    scene_free(&s);
}

/* Bad sampling parameters: exact messages with line and column. */
Test(sampling, render_statement_errors)
{
    const struct {
        const char *line;
        int col;
        const char *msg;
    } cases[] = {
        {"render sampler=halton\n", 16,
         "expected independent, stratified or sobol for 'sampler', got 'halton'"},
        {"render min-spp=1\n", 16, "expected 'min-spp' in 2..4294967295, got 1"},
        {"render min-spp=128 max-spp=64\n", 16, "expected 'min-spp' <= 'max-spp' (64), got 128"},
        {"render tolerance=0\n", 18, "expected 'tolerance' > 0, got 0"},
        {"render batch=0\n", 14, "expected 'batch' in 1..4294967295, got 0"},
        {"render adaptive=yes\n", 17, "expected true or false for 'adaptive', got 'yes'"},
        {"render adaptive-rule=early\n", 22,
         "expected pilot, stop or budget for 'adaptive-rule', got 'early'"},
        {"render pilot-spp=1\n", 18, "expected 'pilot-spp' in 2..4294967295, got 1"},
        {"render pilot-spp=0\n", 18, "expected 'pilot-spp' in 2..4294967295, got 0"},
        {"render light-sampling=sphere\n", 23,
         "expected area or solid-angle for "
         "'light-sampling', got 'sphere'"},
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        char text[256];
        snprintf(text, sizeof text, CAM "%s", cases[c].line);
        struct scene s;
        struct mcpt_error err = {0};
        cr_assert_not(load_text(text, &s, &err), "%s", cases[c].line);
        cr_assert_eq(err.line, 2, "%s: line %d", cases[c].line, err.line);
        cr_assert_eq(err.col, cases[c].col, "%s: column %d", cases[c].line, err.col);
        cr_assert_str_eq(err.msg, cases[c].msg);
    }
}
