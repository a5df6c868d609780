/* tests/film_test.c - film.c: the accumulation buffer.  film_pixel_problem, the check readers of
 * saved films apply (checkpoints, partial renders), accepts every pixel a render can leave --
 * including samples near FLT_MAX, whose squares only a double holds, a million samples, dropped
 * samples -- and names each kind of value no render leaves: NaN or infinite sums, negative
 * squares, more samples than the render takes, an empty pixel with sums, and a sum beyond the
 * Cauchy-Schwarz bound sum^2 <= n sum_sq. */
#include <criterion/criterion.h>

#include <float.h>

#include "film.h"
#include "sample.h"

/* Pixels a render makes pass: random samples over 40 orders of magnitude, FLT_MAX itself, one
 * sample, a million equal samples (where rounding meets the bound hardest), dropped samples. */
Test(film, rendered_pixels_pass)
{
    struct pcg32 rng;
    sample_pcg32_seed(&rng, 1, 2);
    for (int t = 0; t < 200; t++) {
        struct film_pixel p = {0};
        uint32_t n = 1 + sample_pcg32_next(&rng) % 300;
        float scale = exp2f((float)(sample_pcg32_next(&rng) % 250) - 125.0f);
        for (uint32_t k = 0; k < n; k++)
            film_add(&p, v3(scale * sample_pcg32_float(&rng), scale * sample_pcg32_float(&rng),
                            scale * sample_pcg32_float(&rng)));
        p.n_dropped = t % 3;
        cr_assert_null(film_pixel_problem(&p, n + 2), "trial %d: %s", t,
                       film_pixel_problem(&p, n + 2));
    }
    struct film_pixel p = {0};
    for (int k = 0; k < 5; k++)
        film_add(&p, v3(FLT_MAX, 0.0f, FLT_MAX));
    cr_assert_null(film_pixel_problem(&p, 5));
    memset(&p, 0, sizeof p);
    for (int k = 0; k < 1000000; k++)
        film_add(&p, v3(0.1f, 0.7f, 3.3f));
    cr_assert_null(film_pixel_problem(&p, 1000000));
    struct film_pixel empty = {.n_dropped = 4};
    cr_assert_null(film_pixel_problem(&empty, 4));
}

/* Each value no render leaves is named. */
Test(film, impossible_pixels_named)
{
    struct film_pixel base = {0};
    for (int k = 0; k < 8; k++)
        film_add(&base, v3(0.5f, 0.25f, 1.0f));
    struct film_pixel p = base;
    p.sum[1] = NAN;
    cr_assert_str_eq(film_pixel_problem(&p, 8),
                     "a sum that is not finite or exceeds the count times the largest float");
    p = base;
    p.sum_sq[2] = INFINITY;
    cr_assert_str_eq(film_pixel_problem(&p, 8),
                     "a sum of squares below 0, not finite or beyond the count's reach");
    p = base;
    p.sum_sq[0] = -1e-300;
    cr_assert_not_null(film_pixel_problem(&p, 8));
    p = base;
    p.sum[1] = -p.sum[1]; /* within Cauchy-Schwarz, but radiance is never negative */
    cr_assert_str_eq(film_pixel_problem(&p, 8), "a negative sum");
    struct film_pixel dark = {0}; /* eight black samples: a sum of -0 is 0, not negative */
    for (int k = 0; k < 8; k++)
        film_add(&dark, v3(0.0f, 0.0f, 0.0f));
    dark.sum[0] = -0.0;
    cr_assert_null(film_pixel_problem(&dark, 8));
    p = base;
    p.sum_lum_sq = 0.0; /* the luminance's sum is not 0 */
    cr_assert_str_eq(film_pixel_problem(&p, 8),
                     "a sum whose square exceeds the count times the sum of squares");
    p = base;
    p.sum[0] = 9 * 0.5; /* one sample more than counted */
    cr_assert_not_null(film_pixel_problem(&p, 8));
    p = base;
    cr_assert_str_eq(film_pixel_problem(&p, 7), "more samples than the render takes");
    p = base;
    p.n_dropped = UINT32_MAX; /* n + n_dropped must not wrap */
    cr_assert_not_null(film_pixel_problem(&p, UINT32_MAX));
    struct film_pixel empty = {.sum = {1e-300, 0.0, 0.0}};
    cr_assert_not_null(film_pixel_problem(&empty, 8));
    p = base;
    p.sum[2] = 8.0 * FLT_MAX * 1.01; /* beyond 8 finite float samples */
    cr_assert_not_null(film_pixel_problem(&p, 8));
}
