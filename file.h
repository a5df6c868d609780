/* file.h - files replaced whole or not at all.  A write goes to a fresh temporary file beside
 * the destination, "<path>.tmp.<pid>.<n>" (n = 0..99, the first that does not exist), is
 * flushed to disk (fsync) and is then renamed over the destination: rename(2) replaces a file
 * atomically (POSIX.1-2008), so a reader, or a later run after a crash or a second Ctrl-C, sees
 * the old file or the new one, never a truncated one.  Every image, curve, plot and checkpoint
 * mcpt writes goes through here.  The two halves of a commit, file_atomic_finish and
 * file_atomic_rename, are separate so that a caller can write several temporaries before it
 * renames any of them. */
#ifndef MCPT_FILE_H
#define MCPT_FILE_H

#include "vec.h"

#define FILE_PATH_BYTES 4096   /* longest destination path, including the NUL (PATH_MAX) */
#define FILE_TMP_INFIX ".tmp." /* the temporary is path FILE_TMP_INFIX "<pid>.<n>" */

/* A file being written: its destination and its temporary. */
struct file_atomic {
    char path[FILE_PATH_BYTES];          /* the destination */
    char tmp_path[FILE_PATH_BYTES + 32]; /* "<path>.tmp.<pid>.<n>" */
    int fd;                              /* the temporary, open for writing; -1 once closed */
    FILE *f;                             /* a stdio stream on fd, or NULL (file_atomic_stream) */
    bool is_finished;                    /* written, flushed and closed: only the rename is left */
};

/* Creates the temporary beside path (O_EXCL, so two writers never share one) and opens it for
 * writing on af->fd.  False with *err (runtime; file = path, "cannot write: <strerror>") when
 * the name is too long or the file cannot be created; nothing is left behind then. */
bool file_atomic_open(struct file_atomic *af, const char *path, struct mcpt_error *err);

/* A stdio stream on the temporary, for callers that print (made on the first call, owned by
 * af).  NULL with *err (runtime) when out of memory. */
FILE *file_atomic_stream(struct file_atomic *af, struct mcpt_error *err);

/* Makes the temporary durable: flushes the stream, checks it for earlier write errors, fsyncs
 * and closes.  The destination is untouched.  False with *err (runtime, "cannot write: ...")
 * after removing the temporary. */
bool file_atomic_finish(struct file_atomic *af, struct mcpt_error *err);

/* Renames the finished temporary over the destination.  False with *err (runtime) after
 * removing the temporary. */
bool file_atomic_rename(struct file_atomic *af, struct mcpt_error *err);

/* file_atomic_finish, then file_atomic_rename. */
bool file_atomic_commit(struct file_atomic *af, struct mcpt_error *err);

/* Discards the temporary (open, finished or already gone); the destination is untouched. */
void file_atomic_abort(struct file_atomic *af);

#endif
