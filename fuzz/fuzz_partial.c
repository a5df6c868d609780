/* fuzz/fuzz_partial.c - libFuzzer harness for the EXR readers: image_read_exr and
 * stats_image_from_exr (what `mcpt compare` and --reference read), then partial_read_exr (what
 * `mcpt merge` trusts with a render's sums) and partial_merge of an accepted part.  Each input
 * is written to a.exr in a private folder.  A crash, hang, leak or sanitizer report is a bug.
 * A rejected input must carry a one-line message naming a file; an accepted partial render
 * must hold what a render writes (film_pixel_problem finds nothing at the ranges' sample
 * count; ranges sorted and disjoint) and resolve to finite floats, and merging it with itself
 * must be refused (its ranges overlap) without changing it.
 * Run: make fuzz FUZZ_SECONDS=N (fuzz/run.sh); seeds: tests/data/partial, tests/data/image. */
#include "partial.h"

#include <stdlib.h>
#include <unistd.h>

#include "fuzz_util.h"
#include "image.h"
#include "stats.h"

static char exr_path[96]; /* the scratch folder's a.exr */

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    fuzz_make_dir("partial");
    fuzz_path(exr_path, sizeof exr_path, "a.exr");
    return 0;
}

/* An image as compare and --reference read it. */
static void read_as_image(void)
{
    struct image img;
    struct stats_image simg;
    struct mcpt_error err = {0};
    if (!image_read_exr(exr_path, &img, &err)) {
        fuzz_check_rejection(&err);
        return;
    }
    if (img.width < 1 || img.height < 1 || img.n_channels < 0 ||
        img.n_channels > IMAGE_MAX_CHANNELS || img.n_attrs < 0 || img.n_attrs > IMAGE_MAX_ATTRS)
        abort();
    if (!stats_image_from_exr(&img, exr_path, &simg, &err))
        fuzz_check_rejection(&err);
    image_free(&img);
}

static void check_part(const struct film *film, const struct partial_info *info)
{
    if (film->width < 1 || film->height < 1 || info->n_ranges < 1 ||
        info->n_ranges > PARTIAL_MAX_RANGES)
        abort();
    for (uint32_t i = 0; i < info->n_ranges; i++)
        if (info->ranges[i].begin >= info->ranges[i].end ||
            (i > 0 && info->ranges[i].begin <= info->ranges[i - 1].end))
            abort();
    uint64_t n = partial_n_samples(info);
    size_t n_pixels = (size_t)film->width * (size_t)film->height;
    for (size_t i = 0; i < n_pixels; i++) {
        const struct film_pixel *p = &film->pixels[i];
        if ((uint64_t)p->n + p->n_dropped != n || film_pixel_problem(p, n))
            abort();
        for (int c = 0; c < 3; c++)
            if (!isfinite(film_mean(p, c)) || !isfinite(film_var_of_mean(p, c)))
                abort();
    }
    /* merging a part with itself: its ranges overlap, so refused, and nothing changes */
    struct film copy = {0};
    struct partial_info copy_info = *info;
    struct mcpt_error err = {0};
    if (!film_init(&copy, film->width, film->height, &err))
        return;
    memcpy(copy.pixels, film->pixels, sizeof *film->pixels * n_pixels);
    if (partial_merge(&copy, &copy_info, film, info, exr_path, &err) ||
        memcmp(copy.pixels, film->pixels, sizeof *film->pixels * n_pixels) != 0)
        abort();
    fuzz_check_rejection(&err);
    film_free(&copy);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fuzz_write_file(exr_path, data, size);
    read_as_image();
    struct film film;
    struct partial_info info;
    struct mcpt_error err = {0};
    if (partial_read_exr(exr_path, &film, &info, &err)) {
        check_part(&film, &info);
        film_free(&film);
    } else {
        fuzz_check_rejection(&err);
        if (film.pixels)
            abort();
    }
    return 0;
}
