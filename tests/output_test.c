/* tests/output_test.c - output.c: the names of a render's files and their writing.  The image's
 * name comes from -o or the scene's base name; the preview, snapshots, heat map, contact sheet
 * and curve files are named from it by replacing the extension (appending where there is none,
 * and never taking a leading dot for one); a name that does not fit is refused before any
 * render (bad input).  An image is written as the EXR of every render (7 channels) with its PNG
 * beside it; a snapshot's names carry the spp zero-padded to the final spp's digits. */
#include <criterion/criterion.h>

#include "image.h"
#include "output.h"
#include "test_util.h"

Test(output, names_follow_the_image)
{
    struct output_paths p;
    struct mcpt_error err;
    cr_assert(output_paths_init(&p, "scenes/cornell-box.txt", NULL, NULL, NULL, false, &err));
    cr_assert_str_eq(p.exr, "cornell-box.exr");
    cr_assert_str_eq(p.png, "cornell-box.png");
    cr_assert_str_eq(p.checkpoint, "cornell-box.exr.ckpt");
    cr_assert_str_eq(p.heatmap, "");
    cr_assert(output_paths_init(&p, "x/.hidden", "out/v1.2/render", NULL, NULL, true, &err));
    cr_assert_str_eq(p.exr, "out/v1.2/render");
    cr_assert_str_eq(p.png, "out/v1.2/render.png");
    cr_assert_str_eq(p.heatmap, "out/v1.2/render.samples.png");
    cr_assert(output_paths_init(&p, "s.txt", "dir/.x", "c.ckpt", "h.png", true, &err));
    cr_assert_str_eq(p.png, "dir/.x.png");
    cr_assert_str_eq(p.checkpoint, "c.ckpt");
    cr_assert_str_eq(p.heatmap, "h.png");
    cr_assert(output_paths_init(&p, "x/.hidden", NULL, NULL, NULL, false, &err));
    cr_assert_str_eq(p.exr, ".hidden.exr");

    static char long_name[FILE_PATH_BYTES];
    memset(long_name, 'n', sizeof long_name - 5);
    cr_assert_not(output_paths_init(&p, "s.txt", long_name, NULL, NULL, false, &err));
    cr_assert_eq(err.kind, MCPT_ERROR_INPUT);
    cr_assert(strstr(err.msg, "expected a file name of at most 4095 bytes"), "%s", err.msg);
}

/* The image and its preview, and a snapshot at 4 of 100 spp (OUT-spp004.exr/.png). */
Test(output, image_and_snapshot_files)
{
    char dir[256], out[300], path[340];
    test_make_dir(dir, sizeof dir, "output");
    snprintf(out, sizeof out, "%s/r.exr", dir);
    struct output_paths p;
    struct mcpt_error err;
    cr_assert(output_paths_init(&p, "s.txt", out, NULL, NULL, false, &err));
    struct film film;
    cr_assert(film_init(&film, 3, 2, &err));
    for (int i = 0; i < 6; i++)
        for (int k = 0; k < 2 + i; k++)
            film_add(&film.pixels[i], v3(0.1f * (float)k, 0.5f, 1.0f));
    cr_assert(output_write_image(&p, &film, NULL, 0.0f, &err), "%s", err.msg);
    cr_assert(test_exists(p.png));
    struct image img;
    cr_assert(image_read_exr(p.exr, &img, &err), "%s", err.msg);
    cr_assert_eq(img.n_channels, 7);
    int s = image_find_channel(&img, "samples");
    cr_assert(s >= 0 && img.data[s][5] == 7.0f);
    cr_assert(image_find_channel(&img, "variance.G") >= 0);
    image_free(&img);
    cr_assert(output_write_snapshot(&p, &film, 4, 100, 0.0f, &err), "%s", err.msg);
    snprintf(path, sizeof path, "%s/r-spp004.exr", dir);
    cr_assert(test_exists(path), "%s", path);
    snprintf(path, sizeof path, "%s/r-spp004.png", dir);
    cr_assert(test_exists(path), "%s", path);
    cr_assert(output_write_heatmap(&p, &film, &err)); /* none asked for: nothing written */
    film_free(&film);
    test_remove_dir(dir);
}
