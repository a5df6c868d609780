/* tests/report.c - not a test: a Criterion report hook that lists, at the end of every run, the
 * tests that were skipped and why (cr_skip_test's message), one line each, then their number.
 * Criterion's default output only leaves them out of its count, so a test that needs the
 * shared models (../shared/models) or an optional tool could vanish unnoticed. */
#include <criterion/criterion.h>
#include <criterion/hooks.h>
#include <stdio.h>

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
