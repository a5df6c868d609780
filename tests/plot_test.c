/* tests/plot_test.c - plot.c: the pictures of results.  Their sizes follow the documented
 * layout (docs/convergence.md): a heat map scales a film narrower than 256 pixels up by a whole
 * factor above a 43-row legend; a contact sheet tiles thumbnails of about 160 pixels, five to a
 * row, each above three lines of labels (spp, PSNR, whose seed).  The bitmap font draws each
 * glyph's rows as stored; the SVG is complete, escapes the scene's name and draws the
 * uncorrected curve dashed above the corrected one.  A map too large, or a sheet with no
 * thumbnail, is refused (a runtime error) and writes nothing. */
#include <criterion/criterion.h>

#include <png.h>
#include <stdlib.h>

#include "plot.h"
#include "sample.h"
#include "test_util.h"

/* Width and height of a PNG, from its IHDR chunk (big-endian, bytes 16-23 of the file). */
static void png_size(const char *path, uint32_t *width, uint32_t *height)
{
    unsigned char head[24];
    FILE *f = fopen(path, "rb");
    cr_assert(f && fread(head, 1, sizeof head, f) == sizeof head, "cannot read %s", path);
    fclose(f);
    *width = 0;
    *height = 0;
    for (int i = 0; i < 4; i++) {
        *width = *width << 8 | head[16 + i];
        *height = *height << 8 | head[20 + i];
    }
}

/* The sample-count map of a 4 x 3 film is scaled by a whole factor to 256 pixels wide (k = 64)
 * above a legend of 43 rows: 256 x 235.  A film so narrow and tall that its map would exceed
 * 65535 rows (1 x 300: k = 256) is refused with a message and no file. */
Test(plot, count_heatmap_size_and_limit)
{
    char dir[256], path[300];
    test_make_dir(dir, sizeof dir, "plot_count");
    snprintf(path, sizeof path, "%s/count.png", dir);
    struct film film;
    struct mcpt_error err;
    cr_assert(film_init(&film, 4, 3, &err));
    for (int i = 0; i < 12; i++)
        film.pixels[i].n = (uint32_t)(10 * i);
    cr_assert(plot_write_count_heatmap(path, &film, &err), "%s", err.msg);
    uint32_t w, h;
    png_size(path, &w, &h);
    cr_assert(w == 256 && h == 3 * 64 + 43, "%ux%u", w, h);
    film_free(&film);

    snprintf(path, sizeof path, "%s/tall.png", dir);
    cr_assert(film_init(&film, 1, 300, &err));
    cr_assert_not(plot_write_count_heatmap(path, &film, &err));
    cr_assert_str_eq(err.msg, "expected a film whose sample-count map is at most 65535 pixels a "
                              "side, got a 1x300 film");
    cr_assert_eq(err.kind, MCPT_ERROR_RUNTIME);
    cr_assert_not(test_exists(path));
    film_free(&film);
    test_remove_dir(dir);
}

/* An 8 x 8 film of constant 0.5 with a constant reference: its statistics, for the writers. */
struct fixture {
    struct film film;
    float planes[7 * 64];
    struct stats_image img;
};

static void fixture_init(struct fixture *fx)
{
    struct mcpt_error err;
    cr_assert(film_init(&fx->film, 8, 8, &err));
    for (int i = 0; i < 64; i++)
        for (int k = 0; k < 4; k++)
            film_add(&fx->film.pixels[i], v3(0.5f + 0.01f * (float)k, 0.25f, 0.125f));
    stats_image_from_film(&fx->film, fx->planes, &fx->img);
}

/* The error map of a 4 x 3 image is scaled by k = 64 to 256 pixels wide above the legend:
 * 256 x 235, as the sample-count map. */
Test(plot, error_heatmap_size)
{
    char dir[256], path[300];
    test_make_dir(dir, sizeof dir, "plot_error");
    snprintf(path, sizeof path, "%s/err.png", dir);
    float a_data[3][12], r_data[3][12];
    struct stats_image a = {.width = 4, .height = 3}, r = {.width = 4, .height = 3};
    for (int c = 0; c < 3; c++) {
        for (int i = 0; i < 12; i++) {
            r_data[c][i] = 0.5f;
            a_data[c][i] = 0.5f + 0.01f * (float)i; /* pixel 0 exact: no error to draw */
        }
        a.rgb[c] = a_data[c];
        r.rgb[c] = r_data[c];
    }
    struct mcpt_error err;
    cr_assert(plot_write_error_heatmap(path, &a, &r, &err), "%s", err.msg);
    uint32_t w, h;
    png_size(path, &w, &h);
    cr_assert(w == 256 && h == 3 * 64 + 43, "%ux%u", w, h);
    test_remove_dir(dir);
}

/* Three thumbnails of an 8 x 8 film, each repeated up by 160 / 8 = 20 to 160 x 160, tile in one
 * row: width 8 + 3 (160 + 8) = 512, height 8 + 160 + 3 (7 + 3) 2 + 8 = 236 (three label lines:
 * spp, PSNR, seed).  No thumbnail: no sheet. */
Test(plot, contact_sheet_layout)
{
    char dir[256], path[300];
    test_make_dir(dir, sizeof dir, "plot_sheet");
    snprintf(path, sizeof path, "%s/sheet.png", dir);
    struct fixture fx;
    fixture_init(&fx);
    struct plot_sheet sheet = {0};
    struct mcpt_error err;
    cr_assert_not(plot_write_contact_sheet(path, &sheet, &err));
    cr_assert_str_eq(err.msg, "expected snapshots for the contact sheet, got none");
    cr_assert_eq(err.kind, MCPT_ERROR_RUNTIME);
    cr_assert_not(test_exists(path));
    const struct image_look plain = {0}, brighter = {.exposure = 1.0f};
    cr_assert(plot_sheet_add(&sheet, &fx.img, 1, 20.0, STATS_ERR_REFERENCE, &plain, &err));
    cr_assert(plot_sheet_add(&sheet, &fx.img, 2, NAN, STATS_ERR_REFERENCE_CORRECTED, &plain, &err));
    cr_assert(
        plot_sheet_add(&sheet, &fx.img, 4, INFINITY, STATS_ERR_OWN_VARIANCE, &brighter, &err));
    cr_assert_eq(sheet.n_thumbs, 3);
    cr_assert(sheet.thumbs[0].width == 160 && sheet.thumbs[0].height == 160);
    cr_assert(plot_write_contact_sheet(path, &sheet, &err), "%s", err.msg);
    uint32_t w, h;
    png_size(path, &w, &h);
    cr_assert(w == 512 && h == 236, "%ux%u", w, h);
    plot_sheet_free(&sheet);
    film_free(&fx.film);
    test_remove_dir(dir);
}

/* The plot is a complete SVG document with both panels, and the scene's name is escaped. */
Test(plot, svg_is_complete_and_escaped)
{
    char dir[256], path[300];
    test_make_dir(dir, sizeof dir, "plot_svg");
    snprintf(path, sizeof path, "%s/c.svg", dir);
    struct fixture fx;
    fixture_init(&fx);
    struct stats_run_info info = {.scene = "a<b>&c.txt",
                                  .sampler = "sobol",
                                  .integrator = "path-mis",
                                  .max_depth = 5,
                                  .width = 8,
                                  .height = 8};
    struct stats_curve curve;
    stats_curve_init(&curve, &info);
    struct mcpt_error err;
    for (uint32_t spp = 1; spp <= 4; spp *= 2)
        cr_assert(stats_curve_add(&curve, &fx.film, NULL, 1, spp, 0.1 * spp, NULL, &err));
    struct stats_summary sum;
    cr_assert(stats_summarize(&curve, 0.0, &sum));
    cr_assert(plot_write_svg(path, &curve, &sum, &err), "%s", err.msg);
    static char text[1 << 16];
    cr_assert(test_read_file(path, text, sizeof text) > 0);
    cr_assert(strncmp(text, "<?xml", 5) == 0);
    cr_assert(strstr(text, "</svg>\n") != NULL);
    cr_assert(strstr(text, "clip_spp") && strstr(text, "clip_sec"));
    cr_assert(strstr(text, ">a&lt;b&gt;&amp;c.txt: 8x8, sampler sobol, path-mis, max depth 5"),
              "%.400s", text);
    stats_summary_free(&sum);
    stats_curve_free(&curve);
    film_free(&fx.film);
    test_remove_dir(dir);
}

/* '1' at scale 1 sets exactly the pixels of its stored rows (bit 4 leftmost); a character
 * outside printable ASCII draws an outlined box; the width is n (5 + 1) - 1 pixels. */
Test(plot, font_draws_stored_glyphs)
{
    static const uint8_t ONE[PLOT_FONT_H] = {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E};
    const uint8_t white[3] = {255, 255, 255};
    uint8_t img[PLOT_FONT_H][12][3];
    memset(img, 0, sizeof img);
    cr_assert_eq(plot_draw_text(&img[0][0][0], 12, PLOT_FONT_H, 0, 0, 1, "1\x01", white), 11);
    for (int r = 0; r < PLOT_FONT_H; r++)
        for (int col = 0; col < PLOT_FONT_W; col++) {
            bool one = ONE[r] & (0x10 >> col);
            bool box = r == 0 || r == PLOT_FONT_H - 1 || col == 0 || col == PLOT_FONT_W - 1;
            cr_assert_eq(img[r][col][0] == 255, one, "'1' row %d col %d", r, col);
            cr_assert_eq(img[r][6 + col][0] == 255, box, "box row %d col %d", r, col);
        }
}

/* The third label line of a tile names the seed whose PSNR it shows, "only" when the run had
 * several (the summary table averages over them): the sheet's pixels there are exactly those
 * of the font drawing "seed 7 only" on the background. */
Test(plot, contact_sheet_names_the_seed)
{
    char dir[256], path[300];
    test_make_dir(dir, sizeof dir, "plot_seed");
    snprintf(path, sizeof path, "%s/sheet.png", dir);
    struct fixture fx;
    fixture_init(&fx);
    struct plot_sheet sheet = {.seed = 7, .n_seeds = 3};
    struct mcpt_error err;
    const struct image_look look = {0};
    cr_assert(plot_sheet_add(&sheet, &fx.img, 1, 20.0, STATS_ERR_REFERENCE, &look, &err));
    cr_assert(plot_write_contact_sheet(path, &sheet, &err), "%s", err.msg);
    png_image im;
    memset(&im, 0, sizeof im);
    im.version = PNG_IMAGE_VERSION;
    cr_assert(png_image_begin_read_from_file(&im, path), "%s", im.message);
    im.format = PNG_FORMAT_RGB;
    uint8_t *got = malloc(PNG_IMAGE_SIZE(im));
    cr_assert(got && png_image_finish_read(&im, NULL, got, 0, NULL), "%s", im.message);
    int w = (int)im.width, h = (int)im.height;
    /* the layout of plot_write_contact_sheet: margin 8, font scale 2, a 160-pixel tile, labels
     * 3 scale below it, (7 + 3) scale apart */
    const int scale = 2, x0 = 8, y = 8 + 160 + 3 * scale + 2 * (PLOT_FONT_H + 3) * scale;
    uint8_t *want = malloc((size_t)w * h * 3);
    cr_assert_not_null(want);
    for (int i = 0; i < w * h; i++)
        memcpy(want + 3 * i, (const uint8_t[3]){32, 32, 32}, 3); /* the sheet's background */
    int text_w = plot_draw_text(want, w, h, x0, y, scale, "seed 7 only",
                                (const uint8_t[3]){255, 255, 255});
    cr_assert_gt(text_w, 0);
    for (int yy = y; yy < y + PLOT_FONT_H * scale; yy++)
        for (int xx = x0; xx < x0 + text_w; xx++)
            for (int c = 0; c < 3; c++)
                cr_assert_eq(got[3 * (yy * w + xx) + c], want[3 * (yy * w + xx) + c], "pixel %d,%d",
                             xx, yy);
    free(want);
    free(got);
    plot_sheet_free(&sheet);
    film_free(&fx.film);
    test_remove_dir(dir);
}

/* Against a reference with variance channels the plot has the corrected RMSE (solid) and the
 * uncorrected one, dashed and drawn after it, so that it shows where the two coincide. */
Test(plot, uncorrected_curve_is_dashed_and_on_top)
{
    char dir[256], path[300];
    test_make_dir(dir, sizeof dir, "plot_raw");
    snprintf(path, sizeof path, "%s/c.svg", dir);
    struct fixture ref, fx;
    fixture_init(&ref);
    fixture_init(&fx);
    for (int i = 0; i < 64; i++) /* the image: brighter than the reference, so the error > 0 */
        film_add(&fx.film.pixels[i], v3(0.9f, 0.25f, 0.125f));
    struct stats_run_info info = {.scene = "s.txt",
                                  .sampler = "sobol",
                                  .integrator = "path-mis",
                                  .max_depth = 5,
                                  .width = 8,
                                  .height = 8};
    struct stats_curve curve;
    stats_curve_init(&curve, &info);
    struct mcpt_error err;
    for (uint32_t spp = 1; spp <= 4; spp *= 2)
        cr_assert(stats_curve_add(&curve, &fx.film, &ref.img, 1, spp, 0.1 * spp, NULL, &err), "%s",
                  err.msg);
    struct stats_summary sum;
    cr_assert(stats_summarize(&curve, 0.0, &sum));
    cr_assert_eq(sum.source, STATS_ERR_REFERENCE_CORRECTED);
    cr_assert(plot_write_svg(path, &curve, &sum, &err), "%s", err.msg);
    static char text[1 << 16];
    cr_assert(test_read_file(path, text, sizeof text) > 0);
    const char *raw = strstr(text, "fill=\"none\" stroke=\"#ff7f0e\" stroke-width=\"1.8\" "
                                   "stroke-dasharray=\"5,3\" points=\"");
    const char *rmse = strstr(text, "fill=\"none\" stroke=\"#1f77b4\" stroke-width=\"1.8\" "
                                    "points=\"");
    cr_assert(raw && rmse, "%.2000s", text);
    cr_assert_gt(raw, rmse, "the uncorrected curve is drawn before (under) the corrected one");
    stats_summary_free(&sum);
    stats_curve_free(&curve);
    film_free(&fx.film);
    film_free(&ref.film);
    test_remove_dir(dir);
}
