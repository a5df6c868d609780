/* tests/cli_test.c - main.c: exit status 0 / 2 / 1, one error line for bad usage and bad input,
 * nothing written on error, and a small render producing a readable EXR (with variance and
 * sample-count channels) and a PNG.  Runs the binary named by $MCPT (default ./mcpt). */
#include <criterion/criterion.h>
#include <sys/stat.h>
#include <time.h>

#include "image.h"
#include "test_util.h"

static char tmpdir[256];

static void setup(void) { test_make_dir(tmpdir, sizeof tmpdir, "cli"); }
static void teardown(void) { test_remove_dir(tmpdir); }

/* Runs mcpt with args (NULL-terminated), stdout discarded, stderr captured in err_out; returns
 * the exit status. */
static int run_mcpt(const char *const *args, char *err_out, size_t err_bytes)
{
    char err_path[300];
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    int rc = test_run_mcpt(args, NULL, err_path, 0);
    test_read_file(err_path, err_out, err_bytes);
    return rc;
}

static int count_lines(const char *s)
{
    int n = 0;
    for (; *s; s++)
        n += *s == '\n';
    return n;
}

/* Bad usage: exit 2, exactly one line "mcpt: error: expected ...". */
Test(cli, bad_usage, .init = setup, .fini = teardown)
{
    const char *cases[][8] = {
        {NULL},
        {"tests/data/cli/tiny.txt", "--spp", "0", NULL},
        {"tests/data/cli/tiny.txt", "--spp", "-3", NULL},
        {"tests/data/cli/tiny.txt", "--spp", "abc", NULL},
        {"tests/data/cli/tiny.txt", "--spp", "4294967296", NULL},
        {"tests/data/cli/tiny.txt", "--threads", "0", NULL},
        {"tests/data/cli/tiny.txt", "--max-depth", "x", NULL},
        {"tests/data/cli/tiny.txt", "--width", "0", NULL},
        {"tests/data/cli/tiny.txt", "--seed", "-1", NULL},
        {"tests/data/cli/tiny.txt", "--bogus", NULL},
        {"tests/data/cli/tiny.txt", "--spp", NULL},
        {"a.txt", "b.txt", NULL},
        {"tests/data/cli/tiny.txt", "--adaptive", "--adaptive-rule", "early", NULL},
        {"tests/data/cli/tiny.txt", "--adaptive", "--pilot-spp", "1", NULL},
        {"tests/data/cli/tiny.txt", "--adaptive-rule", "pilot", NULL}, /* without --adaptive */
        {"tests/data/cli/tiny.txt", "--adaptive", "--adaptive-rule", "stop", "--pilot-spp", "8"},
        /* the budget rule: a budget that leaves no room past the pilot and the least count, a
         * tolerance it does not use, a maximum below the budget */
        {"tests/data/cli/tiny.txt", "--spp", "8", "--adaptive", "--adaptive-rule", "budget"},
        {"tests/data/cli/tiny.txt", "--adaptive", "--adaptive-rule", "budget", "--tolerance",
         "0.1"},
        {"tests/data/cli/tiny.txt", "--adaptive", "--adaptive-rule", "budget", "--max-spp", "2"},
        {"tests/data/cli/tiny.txt", "--light-sampling", "sphere", NULL},
        {"tests/data/cli/tiny.txt", "--rr-threshold", "0", NULL},
        {"", NULL},                                             /* an empty scene name */
        {"tests/data/cli/tiny.txt", "--exposure", " 2", NULL},  /* decimal numbers only, */
        {"tests/data/cli/tiny.txt", "--scale", "0x1p-1", NULL}, /* as in the scene format */
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char err[4096];
        int rc = run_mcpt(cases[i], err, sizeof err);
        cr_assert_eq(rc, 2, "case %zu: exit %d, stderr: %s", i, rc, err);
        cr_assert_eq(count_lines(err), 1, "case %zu: one line, got: %s", i, err);
        cr_assert(strncmp(err, "mcpt: error: expected ", 22) == 0, "case %zu: %s", i, err);
    }
}

/* Bad scene: exit 2, one line naming file:line:col, and an existing output left untouched. */
Test(cli, bad_scene_writes_nothing, .init = setup, .fini = teardown)
{
    char out[300], png[300], err[4096];
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(png, sizeof png, "%s/out.png", tmpdir);
    FILE *f = fopen(out, "w");
    fputs("precious", f);
    fclose(f);
    const char *args[] = {"tests/data/cli/bad-statement.txt", "-o", out, NULL};
    cr_assert_eq(run_mcpt(args, err, sizeof err), 2);
    cr_assert_eq(count_lines(err), 1, "%s", err);
    cr_assert(strncmp(err, "tests/data/cli/bad-statement.txt:2:1: error: expected ", 54) == 0, "%s",
              err);
    char buf[16] = {0};
    f = fopen(out, "r");
    cr_assert(fread(buf, 1, sizeof buf - 1, f) == 8);
    fclose(f);
    cr_assert_str_eq(buf, "precious");
    cr_assert_not(test_exists(png));
    const char *missing[] = {"tests/data/cli/no-such-scene.txt", "-o", out, NULL};
    cr_assert_eq(run_mcpt(missing, err, sizeof err), 2);
    cr_assert(strstr(err, "tests/data/cli/no-such-scene.txt") == err, "%s", err);
}

/* The budget rule's settings from the scene alone are checked as the scene's: exit 2, one line
 * at its adaptive-rule, nothing written; --spp on the command line makes them the options'. */
Test(cli, budget_rule_settings_from_the_scene, .init = setup, .fini = teardown)
{
    char out[300], err[4096];
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    const char *args[] = {"tests/data/cli/budget-too-small.txt", "-o", out, NULL};
    cr_assert_eq(run_mcpt(args, err, sizeof err), 2, "%s", err);
    cr_assert_str_eq(err,
                     "tests/data/cli/budget-too-small.txt:5:42: error: expected spp (8, the "
                     "budget) >= the pilot (8) plus min-spp (2) with 'adaptive-rule' budget\n");
    cr_assert_not(test_exists(out));
    const char *fixed[] = {
        "tests/data/cli/budget-too-small.txt", "--spp", "32", "--quiet", "-o", out, NULL};
    cr_assert_eq(run_mcpt(fixed, err, sizeof err), 0, "%s", err);
    cr_assert(test_exists(out));
}

/* A scene read from standard input that is a folder is bad input like a folder named as the
 * scene (exit 2, one line), not a read failure (exit 1). */
Test(cli, scene_from_stdin_that_is_a_folder, .init = setup, .fini = teardown)
{
    char cmd[1024], err_path[300], err[4096];
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    snprintf(cmd, sizeof cmd, "'%s' - -o '%s/out.exr' < tests/data > /dev/null 2> '%s'",
             getenv("MCPT") ? getenv("MCPT") : "./mcpt", tmpdir, err_path);
    int status = system(cmd);
    cr_assert(WIFEXITED(status));
    test_read_file(err_path, err, sizeof err);
    cr_assert_eq(WEXITSTATUS(status), 2, "%s", err);
    cr_assert_str_eq(err, "<stdin>: error: expected a scene, got a directory\n");
}

/* The folder's modification time, to nanoseconds: creating or removing any file in it (even a
 * temporary made and removed at once) changes it. */
static struct timespec folder_mtime(const char *dir)
{
    struct stat st;
    cr_assert_eq(stat(dir, &st), 0);
    return st.st_mtim;
}

/* Bad input or a bad later output touches no output folder, not even by the probe that makes
 * and removes a temporary to learn that an output can be created: every name is checked
 * first, and the subcommands read their inputs before they probe their outputs. */
Test(cli, bad_input_touches_no_output_folder, .init = setup, .fini = teardown)
{
    char dir[300], sub[300], out[300], bad[300], err[4096];
    snprintf(dir, sizeof dir, "%s/d", tmpdir);
    snprintf(sub, sizeof sub, "%s/d/out.png", tmpdir); /* the preview's name is a folder */
    snprintf(out, sizeof out, "%s/d/out.exr", tmpdir);
    snprintf(bad, sizeof bad, "%s/bad.exr", tmpdir);
    cr_assert_eq(mkdir(dir, 0755), 0);
    cr_assert_eq(mkdir(sub, 0755), 0);
    FILE *f = fopen(bad, "w");
    fputs("not an image", f);
    fclose(f);
    nanosleep(&(struct timespec){0, 20 * 1000 * 1000}, NULL); /* past the clock's granularity */
    struct timespec before = folder_mtime(dir);
    char png[300], heat[300], merged[300];
    snprintf(png, sizeof png, "%s/d/c.png", tmpdir);
    snprintf(heat, sizeof heat, "%s/d/h.png", tmpdir);
    snprintf(merged, sizeof merged, "%s/d/m.exr", tmpdir);
    const char *render[] = {"tests/data/cli/tiny.txt", "-o", out, NULL};
    const char *merge[] = {"merge", bad, "-o", merged, NULL};
    const char *convert[] = {"convert", bad, png, NULL};
    const char *compare[] = {"compare", bad, bad, "--heatmap", heat, NULL};
    const char *const *cases[] = {render, merge, convert, compare};
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        cr_assert_eq(run_mcpt(cases[i], err, sizeof err), 2, "case %zu: %s", i, err);
        struct timespec after = folder_mtime(dir);
        cr_assert(after.tv_sec == before.tv_sec && after.tv_nsec == before.tv_nsec,
                  "case %zu: the output folder was written to: %s", i, err);
    }
}

/* --help and --version exit 0. */
Test(cli, help_version, .init = setup, .fini = teardown)
{
    char err[4096];
    const char *h[] = {"--help", NULL};
    cr_assert_eq(run_mcpt(h, err, sizeof err), 0);
    const char *v[] = {"--version", NULL};
    cr_assert_eq(run_mcpt(v, err, sizeof err), 0);
}

/* A render writes an EXR with R, G, B, variance.R/G/B and samples (= spp everywhere) and a
 * PNG beside it; no NaN anywhere. */
Test(cli, render_writes_exr_and_png, .init = setup, .fini = teardown)
{
    char out[300], png[300], err[4096];
    snprintf(out, sizeof out, "%s/tiny.exr", tmpdir);
    snprintf(png, sizeof png, "%s/tiny.png", tmpdir);
    const char *args[] = {"tests/data/cli/tiny.txt", "-o", out, "--spp", "5", "--quiet", NULL};
    cr_assert_eq(run_mcpt(args, err, sizeof err), 0, "%s", err);
    cr_assert(test_exists(png));
    struct image img;
    struct mcpt_error e;
    cr_assert(image_read_exr(out, &img, &e), "%s", e.msg);
    cr_assert_eq(img.width, 16);
    cr_assert_eq(img.height, 12);
    const char *names[] = {"R", "G", "B", "variance.R", "variance.G", "variance.B", "samples"};
    for (int c = 0; c < 7; c++) {
        int idx = image_find_channel(&img, names[c]);
        cr_assert(idx >= 0, "channel %s", names[c]);
        for (int i = 0; i < 16 * 12; i++)
            cr_assert(isfinite(img.data[idx][i]));
    }
    int s = image_find_channel(&img, "samples");
    for (int i = 0; i < 16 * 12; i++)
        cr_assert_eq(img.data[s][i], 5.0f);
    image_free(&img);
}
