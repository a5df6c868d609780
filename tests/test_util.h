/* tests/test_util.h - helpers for the tests that run the mcpt binary ($MCPT, default ./mcpt) as a
 * user would: a scratch folder, starting the binary with its stdout and stderr in files, and
 * reading small files back.  Header-only: static inline, so a test file that uses some of them
 * compiles warning-free; every failure of the helpers themselves is a Criterion assertion. */
#ifndef MCPT_TEST_UTIL_H
#define MCPT_TEST_UTIL_H

#include <criterion/criterion.h>

#include <fcntl.h>
#include <signal.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

/* A Criterion timeout is a hang cap, not a speed assertion: `make check-sanitize` compiles with
 * -DTEST_TIMEOUT_SCALE=10, because an ASan + UBSan build at -O1 renders 10-40 times slower. */
#ifndef TEST_TIMEOUT_SCALE
#define TEST_TIMEOUT_SCALE 1
#endif
#define TEST_TIMEOUT_S(s) ((s)*TEST_TIMEOUT_SCALE)

#define TEST_MAX_ARGS 62 /* arguments test_start_mcpt passes after the program name */

/* Makes a new empty folder "/tmp/mcpt_<name>_XXXXXX" (mkdtemp) and writes its path to dir. */
static inline void test_make_dir(char *dir, size_t dir_bytes, const char *name)
{
    int len = snprintf(dir, dir_bytes, "/tmp/mcpt_%s_XXXXXX", name);
    cr_assert(len > 0 && (size_t)len < dir_bytes, "folder name too long for %zu bytes", dir_bytes);
    cr_assert(mkdtemp(dir), "mkdtemp %s", dir);
}

/* Removes dir and everything in it (rm -rf). */
static inline void test_remove_dir(const char *dir)
{
    char cmd[512];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    cr_assert_eq(system(cmd), 0);
}

/* Whether path names an existing file or folder. */
static inline bool test_exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

/* Reads at most buf_bytes - 1 bytes of path into buf and NUL-terminates it.  Returns the bytes
 * read, or -1 (buf = "") when path cannot be opened. */
static inline long test_read_file(const char *path, char *buf, size_t buf_bytes)
{
    buf[0] = '\0';
    FILE *f = fopen(path, "rb");
    if (!f)
        return -1;
    size_t n = fread(buf, 1, buf_bytes - 1, f);
    buf[n] = '\0';
    fclose(f);
    return (long)n;
}

/* Starts mcpt with args (NULL-terminated, at most TEST_MAX_ARGS) and returns its pid.  Its stdout
 * goes to out_path and its stderr to err_path (created or emptied before it returns, so that a
 * poll of them never reads an earlier run's; NULL: /dev/null).  With
 * alarm_s > 0 an alarm that survives exec ends a hung run by SIGALRM after
 * TEST_TIMEOUT_S(alarm_s) seconds instead of hanging the suite: a hang cap, scaled like the
 * Criterion timeouts.  Collect it with test_wait. */
static inline pid_t test_start_mcpt(const char *const *args, const char *out_path,
                                    const char *err_path, unsigned alarm_s)
{
    const char *bin = getenv("MCPT") ? getenv("MCPT") : "./mcpt";
    const char *argv[TEST_MAX_ARGS + 2] = {bin};
    int argc = 1;
    for (; args[argc - 1]; argc++) {
        cr_assert(argc <= TEST_MAX_ARGS, "more than %d arguments for mcpt", TEST_MAX_ARGS);
        argv[argc] = args[argc - 1];
    }
    argv[argc] = NULL;
    const char *paths[2] = {out_path, err_path}; /* emptied here: no earlier run's lines read */
    for (int i = 0; i < 2; i++) {
        if (!paths[i])
            continue;
        int fd = open(paths[i], O_WRONLY | O_CREAT | O_TRUNC, 0644);
        cr_assert(fd >= 0, "cannot create %s", paths[i]);
        close(fd);
    }
    pid_t pid = fork();
    cr_assert(pid >= 0);
    if (pid == 0) {
        int out_fd = open(out_path ? out_path : "/dev/null", O_WRONLY | O_CREAT | O_TRUNC, 0644);
        int err_fd = open(err_path ? err_path : "/dev/null", O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (out_fd < 0 || err_fd < 0 || dup2(out_fd, 1) < 0 || dup2(err_fd, 2) < 0)
            _exit(127);
        if (alarm_s > 0)
            alarm(TEST_TIMEOUT_S(alarm_s));
        execv(bin, (char *const *)argv);
        _exit(127);
    }
    return pid;
}

/* Waits for pid; returns its exit status, or 128 + the signal that ended it. */
static inline int test_wait(pid_t pid)
{
    int status;
    cr_assert_eq(waitpid(pid, &status, 0), pid);
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

/* Whether the child pid has ended, without collecting it (test_wait still gives its status).
 * A poll for something mcpt does ends here too, rather than at a deadline a slow machine can
 * pass: a run that never ends is ended by its alarm. */
static inline bool test_has_ended(pid_t pid)
{
    siginfo_t info = {0};
    cr_assert_eq(waitid(P_PID, (id_t)pid, &info, WEXITED | WNOHANG | WNOWAIT), 0);
    return info.si_pid == pid;
}

/* Stops the child pid (SIGSTOP) and returns once it has stopped, all its threads: what it has
 * written can then be read without racing it, and signals sent to it stay pending until
 * kill(pid, SIGCONT) delivers them together.  Returns false when it ended before the stop, its
 * status (as test_wait gives it) in *status. */
static inline bool test_stop(pid_t pid, int *status)
{
    int st;
    cr_assert_eq(kill(pid, SIGSTOP), 0);
    cr_assert_eq(waitpid(pid, &st, WUNTRACED), pid);
    if (WIFSTOPPED(st))
        return true;
    *status = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
    return false;
}

/* test_start_mcpt, then test_wait: runs mcpt to the end and returns its status. */
static inline int test_run_mcpt(const char *const *args, const char *out_path, const char *err_path,
                                unsigned alarm_s)
{
    return test_wait(test_start_mcpt(args, out_path, err_path, alarm_s));
}

#endif
