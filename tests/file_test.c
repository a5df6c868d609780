/* tests/file_test.c - file.c: files replaced whole or not at all (a temporary beside the
 * destination, fsync, rename(2), atomic by POSIX.1-2008).  A commit replaces the destination
 * and leaves no temporary; an abort, a failed write or a failed open leaves the destination as
 * it was and no temporary; several files can be finished before any is renamed, so a reader
 * never sees the new one of a pair beside the old other; every failure is a runtime error that
 * names the destination.  Around it: temporaries of dead writers are removed and live ones kept
 * (the writer's lock), a signal handler can remove the open ones, inputs open without blocking,
 * paths are compared as files, and an output is checked creatable before a render.  The image
 * writers' own failures are tests/image_test.c's. */
#include <criterion/criterion.h>

#include <dirent.h>
#include <fcntl.h>
#include <time.h>
#include <sys/stat.h>
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

/* Makes path a file last written ago_s seconds ago. */
static void write_aged(const char *path, const char *text, int ago_s)
{
    write_text(path, text);
    struct timespec times[2];
    clock_gettime(CLOCK_REALTIME, &times[0]);
    times[0].tv_sec -= ago_s;
    times[1] = times[0];
    cr_assert_eq(utimensat(AT_FDCWD, path, times, 0), 0);
}

/* Temporaries of dead writers go, those of live writers stay: a writer holds a lock on its
 * temporary until the rename (here a child process, stopped mid-write), and the kernel drops the
 * lock of a process however it dies.  Only names of the pattern "<path>.tmp.<pid>.<n>" are
 * touched, and none written in the last FILE_STALE_S seconds. */
Test(file, stale_temporaries_removed_live_ones_kept, .init = setup, .fini = teardown)
{
    char path[300], dead[340], fresh[340], other[340], other2[340];
    snprintf(path, sizeof path, "%s/out.exr", tmpdir);
    snprintf(dead, sizeof dead, "%s.tmp.999999999.0", path);
    snprintf(fresh, sizeof fresh, "%s.tmp.999999998.3", path);
    snprintf(other, sizeof other, "%s.tmp.12x.0", path);
    snprintf(other2, sizeof other2, "%s/other.exr.tmp.999999999.0", tmpdir);
    write_aged(dead, "dead", 60);
    write_aged(fresh, "fresh", 0);
    write_aged(other, "not ours", 60);
    write_aged(other2, "another output's", 60);
    int pipe_fd[2];
    cr_assert_eq(pipe(pipe_fd), 0);
    pid_t child = fork();
    cr_assert_geq(child, 0);
    if (child == 0) { /* a live writer: open, write, age the file, then wait to be killed */
        alarm(60);    /* or to time out, should the test fail before it kills */
        struct file_atomic af;
        struct mcpt_error err;
        if (!file_atomic_open(&af, path, &err) || write(af.fd, "live", 4) != 4)
            _exit(1);
        struct timespec times[2] = {{0, 0}, {0, 0}}; /* 1970: far older than FILE_STALE_S */
        futimens(af.fd, times);
        if (write(pipe_fd[1], af.tmp_path, strlen(af.tmp_path) + 1) < 0)
            _exit(1);
        pause();
        _exit(0);
    }
    char live[400] = {0};
    cr_assert_gt(read(pipe_fd[0], live, sizeof live - 1), 0);
    cr_assert_eq(file_remove_stale(path), 1);
    cr_assert_not(test_exists(dead));
    cr_assert(test_exists(live), "a live writer's temporary was removed");
    cr_assert(test_exists(fresh) && test_exists(other) && test_exists(other2));
    kill(child, SIGKILL); /* now its writer is dead: its temporary is stale */
    cr_assert_eq(waitpid(child, NULL, 0), child);
    cr_assert_eq(file_remove_stale(path), 1);
    cr_assert_not(test_exists(live));
    close(pipe_fd[0]);
    close(pipe_fd[1]);
}

/* What a signal handler calls before _exit: every temporary not yet renamed is removed, the
 * renamed files stay. */
Test(file, remove_temporaries_now, .init = setup, .fini = teardown)
{
    char a[300], b[300];
    snprintf(a, sizeof a, "%s/a.exr", tmpdir);
    snprintf(b, sizeof b, "%s/b.exr", tmpdir);
    struct file_atomic fa, fb;
    struct mcpt_error err;
    cr_assert(file_atomic_open(&fa, a, &err) && file_atomic_open(&fb, b, &err));
    cr_assert(write(fa.fd, "a", 1) == 1 && write(fb.fd, "b", 1) == 1);
    cr_assert(file_atomic_commit(&fa, &err));
    cr_assert_eq(count_entries(), 2);
    file_remove_temporaries_now();
    cr_assert_eq(count_entries(), 1);
    assert_text(a, "a");
    file_atomic_abort(&fb); /* its temporary is already gone */
    cr_assert_eq(count_entries(), 1);
}

/* Inputs: a regular file opens; a FIFO with no writer, a directory and a character device are
 * refused at once, named (a FIFO is accepted when pipes are allowed); a missing file gives
 * errno. */
Test(file, open_input_never_blocks, .init = setup, .fini = teardown, .timeout = TEST_TIMEOUT_S(10))
{
    char reg[300], fifo[300], missing[300];
    snprintf(reg, sizeof reg, "%s/a.txt", tmpdir);
    snprintf(fifo, sizeof fifo, "%s/fifo", tmpdir);
    snprintf(missing, sizeof missing, "%s/missing", tmpdir);
    write_text(reg, "x");
    cr_assert_eq(mkfifo(fifo, 0644), 0);
    const char *what;
    int fd = file_open_input(reg, false, &what);
    cr_assert_geq(fd, 0);
    close(fd);
    cr_assert_eq(file_open_input(fifo, false, &what), -1);
    cr_assert_str_eq(what, "a FIFO");
    cr_assert_eq(file_open_input(tmpdir, false, &what), -1);
    cr_assert_str_eq(what, "a directory");
    cr_assert_eq(file_open_input("/dev/null", true, &what), -1);
    cr_assert_str_eq(what, "a character device");
    fd = file_open_input(fifo, true, &what);
    cr_assert_geq(fd, 0);
    close(fd);
    cr_assert_eq(file_open_input(missing, false, &what), -1);
    cr_assert_null(what);
    cr_assert_eq(errno, ENOENT);
    struct mcpt_error err;
    cr_assert_eq(file_open_regular(fifo, &err), -1);
    cr_assert_str_eq(err.msg, "expected a regular file, got a FIFO");
    cr_assert_eq(err.kind, MCPT_ERROR_INPUT);
    cr_assert_eq(file_open_regular(missing, &err), -1);
    cr_assert_str_eq(err.msg, "cannot open: No such file or directory");
}

/* One file under several names: "x", "./x", "d/../x", a hard link and a symbolic link are the
 * same file; for names that do not exist yet the normalised paths decide. */
Test(file, identity_of_paths, .init = setup, .fini = teardown)
{
    char a[300], dot[300], up[300], hard[300], sym[300], other[300], d[300];
    snprintf(a, sizeof a, "%s/a.exr", tmpdir);
    snprintf(dot, sizeof dot, "%s/./a.exr", tmpdir);
    snprintf(d, sizeof d, "%s/d", tmpdir);
    snprintf(up, sizeof up, "%s/d/../a.exr", tmpdir);
    snprintf(hard, sizeof hard, "%s/hard.exr", tmpdir);
    snprintf(sym, sizeof sym, "%s/sym.exr", tmpdir);
    snprintf(other, sizeof other, "%s/b.exr", tmpdir);
    cr_assert_eq(mkdir(d, 0755), 0);
    struct file_id ia, ib;
    /* not yet existing: by name */
    cr_assert(file_id_of(a, &ia) && file_id_of(up, &ib));
    cr_assert_not(ia.exists);
    cr_assert(file_id_same(&ia, &ib), "%s vs %s", ia.canonical, ib.canonical);
    cr_assert(file_id_of(other, &ib));
    cr_assert_not(file_id_same(&ia, &ib));
    /* existing: by device and inode */
    write_text(a, "a");
    write_text(other, "b");
    cr_assert_eq(link(a, hard), 0);
    cr_assert_eq(symlink("a.exr", sym), 0);
    cr_assert(file_id_of(a, &ia));
    const char *same[] = {dot, up, hard, sym};
    for (int k = 0; k < 4; k++) {
        cr_assert(file_id_of(same[k], &ib));
        cr_assert(file_id_same(&ia, &ib), "%s", same[k]);
    }
    cr_assert(file_id_of(other, &ib));
    cr_assert_not(file_id_same(&ia, &ib));
    /* relative to the working directory */
    char cwd[300], rel[300];
    cr_assert_not_null(getcwd(cwd, sizeof cwd));
    cr_assert_eq(chdir(tmpdir), 0);
    snprintf(rel, sizeof rel, "d/../new.exr");
    cr_assert(file_id_of(rel, &ia));
    cr_assert_eq(chdir(cwd), 0);
    snprintf(rel, sizeof rel, "%s/new.exr", tmpdir);
    cr_assert(file_id_of(rel, &ib));
    cr_assert(file_id_same(&ia, &ib), "%s vs %s", ia.canonical, ib.canonical);
}

/* The check before a render: a new name in an existing folder and an existing file pass and
 * leave nothing behind; a missing folder, a directory and a FIFO as the output are bad input
 * with a message naming the path. */
Test(file, check_creatable, .init = setup, .fini = teardown)
{
    char path[300], missing[300], fifo[300];
    struct mcpt_error err;
    snprintf(path, sizeof path, "%s/out.exr", tmpdir);
    cr_assert(file_check_creatable(path, &err), "%s", err.msg);
    cr_assert_eq(count_entries(), 0);
    write_text(path, "old");
    cr_assert(file_check_creatable(path, &err), "%s", err.msg);
    cr_assert_eq(count_entries(), 1);
    snprintf(missing, sizeof missing, "%s/no/out.exr", tmpdir);
    cr_assert_not(file_check_creatable(missing, &err));
    char want[400];
    snprintf(want, sizeof want, "cannot create: no folder '%s/no'", tmpdir);
    cr_assert_str_eq(err.msg, want);
    cr_assert_str_eq(err.file, missing);
    cr_assert_eq(err.kind, MCPT_ERROR_INPUT);
    cr_assert_not(file_check_creatable(tmpdir, &err));
    cr_assert_str_eq(err.msg, "expected a regular file or a new name to write, got a directory");
    snprintf(fifo, sizeof fifo, "%s/fifo", tmpdir);
    cr_assert_eq(mkfifo(fifo, 0644), 0);
    cr_assert_not(file_check_creatable(fifo, &err));
    cr_assert_str_eq(err.msg, "expected a regular file or a new name to write, got a FIFO");
    cr_assert_not(file_check_creatable("/dev/null", &err));
    cr_assert_str_eq(err.msg, "expected a regular file or a new name to write, got a character "
                              "device");
}

/* FNV-1a 64 against its published vectors (Fowler, Noll, Vo, draft-eastlake-fnv): "" is the
 * offset basis cbf29ce484222325, "a" gives af63dc4c8601ec8c, "foobar" 85944171f73967e8; and a
 * hash fed in pieces is the hash of the whole. */
Test(file, fnv1a64_vectors)
{
    cr_assert_eq(file_fnv1a64(FILE_FNV_OFFSET, "", 0), 0xcbf29ce484222325ull);
    cr_assert_eq(file_fnv1a64(FILE_FNV_OFFSET, "a", 1), 0xaf63dc4c8601ec8cull);
    cr_assert_eq(file_fnv1a64(FILE_FNV_OFFSET, "foobar", 6), 0x85944171f73967e8ull);
    cr_assert_eq(file_fnv1a64(file_fnv1a64(FILE_FNV_OFFSET, "foo", 3), "bar", 3),
                 0x85944171f73967e8ull);
}
