/* tests/checkpoint_test.c - checkpoint.c: an interrupted render's file.  Save then load is the
 * identity on the pixel records and settings; every kind of damage (a flipped bit, a truncation,
 * a count no run could make, sums no samples could give under a valid checksum) is refused
 * naming the file; a failed write leaves nothing; a resumed run whose settings
 * differ from the saved ones is refused naming the first difference.  The resume itself, through
 * the binary, is tests/resume_test.c's. */
#include <criterion/criterion.h>

#include <unistd.h>

#include "checkpoint.h"
#include "sample.h"
#include "test_util.h"

static char tmpdir[256];

static void setup(void) { test_make_dir(tmpdir, sizeof tmpdir, "checkpoint"); }
static void teardown(void) { test_remove_dir(tmpdir); }

/* Save then load returns the same pixel records and settings; one flipped byte, a truncation
 * or a count above spp is refused with a message naming the file. */
Test(checkpoint, round_trip_and_damage, .init = setup, .fini = teardown)
{
    struct film film, back;
    struct mcpt_error err;
    cr_assert(film_init(&film, 5, 3, &err));
    for (int i = 0; i < 15; i++) { /* pixel i: i samples, as a render adds them */
        struct film_pixel *p = &film.pixels[i];
        for (int k = 0; k < i; k++)
            film_add(p, v3(0.1f * (float)k, 1.0f / (float)(i + 1), (float)(i * k)));
        p->n_dropped = i == 7;
    }
    struct checkpoint_info info = {.scene_hash = 42,
                                   .seed = 7,
                                   .spp = 16,
                                   .max_depth = 3,
                                   .sampler = 0,
                                   .sample_offset = 5,
                                   .args_bytes = 9};
    snprintf(info.scene_path, sizeof info.scene_path, "a/scene.txt");
    memcpy(info.args, "--spp=16", 9);
    char path[300];
    snprintf(path, sizeof path, "%s/x.ckpt", tmpdir);
    cr_assert(checkpoint_save(path, &film, &info, &err), "%s", err.msg);
    struct checkpoint_info got;
    cr_assert(checkpoint_load(path, &back, &got, &err), "%s", err.msg);
    cr_assert(back.width == 5 && back.height == 3);
    cr_assert(memcmp(back.pixels, film.pixels, 15 * sizeof(struct film_pixel)) == 0);
    cr_assert(got.scene_hash == 42 && got.seed == 7 && got.spp == 16 && got.max_depth == 3 &&
              got.sample_offset == 5 && got.args_bytes == 9);
    cr_assert_str_eq(got.scene_path, "a/scene.txt");
    cr_assert_str_eq(got.args, "--spp=16");
    film_free(&back);

    /* flip one bit of a pixel record: the checksum catches it */
    FILE *f = fopen(path, "r+b");
    cr_assert_not_null(f);
    fseek(f, -100, SEEK_END);
    int ch = fgetc(f);
    fseek(f, -100, SEEK_END);
    fputc(ch ^ 1, f);
    fclose(f);
    cr_assert_not(checkpoint_load(path, &back, &got, &err));
    cr_assert(strncmp(err.msg, "expected checksum", 17) == 0, "%s", err.msg);
    cr_assert_str_eq(err.file, path);
    cr_assert_eq(err.kind, MCPT_ERROR_INPUT);
    cr_assert_null(back.pixels);

    /* a truncated file names the length it expected */
    cr_assert(checkpoint_save(path, &film, &info, &err));
    cr_assert_eq(truncate(path, 200), 0);
    cr_assert_not(checkpoint_load(path, &back, &got, &err));
    cr_assert(strstr(err.msg, "bytes for a 5x3 film, got 200"), "%s", err.msg);

    /* a pixel beyond the spp target cannot come from a real run */
    film.pixels[3].n = 17;
    cr_assert(checkpoint_save(path, &film, &info, &err));
    cr_assert_not(checkpoint_load(path, &back, &got, &err));
    cr_assert(strstr(err.msg, "at most 16 samples in a pixel"), "%s", err.msg);
    film.pixels[3].n = 3;

    /* a valid checksum over values no render writes: a NaN sum, an infinite or negative sum of
     * squares (issue 15) */
    double *fields[] = {&film.pixels[4].sum[1], &film.pixels[4].sum_sq[2],
                        &film.pixels[4].sum_sq[0], &film.pixels[4].sum[0]};
    double values[] = {NAN, INFINITY, -1.0, -1e-3}; /* the last: a negative sum (probing) */
    for (int k = 0; k < 4; k++) {
        double keep = *fields[k];
        *fields[k] = values[k];
        cr_assert(checkpoint_save(path, &film, &info, &err));
        cr_assert_not(checkpoint_load(path, &back, &got, &err), "value %g accepted", values[k]);
        cr_assert(strncmp(err.msg, "expected pixel sums that 4 samples can give, got ", 49) == 0 &&
                      strstr(err.msg, "at pixel 4,0"),
                  "%s", err.msg);
        cr_assert_null(back.pixels);
        *fields[k] = keep;
    }
    cr_assert(checkpoint_save(path, &film, &info, &err));
    cr_assert(checkpoint_load(path, &back, &got, &err), "%s", err.msg);
    film_free(&back);

    /* writing into a missing folder fails cleanly and leaves nothing */
    char bad[320];
    snprintf(bad, sizeof bad, "%s/no/such/dir.ckpt", tmpdir);
    cr_assert_not(checkpoint_save(bad, &film, &info, &err));
    cr_assert(strncmp(err.msg, "cannot write: ", 14) == 0, "%s", err.msg);
    cr_assert_eq(err.kind, MCPT_ERROR_RUNTIME);
    film_free(&film);
}

/* Each setting a resumed run must repeat is compared, the scene first, and the message names
 * the first that differs with the saved and the given value (bad input, file = the
 * checkpoint). */
Test(checkpoint, matches_names_the_first_difference)
{
    struct checkpoint_info saved = {.scene_hash = 1,
                                    .seed = 2,
                                    .spp = 64,
                                    .max_depth = 5,
                                    .sampler = SAMPLER_SOBOL,
                                    .sample_offset = 0};
    snprintf(saved.scene_path, sizeof saved.scene_path, "scenes/x.txt");
    struct checkpoint_info run = saved;
    struct mcpt_error err;
    cr_assert(checkpoint_matches("c.ckpt", &saved, &run, &err));
    run.seed = 3;
    run.spp = 32;
    cr_assert_not(checkpoint_matches("c.ckpt", &saved, &run, &err));
    cr_assert_str_eq(err.msg, "expected --spp 64 as in the checkpoint, got 32");
    cr_assert_str_eq(err.file, "c.ckpt");
    cr_assert_eq(err.kind, MCPT_ERROR_INPUT);
    run.spp = 64;
    cr_assert_not(checkpoint_matches("c.ckpt", &saved, &run, &err));
    cr_assert_str_eq(err.msg, "expected --seed 2 as in the checkpoint, got 3");
    run.seed = 2;
    run.max_depth = UINT32_MAX;
    cr_assert_not(checkpoint_matches("c.ckpt", &saved, &run, &err));
    cr_assert_str_eq(err.msg, "expected --max-depth 5 as in the checkpoint, got 4294967295");
    run.max_depth = 5;
    run.sampler = SAMPLER_INDEPENDENT;
    cr_assert_not(checkpoint_matches("c.ckpt", &saved, &run, &err));
    cr_assert_str_eq(err.msg, "expected --sampler sobol as in the checkpoint, got independent");
    run.sampler = SAMPLER_SOBOL;
    run.sample_offset = 8;
    cr_assert_not(checkpoint_matches("c.ckpt", &saved, &run, &err));
    cr_assert_str_eq(err.msg, "expected the sample offset 0 as in the checkpoint, got 8");
    run.scene_hash = 0xff; /* the scene is compared before everything else */
    cr_assert_not(checkpoint_matches("c.ckpt", &saved, &run, &err));
    cr_assert_str_eq(err.msg, "expected the scene the checkpoint was made from ('scenes/x.txt', "
                              "FNV-1a 0000000000000001), got files with hash 00000000000000ff "
                              "(the scene, or a mesh or MTL file it loads, changed)");
}
