/* tests/report.c - not a test: Criterion hooks for the whole run.  Before it, every test gets
 * a hang cap (one without its own .timeout would otherwise run forever: CI once waited 90
 * minutes on a test blocked on a FIFO).  After it, the tests that were skipped are listed with
 * why (cr_skip_test's message), one line each, then their number.  Criterion's default output
 * only leaves them out of its count, so a test that needs the shared models (../shared/models)
 * or an optional tool could vanish unnoticed. */
#include <criterion/criterion.h>
#include <criterion/hooks.h>
#include <criterion/internal/ordered-set.h>
#include <stdio.h>

#include "test_util.h"

/* seconds: the slowest test takes about 30 s alone on 2 loaded cores */
#define DEFAULT_TIMEOUT_S 300

/* Every test without a .timeout (nor its suite one) gets DEFAULT_TIMEOUT_S.  Criterion 2.4's
 * --timeout only lowers the timeouts tests have, so the tests' own data is set here, in the
 * runner, before it spawns them.  An ordered set's element follows its node in memory (what
 * Criterion's FOREACH_SET relies on). */
ReportHook(PRE_ALL)(struct criterion_test_set *set)
{
    for (struct criterion_ordered_set_node *ns = set->suites->first; ns; ns = ns->next) {
        struct criterion_suite_set *s = (void *)(ns + 1);
        if ((s->suite.data && s->suite.data->timeout > 0) || !s->tests)
            continue;
        for (struct criterion_ordered_set_node *nt = s->tests->first; nt; nt = nt->next) {
            struct criterion_test *t = (void *)(nt + 1);
            if (t->data->timeout <= 0)
                t->data->timeout = TEST_TIMEOUT_S(DEFAULT_TIMEOUT_S);
        }
    }
}

ReportHook(POST_ALL)(struct criterion_global_stats *stats)
{
    size_t n_skipped = 0, n_run = 0, n_unselected = 0;
    for (struct criterion_suite_stats *s = stats->suites; s; s = s->next)
        for (struct criterion_test_stats *t = s->tests; t; t = t->next) {
            if (t->test->data->disabled) { /* left out by --filter, or .disabled */
                n_unselected++;
                continue;
            }
            n_run++;
            if (t->test_status != CR_STATUS_SKIPPED)
                continue;
            n_skipped++;
            fprintf(stderr, "[SKIP] %s::%s: %s\n", t->test->category, t->test->name,
                    t->message && *t->message ? t->message : "(no reason given)");
        }
    fprintf(stderr, "[====] Skipped: %zu of %zu tests%s", n_skipped, n_run,
            n_skipped ? " (listed above, each with its reason)" : "");
    if (n_unselected)
        fprintf(stderr, "; %zu not selected (--filter, or disabled)", n_unselected);
    fputc('\n', stderr);
}
