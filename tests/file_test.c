/* tests/file_test.c - file.c: files replaced whole or not at all (a temporary beside the
 * destination, fsync, rename(2), atomic by POSIX.1-2008).  A commit replaces the destination
 * and leaves no temporary; an abort, a failed write or a failed open leaves the destination as
 * it was and no temporary; several files can be finished before any is renamed, so a reader
 * never sees the new one of a pair beside the old other; every failure is a runtime error that
 * names the destination.  The image writers' own failures are tests/image_test.c's. */
#include <criterion/criterion.h>

#include <dirent.h>
#include <errno.h>
#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include "file.h"
#include "test_util.h"

static char tmpdir[256];

static void setup(void) { test_make_dir(tmpdir, sizeof tmpdir, "file"); }
static void teardown(void) { test_remove_dir(tmpdir); }

static int count_entries(void)
{
    DIR *d = opendir(tmpdir);
    cr_assert_not_null(d);
    int n = 0;
    for (struct dirent *e; (e = readdir(d));)
        n += strcmp(e->d_name, ".") != 0 && strcmp(e->d_name, "..") != 0;
    closedir(d);
    return n;
}

static void write_text(const char *path, const char *text)
{
    FILE *f = fopen(path, "wb");
    cr_assert_not_null(f);
    fputs(text, f);
    fclose(f);
}

static void assert_text(const char *path, const char *want)
{
    char buf[256];
    cr_assert(test_read_file(path, buf, sizeof buf) >= 0, "cannot read %s", path);
    cr_assert_str_eq(buf, want);
}

/* A stream written and committed replaces the old file; the temporary was "<path>.tmp.<pid>.0"
 * beside it while it was open, and nothing else is left. */
Test(file, commit_replaces_and_leaves_no_temporary, .init = setup, .fini = teardown)
{
    char path[300], tmp[340];
    snprintf(path, sizeof path, "%s/out.txt", tmpdir);
    snprintf(tmp, sizeof tmp, "%s.tmp.%ld.0", path, (long)getpid());
    write_text(path, "old");
    struct file_atomic af;
    struct mcpt_error err;
    cr_assert(file_atomic_open(&af, path, &err), "%s", err.msg);
    cr_assert_str_eq(af.tmp_path, tmp);
    cr_assert(test_exists(tmp));
    FILE *f = file_atomic_stream(&af, &err);
    cr_assert_not_null(f);
    fputs("new", f);
    assert_text(path, "old");
    cr_assert(file_atomic_commit(&af, &err), "%s", err.msg);
    assert_text(path, "new");
    cr_assert_eq(count_entries(), 1);
}

/* An abort, before or after the temporary is finished, keeps the destination and removes the
 * temporary. */
Test(file, abort_keeps_the_destination, .init = setup, .fini = teardown)
{
    char path[300];
    snprintf(path, sizeof path, "%s/out.txt", tmpdir);
    write_text(path, "old");
    struct file_atomic af;
    struct mcpt_error err;
    cr_assert(file_atomic_open(&af, path, &err));
    cr_assert(write(af.fd, "new", 3) == 3);
    file_atomic_abort(&af);
    assert_text(path, "old");
    cr_assert_eq(count_entries(), 1);
    cr_assert(file_atomic_open(&af, path, &err));
    cr_assert(write(af.fd, "new", 3) == 3);
    cr_assert(file_atomic_finish(&af, &err), "%s", err.msg);
    cr_assert_eq(count_entries(), 2);
    file_atomic_abort(&af);
    assert_text(path, "old");
    cr_assert_eq(count_entries(), 1);
}

/* Two files finished, then renamed: until the renames both destinations hold their old bytes,
 * after them both hold the new (the pattern of an image and its preview). */
Test(file, finish_both_then_rename_both, .init = setup, .fini = teardown)
{
    char a[300], b[300];
    snprintf(a, sizeof a, "%s/a.exr", tmpdir);
    snprintf(b, sizeof b, "%s/a.png", tmpdir);
    write_text(a, "old a");
    write_text(b, "old b");
    struct file_atomic fa, fb;
    struct mcpt_error err;
    cr_assert(file_atomic_open(&fa, a, &err) && file_atomic_open(&fb, b, &err));
    fputs("new a", file_atomic_stream(&fa, &err));
    cr_assert(write(fb.fd, "new b", 5) == 5);
    cr_assert(file_atomic_finish(&fa, &err) && file_atomic_finish(&fb, &err), "%s", err.msg);
    assert_text(a, "old a");
    assert_text(b, "old b");
    cr_assert_eq(count_entries(), 4);
    cr_assert(file_atomic_rename(&fa, &err) && file_atomic_rename(&fb, &err), "%s", err.msg);
    assert_text(a, "new a");
    assert_text(b, "new b");
    cr_assert_eq(count_entries(), 2);
}

/* A missing folder, a name too long and a write that fails midway (RLIMIT_FSIZE: EFBIG) are
 * runtime errors naming the destination, and leave no temporary. */
Test(file, failures_are_runtime_errors_naming_the_file, .init = setup, .fini = teardown)
{
    char path[300];
    struct file_atomic af;
    struct mcpt_error err;
    snprintf(path, sizeof path, "%s/no/such/dir.txt", tmpdir);
    cr_assert_not(file_atomic_open(&af, path, &err));
    cr_assert_str_eq(err.msg, "cannot write: No such file or directory");
    cr_assert_str_eq(err.file, path);
    cr_assert_eq(err.kind, MCPT_ERROR_RUNTIME);

    static char long_path[FILE_PATH_BYTES + 8];
    memset(long_path, 'x', sizeof long_path - 1);
    cr_assert_not(file_atomic_open(&af, long_path, &err));
    cr_assert_eq(err.kind, MCPT_ERROR_RUNTIME);
    cr_assert_str_eq(err.msg, "cannot write: File name too long");

    snprintf(path, sizeof path, "%s/big.txt", tmpdir);
    write_text(path, "old");
    void (*old_handler)(int) = signal(SIGXFSZ, SIG_IGN); /* EFBIG instead of the signal */
    struct rlimit old_lim, lim;
    cr_assert_eq(getrlimit(RLIMIT_FSIZE, &old_lim), 0);
    lim = old_lim;
    lim.rlim_cur = 4096;
    cr_assert_eq(setrlimit(RLIMIT_FSIZE, &lim), 0);
    cr_assert(file_atomic_open(&af, path, &err));
    FILE *f = file_atomic_stream(&af, &err);
    for (int i = 0; i < 2000; i++)
        fputs("0123456789", f);
    bool ok = file_atomic_commit(&af, &err);
    cr_assert_eq(setrlimit(RLIMIT_FSIZE, &old_lim), 0);
    signal(SIGXFSZ, old_handler);
    cr_assert_not(ok);
    char want[128];
    snprintf(want, sizeof want, "cannot write: %s", strerror(EFBIG));
    cr_assert_str_eq(err.msg, want);
    cr_assert_eq(err.kind, MCPT_ERROR_RUNTIME);
    assert_text(path, "old");
    cr_assert_eq(count_entries(), 1);
}
