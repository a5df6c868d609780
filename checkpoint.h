/* checkpoint.h - an interrupted render on disk: its film and the settings a resumed run must
 * repeat.  With them each pixel continues from its own count with the same sample indices, so
 * `mcpt --resume` ends on the image an uninterrupted run gives, bit for bit.  The file is
 * written atomically (file.h) and checksummed; reading it checks every field before trusting
 * it.  Format: docs/reliability.md. */
#ifndef MCPT_CHECKPOINT_H
#define MCPT_CHECKPOINT_H

#include "film.h"

#define CHECKPOINT_VERSION 2u      /* 2: the scene hash covers the meshes and MTL files too */
#define CHECKPOINT_PATH_BYTES 1024 /* scene path stored for messages, incl. NUL */
#define CHECKPOINT_ARGS_BYTES 4096 /* the run's options, NUL-separated words */

/* The render parameters a resumed run must reproduce exactly. */
struct checkpoint_info {
    uint64_t scene_hash;    /* FNV-1a 64 of the scene file's bytes, then of every mesh and MTL
                               file it loads, in load order (main.c) */
    uint64_t seed;          /* render seed */
    uint32_t spp;           /* target samples per pixel */
    uint32_t max_depth;     /* most bounces, TRACE_DEPTH_INFINITE allowed */
    uint32_t sampler;       /* enum sampler_kind */
    uint32_t sample_offset; /* sample index of a pixel's first film sample */
    char scene_path[CHECKPOINT_PATH_BYTES]; /* as given on the command line */
    uint32_t args_bytes;                    /* bytes of args in use */
    char args[CHECKPOINT_ARGS_BYTES];       /* options of the run, each word NUL-ended */
};

/* Writes film and info to path atomically (file.h), so a reader sees the old file or the new
 * one, never a mix.  Layout: magic "MCPTCKPT", version, byte-order mark, pixel record size,
 * film size, info, the raw pixel records, then an FNV-1a 64 checksum of everything before it.
 * Returns false with *err (runtime; file = path, no line) on an I/O failure; nothing is left
 * behind then. */
bool checkpoint_save(const char *path, const struct film *film, const struct checkpoint_info *info,
                     struct mcpt_error *err);

/* Reads a checkpoint written by checkpoint_save into a new film (free with film_free) and
 * *info.  The file must be a regular one (a FIFO is refused without blocking).  Every field is
 * checked (magic, version, byte order, record size, film size against memory, spp >= 1 with
 * sample indices below 2^32, the sampler, string lengths, exact file length, checksum), then
 * every pixel's values as a render leaves them (film_pixel_problem: counts at most spp, finite
 * sums, squares >= 0 and consistent with the sums): a valid checksum proves no writer.  On any
 * mismatch returns false with *film zeroed and *err naming path and what was expected (bad
 * input; a runtime error when the film cannot be allocated).  The stored options are only
 * checked to be NUL-ended words; main.c checks them as options. */
bool checkpoint_load(const char *path, struct film *film, struct checkpoint_info *info,
                     struct mcpt_error *err);

/* Whether path is a regular file that starts as checkpoint_save writes one (the magic
 * "MCPTCKPT"), read without blocking.  A render may discard such a file (--restart) and never
 * another: false for a missing, unreadable or non-regular path and for any other content. */
bool checkpoint_is_one(const char *path);

/* Whether a run with the settings in *run repeats the render saved in *saved (read from
 * path): the same scene bytes, spp target, seed, depth, sampler and sample offset.  False
 * with *err (bad input; file = path) naming the first setting that differs, e.g. "expected
 * --seed 0 as in the checkpoint, got 5".  The film's size is the caller's to compare. */
bool checkpoint_matches(const char *path, const struct checkpoint_info *saved,
                        const struct checkpoint_info *run, struct mcpt_error *err);

#endif
