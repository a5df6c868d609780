/* tests/cmd_test.c - cmd.c: the command-line helpers and the subcommands' exit statuses.  Numbers
 * are parsed strictly (the whole word, in range, no sign or space); a usage error reads
 * "mcpt: error: <msg> (see mcpt --help)" and keeps the hint whatever the message's length;
 * cmd_fail prints one line and returns 2 for bad input and 1 for a runtime error; through the
 * binary, each subcommand exits 0 for --help, 2 for bad usage or bad input and 1 for a write
 * that fails.  The metrics, the laboratory and the merge themselves are tested with their
 * modules (tests/stats_test.c, tests/partial_test.c). */
#include <criterion/criterion.h>

#include "cmd.h"
#include "image.h"
#include "test_util.h"

Test(cmd, numbers_are_parsed_strictly)
{
    uint64_t v;
    cr_assert(cmd_parse_u64("42", 1, 100, &v) && v == 42);
    cr_assert(cmd_parse_u64("18446744073709551615", 0, UINT64_MAX, &v) && v == UINT64_MAX);
    const char *bad[] = {"", "-1", "+1", " 1", "1 ", "1x", "0x10", "101", "18446744073709551616"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++)
        cr_assert_not(cmd_parse_u64(bad[i], 1, 100, &v), "'%s'", bad[i]);
    float f;
    cr_assert(cmd_parse_float("-0.5", -1.0f, 1.0f, &f) && f == -0.5f);
    const char *bad_f[] = {"", "nan", "inf", "1e39", "2", "0.5x"};
    for (size_t i = 0; i < sizeof bad_f / sizeof bad_f[0]; i++)
        cr_assert_not(cmd_parse_float(bad_f[i], -1.0f, 1.0f, &f), "'%s'", bad_f[i]);
}

/* The kind of the error decides the status; the line is mcpt_error_format's. */
Test(cmd, fail_maps_kinds_to_exit_statuses)
{
    struct mcpt_error err;
    cr_assert_not(cmd_usage_error(&err, "expected %s, got %d", "one", 2));
    char line[MCPT_ERROR_LINE_BYTES];
    mcpt_error_format(&err, line, sizeof line);
    cr_assert_str_eq(line, "mcpt: error: expected one, got 2 (see mcpt --help)");
    cr_assert_eq(err.kind, MCPT_ERROR_INPUT);
    static char word[2000];
    memset(word, 'w', sizeof word - 1);
    cr_assert_not(cmd_usage_error(&err, "expected a number, got '%s'", word));
    size_t len = strlen(err.msg);
    cr_assert(len > 200 && strcmp(err.msg + len - 18, " (see mcpt --help)") == 0, "%s", err.msg);

    FILE *saved = stderr;
    stderr = fopen("/dev/null", "w");
    cr_assert_eq(cmd_fail(&err), CMD_EXIT_INPUT);
    mcpt_error_runtime(&err, "out.exr", "cannot write: %s", "No space left on device");
    cr_assert_eq(cmd_fail(&err), CMD_EXIT_RUNTIME);
    mcpt_error_set(&err, "scene.txt", 3, 7, "expected 3 numbers after 'v', got 2");
    cr_assert_eq(cmd_fail(&err), CMD_EXIT_INPUT);
    fclose(stderr);
    stderr = saved;
}

static char tmpdir[256];

static void setup(void) { test_make_dir(tmpdir, sizeof tmpdir, "cmd"); }
static void teardown(void) { test_remove_dir(tmpdir); }

/* Runs mcpt with args; returns the exit status and the first line of stderr in err_out. */
static int run_mcpt(const char *const *args, char *err_out, size_t err_bytes)
{
    char err_path[300];
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    int rc = test_run_mcpt(args, NULL, err_path, 60);
    test_read_file(err_path, err_out, err_bytes);
    return rc;
}

/* Each subcommand: --help 0; an unknown option, a missing file 2; a write into a missing folder
 * 2, found before any work (issue 15), with one line naming the file. */
Test(cmd, subcommand_exit_statuses, .init = setup, .fini = teardown, .timeout = TEST_TIMEOUT_S(60))
{
    char img[300], bad_out[300], part[300], err[4096], want[800];
    snprintf(img, sizeof img, "%s/img.exr", tmpdir);
    snprintf(part, sizeof part, "%s/part.exr", tmpdir);
    snprintf(bad_out, sizeof bad_out, "%s/no/such/dir/out.png", tmpdir);
    const char *render[] = {"tests/data/cli/tiny.txt", "--spp", "2", "--quiet", "-o", img, NULL};
    cr_assert_eq(run_mcpt(render, err, sizeof err), 0, "%s", err);
    const char *render_part[] = {"tests/data/cli/tiny.txt",
                                 "--spp",
                                 "2",
                                 "--sample-range",
                                 "0:2",
                                 "--quiet",
                                 "-o",
                                 part,
                                 NULL};
    cr_assert_eq(run_mcpt(render_part, err, sizeof err), 0, "%s", err);

    const char *help[][3] = {{"compare", "--help", NULL},
                             {"integrate", "--help", NULL},
                             {"merge", "--help", NULL}};
    for (int i = 0; i < 3; i++)
        cr_assert_eq(run_mcpt(help[i], err, sizeof err), 0, "%s --help: %s", help[i][0], err);
    const char *usage[][6] = {{"compare", "--bogus", NULL},
                              {"integrate", "--bogus", NULL},
                              {"merge", "--bogus", NULL},
                              {"compare", img, "missing.exr", NULL},
                              {"merge", "missing.exr", "-o", NULL},
                              {"compare", img, img, "--max-ref-luminance", "-1", NULL},
                              {"compare", img, img, "--max-ref-luminance", "nan", NULL}};
    for (int i = 0; i < 7; i++)
        cr_assert_eq(run_mcpt(usage[i], err, sizeof err), 2, "%s %s: %s", usage[i][0], usage[i][1],
                     err);

    const char *heat[] = {"compare", img, img, "--heatmap", bad_out, NULL};
    cr_assert_eq(run_mcpt(heat, err, sizeof err), 2, "%s", err);
    snprintf(want, sizeof want, "%s: error: cannot create: no folder '%s/no/such/dir'\n", bad_out,
             tmpdir);
    cr_assert_str_eq(err, want);
    snprintf(bad_out, sizeof bad_out, "%s/no/such/dir/merged.exr", tmpdir);
    const char *merge[] = {"merge", part, "-o", bad_out, NULL};
    cr_assert_eq(run_mcpt(merge, err, sizeof err), 2, "%s", err);
    snprintf(want, sizeof want, "%s: error: cannot create: no folder '%s/no/such/dir'\n", bad_out,
             tmpdir);
    cr_assert_str_eq(err, want);
}

/* integrate --sampler: every name of the comma-separated list must be a sampler.  An empty list
 * ('' or ','), or one past 255 bytes of commas, ran no sampler and exited 0 with only the CSV
 * header; an empty item ('sobol,') is refused too. */
Test(cmd, integrate_sampler_list_has_no_empty_name, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(60))
{
    static char commas[301];
    memset(commas, ',', sizeof commas - 1);
    const char *bad[] = {"", ",", "sobol,", ",sobol", "sobol,,independent", commas, "all,sobol"};
    const char *got[] = {"''", "''", "''", "''", "''", "''", "'all'"};
    char err[4096], want[200];
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        const char *args[] = {"integrate", "disk",      "--spp", "2", "--seeds",
                              "1",         "--sampler", bad[i],  NULL};
        cr_assert_eq(run_mcpt(args, err, sizeof err), 2, "'%s': %s", bad[i], err);
        snprintf(want, sizeof want,
                 "mcpt: error: expected --sampler independent, stratified, sobol, all or a "
                 "comma-separated list of the three, got %s in '",
                 got[i]);
        cr_assert(strncmp(err, want, strlen(want)) == 0, "'%s': %s", bad[i], err);
    }
    const char *good[] = {"integrate",         "disk", "--spp", "2", "--seeds", "1", "--sampler",
                          "sobol,independent", NULL};
    cr_assert_eq(run_mcpt(good, err, sizeof err), 0, "%s", err);
}

/* Writes a 4x3 EXR of channels names[0 .. n-1], channel c from planes[c]. */
static void write_planes(const char *path, int n, const char *const *names, float planes[][12])
{
    struct image img = {.width = 4, .height = 3, .n_channels = n};
    for (int c = 0; c < n; c++) {
        snprintf(img.names[c], sizeof img.names[c], "%s", names[c]);
        img.data[c] = planes[c];
    }
    struct mcpt_error err;
    cr_assert(image_write_exr(path, &img, &err), "%s", err.msg);
}

/* Writes a 4x3 EXR of R, G, B, every value v (with all_nan, one channel of each pixel NaN)
 * and, with var, variance.R/G/B of value *var. */
static void write_rgb(const char *path, float v, bool all_nan, const float *var)
{
    const char *names[] = {"R", "G", "B", "variance.R", "variance.G", "variance.B"};
    float planes[6][12];
    for (int c = 0; c < 6; c++)
        for (int i = 0; i < 12; i++)
            planes[c][i] = c >= 3 ? (var ? *var : 0.0f) : all_nan && (c == i % 3) ? NAN : v;
    write_planes(path, var ? 6 : 3, names, planes);
}

/* An image whose every pixel has a NaN or infinite channel (a half-float EXR of values over
 * 65504), or variances below 0, leaves no pixel to measure: compare and --reference refuse it
 * (exit 2, one line naming the file) instead of printing NaN for every metric and exiting 0;
 * so does compare when the usable pixels of the two images never meet or --max-ref-luminance
 * leaves none.  Found by probing. */
Test(cmd, images_without_usable_pixels_refused, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(60))
{
    char good[300], nan_img[300], neg_var[300], out[300], csv[300], err[4096], want[800];
    snprintf(good, sizeof good, "%s/good.exr", tmpdir);
    snprintf(nan_img, sizeof nan_img, "%s/nan.exr", tmpdir);
    snprintf(neg_var, sizeof neg_var, "%s/negvar.exr", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(csv, sizeof csv, "%s/curve.csv", tmpdir);
    float var_ok = 0.0f, var_neg = -1.0f;
    write_rgb(good, 1.0f, false, &var_ok);
    write_rgb(nan_img, 1.0f, true, NULL);
    write_rgb(neg_var, 1.0f, false, &var_neg);

    const char *cases[][2] = {{good, nan_img}, {nan_img, good}, {good, neg_var}};
    const char *bad[] = {nan_img, nan_img, neg_var};
    const char *what[] = {"", "", " and variances >= 0"};
    for (int i = 0; i < 3; i++) {
        const char *a[] = {"compare", cases[i][0], cases[i][1], NULL};
        cr_assert_eq(run_mcpt(a, err, sizeof err), 2, "case %d: %s", i, err);
        snprintf(want, sizeof want,
                 "%s: error: expected a pixel with finite R, G and B%s, got none in 4x3\n", bad[i],
                 what[i]);
        cr_assert_str_eq(err, want, "case %d", i);
    }
    const char *masked[] = {"compare", good, good, "--max-ref-luminance", "0.5", NULL};
    cr_assert_eq(run_mcpt(masked, err, sizeof err), 2, "%s", err);
    snprintf(want, sizeof want,
             "%s: error: expected pixels to compare, got none (0 channel values NaN or infinite "
             "in either image, 12 of 4x3 pixels above --max-ref-luminance)\n",
             good);
    cr_assert_str_eq(err, want);

    /* a render measured against such a reference stops before rendering, writing nothing */
    const char *render[] = {"tests/data/cli/tiny.txt", "--width", "4", "--height", "3",
                            "--spp", "2", "--reference", nan_img, "--curve", csv, "-o", out,
                            NULL};
    cr_assert_eq(run_mcpt(render, err, sizeof err), 2, "%s", err);
    snprintf(want, sizeof want, "%s: error: expected a pixel with finite R, G and B, got none in "
                                "4x3\n", nan_img);
    cr_assert_str_eq(err, want);
    cr_assert_not(test_exists(out));
    cr_assert_not(test_exists(csv));
}

/* Writes a 4x3 EXR of channels names[0 .. n-1], channel c every value values[c]. */
static void write_channels(const char *path, int n, const char *const *names, const float *values)
{
    float planes[IMAGE_MAX_CHANNELS][12];
    for (int c = 0; c < n; c++)
        for (int i = 0; i < 12; i++)
            planes[c][i] = values[c];
    write_planes(path, n, names, planes);
}

/* compare and convert read Blender's multilayer EXRs (a Cycles reference saved as "OpenEXR
 * MultiLayer"): the colour is that of the one layer with .R, .G and .B, or of the layer named
 * Combined among several, so the layered copy of an image compares to it with MSE 0; two layers
 * neither of which is Combined are refused (exit 2) with one line that says what was expected.
 * Before, every such file was refused for lacking plain R, G and B. */
Test(cmd, compare_and_convert_read_blender_layers, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(60))
{
    char plain[300], layered[300], one[300], two[300], png[300], out[4096], err[4096];
    snprintf(plain, sizeof plain, "%s/plain.exr", tmpdir);
    snprintf(layered, sizeof layered, "%s/layered.exr", tmpdir);
    snprintf(one, sizeof one, "%s/one.exr", tmpdir);
    snprintf(two, sizeof two, "%s/two.exr", tmpdir);
    snprintf(png, sizeof png, "%s/out.png", tmpdir);
    const char *rgb[] = {"R", "G", "B"};
    const float colour[] = {0.25f, 0.5f, 0.75f};
    write_channels(plain, 3, rgb, colour);
    const char *blender[] = {"ViewLayer.Combined.R",    "ViewLayer.Combined.G",
                             "ViewLayer.Combined.B",    "ViewLayer.Combined.A",
                             "ViewLayer.Depth.Z",       "ViewLayer.Noisy Image.R",
                             "ViewLayer.Noisy Image.G", "ViewLayer.Noisy Image.B"};
    const float blender_v[] = {0.25f, 0.5f, 0.75f, 1.0f, 7.0f, 9.0f, 9.0f, 9.0f};
    write_channels(layered, 8, blender, blender_v);
    const char *single[] = {"Image.R", "Image.G", "Image.B", "Image.A"};
    write_channels(one, 4, single, blender_v);
    const char *ambiguous[] = {"A.R", "A.G", "A.B", "B.R", "B.G", "B.B"};
    write_channels(two, 6, ambiguous, blender_v);

    char json[300];
    snprintf(json, sizeof json, "%s/out.json", tmpdir);
    const char *cmp[] = {"compare", layered, plain, "--json", NULL};
    cr_assert_eq(test_run_mcpt(cmp, json, NULL, 60), 0);
    test_read_file(json, out, sizeof out);
    cr_assert(strstr(out, "\"mse\": 0,") || strstr(out, "\"mse\":0,"), "%s", out);
    const char *cmp1[] = {"compare", plain, one, "--json", NULL};
    cr_assert_eq(test_run_mcpt(cmp1, json, NULL, 60), 0);
    test_read_file(json, out, sizeof out);
    cr_assert(strstr(out, "\"mse\": 0,") || strstr(out, "\"mse\":0,"), "%s", out);
    const char *conv[] = {"convert", layered, png, "--quiet", NULL};
    cr_assert_eq(run_mcpt(conv, err, sizeof err), 0, "%s", err);

    const char *bad[] = {"compare", two, plain, NULL};
    cr_assert_eq(run_mcpt(bad, err, sizeof err), 2, "%s", err);
    char want[600];
    snprintf(want, sizeof want,
             "%s: error: expected channels R, G and B, or one layer's (LAYER.R, LAYER.G, LAYER.B; "
             "of several, the one named Combined), got A.B, A.G, A.R, B.B, B.G, B.R\n",
             two);
    cr_assert_str_eq(err, want);
    const char *bad_conv[] = {"convert", two, png, NULL};
    cr_assert_eq(run_mcpt(bad_conv, err, sizeof err), 2, "%s", err);
}
