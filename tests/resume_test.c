/* tests/resume_test.c - interrupt and resume: main.c's SIGINT/SIGTERM handling and --resume,
 * run through the binary $MCPT (default ./mcpt); the checkpoint file itself is tested by
 * tests/checkpoint_test.c.  The property checked is the one the design rests on: each
 * pixel's samples are added in sample-index order from its own count (film.h), so a render
 * interrupted any number of times and resumed is bit-identical to an uninterrupted one. */
#include <criterion/criterion.h>

#include <dirent.h>
#include <signal.h>
#include <time.h>

#include "checkpoint.h"
#include "film.h"
#include "image.h"
#include "scene.h"
#include "test_util.h"
#include "trace.h"

#define SCENE "tests/data/resume/small.txt"
/* long enough to interrupt twice: 0.9 s on 2 threads of a 2-vCPU Xeon (at 4096 spp the resumed
 * run of sigint_then_sigterm_then_bit_identical could end before its signal there) */
#define SIGNAL_SPP "8192"
#define SIGNAL_SPP_F 8192.0f
#define ALARM_S 60u       /* a hung run ends instead of hanging the suite */

static char tmpdir[256];

static void setup(void) { test_make_dir(tmpdir, sizeof tmpdir, "resume"); }
static void teardown(void) { test_remove_dir(tmpdir); }

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Polls err_path until the child pid (mcpt) has printed a progress line (it has rendered a
 * quarter of what it set out to), so that a signal can land mid-render.  Returns false when
 * mcpt ended first (not collected: test_wait gives its status).  No deadline of its own, which
 * a slow machine could pass (a sanitizer build on a machine shared by many jobs has taken over
 * 30 s to its first quarter): a run that never ends is ended by its alarm. */
static bool wait_for_progress(pid_t pid, const char *err_path)
{
    char buf[4096];
    for (;;) {
        bool has_ended = test_has_ended(pid); /* before the read: its last line is read */
        test_read_file(err_path, buf, sizeof buf);
        if (strstr(buf, "progress:"))
            return true;
        if (has_ended)
            return false;
        nanosleep(&(struct timespec){0, 5 * 1000 * 1000}, NULL);
    }
}

/* Waits for the child pid's first progress line, then sends it sig; returns its exit status
 * and in *stop_s the seconds from the signal to its end.  The signal races the render's end:
 * a test descheduled between seeing the line and the kill (a loaded machine) can find the
 * render finished, so 0 (a whole image, no checkpoint) is a legitimate outcome, for the caller
 * to check and to try again. */
static int signal_mid_render(pid_t pid, const char *err_path, int sig, double *stop_s)
{
    bool is_rendering = wait_for_progress(pid, err_path);
    double t0 = now_s();
    if (is_rendering)
        kill(pid, sig);
    int rc = test_wait(pid);
    *stop_s = now_s() - t0;
    return rc;
}

/* Waits for the child pid's first progress line, then stops it (test_stop), so that signals
 * sent to it are delivered together, mid-render, by kill(pid, SIGCONT).  Returns false when
 * the render ended before the stop (a descheduled test on a loaded machine), its exit status
 * in *rc. */
static bool stop_mid_render(pid_t pid, const char *err_path, int *rc)
{
    if (!wait_for_progress(pid, err_path)) {
        *rc = test_wait(pid);
        return false;
    }
    return test_stop(pid, rc);
}

/* Every channel of a holds the same float bytes as the channel of that name in b. */
static void assert_same_exr(const char *path_a, const char *path_b)
{
    struct image a, b;
    struct mcpt_error err;
    cr_assert(image_read_exr(path_a, &a, &err), "%s: %s", path_a, err.msg);
    cr_assert(image_read_exr(path_b, &b, &err), "%s: %s", path_b, err.msg);
    cr_assert(a.width == b.width && a.height == b.height && a.n_channels == b.n_channels);
    size_t n = (size_t)a.width * (size_t)a.height;
    for (int c = 0; c < a.n_channels; c++) {
        int k = image_find_channel(&b, a.names[c]);
        cr_assert(k >= 0, "channel %s missing from %s", a.names[c], path_b);
        cr_assert(memcmp(a.data[c], b.data[k], n * sizeof(float)) == 0,
                  "channel %s of %s and %s differs", a.names[c], path_a, path_b);
    }
    image_free(&a);
    image_free(&b);
}

/* The least and the most samples of any pixel of a finite image (its samples channel). */
static void samples_range(const char *exr_path, float *lo, float *hi)
{
    struct image img;
    struct mcpt_error err;
    cr_assert(image_read_exr(exr_path, &img, &err), "%s: %s", exr_path, err.msg);
    int s = image_find_channel(&img, "samples");
    cr_assert(s >= 0);
    size_t n = (size_t)img.width * (size_t)img.height;
    *lo = INFINITY;
    *hi = 0.0f;
    for (size_t i = 0; i < n; i++) {
        *lo = fminf(*lo, img.data[s][i]);
        *hi = fmaxf(*hi, img.data[s][i]);
        for (int c = 0; c < img.n_channels; c++)
            cr_assert(isfinite(img.data[c][i]));
    }
    image_free(&img);
}

/* A partial image: finite, with some pixels short of spp and some samples taken. */
static void assert_partial(const char *exr_path, float spp)
{
    float lo, hi;
    samples_range(exr_path, &lo, &hi);
    cr_assert(lo < spp && hi > 0.0f, "samples in [%g, %g] of %g", lo, hi, spp);
}

/* A whole image: finite, every pixel at spp. */
static void assert_whole(const char *exr_path, float spp)
{
    float lo, hi;
    samples_range(exr_path, &lo, &hi);
    cr_assert(lo == spp && hi == spp, "samples in [%g, %g] of %g", lo, hi, spp);
}

/* A checkpoint at ckpt, if there is one, loads (a signal never leaves a corrupt one). */
static void assert_checkpoint_loads_if_any(const char *ckpt)
{
    if (!test_exists(ckpt))
        return;
    struct film film;
    struct checkpoint_info info;
    struct mcpt_error e;
    cr_assert(checkpoint_load(ckpt, &film, &info, &e), "%s", e.msg);
    film_free(&film);
}

/* FNV-1a 64 of a file, as the scene loader records it (scene.file_hash, docs/reliability.md). */
static uint64_t fnv1a_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    cr_assert_not_null(f);
    uint64_t h = 0xcbf29ce484222325ull;
    for (int ch; (ch = fgetc(f)) != EOF;)
        h = (h ^ (uint64_t)ch) * 0x100000001b3ull;
    fclose(f);
    return h;
}

/* Renders SCENE in-process to spp_done samples per pixel and saves a checkpoint that targets
 * spp_target, as an interrupted `mcpt SCENE --spp spp_target` would have (its options stored);
 * with range_end > 0, as `... --sample-range range_begin:range_end` would have. */
static void make_checkpoint_of(const char *path, uint32_t spp_done, uint32_t spp_target,
                               uint32_t range_begin, uint32_t range_end)
{
    struct scene scene;
    struct mcpt_error err;
    cr_assert(scene_load(SCENE, &scene, &err), "%s", err.msg);
    struct trace_scene *ts = trace_prepare(&scene, 1, &err);
    cr_assert_not_null(ts, "%s", err.msg);
    struct film film;
    cr_assert(film_init(&film, scene.width, scene.height, &err));
    struct trace_options opt = {.spp = spp_done,
                                .max_depth = scene.render.max_depth,
                                .seed = 0,
                                .sampler = SAMPLER_INDEPENDENT,
                                .n_threads = 2,
                                .sample_offset = range_begin,
                                .sampler_spp = range_end ? spp_target : 0};
    struct trace_result res;
    cr_assert(trace_render(ts, &opt, &film, &res, &err));
    struct checkpoint_info info = {.scene_hash = fnv1a_file(SCENE),
                                   .seed = 0,
                                   .spp = range_end ? range_end - range_begin : spp_target,
                                   .max_depth = opt.max_depth,
                                   .sampler = SAMPLER_INDEPENDENT,
                                   .sample_offset = range_begin};
    snprintf(info.scene_path, sizeof info.scene_path, "%s", SCENE);
    int n = snprintf(info.args, sizeof info.args, "--spp=%u", spp_target) + 1;
    n += snprintf(info.args + n, sizeof info.args - (size_t)n, "--sampler=independent") + 1;
    if (range_end)
        n += snprintf(info.args + n, sizeof info.args - (size_t)n, "--sample-range=%u:%u",
                      range_begin, range_end) +
             1;
    info.args_bytes = (uint32_t)n;
    cr_assert(checkpoint_save(path, &film, &info, &err), "%s", err.msg);
    film_free(&film);
    trace_free(ts);
    scene_free(&scene);
}

static void make_checkpoint(const char *path, uint32_t spp_done, uint32_t spp_target)
{
    make_checkpoint_of(path, spp_done, spp_target, 0, 0);
}

/* A checkpoint of 13 of 64 spp, resumed by mcpt (scene named by the checkpoint), gives the
 * same EXR bytes as one uninterrupted 64-spp run; the spent checkpoint is removed. */
Test(resume, from_checkpoint_bit_identical, .init = setup, .fini = teardown)
{
    char ckpt[300], full[300], resumed[300], err_path[300];
    snprintf(ckpt, sizeof ckpt, "%s/part.ckpt", tmpdir);
    snprintf(full, sizeof full, "%s/full.exr", tmpdir);
    snprintf(resumed, sizeof resumed, "%s/resumed.exr", tmpdir);
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    make_checkpoint(ckpt, 13, 64);
    const char *a_full[] = {SCENE,       "--spp", "64", "--sampler", "independent",
                            "--threads", "1",     "-o", full,        NULL};
    cr_assert_eq(test_run_mcpt(a_full, NULL, err_path, ALARM_S), 0);
    const char *a_res[] = {"--resume", ckpt, "--threads", "2", "-o", resumed, NULL};
    char err[4096];
    int rc = test_run_mcpt(a_res, NULL, err_path, ALARM_S);
    test_read_file(err_path, err, sizeof err);
    cr_assert_eq(rc, 0, "%s", err);
    assert_same_exr(full, resumed);
    cr_assert_not(test_exists(ckpt), "the checkpoint of a finished render is removed");
}

/* The paths of a refused resume (each 300 bytes) and a checkpoint of 2 of 8 samples a pixel. */
static void refusal_setup(char *ckpt, char *out, char *err_path)
{
    snprintf(ckpt, 300, "%s/part.ckpt", tmpdir);
    snprintf(out, 300, "%s/out.exr", tmpdir);
    snprintf(err_path, 300, "%s/stderr.txt", tmpdir);
    make_checkpoint(ckpt, 2, 8);
}

/* A resumed run must render what the interrupted one would have: another seed, film size or
 * scene is refused (exit 2, one line naming the checkpoint), and nothing is written. */
Test(resume, mismatch_refused, .init = setup, .fini = teardown)
{
    char ckpt[300], out[300], err_path[300], err[4096], want[400];
    refusal_setup(ckpt, out, err_path);
    const char *seed[] = {SCENE, "--resume", ckpt, "--seed", "5", "-o", out, NULL};
    cr_assert_eq(test_run_mcpt(seed, NULL, err_path, ALARM_S), 2);
    test_read_file(err_path, err, sizeof err);
    snprintf(want, sizeof want, "%s: error: expected --seed 0 as in the checkpoint, got 5\n", ckpt);
    cr_assert_str_eq(err, want);

    const char *spp[] = {"--resume", ckpt, "--spp", "9", "-o", out, NULL};
    cr_assert_eq(test_run_mcpt(spp, NULL, err_path, ALARM_S), 2);
    test_read_file(err_path, err, sizeof err);
    snprintf(want, sizeof want, "%s: error: expected --spp 8 as in the checkpoint, got 9\n", ckpt);
    cr_assert_str_eq(err, want);

    /* --width alone keeps the film's aspect ratio: 24x16 -> 8x5 (5.33 rounded) */
    const char *size[] = {"--resume", ckpt, "--width", "8", "-o", out, NULL};
    cr_assert_eq(test_run_mcpt(size, NULL, err_path, ALARM_S), 2);
    test_read_file(err_path, err, sizeof err);
    snprintf(want, sizeof want,
             "%s: error: expected a 24x16 film as in the checkpoint, got "
             "8x5\n",
             ckpt);
    cr_assert_str_eq(err, want);

    const char *scene[] = {"tests/data/cli/tiny.txt", "--resume", ckpt, "-o", out, NULL};
    cr_assert_eq(test_run_mcpt(scene, NULL, err_path, ALARM_S), 2);
    test_read_file(err_path, err, sizeof err);
    snprintf(want, sizeof want, "%s: error: expected the scene the checkpoint was made from", ckpt);
    cr_assert(strncmp(err, want, strlen(want)) == 0, "%s", err);
    cr_assert_not(test_exists(out));
    cr_assert(test_exists(ckpt), "a refused resume keeps its checkpoint");
}

/* A resumed render adds samples of the same estimator: another --direct, --split,
 * --light-samples, roulette, light sampling or adaptive sampling than the checkpoint's options
 * give with its scene is refused (exit 2, one line naming the checkpoint and the setting), and
 * nothing is written.  Found by probing: such a resume ran, and wrote an image that mixed two
 * estimators.  An option that repeats the checkpoint's setting (--split full, the default) is
 * accepted. */
Test(resume, changed_estimator_refused, .init = setup, .fini = teardown)
{
    char ckpt[300], out[300], err_path[300], err[4096], want[400];
    refusal_setup(ckpt, out, err_path);
    const char *changes[][3] = {
        {"--direct", "light", "--direct mis as in the checkpoint, got light"},
        {"--split", "indirect", "--split full as in the checkpoint, got indirect"},
        {"--light-samples", "2", "--light-samples 1 as in the checkpoint, got 2"},
        {"--rr", "0.5", "--rr throughput as in the checkpoint, got 0.5"},
        {"--rr-depth", "3", "--rr-depth 2 as in the checkpoint, got 3"},
        {"--rr-threshold", "1", "--rr-threshold 0.25 as in the checkpoint, got 1"},
        {"--light-sampling", "solid-angle",
         "--light-sampling area as in the checkpoint, got solid-angle"},
        {"--adaptive", NULL, "adaptive sampling off as in the checkpoint, got on"},
    };
    for (size_t i = 0; i < sizeof changes / sizeof changes[0]; i++) {
        const char *args[] = {"--resume", ckpt, "-o", out, changes[i][0], changes[i][1], NULL};
        cr_assert_eq(test_run_mcpt(args, NULL, err_path, ALARM_S), 2, "case %zu", i);
        test_read_file(err_path, err, sizeof err);
        snprintf(want, sizeof want,
                 "%s: error: expected %s (a resumed render adds samples of "
                 "the same estimator)\n",
                 ckpt, changes[i][2]);
        cr_assert_str_eq(err, want);
        cr_assert_not(test_exists(out));
        cr_assert(test_exists(ckpt), "a refused resume keeps its checkpoint");
    }
    const char *same[] = {"--resume", ckpt, "-o", out, "--split", "full", "--quiet", NULL};
    cr_assert_eq(test_run_mcpt(same, NULL, err_path, ALARM_S), 0);
    cr_assert(test_exists(out));
}

/* A part of a render (--sample-range) is stratified for the whole render's spp, so resuming
 * it with another --spp, or with another range or none, would mix samples of two renders; a
 * plain render's checkpoint resumed with a range likewise.  Each is refused (exit 2, one line
 * naming the checkpoint and the option), nothing is written, the checkpoint is kept.  Found by
 * probing: `--resume PART.ckpt --spp N` with the range's own count N ran and wrote a part
 * labelled as N's; `--sample-range 7:9` on a plain checkpoint said "expected --spp 8 ..., got
 * 2", naming an option not given. */
Test(resume, changed_sample_range_or_whole_spp_refused, .init = setup, .fini = teardown)
{
    char part[300], plain[300], out[300], err_path[300], err[4096], want[400];
    snprintf(part, sizeof part, "%s/part.ckpt", tmpdir);
    snprintf(plain, sizeof plain, "%s/plain.ckpt", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    make_checkpoint_of(part, 2, 16, 0, 8); /* samples 0..7 of a 16-spp render, 2 done */
    make_checkpoint(plain, 2, 8);
    struct {
        const char *ckpt;
        const char *args[4];
        const char *msg;
    } cases[] = {
        {part, {"--spp", "8"}, "expected --spp 16 as in the checkpoint, got 8 (a resumed render "
                               "adds samples of the same estimator)"},
        {part, {"--sample-range", "0:4"}, "expected --sample-range 0:8 as in the checkpoint, got "
                                          "--sample-range 0:4 (a resumed render adds the samples "
                                          "the interrupted one would have)"},
        {part, {"--spp", "8", "--sample-range", "0:8"},
         "expected --spp 16 as in the checkpoint, got 8 (a resumed render adds samples of the "
         "same estimator)"},
        {plain, {"--sample-range", "0:8"},
         "expected no --sample-range as in the checkpoint, got --sample-range 0:8 (a resumed "
         "render adds the samples the interrupted one would have)"},
        {plain, {"--spp", "16", "--sample-range", "0:8"},
         "expected no --sample-range as in the checkpoint, got --sample-range 0:8 (a resumed "
         "render adds the samples the interrupted one would have)"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        const char *a[] = {"--resume", cases[i].ckpt, "-o",          out,
                           cases[i].args[0], cases[i].args[1], cases[i].args[2], cases[i].args[3],
                           NULL};
        cr_assert_eq(test_run_mcpt(a, NULL, err_path, ALARM_S), 2, "case %zu", i);
        test_read_file(err_path, err, sizeof err);
        snprintf(want, sizeof want, "%s: error: %s\n", cases[i].ckpt, cases[i].msg);
        cr_assert_str_eq(err, want, "case %zu", i);
        cr_assert_not(test_exists(out), "case %zu", i);
        cr_assert(test_exists(cases[i].ckpt), "a refused resume keeps its checkpoint");
    }
    /* the part resumed as it was made completes it */
    const char *same[] = {"--resume", part, "-o", out, "--quiet", NULL};
    cr_assert_eq(test_run_mcpt(same, NULL, err_path, ALARM_S), 0);
    cr_assert(test_exists(out));
}

/* ---- signals ---- */

/* Starts mcpt with args and sends it sig at its first progress line; a render that ends first
 * (exit 0: a loaded machine) must have written the image of full and left no checkpoint ckpt,
 * and is started again, up to three times.  Returns the last exit status, its stderr in err
 * and in *stop_s the seconds from the signal to the end. */
static int interrupt_mid_render(const char *const *args, const char *err_path, int sig,
                                const char *full, const char *out, const char *ckpt, double *stop_s,
                                char *err, size_t err_bytes)
{
    int rc = 0;
    for (int attempt = 1; attempt <= 3 && rc == 0; attempt++) {
        pid_t pid = test_start_mcpt(args, NULL, err_path, ALARM_S);
        rc = signal_mid_render(pid, err_path, sig, stop_s);
        test_read_file(err_path, err, err_bytes);
        if (rc == 0) { /* the render ended first */
            cr_log_info("attempt %d: the render ended before the signal", attempt);
            assert_same_exr(full, out);
            cr_assert_not(test_exists(ckpt), "a finished render left a checkpoint");
        }
    }
    return rc;
}

/* SIGINT mid-render: exit 130 within a second or so, a valid partial EXR (its samples channel
 * short of spp somewhere) and a checkpoint.  The resumed run is interrupted again with SIGTERM
 * (exit 143), then resumed without naming the scene; the final EXR has the same bytes as an
 * uninterrupted run on another thread count.  A signal that comes after the render's end (the
 * test descheduled after the progress line, on a loaded machine) finds exit 0 and the whole,
 * bit-identical image, no checkpoint left: that run is tried again (the resumed one from a copy
 * of its checkpoint), up to three times. */
Test(interrupt, sigint_then_sigterm_then_bit_identical, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(240))
{
    char full[300], part[300], ckpt[300], saved[300], final[300], err_path[300], err[4096];
    snprintf(full, sizeof full, "%s/full.exr", tmpdir);
    snprintf(part, sizeof part, "%s/part.exr", tmpdir);
    snprintf(ckpt, sizeof ckpt, "%s/part.exr.ckpt", tmpdir);
    snprintf(saved, sizeof saved, "%s/saved.ckpt", tmpdir);
    snprintf(final, sizeof final, "%s/final.exr", tmpdir);
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);

    const char *a_full[] = {SCENE,     "--spp", SIGNAL_SPP, "--threads", "1",
                            "--quiet", "-o",    full,       NULL};
    cr_assert_eq(test_run_mcpt(a_full, NULL, err_path, ALARM_S), 0);

    /* first interruption: SIGINT */
    snprintf(err_path, sizeof err_path, "%s/stderr1.txt", tmpdir);
    const char *a_int[] = {SCENE, "--spp", SIGNAL_SPP, "--threads", "2", "-o", part, NULL};
    double stop_s = 0.0;
    int rc = interrupt_mid_render(a_int, err_path, SIGINT, full, part, ckpt, &stop_s, err,
                                  sizeof err);
    cr_assert_eq(rc, 130, "exit %d: %s", rc, err);
    cr_assert_lt(stop_s, 2.0, "took %.2f s to stop", stop_s);
    cr_log_info("SIGINT to exit: %.3f s", stop_s);
    cr_assert(strstr(err, "mcpt: interrupted by SIGINT"), "%s", err);
    char hint[700]; /* the command as this binary was invoked (issue 14, item 5) */
    snprintf(hint, sizeof hint, "continue with: %s %s --resume %s\n",
             getenv("MCPT") ? getenv("MCPT") : "./mcpt", SCENE, ckpt);
    cr_assert(strstr(err, hint), "want '%s' in: %s", hint, err);
    assert_partial(part, SIGNAL_SPP_F);
    cr_assert(test_exists(ckpt));

    /* second interruption, of the resumed run: SIGTERM */
    char cmd[700];
    snprintf(cmd, sizeof cmd, "cp '%s' '%s'", ckpt, saved);
    cr_assert_eq(system(cmd), 0);
    snprintf(cmd, sizeof cmd, "cp '%s' '%s'", saved, ckpt);
    snprintf(err_path, sizeof err_path, "%s/stderr2.txt", tmpdir); /* no old progress lines */
    const char *a_res[] = {SCENE, "--resume", ckpt, "--threads", "2", NULL};
    rc = 0;
    for (int attempt = 1; attempt <= 3 && rc == 0; attempt++) {
        cr_assert_eq(system(cmd), 0);
        pid_t pid = test_start_mcpt(a_res, NULL, err_path, ALARM_S);
        rc = signal_mid_render(pid, err_path, SIGTERM, &stop_s);
        test_read_file(err_path, err, sizeof err);
        if (rc == 0) { /* the resumed render ended first */
            cr_log_info("attempt %d: the resumed render ended before SIGTERM", attempt);
            assert_same_exr(full, part);
            cr_assert_not(test_exists(ckpt), "a finished render left a checkpoint");
        }
    }
    cr_assert_eq(rc, 143, "exit %d: %s", rc, err);
    cr_assert(strstr(err, "mcpt: interrupted by SIGTERM"), "%s", err);
    assert_partial(part, SIGNAL_SPP_F); /* the stored -o: the same partial image, further on */
    cr_assert(test_exists(ckpt));

    /* the last resume names no scene and writes elsewhere */
    const char *a_fin[] = {"--resume", ckpt, "--threads", "2", "--quiet", "-o", final, NULL};
    rc = test_run_mcpt(a_fin, NULL, err_path, ALARM_S);
    test_read_file(err_path, err, sizeof err);
    cr_assert_eq(rc, 0, "exit %d: %s", rc, err);
    assert_same_exr(full, final);
    cr_assert_not(test_exists(ckpt));
}

/* The adaptive budget rule, interrupted by SIGINT and resumed, gives the image of an
 * uninterrupted run to the bit: the resumed run renders every pixel's pilot again and gets the
 * same counts.  As above, a render that ends before the signal is tried again. */
Test(interrupt, budget_rule_resumes_bit_identical, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(240))
{
    char full[300], part[300], ckpt[300], err_path[300], err[4096];
    snprintf(full, sizeof full, "%s/full.exr", tmpdir);
    snprintf(part, sizeof part, "%s/part.exr", tmpdir);
    snprintf(ckpt, sizeof ckpt, "%s/part.exr.ckpt", tmpdir);
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    const char *a_full[] = {SCENE,    "--spp",     SIGNAL_SPP, "--adaptive", "--adaptive-rule",
                            "budget", "--threads", "1",        "--quiet",    "-o",
                            full,     NULL};
    cr_assert_eq(test_run_mcpt(a_full, NULL, err_path, ALARM_S), 0);
    const char *a_int[] = {SCENE,    "--spp",     SIGNAL_SPP, "--adaptive", "--adaptive-rule",
                           "budget", "--threads", "2",        "-o",         part,
                           NULL};
    double stop_s = 0.0;
    int rc = interrupt_mid_render(a_int, err_path, SIGINT, full, part, ckpt, &stop_s, err,
                                  sizeof err);
    cr_assert_eq(rc, 130, "exit %d: %s", rc, err);
    cr_assert(test_exists(ckpt));
    const char *a_res[] = {"--resume", ckpt, "--threads", "2", "--quiet", NULL};
    rc = test_run_mcpt(a_res, NULL, err_path, ALARM_S);
    test_read_file(err_path, err, sizeof err);
    cr_assert_eq(rc, 0, "exit %d: %s", rc, err);
    assert_same_exr(full, part);
    cr_assert_not(test_exists(ckpt));
}

/* A signal during the adaptive pilot (here one of 10^8 samples a pixel, which would take
 * hours) stops it as it stops the render: exit 143 at once, nothing written.  Found by
 * probing: the pilot's loop did not look at the signal, so only SIGKILL ended such a run.  The
 * signal may also land before the pilot starts (a loaded machine); the outcome is the same. */
Test(interrupt, during_the_adaptive_pilot, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(120))
{
    char out[300], err_path[300], err[4096];
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    const char *args[] = {SCENE,       "--spp",     "2", "--adaptive", "--pilot-spp",
                          "100000000", "--min-spp", "2", "--threads",  "2",
                          "-o",        out,         NULL};
    pid_t pid = test_start_mcpt(args, NULL, err_path, ALARM_S);
    nanosleep(&(struct timespec){0, 500 * 1000 * 1000}, NULL);
    double t0 = now_s();
    kill(pid, SIGTERM);
    int rc = test_wait(pid);
    double stop_s = now_s() - t0;
    test_read_file(err_path, err, sizeof err);
    cr_assert_eq(rc, 143, "exit %d: %s", rc, err);
    cr_assert_lt(stop_s, 2.0, "took %.2f s to stop", stop_s);
    cr_assert(strstr(err, "mcpt: interrupted by SIGTERM"), "%s", err);
    cr_assert_not(test_exists(out));
}

/* A second signal exits at once (status 128 + its number) without finishing the render or the
 * writes, and leaves no corrupt file: OUT.exr is the earlier file or a whole new image, and a
 * checkpoint, if one was written, loads.  The two signals differ (SIGTERM, then SIGINT) because
 * a second SIGINT sent while the first is still pending would merge with it.  Both are sent
 * while mcpt is stopped (SIGSTOP) and delivered together by SIGCONT: sent one after the other
 * to a running mcpt, a test descheduled between the two kills (a loaded machine) let the first
 * signal's path run to its end.  A render that ends before the stop is tried again, up to
 * three times. */
Test(interrupt, second_signal_exits_at_once, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(180))
{
    char out[300], ckpt[300], err_path[300], err[4096];
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(ckpt, sizeof ckpt, "%s/out.exr.ckpt", tmpdir);
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    const char *args[] = {SCENE, "--spp", SIGNAL_SPP, "--threads", "2", "-o", out, NULL};
    bool is_stopped = false;
    int rc = 0;
    double stop_s = 0.0;
    for (int attempt = 1; attempt <= 3 && !is_stopped; attempt++) {
        FILE *f = fopen(out, "w");
        fputs("earlier", f);
        fclose(f);
        pid_t pid = test_start_mcpt(args, NULL, err_path, ALARM_S);
        is_stopped = stop_mid_render(pid, err_path, &rc);
        if (!is_stopped) {
            test_read_file(err_path, err, sizeof err);
            cr_log_info("attempt %d: the render ended before the stop", attempt);
            cr_assert_eq(rc, 0, "exit %d: %s", rc, err);
            continue;
        }
        kill(pid, SIGTERM);
        kill(pid, SIGINT);
        double t0 = now_s();
        kill(pid, SIGCONT);
        rc = test_wait(pid);
        stop_s = now_s() - t0;
    }
    test_read_file(err_path, err, sizeof err);
    cr_assert(is_stopped, "the render ended before each of three stops: %s", err);
    cr_assert(rc == 130 || rc == 143, "exit %d: %s", rc, err);
    cr_assert_not(strstr(err, "interrupted by"), "the first signal's path ran to the end: %s", err);
    cr_assert_lt(stop_s, 1.0, "took %.2f s", stop_s);
    cr_log_info("SIGCONT to exit: %.3f s", stop_s);

    char buf[16] = {0};
    FILE *f = fopen(out, "rb");
    cr_assert_not_null(f);
    cr_assert(fread(buf, 1, sizeof buf - 1, f) > 0);
    fclose(f);
    if (strcmp(buf, "earlier") != 0) {
        struct image img;
        struct mcpt_error e;
        cr_assert(image_read_exr(out, &img, &e), "%s", e.msg);
        image_free(&img);
    }
    assert_checkpoint_loads_if_any(ckpt);
}

/* Whether dir holds a file whose name starts with prefix. */
static bool has_file_starting(const char *dir, const char *prefix)
{
    bool found = false;
    DIR *d = opendir(dir);
    for (struct dirent *e; d && (e = readdir(d));)
        found |= strncmp(e->d_name, prefix, strlen(prefix)) == 0;
    closedir(d);
    return found;
}

/* Two signals during the checkpoint's write (the first starts it, the second arrives while its
 * temporary is being written): mcpt exits at once (143, the second signal's status, before
 * the first's "interrupted by" line) and leaves no temporary and no checkpoint behind.  The
 * film is 1500x1500, so the checkpoint is 144 MB and takes long enough to be caught mid-write:
 * once its temporary appears, mcpt is stopped (SIGSTOP) and the temporary looked for again,
 * so the second signal, delivered by SIGCONT, lands before the rename.  A test descheduled
 * past the write (a loaded machine) finds the checkpoint renamed into place instead, or the
 * render ended before the first signal: no temporary is left then either, a checkpoint
 * written loads, and the attempt is repeated, up to three times. */
Test(interrupt, second_signal_mid_checkpoint_leaves_no_temporary, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(180))
{
    char out[300], ckpt[300], err_path[300], err[4096];
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(ckpt, sizeof ckpt, "%s/out.exr.ckpt", tmpdir);
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    const char *args[] = {SCENE,   "--width", "1500",      "--height", "1500",
                          "--spp", "16",      "--threads", "2",        "--checkpoint-every",
                          "0",     "-o",      out,         NULL};
    bool is_mid_write = false; /* stopped with the checkpoint's temporary not yet renamed */
    for (int attempt = 1; attempt <= 3 && !is_mid_write; attempt++) {
        unlink(ckpt);
        pid_t pid = test_start_mcpt(args, NULL, err_path, ALARM_S);
        int rc = 0;
        if (wait_for_progress(pid, err_path)) {
            kill(pid, SIGINT);
            bool has_ended = false;
            while (!has_file_starting(tmpdir, "out.exr.ckpt.tmp.") && !has_ended) {
                has_ended = test_has_ended(pid);
                nanosleep(&(struct timespec){0, 500 * 1000}, NULL);
            }
            if (test_stop(pid, &rc)) {
                is_mid_write = has_file_starting(tmpdir, "out.exr.ckpt.tmp.");
                kill(pid, SIGTERM);
                kill(pid, SIGCONT);
                rc = test_wait(pid);
            }
        } else {
            rc = test_wait(pid);
        }
        test_read_file(err_path, err, sizeof err);
        cr_log_info("attempt %d: exit %d, %s", attempt, rc,
                    is_mid_write ? "stopped mid-write" : "the write was not caught");
        DIR *d = opendir(tmpdir);
        for (struct dirent *e; d && (e = readdir(d));)
            cr_assert_null(strstr(e->d_name, ".tmp."), "left %s (exit %d)", e->d_name, rc);
        closedir(d);
        if (is_mid_write) {
            cr_assert_eq(rc, 143, "exit %d: %s", rc, err);
            cr_assert_not(strstr(err, "interrupted by"), "%s", err);
            cr_assert_not(test_exists(ckpt), "the checkpoint was renamed into place");
        } else {
            cr_assert(rc == 0 || rc == 130 || rc == 143, "exit %d: %s", rc, err);
            assert_checkpoint_loads_if_any(ckpt);
        }
    }
    cr_assert(is_mid_write, "the checkpoint's write was not caught in three attempts: %s", err);
}

/* SIGINT when the checkpoint cannot be written (its folder was removed during the render):
 * the partial image is still written, and the one error line says so; exit 1.  A render that
 * ends before the signal (exit 0, a whole image) is tried again, up to three times. */
Test(interrupt, checkpoint_unwritable_still_writes_the_image, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(180))
{
    char dir[300], ckpt[340], out[300], err_path[300], err[4096];
    snprintf(dir, sizeof dir, "%s/ck", tmpdir);
    snprintf(ckpt, sizeof ckpt, "%s/c.ckpt", dir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    const char *args[] = {SCENE, "--spp", SIGNAL_SPP, "--threads",          "2", "--checkpoint",
                          ckpt,  "-o",    out,        "--checkpoint-every", "0", NULL};
    int rc = 0;
    for (int attempt = 1; attempt <= 3 && rc == 0; attempt++) {
        cr_assert_eq(mkdir(dir, 0755), 0);
        pid_t pid = test_start_mcpt(args, NULL, err_path, ALARM_S);
        bool is_rendering = wait_for_progress(pid, err_path);
        cr_assert_eq(rmdir(dir), 0);
        if (is_rendering)
            kill(pid, SIGINT);
        rc = test_wait(pid);
        test_read_file(err_path, err, sizeof err);
        if (rc == 0) { /* the render ended first */
            cr_log_info("attempt %d: the render ended before SIGINT", attempt);
            cr_assert_not(strstr(err, "error"), "%s", err);
            assert_whole(out, SIGNAL_SPP_F);
        }
    }
    cr_assert_eq(rc, 1, "exit %d: %s", rc, err);
    char want[800];
    snprintf(want, sizeof want,
             "%s: error: cannot write: No such file or directory; the partial image %s was "
             "written, but the render cannot be resumed\n",
             ckpt, out);
    cr_assert(strstr(err, want), "want '%s' in: %s", want, err);
    assert_partial(out, SIGNAL_SPP_F);
}

/* A render stopped (SIGSTOP) for 1.5 s and continued (SIGCONT) reports its wall time, which
 * counts the stop, and its CPU time, which does not: "render W s wall, C s CPU", W - C >= 1.5
 * on one thread.  The 1.5 s are timed from the stop's taking effect, and the stop counts only
 * when it lands in the render, before its 100% progress line; one that lands later (a test
 * descheduled after the first progress line, on a loaded machine) is tried again, up to three
 * times. */
Test(interrupt, stopped_time_is_wall_not_cpu, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(180))
{
    char out[300], out_path[300], err_path[300], text[4096], err[4096];
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(out_path, sizeof out_path, "%s/stdout.txt", tmpdir);
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    const char *args[] = {SCENE, "--spp", "2048", "--threads", "1", "-o", out, NULL};
    bool is_stopped_mid_render = false;
    for (int attempt = 1; attempt <= 3 && !is_stopped_mid_render; attempt++) {
        pid_t pid = test_start_mcpt(args, out_path, err_path, ALARM_S);
        int rc = 0;
        if (stop_mid_render(pid, err_path, &rc)) {
            test_read_file(err_path, err, sizeof err); /* what it printed before the stop */
            is_stopped_mid_render = !strstr(err, "progress: 100%");
            nanosleep(&(struct timespec){1, 500 * 1000 * 1000}, NULL);
            kill(pid, SIGCONT);
            rc = test_wait(pid);
        }
        cr_assert_eq(rc, 0);
        test_read_file(out_path, text, sizeof text);
        const char *r = strstr(text, "render ");
        double wall = 0.0, cpu = 0.0;
        cr_assert(r && sscanf(r, "render %lf s wall, %lf s CPU", &wall, &cpu) == 2, "%s", text);
        cr_log_info("attempt %d: %s: wall %.2f s, CPU %.2f s", attempt,
                    is_stopped_mid_render ? "stopped mid-render" : "the render ended first", wall,
                    cpu);
        if (is_stopped_mid_render)
            cr_assert_geq(wall - cpu, 1.5, "wall %.2f s, CPU %.2f s", wall, cpu);
    }
    cr_assert(is_stopped_mid_render, "the render ended before each of three stops");
}
