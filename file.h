/* file.h - files replaced whole or not at all, and the checks around them.  A write goes to a
 * fresh temporary file beside the destination, "<path>.tmp.<pid>.<n>" (n = 0..99, the first
 * that does not exist), is flushed to disk (fsync) and is then renamed over the destination:
 * rename(2) replaces a file atomically (POSIX.1-2008), so a reader, or a later run after a crash
 * or a second Ctrl-C, sees the old file or the new one, never a truncated one.  Every image,
 * curve, plot and checkpoint mcpt writes goes through here.  The two halves of a commit,
 * file_atomic_finish and file_atomic_rename, are separate so that a caller can write several
 * temporaries before it renames any of them.  A writer holds a POSIX lock on its temporary until
 * the rename, which the kernel drops when the process dies however it dies; that is how a later
 * run tells a dead writer's temporary (file_remove_stale) from a live one's.  Also here: opening
 * an input without blocking, telling whether two paths name one file, and checking before a
 * render that an output can be created. */
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
    bool is_finished;                    /* written and flushed: only the rename is left */
    int slot_idx;                        /* its entry in the list of open temporaries, or -1 */
};

/* Creates the temporary beside path (O_EXCL, so two writers never share one), opens it for
 * writing on af->fd and locks it (a write lock on the whole file, held until the rename or the
 * abort).  False with *err (runtime; file = path, "cannot write: <strerror>") when the name is
 * too long or the file cannot be created; nothing is left behind then.  While it is open, the
 * temporary is listed for file_remove_temporaries_now. */
bool file_atomic_open(struct file_atomic *af, const char *path, struct mcpt_error *err);

/* A stdio stream on the temporary, for callers that print (made on the first call, owned by
 * af).  NULL with *err (runtime) when out of memory. */
FILE *file_atomic_stream(struct file_atomic *af, struct mcpt_error *err);

/* Makes the temporary durable: flushes the stream, checks it for earlier write errors and
 * fsyncs; it stays open (and locked) until the rename.  The destination is untouched.  False
 * with *err (runtime, "cannot write: ...") after removing the temporary. */
bool file_atomic_finish(struct file_atomic *af, struct mcpt_error *err);

/* Renames the finished temporary over the destination and closes it.  False with *err
 * (runtime) after removing the temporary. */
bool file_atomic_rename(struct file_atomic *af, struct mcpt_error *err);

/* file_atomic_finish, then file_atomic_rename. */
bool file_atomic_commit(struct file_atomic *af, struct mcpt_error *err);

/* Discards the temporary (open, finished or already gone); the destination is untouched. */
void file_atomic_abort(struct file_atomic *af);

/* Removes every temporary file_atomic_open made that is not yet renamed or aborted.  Only
 * async-signal-safe calls (unlink): for a signal handler about to _exit, so that a second
 * Ctrl-C leaves no film-sized temporary behind. */
void file_remove_temporaries_now(void);

/* Removes the temporaries that writers of path left when they died (kill -9, a power cut, a
 * second signal before this version): the files "<path>.tmp.<digits>.<digits>" beside path that
 * no process holds locked (file_atomic_open) and that were last written more than
 * FILE_STALE_S seconds ago.  A lock, unlike a PID, is not fooled by PID reuse and is held
 * across hosts on a network filesystem; a filesystem without locks keeps every temporary.
 * Returns the number removed; errors are ignored (this is housekeeping). */
#define FILE_STALE_S 2 /* seconds: a live writer locks its temporary at once */
int file_remove_stale(const char *path);

/* Opens path for reading without ever blocking in open() (a FIFO with no writer would block
 * forever) and refuses anything but a regular file, or with allow_pipe a FIFO or pipe too.
 * Returns a descriptor in blocking mode.  On failure returns -1 with either errno set and
 * *not_regular = NULL (the file cannot be opened), or *not_regular naming what the path is
 * ("a directory", "a FIFO", "a character device", ...). */
int file_open_input(const char *path, bool allow_pipe, const char **not_regular);

/* file_open_input for a regular file, with the error filled in: *err (bad input, file = path)
 * "expected a regular file, got a FIFO" or "cannot open: <strerror>" (a runtime error for an
 * I/O error).  Returns the descriptor, or -1. */
int file_open_regular(const char *path, struct mcpt_error *err);

/* FNV-1a 64 (Fowler, Noll, Vo, "The FNV Non-Cryptographic Hash Algorithm"): h updated with
 * n_bytes of data; start from FILE_FNV_OFFSET.  What ties a checkpoint to its scene file's
 * bytes, checksums the checkpoint, and keys obj.c's name table. */
#define FILE_FNV_OFFSET 0xcbf29ce484222325ull /* offset basis */
uint64_t file_fnv1a64(uint64_t h, const void *data, size_t n_bytes);

/* Updates *h (file_fnv1a64) with every byte of the regular file at path.  False with *err
 * (file = path: bad input when it cannot be opened or is not a regular file, runtime on a read
 * error). */
bool file_hash_file(const char *path, uint64_t *h, struct mcpt_error *err);

/* What a path names, to tell whether two paths are one file: the device and inode of an
 * existing file (hard links, symbolic links, "./x" and "x" alike), else the absolute path
 * with its existing folder resolved (realpath) and "." and ".." removed. */
struct file_id {
    bool exists;                     /* the path names an existing file: dev, ino */
    unsigned long long dev;          /* st_dev */
    unsigned long long ino;          /* st_ino */
    char canonical[FILE_PATH_BYTES]; /* otherwise: the normalised absolute path */
};

/* Fills *id for path; false (id->canonical "") when the name cannot be normalised (too long,
 * no working directory). */
bool file_id_of(const char *path, struct file_id *id);

/* Whether a and b name the same file (see struct file_id). */
bool file_id_same(const struct file_id *a, const struct file_id *b);

/* Checks before a long job that the output path can be written: it is a regular file or does
 * not exist, and a temporary can be created beside it (made and removed at once).  False with
 * *err (file = path): bad input when the path is wrong (a missing folder, a directory, a FIFO,
 * a name too long, no permission, a read-only filesystem), a runtime error otherwise (disk
 * full, I/O). */
bool file_check_creatable(const char *path, struct mcpt_error *err);

/* The part of file_check_creatable that touches nothing: the path is a regular file or does
 * not exist, and its folder exists.  Run on every output before any is probed, so that a bad
 * later path is refused before a temporary is made beside an earlier one. */
bool file_check_name(const char *path, struct mcpt_error *err);

#endif
