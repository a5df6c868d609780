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
