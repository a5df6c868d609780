/* tests/fault_test.c - the binary ($MCPT, default ./mcpt) under faults its user did not mean to
 * cause (issue 15, docs/reliability.md): inputs that would block, loops a number can make
 * endless, outputs that name an input or each other, outputs that cannot be created, memory
 * limits, a full disk, kill -9.  Each test states the promise it checks: no hang, no file of
 * the user's destroyed, a failure reported before the render rather than after it, and at
 * most a minute of work lost. */
#include <criterion/criterion.h>

#include <signal.h>
#include <time.h>

#include "test_util.h"

#define TINY "tests/data/cli/tiny.txt"
#define ALARM_S 30u /* a run longer than this is a hang */

static char tmpdir[256];

static void setup(void) { test_make_dir(tmpdir, sizeof tmpdir, "fault"); }
static void teardown(void) { test_remove_dir(tmpdir); }

/* Runs mcpt with args (NULL-terminated) under an alarm, stdout to tmpdir/stdout.txt and stderr
 * into err (err_bytes); returns the exit status (128 + SIGALRM for a hang). */
static int run(const char *const *args, char *err, size_t err_bytes)
{
    char out_path[300], err_path[300];
    snprintf(out_path, sizeof out_path, "%s/stdout.txt", tmpdir);
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    int rc = test_run_mcpt(args, out_path, err_path, ALARM_S);
    test_read_file(err_path, err, err_bytes);
    return rc;
}

/* ---- hangs ---- */

/* Stratified sets of 2^32 - 1 samples, from --spp or from the adaptive --batch: the grid's row
 * count once wrapped to 0 and one sample never ended (nor did SIGTERM end it).  Both runs
 * finish. */
Test(hang, stratified_set_of_2_32_minus_1, .init = setup, .fini = teardown)
{
    char out[300], err[4096];
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    const char *batch[] = {TINY,         "--adaptive", "--batch", "4294967295", "--sampler",
                           "stratified", "-o",         out,       "--quiet",    NULL};
    int rc = run(batch, err, sizeof err);
    cr_assert_eq(rc, 0, "--batch 4294967295: exit %d: %s", rc, err);
    const char *range[] = {TINY,         "--sampler",      "stratified", "--spp",
                           "4294967295", "--sample-range", "0:1",        "-o",
                           out,          "--quiet",        NULL};
    rc = run(range, err, sizeof err);
    cr_assert_eq(rc, 0, "--spp 4294967295 --sample-range 0:1: exit %d: %s", rc, err);
}

/* A FIFO with no writer, given wherever mcpt reads a file (--resume, compare's two images,
 * merge's parts, --reference), is refused at once as bad input naming it: open() of a FIFO
 * blocks until a writer comes, so inputs are opened without blocking and must be regular
 * files. */
Test(hang, fifo_inputs_refused_at_once, .init = setup, .fini = teardown)
{
    char fifo[300], out[300], img[300], err[4096], want[400];
    snprintf(fifo, sizeof fifo, "%s/fifo", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(img, sizeof img, "%s/img.exr", tmpdir);
    cr_assert_eq(mkfifo(fifo, 0644), 0);
    const char *render[] = {TINY, "--spp", "2", "-o", img, "--quiet", NULL};
    cr_assert_eq(run(render, err, sizeof err), 0, "%s", err);
    const char *cases[][10] = {
        {TINY, "--resume", fifo, "-o", out, NULL},
        {"compare", fifo, img, NULL},
        {"compare", img, fifo, NULL},
        {"merge", fifo, "-o", out, NULL},
        {TINY, "--reference", fifo, "--spp", "2", "-o", out, NULL},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        int rc = run(cases[i], err, sizeof err);
        cr_assert_eq(rc, 2, "case %zu: exit %d: %s", i, rc, err);
        snprintf(want, sizeof want, "%s: error: expected a ", fifo);
        cr_assert(strncmp(err, want, strlen(want)) == 0 && strstr(err, "got a FIFO\n"),
                  "case %zu: %s", i, err);
        cr_assert_not(test_exists(out), "case %zu wrote %s", i, out);
    }
}
