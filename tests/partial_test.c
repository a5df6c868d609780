/* tests/partial_test.c - partial.c and the CLI around it (--sample-range, mcpt merge): the
 * double-float pair (Dekker 1971) keeps each film sum to 2^-48 relative through an EXR; merges
 * add raw moments (Chan, Golub & LeVeque 1979) and refuse incompatible parts with golden
 * messages; the result does not depend on the order of the parts; and 4 processes started by
 * GNU parallel over 4 disjoint sample ranges, merged, equal one process rendering every sample
 * to within the float-rounding bound derived in docs/distributed.md. */
#include <criterion/criterion.h>

#include <float.h>
#include <stdarg.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include "image.h"
#include "partial.h"
#include "test_util.h"

static char g_dir[256];

static void setup(void)
{
    snprintf(g_dir, sizeof g_dir, "/tmp/mcpt_partial_XXXXXX");
    cr_assert_not_null(mkdtemp(g_dir));
}

static void teardown(void)
{
    char cmd[512];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", g_dir);
    cr_assert_eq(system(cmd), 0);
}

static const char *scratch(char *buf, size_t buf_bytes, const char *name)
{
    snprintf(buf, buf_bytes, "%s/%s", g_dir, name);
    return buf;
}

static uint64_t g_rng = 0x853c49e6748fea9bull;

/* xorshift64*: test data only */
static double uniform01(void)
{
    g_rng ^= g_rng >> 12;
    g_rng ^= g_rng << 25;
    g_rng ^= g_rng >> 27;
    return (double)((g_rng * 0x2545F4914F6CDD1Dull) >> 11) * 0x1p-53;
}

/* A film whose pixels hold random sums spanning exponents 2^-60 .. 2^60 and sums of squares
 * 2^-60 .. 2^100, counts n with n + n_dropped = n_total, and sums that n samples can give
 * (film_pixel_problem: each sum of squares at least sum^2 / n, Cauchy-Schwarz). */
static void random_film(struct film *film, int width, int height, uint32_t n_total)
{
    struct mcpt_error err;
    cr_assert(film_init(film, width, height, &err), "%s", err.msg);
    for (int i = 0; i < width * height; i++) {
        struct film_pixel *p = &film->pixels[i];
        p->n_dropped = (uint32_t)(uniform01() * 3.0);
        if (p->n_dropped >= n_total)
            p->n_dropped = n_total - 1;
        p->n = n_total - p->n_dropped;
        double n = (double)p->n;
        for (int c = 0; c < 3; c++) {
            p->sum[c] = uniform01() * ldexp(1.0, (int)(uniform01() * 120.0) - 60);
            p->sum_sq[c] = fmax(uniform01() * ldexp(1.0, (int)(uniform01() * 160.0) - 60),
                                p->sum[c] * p->sum[c] / n * 1.001);
        }
        double lum = film_sum_lum(p);
        p->sum_lum_sq = fmax(uniform01() * 1e10, lum * lum / n * 1.001);
    }
}

static struct partial_info one_range(uint32_t begin, uint32_t end, const char *render)
{
    struct partial_info info;
    memset(&info, 0, sizeof info);
    info.n_ranges = 1;
    info.ranges[0] = (struct partial_range){begin, end};
    snprintf(info.render, sizeof info.render, "%s", render);
    return info;
}

/* ---- units ---- */

/* "A:B" with 0 <= A < B <= 2^32 - 1, nothing else. */
Test(partial, parse_range)
{
    struct partial_range r;
    cr_assert(partial_parse_range("0:1", &r));
    cr_assert(r.begin == 0 && r.end == 1);
    cr_assert(partial_parse_range("4294967294:4294967295", &r));
    cr_assert(r.begin == 4294967294u && r.end == 4294967295u);
    const char *bad[] = {"",     "5",    "5:",   ":5",           "5:5",   "6:5", "-1:3",
                         "1:2x", " 1:2", "1:+2", "0:4294967296", "1:2:3", "1,2"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
        cr_assert_not(partial_parse_range(bad[i], &r), "accepted '%s'", bad[i]);
}

/* The double-float pair through an EXR: every sum comes back within 2^-48 of its value
 * (Dekker 1971: hi = fl(x), lo = fl(x - hi), |x - hi - lo| <= 2^-24 |x - hi| <= 2^-48 |x|),
 * counts (integers below 2^32, which two floats hold exactly) and attributes come back exact,
 * and the channels of an ordinary render are there too. */
Test(partial, exr_round_trip_keeps_48_bits, .init = setup, .fini = teardown)
{
    struct film film, back;
    random_film(&film, 13, 7, 4000000000u);
    struct partial_info info = one_range(123, 4000000123u, "scene=0123 spp=4294967295 seed=7");
    char path[300];
    struct mcpt_error err;
    cr_assert(partial_write_exr(scratch(path, sizeof path, "p.exr"), &film, &info, &err), "%s",
              err.msg);
    struct partial_info info_back;
    cr_assert(partial_read_exr(path, &back, &info_back, &err), "%s", err.msg);
    cr_assert_eq(back.width, 13);
    cr_assert_eq(back.height, 7);
    cr_assert_eq(info_back.n_ranges, 1);
    cr_assert_eq(info_back.ranges[0].begin, 123u);
    cr_assert_eq(info_back.ranges[0].end, 4000000123u);
    cr_assert_str_eq(info_back.render, info.render);
    double worst = 0.0;
    for (int i = 0; i < 13 * 7; i++) {
        const struct film_pixel *a = &film.pixels[i], *b = &back.pixels[i];
        double x[7] = {a->sum[0],    a->sum[1],    a->sum[2],    a->sum_sq[0],
                       a->sum_sq[1], a->sum_sq[2], a->sum_lum_sq};
        double y[7] = {b->sum[0],    b->sum[1],    b->sum[2],    b->sum_sq[0],
                       b->sum_sq[1], b->sum_sq[2], b->sum_lum_sq};
        for (int k = 0; k < 7; k++) {
            double rel = fabs(y[k] - x[k]) / x[k];
            worst = fmax(worst, rel);
            cr_assert_leq(rel, 0x1p-48, "pixel %d value %d: %.17g back as %.17g", i, k, x[k], y[k]);
        }
        cr_assert_eq(b->n, a->n);
        cr_assert_eq(b->n_dropped, a->n_dropped);
    }
    cr_assert_gt(worst, 0.0, "expected some rounding: a float pair is not a double");
    struct image img;
    cr_assert(image_read_exr(path, &img, &err), "%s", err.msg);
    const char *std[] = {"R", "G", "B", "variance.R", "variance.G", "variance.B", "samples"};
    for (int c = 0; c < 7; c++)
        cr_assert_geq(image_find_channel(&img, std[c]), 0, "no channel %s", std[c]);
    cr_assert_eq(img.n_channels, 24);
    image_free(&img);
    film_free(&film);
    film_free(&back);
}

/* A sum beyond float range cannot be stored as a float pair: refused, nothing written. */
Test(partial, write_refuses_sums_beyond_float_range, .init = setup, .fini = teardown)
{
    struct film film;
    random_film(&film, 2, 2, 5);
    film.pixels[3].sum_sq[1] = 1e39;
    struct partial_info info = one_range(0, 5, "r");
    char path[300];
    struct mcpt_error err;
    cr_assert_not(partial_write_exr(scratch(path, sizeof path, "big.exr"), &film, &info, &err));
    cr_assert_str_eq(err.msg, "expected per-pixel sums within float range (3.4e38) to store "
                              "them, got 1e+39 in 'sum_sq.G' at pixel 1,1");
    cr_assert_neq(access(path, F_OK), 0);
    film_free(&film);
}

/* A pixel with fewer samples than its ranges hold (an interrupted render) is refused. */
Test(partial, read_refuses_incomplete_pixels, .init = setup, .fini = teardown)
{
    struct film film, back;
    random_film(&film, 3, 2, 16);
    film.pixels[4].n = 7;
    film.pixels[4].n_dropped = 0;
    struct partial_info info = one_range(16, 32, "r"), info_back;
    char path[300];
    struct mcpt_error err;
    cr_assert(partial_write_exr(scratch(path, sizeof path, "cut.exr"), &film, &info, &err));
    cr_assert_not(partial_read_exr(path, &back, &info_back, &err));
    cr_assert_str_eq(err.msg, "expected the 16 samples of ranges 16:32 at every pixel, got 7 at "
                              "pixel 1,1 (an interrupted render? finish it with --resume first)");
    cr_assert_str_eq(err.file, path);
    cr_assert_null(back.pixels);
    film_free(&film);
}

/* Sums no render writes (a negative sum of squares, a sum beyond Cauchy-Schwarz's bound
 * sum^2 <= n sum_sq), though finite and with the right counts, are refused (issue 15). */
Test(partial, read_refuses_impossible_sums, .init = setup, .fini = teardown)
{
    struct film film, back;
    random_film(&film, 3, 2, 16);
    struct partial_info info = one_range(0, 16, "r"), info_back;
    char path[300];
    struct mcpt_error err;
    film.pixels[5].sum_sq[1] = -1.0;
    cr_assert(partial_write_exr(scratch(path, sizeof path, "neg.exr"), &film, &info, &err));
    cr_assert_not(partial_read_exr(path, &back, &info_back, &err));
    cr_assert(strstr(err.msg, "got a sum of squares below 0") && strstr(err.msg, "pixel 2,1"), "%s",
              err.msg);
    film.pixels[5].sum_sq[1] = 1.0;
    film.pixels[5].sum[1] = 100.0; /* 16 samples, squares summing to 1: |sum| <= 4 */
    cr_assert(partial_write_exr(path, &film, &info, &err));
    cr_assert_not(partial_read_exr(path, &back, &info_back, &err));
    cr_assert(strstr(err.msg, "a sum whose square exceeds the count times the sum of squares"),
              "%s", err.msg);
    film.pixels[5].sum[1] = -2.0; /* within the bound, but negative: found by probing */
    cr_assert(partial_write_exr(path, &film, &info, &err));
    cr_assert_not(partial_read_exr(path, &back, &info_back, &err));
    cr_assert(strstr(err.msg, "got a negative sum") && strstr(err.msg, "pixel 2,1"), "%s", err.msg);
    cr_assert_null(back.pixels);
    film_free(&film);
}

/* The attributes mcpt quotes in its messages (the render settings, the ranges) must be
 * printable: a line break or an escape sequence from a file would reach the terminal. */
Test(partial, read_refuses_unprintable_attributes, .init = setup, .fini = teardown)
{
    struct film film, back;
    random_film(&film, 2, 2, 4);
    struct partial_info info = one_range(0, 4, "scene=1\n\x1b[2Jspp=4"), info_back;
    char path[300];
    struct mcpt_error err;
    cr_assert(partial_write_exr(scratch(path, sizeof path, "ctl.exr"), &film, &info, &err));
    cr_assert_not(partial_read_exr(path, &back, &info_back, &err));
    cr_assert_str_eq(err.msg, "expected attribute 'mcpt.render' of printable ASCII characters, "
                              "got other bytes");
    film_free(&film);
}

/* Merging adds every raw moment (Chan et al. 1979) and joins adjacent ranges; incompatible
 * parts (size, settings, overlapping ranges) are refused with golden messages, changing
 * nothing. */
Test(partial, merge_adds_moments_and_checks_parts)
{
    struct film a, b, c;
    random_film(&a, 4, 3, 10);
    random_film(&b, 4, 3, 6);
    random_film(&c, 3, 4, 6);
    struct film a0;
    struct mcpt_error err;
    cr_assert(film_init(&a0, 4, 3, &err));
    memcpy(a0.pixels, a.pixels, sizeof *a.pixels * 12);
    struct partial_info ia = one_range(0, 10, "s"), ib = one_range(10, 16, "s");
    struct partial_info ic = one_range(10, 16, "s"), other = one_range(20, 26, "t");
    struct partial_info overlap = one_range(8, 14, "s");

    cr_assert_not(partial_merge(&a, &ia, &c, &ic, "c.exr", &err));
    cr_assert_str_eq(err.msg, "expected a 4x3 image like the parts before it, got 3x4");
    cr_assert_str_eq(err.file, "c.exr");
    cr_assert_not(partial_merge(&a, &ia, &b, &other, "t.exr", &err));
    cr_assert_str_eq(err.msg, "expected the render settings of the parts before it ('s'), got "
                              "'t'");
    cr_assert_not(partial_merge(&a, &ia, &b, &overlap, "o.exr", &err));
    cr_assert_str_eq(err.msg, "expected sample ranges disjoint from those of the parts before it "
                              "(0:10), got 8:14");
    cr_assert_eq(memcmp(a.pixels, a0.pixels, sizeof *a.pixels * 12), 0, "a failed merge wrote");
    cr_assert_eq(ia.n_ranges, 1);

    cr_assert(partial_merge(&a, &ia, &b, &ib, "b.exr", &err), "%s", err.msg);
    cr_assert_eq(ia.n_ranges, 1, "adjacent ranges 0:10 and 10:16 join");
    cr_assert(ia.ranges[0].begin == 0 && ia.ranges[0].end == 16);
    for (int i = 0; i < 12; i++) {
        for (int k = 0; k < 3; k++) {
            cr_assert_eq(a.pixels[i].sum[k], a0.pixels[i].sum[k] + b.pixels[i].sum[k]);
            cr_assert_eq(a.pixels[i].sum_sq[k], a0.pixels[i].sum_sq[k] + b.pixels[i].sum_sq[k]);
        }
        cr_assert_eq(a.pixels[i].sum_lum_sq, a0.pixels[i].sum_lum_sq + b.pixels[i].sum_lum_sq);
        cr_assert_eq(a.pixels[i].n + a.pixels[i].n_dropped, 16u);
    }
    char ranges[PARTIAL_RENDER_BYTES];
    struct partial_info gap = one_range(30, 40, "s");
    cr_assert(partial_merge(&a, &ia, &b, &gap, "g.exr", &err), "%s", err.msg);
    partial_format_ranges(&ia, ranges, sizeof ranges);
    cr_assert_str_eq(ranges, "0:16,30:40");
    film_free(&a);
    film_free(&a0);
    film_free(&b);
    film_free(&c);
}

/* partial_merge_files adds the parts in the order of their first sample index, so any order
 * of the file names gives the same bits (floating-point addition is not associative, so this
 * fails if the order leaks through); the union of 0:5, 5:12 and 12:20 is 0:20. */
Test(partial, merge_files_independent_of_order, .init = setup, .fini = teardown)
{
    const uint32_t bounds[4] = {0, 5, 12, 20};
    char paths[3][300];
    struct mcpt_error err;
    for (int k = 0; k < 3; k++) {
        struct film f;
        random_film(&f, 9, 5, bounds[k + 1] - bounds[k]);
        struct partial_info info = one_range(bounds[k], bounds[k + 1], "same");
        char name[32];
        snprintf(name, sizeof name, "part%d.exr", k);
        cr_assert(partial_write_exr(scratch(paths[k], sizeof paths[k], name), &f, &info, &err),
                  "%s", err.msg);
        film_free(&f);
    }
    const char *order1[3] = {paths[0], paths[1], paths[2]};
    const char *order2[3] = {paths[2], paths[0], paths[1]};
    struct film m1, m2;
    struct partial_info i1, i2;
    cr_assert(partial_merge_files(order1, 3, &m1, &i1, &err), "%s", err.msg);
    cr_assert(partial_merge_files(order2, 3, &m2, &i2, &err), "%s", err.msg);
    cr_assert_eq(memcmp(m1.pixels, m2.pixels, sizeof *m1.pixels * 45), 0);
    cr_assert(i1.n_ranges == 1 && i1.ranges[0].begin == 0 && i1.ranges[0].end == 20);
    film_free(&m1);
    film_free(&m2);
    const char *bad[2] = {paths[0], "tests/data/nonexistent.exr"};
    cr_assert_not(partial_merge_files(bad, 2, &m1, &i1, &err));
    cr_assert_str_eq(err.file, "tests/data/nonexistent.exr");
    cr_assert_null(m1.pixels);
}

/* ---- end to end: the CLI, GNU parallel ---- */

/* Runs a shell command; returns its exit status. */
static int shell(const char *fmt, ...)
{
    char cmd[4096];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(cmd, sizeof cmd, fmt, ap);
    va_end(ap);
    int status = system(cmd);
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128;
}

static const char *mcpt_bin(void) { return getenv("MCPT") ? getenv("MCPT") : "./mcpt"; }

static float channel(const struct image *img, const char *name, int i)
{
    int c = image_find_channel(img, name);
    cr_assert_geq(c, 0, "no channel %s", name);
    return img->data[c][i];
}

/* The render of every sample by one process and the merge of the parts agree to within float
 * rounding (docs/distributed.md, "Error bound"): both sums approximate the exact sum S of the
 * same n non-negative samples, within eps S with eps = (2n + 8) 2^-53 + 2^-48 (two summation
 * orders, the float-pair storage, the merge's additions), far below float's 2^-24; so each
 * stored mean differs by at most one float ulp, <= 2^-23 max(|a|, |b|), and each variance of
 * the mean by one ulp plus the cancellation term 5 eps Q / (n (n - 1)), Q the sum of squares.
 * Counts are equal.  Returns the number of values that differ at all. */
static int assert_within_rounding(const struct image *merged, const struct image *full)
{
    cr_assert_eq(merged->width, full->width);
    cr_assert_eq(merged->height, full->height);
    int n_pixels = full->width * full->height, n_differ = 0;
    const char *rgb = "RGB";
    for (int i = 0; i < n_pixels; i++) {
        float n = channel(full, "samples", i);
        cr_assert_eq(channel(merged, "samples", i), n, "pixel %d: sample counts differ", i);
        double eps = (2.0 * n + 8.0) * 0x1p-53 + 0x1p-48;
        for (int c = 0; c < 3; c++) {
            char name[32];
            snprintf(name, sizeof name, "%c", rgb[c]);
            float a = channel(merged, name, i), b = channel(full, name, i);
            cr_assert_leq(fabsf(a - b), 0x1p-23f * fmaxf(fabsf(a), fabsf(b)),
                          "pixel %d %s: merged %.9g, one process %.9g", i, name, a, b);
            n_differ += a != b;
            char q_hi[32], q_lo[32];
            snprintf(name, sizeof name, "variance.%c", rgb[c]);
            snprintf(q_hi, sizeof q_hi, "sum_sq.%c", rgb[c]);
            snprintf(q_lo, sizeof q_lo, "sum_sq_lo.%c", rgb[c]);
            double Q = (double)channel(merged, q_hi, i) + (double)channel(merged, q_lo, i);
            float va = channel(merged, name, i), vb = channel(full, name, i);
            double bound = 0x1p-23 * fmax(va, vb) + 5.0 * eps * Q / ((double)n * (n - 1.0));
            cr_assert_leq(fabs((double)va - vb), bound,
                          "pixel %d %s: merged %.9g, one process %.9g", i, name, va, vb);
            n_differ += va != vb;
        }
    }
    return n_differ;
}

/* GNU parallel runs 4 mcpt processes over the uneven disjoint ranges 0:10, 10:27, 27:50 and
 * 50:64 of a 64-spp render of the glass Cornell box (refraction, every kind of path), mcpt
 * merge --partial joins them (keeping the sums the bound below reads), and the result equals
 * one process rendering all 64 samples within the float-rounding bound above; for the Sobol'
 * sampler and for the stratified one (whose strata span the whole render, so a range must use
 * the whole render's sets). */
Test(distributed, gnu_parallel_four_ranges_equal_one_process, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(120))
{
    cr_assert_eq(shell("parallel --version 2>/dev/null | grep -q 'GNU parallel'"), 0,
                 "this test needs GNU parallel (Debian package 'parallel': apt-get install "
                 "parallel); 'parallel' is missing or is not GNU parallel");
    const char *samplers[] = {"sobol", "stratified"};
    for (int s = 0; s < 2; s++) {
        const char *common = "scenes/cornell-glass.txt --width 48 --height 36 --spp 64 "
                             "--threads 1 --quiet";
        cr_assert_eq(shell("parallel --will-cite -j4 --halt now,fail=1 %s %s --sampler %s "
                           "--sample-range {} -o %s/part-{#}.exr ::: 0:10 10:27 27:50 50:64",
                           mcpt_bin(), common, samplers[s], g_dir),
                     0, "parallel or one of the partial renders failed");
        cr_assert_eq(shell("%s merge --quiet --partial %s/part-*.exr -o %s/merged.exr", mcpt_bin(),
                           g_dir, g_dir),
                     0);
        cr_assert_eq(shell("%s %s --sampler %s -o %s/full.exr", mcpt_bin(), common, samplers[s],
                           g_dir),
                     0);
        char path[300];
        struct image merged, full;
        struct mcpt_error err;
        cr_assert(image_read_exr(scratch(path, sizeof path, "merged.exr"), &merged, &err), "%s",
                  err.msg);
        cr_assert(image_read_exr(scratch(path, sizeof path, "full.exr"), &full, &err), "%s",
                  err.msg);
        cr_assert_str_eq(image_find_attr(&merged, PARTIAL_ATTR_RANGES), "0:64");
        int n_differ = assert_within_rounding(&merged, &full);
        cr_log_info("%s: %d of %d values differ, each by at most one float ulp", samplers[s],
                    n_differ, 48 * 36 * 6);
        image_free(&merged);
        image_free(&full);
    }
}

/* --sample-range 0:N renders what a plain N-spp render does: the ordinary channels are
 * bit-identical (same sample indices, same stratified sets, same order of addition). */
Test(distributed, whole_range_is_the_plain_render, .init = setup, .fini = teardown)
{
    const char *common = "scenes/cornell-box.txt --width 32 --height 24 --spp 16 --threads 2 "
                         "--quiet --sampler stratified";
    cr_assert_eq(shell("%s %s -o %s/plain.exr", mcpt_bin(), common, g_dir), 0);
    cr_assert_eq(shell("%s %s --sample-range 0:16 -o %s/range.exr", mcpt_bin(), common, g_dir), 0);
    char path[300];
    struct image a, b;
    struct mcpt_error err;
    cr_assert(image_read_exr(scratch(path, sizeof path, "plain.exr"), &a, &err), "%s", err.msg);
    cr_assert(image_read_exr(scratch(path, sizeof path, "range.exr"), &b, &err), "%s", err.msg);
    for (int c = 0; c < a.n_channels; c++) {
        int k = image_find_channel(&b, a.names[c]);
        cr_assert_geq(k, 0, "%s missing", a.names[c]);
        cr_assert_eq(memcmp(a.data[c], b.data[k], sizeof(float) * 32 * 24), 0, "%s differs",
                     a.names[c]);
    }
    image_free(&a);
    image_free(&b);
}

/* Bad uses exit with status 2 and one line naming what was expected. */
Test(distributed, bad_usage, .init = setup, .fini = teardown)
{
    char plain[300], out[300];
    scratch(plain, sizeof plain, "plain.exr");
    scratch(out, sizeof out, "out.exr");
    cr_assert_eq(shell("%s tests/data/cli/tiny.txt --quiet -o %s", mcpt_bin(), plain), 0);
    char cases[6][2][700];
    snprintf(cases[0][0], 700, "scenes/cornell-box.txt --sample-range 5:5 -o %s", out);
    snprintf(cases[0][1], 700,
             "mcpt: error: expected --sample-range A:B with integers 0 <= A < "
             "B <= 4294967295, got '5:5' (see mcpt --help)");
    snprintf(cases[1][0], 700, "scenes/cornell-box.txt --spp 64 --sample-range 32:65 -o %s", out);
    snprintf(cases[1][1], 700,
             "mcpt: error: expected --sample-range within the render's 64 "
             "samples per pixel (--spp sets them), got 32:65 (see mcpt --help)");
    snprintf(cases[2][0], 700, "scenes/cornell-box.txt --adaptive --sample-range 0:8 -o %s", out);
    snprintf(cases[2][1], 700,
             "mcpt: error: expected no adaptive sampling with --sample-range "
             "(where a pixel stops depends on all its samples), got it (see mcpt --help)");
    snprintf(cases[3][0], 700, "merge %s", plain);
    snprintf(cases[3][1], 700,
             "mcpt: error: expected -o OUT.exr for mcpt merge, got none (see "
             "mcpt --help)");
    snprintf(cases[4][0], 700, "merge -o %s", out);
    snprintf(cases[4][1], 700,
             "mcpt: error: expected partial renders to merge, got none (see "
             "mcpt --help)");
    snprintf(cases[5][0], 700, "merge -o %s %s", out, plain);
    snprintf(cases[5][1], 700,
             "%s: error: expected a partial render (mcpt --sample-range) with "
             "channel 'sum.R', got an image without it",
             plain);
    char err_path[300];
    scratch(err_path, sizeof err_path, "stderr.txt");
    for (int i = 0; i < 6; i++) {
        int status = shell("%s %s >/dev/null 2>%s", mcpt_bin(), cases[i][0], err_path);
        cr_assert_eq(status, 2, "'%s' exited %d", cases[i][0], status);
        FILE *f = fopen(err_path, "r");
        cr_assert_not_null(f);
        char text[1024];
        size_t len = fread(text, 1, sizeof text - 1, f);
        fclose(f);
        text[len] = '\0';
        cr_assert(len > 0 && strchr(text, '\n') == text + len - 1, "'%s': not one line: %s",
                  cases[i][0], text);
        text[len - 1] = '\0';
        cr_assert_str_eq(text, cases[i][1]);
        cr_assert_neq(access(out, F_OK), 0, "'%s' wrote %s", cases[i][0], out);
    }
}
