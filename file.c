/* file.c - files replaced whole or not at all: a temporary file beside the destination, locked
 * while it is written, fsync, then rename(2) over it (POSIX.1-2008: the replacement is atomic).
 * Also the list of open temporaries a signal handler removes, the removal of temporaries dead
 * writers left, inputs opened without blocking, file identity and the check that an output can
 * be created.  See file.h. */
#include "file.h"

#include <assert.h>
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

/* ---- the open temporaries, for a signal handler ---- */

/* Slots of the temporaries not yet renamed or aborted.  Globals only because a signal handler
 * can reach nothing else; a path is written before its slot is marked listed, and the handler
 * reads listed slots only.  More open temporaries than slots are simply not listed. */
#define FILE_MAX_LISTED 16
enum { SLOT_FREE, SLOT_CLAIMED, SLOT_LISTED };
static atomic_int g_slot_state[FILE_MAX_LISTED];
static char g_slot_path[FILE_MAX_LISTED][FILE_PATH_BYTES + 32];

static int list_temporary(const char *tmp_path)
{
    for (int i = 0; i < FILE_MAX_LISTED; i++) {
        int expect = SLOT_FREE;
        if (atomic_compare_exchange_strong(&g_slot_state[i], &expect, SLOT_CLAIMED)) {
            snprintf(g_slot_path[i], sizeof g_slot_path[i], "%s", tmp_path);
            atomic_store(&g_slot_state[i], SLOT_LISTED);
            return i;
        }
    }
    return -1;
}

static void unlist_temporary(struct file_atomic *af)
{
    if (af->slot_idx >= 0)
        atomic_store(&g_slot_state[af->slot_idx], SLOT_FREE);
    af->slot_idx = -1;
}

void file_remove_temporaries_now(void)
{
    for (int i = 0; i < FILE_MAX_LISTED; i++)
        if (atomic_load(&g_slot_state[i]) == SLOT_LISTED)
            unlink(g_slot_path[i]);
}

/* ---- atomic writes ---- */

/* "cannot write: <strerror(error)>" at the destination, and the temporary removed. */
static bool fail(struct file_atomic *af, int error, struct mcpt_error *err)
{
    mcpt_error_runtime(err, af->path, "cannot write: %s", strerror(error ? error : EIO));
    file_atomic_abort(af);
    return false;
}

/* A write lock on all of fd (fcntl, POSIX record locks): held until the descriptor is closed,
 * or the process ends however it ends.  Where the filesystem has no locks, nothing. */
static void lock_whole_file(int fd)
{
    struct flock lk = {.l_type = F_WRLCK, .l_whence = SEEK_SET, .l_start = 0, .l_len = 0};
    (void)fcntl(fd, F_SETLK, &lk);
}

bool file_atomic_open(struct file_atomic *af, const char *path, struct mcpt_error *err)
{
    af->fd = -1;
    af->f = NULL;
    af->is_finished = false;
    af->slot_idx = -1;
    af->tmp_path[0] = '\0';
    int len = snprintf(af->path, sizeof af->path, "%s", path);
    if (len < 0 || (size_t)len >= sizeof af->path) {
        mcpt_error_runtime(err, path, "cannot write: %s", strerror(ENAMETOOLONG));
        return false;
    }
    for (int n = 0; n < 100; n++) {
        snprintf(af->tmp_path, sizeof af->tmp_path, "%s" FILE_TMP_INFIX "%ld.%d", path,
                 (long)getpid(), n);
        af->fd = open(af->tmp_path, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
        if (af->fd >= 0) {
            lock_whole_file(af->fd);
            af->slot_idx = list_temporary(af->tmp_path);
            return true;
        }
        if (errno != EEXIST)
            break;
    }
    int error_number = errno;
    mcpt_error_runtime(err, path, "cannot write: %s", strerror(error_number));
    af->tmp_path[0] = '\0'; /* nothing of ours to remove */
    errno = error_number;   /* for file_check_creatable */
    return false;
}

FILE *file_atomic_stream(struct file_atomic *af, struct mcpt_error *err)
{
    if (!af->f && !(af->f = fdopen(af->fd, "wb"))) {
        fail(af, errno, err);
        return NULL;
    }
    return af->f;
}

bool file_atomic_finish(struct file_atomic *af, struct mcpt_error *err)
{
    int error = 0;
    if (af->f && (fflush(af->f) != 0 || ferror(af->f)))
        error = errno ? errno : EIO;
    if (!error && fsync(af->fd) != 0)
        error = errno;
    if (error)
        return fail(af, error, err);
    af->is_finished = true;
    return true;
}

/* Closes the temporary's descriptor (and stream), which drops its lock. */
static void close_temporary(struct file_atomic *af)
{
    if (af->f)
        fclose(af->f);
    else if (af->fd >= 0)
        close(af->fd);
    af->f = NULL;
    af->fd = -1;
}

bool file_atomic_rename(struct file_atomic *af, struct mcpt_error *err)
{
    assert(af->is_finished);
    if (rename(af->tmp_path, af->path) != 0)
        return fail(af, errno, err);
    /* the data was synced by file_atomic_finish: a close error can lose nothing now */
    close_temporary(af);
    af->tmp_path[0] = '\0'; /* it is the destination now */
    unlist_temporary(af);
    return true;
}

bool file_atomic_commit(struct file_atomic *af, struct mcpt_error *err)
{
    return file_atomic_finish(af, err) && file_atomic_rename(af, err);
}

void file_atomic_abort(struct file_atomic *af)
{
    if (af->tmp_path[0])
        unlink(af->tmp_path); /* before the close: the lock keeps cleaners off until then */
    close_temporary(af);
    af->tmp_path[0] = '\0';
    unlist_temporary(af);
}

/* ---- temporaries of dead writers ---- */

/* Whether name is base ".tmp." digits "." digits, a temporary file_atomic_open names. */
static bool is_temporary_of(const char *name, const char *base, long *pid)
{
    size_t n_base = strlen(base), n_infix = strlen(FILE_TMP_INFIX);
    if (strncmp(name, base, n_base) != 0 || strncmp(name + n_base, FILE_TMP_INFIX, n_infix) != 0)
        return false;
    const char *p = name + n_base + n_infix;
    char *end;
    if (*p < '0' || *p > '9')
        return false;
    *pid = strtol(p, &end, 10);
    if (*end != '.' || end[1] < '0' || end[1] > '9')
        return false;
    for (p = end + 1; *p >= '0' && *p <= '9'; p++)
        ;
    return *p == '\0';
}

/* Whether no process holds a lock on the regular file at path (a read lock can be had).  False
 * when it cannot be told. */
static bool is_unlocked(const char *path)
{
    int fd = open(path, O_RDONLY | O_NONBLOCK | O_NOFOLLOW | O_CLOEXEC);
    if (fd < 0)
        return false;
    struct flock lk = {.l_type = F_RDLCK, .l_whence = SEEK_SET, .l_start = 0, .l_len = 0};
    bool unlocked = fcntl(fd, F_SETLK, &lk) == 0;
    close(fd); /* drops the probe's own lock */
    return unlocked;
}

int file_remove_stale(const char *path)
{
    char dir[FILE_PATH_BYTES];
    const char *slash = strrchr(path, '/');
    const char *base = slash ? slash + 1 : path;
    if (!*base)
        return 0;
    if (!slash)
        snprintf(dir, sizeof dir, ".");
    else if (slash == path)
        snprintf(dir, sizeof dir, "/");
    else
        snprintf(dir, sizeof dir, "%.*s", (int)(slash - path), path);
    DIR *d = opendir(dir);
    if (!d)
        return 0;
    int n_removed = 0;
    time_t now = time(NULL);
    for (struct dirent *e; (e = readdir(d));) {
        long pid;
        char tmp[2 * FILE_PATH_BYTES];
        struct stat st;
        if (!is_temporary_of(e->d_name, base, &pid) || pid == (long)getpid())
            continue; /* ours would lose its lock to the probe: a process holds one lock a file */
        snprintf(tmp, sizeof tmp, "%s/%s", dir, e->d_name);
        if (lstat(tmp, &st) != 0 || !S_ISREG(st.st_mode) || now - st.st_mtime <= FILE_STALE_S)
            continue;
        if (is_unlocked(tmp) && unlink(tmp) == 0)
            n_removed++;
    }
    closedir(d);
    return n_removed;
}

/* ---- inputs ---- */

/* What a file that is not a regular one is, for messages. */
static const char *kind_name(mode_t mode)
{
    return S_ISDIR(mode)    ? "a directory"
           : S_ISFIFO(mode) ? "a FIFO"
           : S_ISCHR(mode)  ? "a character device"
           : S_ISBLK(mode)  ? "a block device"
           : S_ISSOCK(mode) ? "a socket"
                            : "not a regular file";
}

int file_open_input(const char *path, bool allow_pipe, const char **not_regular)
{
    *not_regular = NULL;
    /* O_NONBLOCK: open() of a FIFO returns at once, writer or not */
    int fd = open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0)
        return -1;
    struct stat st;
    int flags;
    if (fstat(fd, &st) != 0)
        goto fail;
    if (!S_ISREG(st.st_mode) && !(allow_pipe && S_ISFIFO(st.st_mode))) {
        *not_regular = kind_name(st.st_mode);
        goto fail;
    }
    /* reads block again: a pipe's reader waits for its writer, and sees the end of file once
     * no writer is left (POSIX read(): an empty pipe with no writer reads as end of file) */
    if ((flags = fcntl(fd, F_GETFL)) < 0 || fcntl(fd, F_SETFL, flags & ~O_NONBLOCK) != 0)
        goto fail;
    return fd;
fail:;
    int error_number = errno;
    close(fd);
    errno = error_number;
    return -1;
}

int file_open_regular(const char *path, struct mcpt_error *err)
{
    const char *not_regular;
    int fd = file_open_input(path, false, &not_regular);
    if (fd >= 0)
        return fd;
    if (not_regular)
        mcpt_error_set(err, path, 0, 0, "expected a regular file, got %s", not_regular);
    else if (errno == EIO)
        mcpt_error_runtime(err, path, "cannot open: %s", strerror(errno));
    else
        mcpt_error_set(err, path, 0, 0, "cannot open: %s", strerror(errno));
    return -1;
}

/* ---- hashing ---- */

uint64_t file_fnv1a64(uint64_t h, const void *data, size_t n_bytes)
{
    const unsigned char *p = data;
    for (size_t i = 0; i < n_bytes; i++) {
        h ^= p[i];
        h *= 0x100000001b3ull; /* FNV-1a 64 prime, 2^40 + 2^8 + 0xb3 */
    }
    return h;
}

bool file_hash_file(const char *path, uint64_t *h, struct mcpt_error *err)
{
    int fd = file_open_regular(path, err);
    if (fd < 0)
        return false;
    unsigned char buf[65536];
    ssize_t n;
    while ((n = read(fd, buf, sizeof buf)) != 0) {
        if (n < 0 && errno == EINTR)
            continue;
        if (n < 0) {
            mcpt_error_runtime(err, path, "cannot read: %s", strerror(errno));
            close(fd);
            return false;
        }
        *h = file_fnv1a64(*h, buf, (size_t)n);
    }
    close(fd);
    return true;
}

/* ---- identity ---- */

/* Normalises the absolute path abs in place: "//" and "/./" become "/", "x/.." goes. */
static void normalise(char *abs)
{
    char *out = abs; /* abs[0] == '/' */
    const char *p = abs;
    size_t n_out = 0;
    while (*p) {
        while (*p == '/')
            p++;
        const char *q = p;
        while (*q && *q != '/')
            q++;
        size_t n = (size_t)(q - p);
        if (n == 0 || (n == 1 && p[0] == '.')) {
            /* nothing */
        } else if (n == 2 && p[0] == '.' && p[1] == '.') {
            while (n_out > 0 && out[n_out - 1] != '/')
                n_out--;
            if (n_out > 0)
                n_out--; /* the slash before the dropped name */
        } else {
            out[n_out++] = '/';
            memmove(out + n_out, p, n);
            n_out += n;
        }
        p = q;
    }
    if (n_out == 0)
        out[n_out++] = '/';
    out[n_out] = '\0';
}

bool file_id_of(const char *path, struct file_id *id)
{
    memset(id, 0, sizeof *id);
    struct stat st;
    if (stat(path, &st) == 0) {
        id->exists = true;
        id->dev = (unsigned long long)st.st_dev;
        id->ino = (unsigned long long)st.st_ino;
        return true;
    }
    char abs[2 * FILE_PATH_BYTES], cwd[FILE_PATH_BYTES];
    if (path[0] == '/')
        snprintf(abs, sizeof abs, "%s", path);
    else if (getcwd(cwd, sizeof cwd))
        snprintf(abs, sizeof abs, "%s/%s", cwd, path);
    else
        return false;
    normalise(abs);
    /* the folder, resolved where it exists (symbolic links and all), then the name */
    char *slash = strrchr(abs, '/');
    char real_dir[PATH_MAX];
    *slash = '\0';
    int n;
    if (realpath(abs[0] ? abs : "/", real_dir))
        n = snprintf(id->canonical, sizeof id->canonical, "%s/%s",
                     strcmp(real_dir, "/") == 0 ? "" : real_dir, slash + 1);
    else
        n = snprintf(id->canonical, sizeof id->canonical, "%s/%s", abs, slash + 1);
    if (n < 0 || (size_t)n >= sizeof id->canonical) {
        id->canonical[0] = '\0';
        return false;
    }
    return true;
}

bool file_id_same(const struct file_id *a, const struct file_id *b)
{
    if (a->exists || b->exists)
        return a->exists && b->exists && a->dev == b->dev && a->ino == b->ino;
    return a->canonical[0] && strcmp(a->canonical, b->canonical) == 0;
}

/* ---- outputs ---- */

/* The folder path names its file in: "." for a bare name, "/" for one at the root. */
static void parent_folder(const char *path, char *dir, size_t dir_bytes)
{
    const char *slash = strrchr(path, '/');
    if (!slash)
        snprintf(dir, dir_bytes, ".");
    else if (slash == path)
        snprintf(dir, dir_bytes, "/");
    else
        snprintf(dir, dir_bytes, "%.*s", (int)(slash - path), path);
}

bool file_check_name(const char *path, struct mcpt_error *err)
{
    struct stat st;
    if (stat(path, &st) == 0 && !S_ISREG(st.st_mode)) {
        mcpt_error_set(err, path, 0, 0, "expected a regular file or a new name to write, got %s",
                       kind_name(st.st_mode));
        return false;
    }
    char dir[FILE_PATH_BYTES];
    parent_folder(path, dir, sizeof dir);
    if (stat(dir, &st) != 0) {
        if (errno != ENOENT)
            return true; /* no permission to look, say: file_check_creatable's probe tells */
        mcpt_error_set(err, path, 0, 0, "cannot create: no folder '%s'", dir);
        return false;
    }
    if (!S_ISDIR(st.st_mode)) {
        mcpt_error_set(err, path, 0, 0, "cannot create: '%s' is not a folder", dir);
        return false;
    }
    return true;
}

bool file_check_creatable(const char *path, struct mcpt_error *err)
{
    if (!file_check_name(path, err))
        return false;
    struct file_atomic af;
    if (file_atomic_open(&af, path, err)) {
        file_atomic_abort(&af);
        return true;
    }
    int e = errno;
    char dir[FILE_PATH_BYTES];
    parent_folder(path, dir, sizeof dir);
    if (e == ENOSPC || e == EIO || e == EDQUOT || e == ENOMEM || e == EMFILE || e == ENFILE)
        mcpt_error_runtime(err, path, "cannot create: %s", strerror(e));
    else if (e == ENOENT)
        mcpt_error_set(err, path, 0, 0, "cannot create: no folder '%s'", dir);
    else if (e == ENOTDIR)
        mcpt_error_set(err, path, 0, 0, "cannot create: '%s' is not a folder", dir);
    else
        mcpt_error_set(err, path, 0, 0, "cannot create: %s", strerror(e));
    return false;
}
