/* fuzz/fuzz_checkpoint.c - libFuzzer harness for checkpoint_load (checkpoint.c), the reader of
 * a file that --resume trusts with a render's state.  An input is a control byte and a
 * checkpoint: when the control byte is odd, the harness first rewrites the last 8 bytes as the
 * FNV-1a 64 checksum of the rest, as a crafted file would carry, so that inputs reach the
 * checks behind the checksum (film size, settings, options, every pixel's values).  A crash,
 * hang, leak or sanitizer report is a bug.  A rejected input must carry a one-line message
 * naming a file; an accepted one must hold what a render writes (film_pixel_problem finds
 * nothing, the settings are in range, the options NUL-ended), and its film must resolve to
 * finite floats, as the resumed run's image would.
 * Run: make fuzz FUZZ_SECONDS=N (fuzz/run.sh); seeds: tests/bad/ckpt. */
#include "checkpoint.h"

#include <stdlib.h>
#include <unistd.h>

#include "fuzz_util.h"
#include "sample.h"

static char ckpt_path[96]; /* the scratch folder's a.ckpt */

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    fuzz_make_dir("checkpoint");
    fuzz_path(ckpt_path, sizeof ckpt_path, "a.ckpt");
    return 0;
}

/* Every value an accepted checkpoint holds is one a render could have written. */
static void check_loaded(const struct film *film, const struct checkpoint_info *info)
{
    if (film->width < 1 || film->height < 1 || !film->pixels)
        abort();
    if (info->spp < 1 || info->sampler >= SAMPLER_COUNT ||
        (uint64_t)info->sample_offset + info->spp > UINT32_MAX)
        abort();
    if (info->args_bytes > CHECKPOINT_ARGS_BYTES ||
        (info->args_bytes > 0 && info->args[info->args_bytes - 1] != '\0'))
        abort();
    if (strnlen(info->scene_path, sizeof info->scene_path) == sizeof info->scene_path)
        abort();
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    float *planes = malloc(sizeof(float) * 7 * n_pixels);
    if (!planes)
        abort();
    float *mean[3] = {planes, planes + n_pixels, planes + 2 * n_pixels};
    float *var[3] = {planes + 3 * n_pixels, planes + 4 * n_pixels, planes + 5 * n_pixels};
    film_resolve(film, mean, var, planes + 6 * n_pixels);
    for (size_t i = 0; i < n_pixels; i++) {
        if (film_pixel_problem(&film->pixels[i], info->spp))
            abort();
        for (int c = 0; c < 7; c++)
            if (!isfinite(planes[(size_t)c * n_pixels + i]))
                abort();
    }
    free(planes);
    struct mcpt_error err;
    if (!checkpoint_matches(ckpt_path, info, info, &err))
        abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1)
        return 0;
    bool is_resealed = data[0] & 1;
    data++;
    size--;
    uint8_t *copy = malloc(size ? size : 1);
    if (!copy)
        abort();
    memcpy(copy, data, size);
    if (is_resealed && size >= 8) { /* FNV-1a 64 of every byte before the last 8 */
        uint64_t h = 0xcbf29ce484222325ull;
        for (size_t i = 0; i < size - 8; i++)
            h = (h ^ copy[i]) * 0x100000001b3ull;
        memcpy(copy + size - 8, &h, 8);
    }
    fuzz_write_file(ckpt_path, copy, size);
    free(copy);
    struct film film;
    struct checkpoint_info info;
    struct mcpt_error err = {0};
    if (checkpoint_load(ckpt_path, &film, &info, &err)) {
        check_loaded(&film, &info);
        film_free(&film);
    } else {
        fuzz_check_rejection(&err);
        if (film.pixels) /* a refused file leaves nothing allocated */
            abort();
    }
    return 0;
}
