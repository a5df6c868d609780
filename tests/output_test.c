/* tests/output_test.c - output.c: the names of a render's files and their writing.  The image's
 * name comes from -o or the scene's base name, and its extension says its format (.exr: the
 * float image and its PNG preview; .png: the PNG alone; anything else refused, as is a name
 * that does not fit, before any render: bad input); the preview, snapshots, heat map, contact
 * sheet and curve files are named from it by replacing the extension (never taking a leading
 * dot for one).  An image is written as the EXR of every render (7 channels and mcpt's header
 * attributes) with its PNG beside it; a snapshot's names carry the spp zero-padded to the
 * final spp's digits.  Every file a render may write is listed before it, and none may be an
 * input or another output. */
#include <criterion/criterion.h>

#include "image.h"
#include "output.h"
#include "test_util.h"

Test(output, names_follow_the_image)
{
    struct output_paths p;
    struct mcpt_error err;
    cr_assert(output_paths_init(&p, "scenes/cornell-box.txt", NULL, NULL, NULL, false, true, &err));
    cr_assert_str_eq(p.exr, "cornell-box.exr");
    cr_assert_str_eq(p.png, "cornell-box.png");
    cr_assert_str_eq(p.checkpoint, "cornell-box.exr.ckpt");
    cr_assert_str_eq(p.heatmap, "");
    cr_assert(
        output_paths_init(&p, "x/.hidden", "out/v1.2/render.exr", NULL, NULL, true, true, &err));
    cr_assert_str_eq(p.exr, "out/v1.2/render.exr");
    cr_assert_str_eq(p.png, "out/v1.2/render.png");
    cr_assert_str_eq(p.heatmap, "out/v1.2/render.samples.png");
    cr_assert(output_paths_init(&p, "s.txt", "dir/.x.EXR", "c.ckpt", "h.png", true, true, &err));
    cr_assert_str_eq(p.png, "dir/.x.png");
    cr_assert_str_eq(p.checkpoint, "c.ckpt");
    cr_assert_str_eq(p.heatmap, "h.png");
    cr_assert(output_paths_init(&p, "x/.hidden", NULL, NULL, NULL, false, true, &err));
    cr_assert_str_eq(p.exr, ".hidden.exr");

    /* --no-preview: the EXR alone */
    cr_assert(output_paths_init(&p, "s.txt", "a.exr", NULL, NULL, false, false, &err));
    cr_assert_str_eq(p.exr, "a.exr");
    cr_assert_str_eq(p.png, "");
    /* an image named .png is a PNG and nothing else; the other names follow it */
    cr_assert(output_paths_init(&p, "s.txt", "d/x.png", NULL, NULL, true, true, &err));
    cr_assert_str_eq(p.exr, "");
    cr_assert_str_eq(p.png, "d/x.png");
    cr_assert_str_eq(output_image_path(&p), "d/x.png");
    cr_assert_str_eq(p.checkpoint, "d/x.png.ckpt");
    cr_assert_str_eq(p.heatmap, "d/x.samples.png");
    /* any other name is refused: no format is written under another's name */
    const char *bad[] = {"x.jpg", "render", "dir.exr/render", ".exr", "x.exr.tmp"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        cr_assert_not(output_paths_init(&p, "s.txt", bad[i], NULL, NULL, false, true, &err), "%s",
                      bad[i]);
        cr_assert_eq(err.kind, MCPT_ERROR_INPUT);
        cr_assert_str_eq(err.file, "mcpt");
        cr_assert(strstr(err.msg, "expected an output name ending in .exr (float image and PNG "
                                  "preview) or .png (8-bit sRGB only), got '"),
                  "%s", err.msg);
    }

    static char long_name[FILE_PATH_BYTES];
    memset(long_name, 'n', sizeof long_name - 5);
    memcpy(long_name + sizeof long_name - 5, ".exr", 4);
    cr_assert_not(output_paths_init(&p, "s.txt", long_name, NULL, NULL, false, true, &err));
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
    cr_assert(output_paths_init(&p, "s.txt", out, NULL, NULL, false, true, &err));
    struct film film;
    cr_assert(film_init(&film, 3, 2, &err));
    for (int i = 0; i < 6; i++)
        for (int k = 0; k < 2 + i; k++)
            film_add(&film.pixels[i], v3(0.1f * (float)k, 0.5f, 1.0f));
    struct output_meta meta = {.scene = "s.txt",
                               .sampler = "sobol",
                               .seed = 7,
                               .max_depth = UINT32_MAX,
                               .render_s = 1.5};
    cr_assert(output_write_image(&p, &film, NULL, &meta, NULL, &err), "%s", err.msg);
    cr_assert(test_exists(p.png));
    struct image img;
    cr_assert(image_read_exr(p.exr, &img, &err), "%s", err.msg);
    cr_assert_eq(img.n_channels, 7);
    int s = image_find_channel(&img, "samples");
    cr_assert(s >= 0 && img.data[s][5] == 7.0f);
    cr_assert(image_find_channel(&img, "variance.G") >= 0);
    /* the header: mcpt's attributes (spp: the mean of 2..7 samples), the Rec. 709 primaries */
    const char *attrs[][2] = {
        {"mcpt.version", MCPT_VERSION},  {"mcpt.spp", "4.5"}, {"mcpt.scene", "s.txt"},
        {"mcpt.sampler", "sobol"},       {"mcpt.seed", "7"},  {"mcpt.max-depth", "inf"},
        {"mcpt.render-seconds", "1.500"}};
    for (size_t i = 0; i < sizeof attrs / sizeof attrs[0]; i++) {
        const char *v = image_find_attr(&img, attrs[i][0]);
        cr_assert(v && strcmp(v, attrs[i][1]) == 0, "%s: %s", attrs[i][0], v ? v : "(none)");
    }
    const float rec709[8] = IMAGE_REC709_CHROMATICITIES;
    cr_assert(img.has_chromaticities);
    cr_assert_eq(memcmp(img.chromaticities, rec709, sizeof rec709), 0);
    image_free(&img);
    meta.render_s = -1.0; /* left out */
    cr_assert(output_write_snapshot(&p, &film, 4, 100, &meta, NULL, &err), "%s", err.msg);
    snprintf(path, sizeof path, "%s/r-spp004.exr", dir);
    cr_assert(image_read_exr(path, &img, &err), "%s", err.msg);
    cr_assert_null(image_find_attr(&img, "mcpt.render-seconds"));
    cr_assert_str_eq(image_find_attr(&img, "mcpt.seed"), "7");
    image_free(&img);
    snprintf(path, sizeof path, "%s/r-spp004.png", dir);
    cr_assert(test_exists(path), "%s", path);
    cr_assert(output_write_heatmap(&p, &film, &err)); /* none asked for: nothing written */
    film_free(&film);
    test_remove_dir(dir);
}

/* Every file a render may write is listed before it starts: image, preview, checkpoint, the
 * curve's three files, a snapshot and its preview at 1, 2, 4 and 5 of 5 spp (the final spp
 * included), the contact sheet; a PNG image (-o r.png) is listed once, as the image. */
Test(output, list_names_every_file)
{
    struct output_paths p;
    struct mcpt_error err;
    cr_assert(output_paths_init(&p, "s.txt", "r.exr", NULL, NULL, false, true, &err));
    static struct output_file files[OUTPUT_MAX_FILES];
    int n = output_list(&p, "c.csv", true, 5, files, &err);
    const char *want[] = {"r.exr",      "r.png",      "r.exr.ckpt", "c.csv",      "c.json",
                          "c.svg",      "r-spp1.exr", "r-spp1.png", "r-spp2.exr", "r-spp2.png",
                          "r-spp4.exr", "r-spp4.png", "r-spp5.exr", "r-spp5.png", "r-contact.png"};
    cr_assert_eq(n, 15);
    for (int i = 0; i < n; i++)
        cr_assert_str_eq(files[i].path, want[i]);
    n = output_list(&p, NULL, true, UINT32_MAX, files, &err);
    cr_assert_eq(n, 3 + 2 * 33 + 1, "1, 2, 4, ..., 2^31 and 2^32 - 1 spp: %d files", n);
    /* a PNG image alone: it is the image, and the snapshots are named from it */
    cr_assert(output_paths_init(&p, "s.txt", "r.png", NULL, NULL, false, true, &err));
    n = output_list(&p, NULL, true, 1, files, &err);
    cr_assert_eq(n, 5);
    cr_assert_str_eq(files[0].path, "r.png");
    cr_assert_str_eq(files[0].role, "the image (-o)");
    cr_assert_str_eq(files[1].path, "r.png.ckpt");
    cr_assert_str_eq(files[2].path, "r-spp1.exr");
}

/* output_check: two outputs of one name, or an output naming an input, are refused (the later
 * output named, with what it would overwrite); distinct creatable outputs pass. */
Test(output, check_refuses_shared_files)
{
    char dir[256];
    test_make_dir(dir, sizeof dir, "output");
    struct output_file out[2] = {{.role = "the image (-o)"}, {.role = "the sample-count map"}};
    struct output_file in[1] = {{.role = "the scene file"}};
    snprintf(out[0].path, sizeof out[0].path, "%s/a.exr", dir);
    snprintf(out[1].path, sizeof out[1].path, "%s/./a.exr", dir);
    snprintf(in[0].path, sizeof in[0].path, "%s/s.txt", dir);
    struct mcpt_error err;
    cr_assert_not(output_check(out, 2, in, 1, &err));
    cr_assert_str_eq(err.file, out[1].path);
    char want[FILE_PATH_BYTES + 200];
    snprintf(want, sizeof want,
             "expected the sample-count map to be a file of its own, got the same file as the "
             "image (-o) '%s'",
             out[0].path);
    cr_assert_str_eq(err.msg, want);
    snprintf(out[1].path, sizeof out[1].path, "%s/b.png", dir);
    cr_assert(output_check(out, 2, in, 1, &err), "%s", err.msg);
    snprintf(out[1].path, sizeof out[1].path, "%s", in[0].path);
    cr_assert_not(output_check(out, 2, in, 1, &err));
    cr_assert(strstr(err.msg, "got the same file as the scene file"), "%s", err.msg);
    test_remove_dir(dir);
}

/* output_save_interval: the interval asked for, unless the last write took more than
 * OUTPUT_MAX_WRITE_SHARE of it; then 1 / that share times the write (10x at the share 0.1). */
Test(output, save_interval_bounds_the_time_spent_writing)
{
    cr_assert_eq(output_save_interval(60.0, 0.0), 60.0);    /* nothing written yet */
    cr_assert_eq(output_save_interval(60.0, 0.5), 60.0);    /* 0.5 s of 60: under the share */
    cr_assert_eq(output_save_interval(0.001, 0.0), 0.001);
    double least = output_save_interval(0.001, 0.25);       /* a tiny interval, a slow write */
    cr_assert_float_eq(least, 0.25 / OUTPUT_MAX_WRITE_SHARE, 1e-12);
    cr_assert_float_eq(0.25 / least, OUTPUT_MAX_WRITE_SHARE, 1e-12);
}
