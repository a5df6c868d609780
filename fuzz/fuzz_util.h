/* fuzz/fuzz_util.h - what the libFuzzer harnesses share: a private scratch folder, writing an
 * input to a file, and the rule every rejected input must follow.  A failure of the harness
 * itself (no folder, a write that fails) aborts, which libFuzzer reports like any crash. */
#ifndef MCPT_FUZZ_UTIL_H
#define MCPT_FUZZ_UTIL_H

#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "vec.h"

/* The harness's private scratch folder "<tmp>/mcpt_fuzz_<name>_XXXXXX" (mkdtemp); <tmp> is
 * /dev/shm (memory) where it exists, else /tmp: rewriting the input file on every execution
 * costs a disk's truncate and discard on /tmp, which made a harness 20 times slower.  Whatever
 * the harness makes in it is removed with it at exit. */
static char fuzz_dir[64];

static void fuzz_remove_dir(void)
{
    DIR *d = opendir(fuzz_dir);
    char path[sizeof fuzz_dir + 256];
    for (struct dirent *e; d && (e = readdir(d));) {
        if (strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0)
            continue;
        snprintf(path, sizeof path, "%s/%s", fuzz_dir, e->d_name);
        unlink(path);
    }
    if (d)
        closedir(d);
    rmdir(fuzz_dir);
}

/* Makes the scratch folder; aborts when it cannot. */
static inline void fuzz_make_dir(const char *name)
{
    const char *tmp = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
    int len = snprintf(fuzz_dir, sizeof fuzz_dir, "%s/mcpt_fuzz_%s_XXXXXX", tmp, name);
    if (len < 0 || (size_t)len >= sizeof fuzz_dir || !mkdtemp(fuzz_dir))
        abort();
    atexit(fuzz_remove_dir);
}

/* The path of file in the scratch folder, written to path. */
static inline void fuzz_path(char *path, size_t path_bytes, const char *file)
{
    int len = snprintf(path, path_bytes, "%s/%s", fuzz_dir, file);
    if (len < 0 || (size_t)len >= path_bytes)
        abort();
}

/* Writes size bytes of data to path, replacing it. */
static inline void fuzz_write_file(const char *path, const void *data, size_t size)
{
    FILE *f = fopen(path, "wb");
    if (!f || fwrite(data, 1, size, f) != size || fclose(f) != 0)
        abort();
}

/* A rejected input must leave an error that main prints as exactly one line naming a file. */
static inline void fuzz_check_rejection(const struct mcpt_error *err)
{
    if (!err->msg[0] || !err->file[0] || strpbrk(err->msg, "\r\n"))
        abort();
}

#endif
