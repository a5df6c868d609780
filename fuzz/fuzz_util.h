/* fuzz/fuzz_util.h - what the libFuzzer harnesses share: a private scratch folder, writing an
 * input to a file, and the rule every rejected input must follow.  A failure of the harness
 * itself (no folder, a write that fails) aborts, which libFuzzer reports like any crash. */
#ifndef MCPT_FUZZ_UTIL_H
#define MCPT_FUZZ_UTIL_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "vec.h"

/* Makes a new empty folder "<tmp>/mcpt_fuzz_<name>_XXXXXX" (mkdtemp) and writes its path to
 * dir; <tmp> is /dev/shm (memory) where it exists, else /tmp: rewriting the input file on
 * every execution costs a disk's truncate and discard on /tmp, which made a harness 20 times
 * slower. */
static inline void fuzz_make_dir(char *dir, size_t dir_bytes, const char *name)
{
    const char *tmp = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
    int len = snprintf(dir, dir_bytes, "%s/mcpt_fuzz_%s_XXXXXX", tmp, name);
    if (len < 0 || (size_t)len >= dir_bytes || !mkdtemp(dir))
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
