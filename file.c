/* file.c - files replaced whole or not at all: a temporary file beside the destination, fsync,
 * then rename(2) over it (POSIX.1-2008: the replacement is atomic).  See file.h. */
#include "file.h"

#include <assert.h>
#include <errno.h>
#include <fcntl.h>
#include <unistd.h>

/* "cannot write: <strerror(error)>" at the destination, and the temporary removed. */
static bool fail(struct file_atomic *af, int error, struct mcpt_error *err)
{
    mcpt_error_runtime(err, af->path, "cannot write: %s", strerror(error ? error : EIO));
    file_atomic_abort(af);
    return false;
}

bool file_atomic_open(struct file_atomic *af, const char *path, struct mcpt_error *err)
{
    af->fd = -1;
    af->f = NULL;
    af->is_finished = false;
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
        if (af->fd >= 0)
            return true;
        if (errno != EEXIST)
            break;
    }
    mcpt_error_runtime(err, path, "cannot write: %s", strerror(errno));
    af->tmp_path[0] = '\0'; /* nothing of ours to remove */
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
    if (af->f) {
        if (fflush(af->f) != 0 || ferror(af->f))
            error = errno ? errno : EIO;
        if (!error && fsync(af->fd) != 0)
            error = errno;
        if (fclose(af->f) != 0 && !error)
            error = errno;
    } else {
        if (fsync(af->fd) != 0)
            error = errno;
        if (close(af->fd) != 0 && !error)
            error = errno;
    }
    af->f = NULL;
    af->fd = -1;
    if (error)
        return fail(af, error, err);
    af->is_finished = true;
    return true;
}

bool file_atomic_rename(struct file_atomic *af, struct mcpt_error *err)
{
    assert(af->is_finished);
    if (rename(af->tmp_path, af->path) != 0)
        return fail(af, errno, err);
    af->tmp_path[0] = '\0'; /* it is the destination now */
    return true;
}

bool file_atomic_commit(struct file_atomic *af, struct mcpt_error *err)
{
    return file_atomic_finish(af, err) && file_atomic_rename(af, err);
}

void file_atomic_abort(struct file_atomic *af)
{
    if (af->f)
        fclose(af->f);
    else if (af->fd >= 0)
        close(af->fd);
    af->f = NULL;
    af->fd = -1;
    if (af->tmp_path[0])
        unlink(af->tmp_path);
    af->tmp_path[0] = '\0';
}
