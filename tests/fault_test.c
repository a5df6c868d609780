/* tests/fault_test.c - the binary ($MCPT, default ./mcpt) under faults its user did not mean to
 * cause (issue 15, docs/reliability.md): inputs that would block, loops a number can make
 * endless, outputs that name an input or each other, outputs that cannot be created, memory
 * limits, a full disk, kill -9.  Each test states the promise it checks: no hang, no file of
 * the user's destroyed, a failure reported before the render rather than after it, and at
 * most a minute of work lost. */
#include <criterion/criterion.h>

#include <dirent.h>
#include <errno.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/statvfs.h>
#include <time.h>

#include "checkpoint.h"
#include "image.h"
#include "sample.h"
#include "scene.h"
#include "test_util.h"

#define TINY "tests/data/cli/tiny.txt"      /* black where the camera looks: every image alike */
#define SMALL "tests/data/resume/small.txt" /* lit and noisy: seeds differ */
#define ALARM_S 30u                         /* a run longer than this is a hang */

static char tmpdir[256];

static void setup(void) { test_make_dir(tmpdir, sizeof tmpdir, "fault"); }
static void teardown(void) { test_remove_dir(tmpdir); }

/* Runs mcpt with args (NULL-terminated) under an alarm, stdout to tmpdir/stdout.txt and stderr
 * into err (err_bytes); returns the exit status (128 + SIGALRM for a hang). */
static int run(const char *const *args, char *err, size_t err_bytes)
{
    char out_path[300], err_path[300];
    snprintf(out_path, sizeof out_path, "%s/stdout.txt", tmpdir);
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    int rc = test_run_mcpt(args, out_path, err_path, ALARM_S);
    test_read_file(err_path, err, err_bytes);
    return rc;
}

/* ---- hangs ---- */

/* Stratified sets of 2^32 - 1 samples, from --spp or from the adaptive --batch: the grid's row
 * count once wrapped to 0 and one sample never ended (nor did SIGTERM end it).  Both runs
 * finish. */
Test(hang, stratified_set_of_2_32_minus_1, .init = setup, .fini = teardown)
{
    char out[300], err[4096];
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    const char *batch[] = {TINY,         "--adaptive", "--batch", "4294967295", "--sampler",
                           "stratified", "-o",         out,       "--quiet",    NULL};
    int rc = run(batch, err, sizeof err);
    cr_assert_eq(rc, 0, "--batch 4294967295: exit %d: %s", rc, err);
    const char *range[] = {TINY,         "--sampler",      "stratified", "--spp",
                           "4294967295", "--sample-range", "0:1",        "-o",
                           out,          "--quiet",        NULL};
    rc = run(range, err, sizeof err);
    cr_assert_eq(rc, 0, "--spp 4294967295 --sample-range 0:1: exit %d: %s", rc, err);
}

/* SIGTERM (and SIGINT alike) ends a run in every long phase: before the render mcpt leaves
 * both signals their default action, so the kernel ends it at once while it loads meshes or
 * builds the BVH; from the render on its handler stops the workers between samples (the
 * interrupt tests in resume_test.c).  A scene of eight Sponzas (532k triangles; about 0.7 s to
 * load and 0.8 s to build here) is signalled 0.3 s in (loading) and 1.1 s in (building, or
 * still loading on a slower machine): each run is ended by the signal's default action (a
 * handler's exit with the same status would mean the signal waited for the render), within
 * half a second of it (a few ms, under the sanitizers and a loaded machine too), having
 * written nothing. */
Test(hang, sigterm_ends_mesh_load_and_bvh_build, .init = setup, .fini = teardown)
{
    const char *model = "../shared/models/sponza-dabrovic.obj";
    if (access(model, R_OK) != 0)
        cr_skip_test("%s not present", model);
    char scene[300], out[300];
    snprintf(scene, sizeof scene, "%s/sponzas.txt", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    FILE *f = fopen(scene, "w");
    cr_assert_not_null(f);
    fprintf(f, "camera eye=0,1,3 look-at=0,0,0 up=0,1,0 fov=40\nfilm width=64 height=64\n");
    char *model_abs = realpath(model, NULL); /* the scene's mesh paths are from its folder */
    cr_assert_not_null(model_abs);
    for (int k = 0; k < 8; k++)
        fprintf(f, "mesh file=%s translate=%d,0,0\n", model_abs, 40 * k);
    free(model_abs);
    fclose(f);
    const long delays_ms[2] = {300, 1100};
    for (int i = 0; i < 2; i++) {
        const char *args[] = {scene, "--spp", "1", "-o", out, NULL};
        pid_t pid = test_start_mcpt(args, NULL, NULL, ALARM_S);
        nanosleep(&(struct timespec){0, delays_ms[i] * 1000 * 1000}, NULL);
        struct timespec t0, t1;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        kill(pid, SIGTERM);
        int status;
        cr_assert_eq(waitpid(pid, &status, 0), pid);
        clock_gettime(CLOCK_MONOTONIC, &t1);
        double dt = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
        cr_assert(WIFSIGNALED(status) && WTERMSIG(status) == SIGTERM,
                  "signal at %ld ms: not ended by SIGTERM's default action (%s %d)", delays_ms[i],
                  WIFEXITED(status) ? "exit" : "signal",
                  WIFEXITED(status) ? WEXITSTATUS(status) : WTERMSIG(status));
        cr_log_info("signal at %ld ms: ended %.3f s later", delays_ms[i], dt);
        cr_assert_lt(dt, 0.5, "signal at %ld ms: ended %.2f s later", delays_ms[i], dt);
        cr_assert_not(test_exists(out), "signal at %ld ms: wrote an image", delays_ms[i]);
    }
}

/* A FIFO with no writer, given wherever mcpt reads a file (--resume, compare's two images,
 * merge's parts, --reference), is refused at once as bad input naming it: open() of a FIFO
 * blocks until a writer comes, so inputs are opened without blocking and must be regular
 * files. */
Test(hang, fifo_checkpoint_images_and_parts_refused_at_once, .init = setup, .fini = teardown)
{
    char fifo[300], out[300], img[300], err[4096], want[400];
    snprintf(fifo, sizeof fifo, "%s/fifo", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(img, sizeof img, "%s/img.exr", tmpdir);
    cr_assert_eq(mkfifo(fifo, 0644), 0);
    const char *render[] = {TINY, "--spp", "2", "-o", img, "--quiet", NULL};
    cr_assert_eq(run(render, err, sizeof err), 0, "%s", err);
    const char *cases[][10] = {
        {TINY, "--resume", fifo, "-o", out, NULL},
        {"compare", fifo, img, NULL},
        {"compare", img, fifo, NULL},
        {"merge", fifo, "-o", out, NULL},
        {TINY, "--reference", fifo, "--spp", "2", "-o", out, NULL},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        int rc = run(cases[i], err, sizeof err);
        cr_assert_eq(rc, 2, "case %zu: exit %d: %s", i, rc, err);
        snprintf(want, sizeof want, "%s: error: expected a ", fifo);
        cr_assert(strncmp(err, want, strlen(want)) == 0 && strstr(err, "got a FIFO\n"),
                  "case %zu: %s", i, err);
        cr_assert_not(test_exists(out), "case %zu wrote %s", i, out);
    }
}

/* A scene read from a pipe (a FIFO with its writer, as `mcpt <(generate)` gives) renders: the
 * scene is read once, and its hash, which a checkpoint records, is of the bytes read.  Two
 * writers: one that wrote it all and left (the bytes wait in the pipe), one still writing
 * (mcpt's reads wait for the rest).  mcpt starts only once the writer is connected: a FIFO with
 * no writer reads as empty at once (bad_test's fifo case), so a writer scheduled late would
 * race it; CI once hung for 90 minutes on that race, the writer blocked in open() forever. */
Test(hang, scene_from_a_pipe_renders, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(120))
{
    char fifo[300], out[300], err[4096];
    snprintf(fifo, sizeof fifo, "%s/scene.fifo", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    cr_assert_eq(mkfifo(fifo, 0644), 0);
    for (int still_writing = 0; still_writing <= 1; still_writing++) {
        /* a reader held here keeps the pipe, and so the bytes written, alive until mcpt reads */
        int hold = open(fifo, O_RDONLY | O_NONBLOCK);
        int ready[2];
        cr_assert(hold >= 0 && pipe(ready) == 0);
        pid_t writer = fork();
        cr_assert_geq(writer, 0);
        if (writer == 0) { /* the generator */
            alarm(60);     /* never outlives the test, whatever happens to mcpt */
            char text[4096];
            long n = test_read_file(SMALL, text, sizeof text);
            int fd = open(fifo, O_WRONLY); /* at once: there is a reader */
            long first = still_writing ? n / 2 : n;
            bool ok = fd >= 0 && n > 0 && write(fd, text, (size_t)first) == first;
            if (still_writing) { /* connected: mcpt may start; the rest comes later */
                ok = ok && write(ready[1], "r", 1) == 1;
                nanosleep(&(struct timespec){0, 300 * 1000 * 1000}, NULL);
                ok = ok && write(fd, text + first, (size_t)(n - first)) == n - first;
            }
            _exit(ok ? 0 : 1);
        }
        close(ready[1]);
        if (still_writing) {
            char c;
            cr_assert_eq(read(ready[0], &c, 1), 1, "the writer never connected");
        } else {
            cr_assert_eq(test_wait(writer), 0, "the writer failed");
        }
        const char *args[] = {fifo, "--spp", "2", "-o", out, "--quiet", NULL};
        int rc = run(args, err, sizeof err);
        if (still_writing)
            cr_assert_eq(test_wait(writer), 0, "the writer failed");
        close(hold);
        close(ready[0]);
        cr_assert_eq(rc, 0, "still writing %d: exit %d: %s", still_writing, rc, err);
        cr_assert(test_exists(out));
        cr_assert_eq(unlink(out), 0);
    }
}

/* ---- outputs that would destroy a file ---- */

/* Copies the file at from to to. */
static void copy_file(const char *from, const char *to)
{
    char buf[65536];
    long n = test_read_file(from, buf, sizeof buf);
    cr_assert_geq(n, 0, "cannot read %s", from);
    FILE *f = fopen(to, "wb");
    cr_assert_not_null(f);
    cr_assert_eq(fwrite(buf, 1, (size_t)n, f), (size_t)n);
    fclose(f);
}

/* Saves at path the checkpoint of an untouched render of the tiny scene (a copy at scene) to
 * spp samples per pixel with its defaults, as an interrupted `mcpt scene --spp spp -o out`
 * would. */
static void save_checkpoint(const char *path, const char *scene, uint32_t spp, const char *out)
{
    struct film film;
    struct mcpt_error err;
    cr_assert(film_init(&film, 16, 12, &err)); /* the tiny scene's film */
    struct checkpoint_info info = {.spp = spp, .max_depth = 3, .sampler = SAMPLER_SOBOL};
    struct scene sc;
    cr_assert(scene_load(scene, &sc, &err), "%s", err.msg);
    info.scene_hash = sc.file_hash;
    scene_free(&sc);
    snprintf(info.scene_path, sizeof info.scene_path, "%s", scene);
    int n = snprintf(info.args, sizeof info.args, "--spp=%u", spp) + 1;
    n += snprintf(info.args + n, sizeof info.args - (size_t)n, "--output=%s", out) + 1;
    info.args_bytes = (uint32_t)n;
    cr_assert(checkpoint_save(path, &film, &info, &err), "%s", err.msg);
    film_free(&film);
}

/* Whether the file at path still holds the bytes of the file at original. */
static bool same_bytes(const char *path, const char *original)
{
    static char a[65536], b[65536];
    long na = test_read_file(path, a, sizeof a), nb = test_read_file(original, b, sizeof b);
    return na >= 0 && na == nb && memcmp(a, b, (size_t)na) == 0;
}

/* Whether the EXRs at a and b hold the same channels with the same values, bit for bit (their
 * headers differ: mcpt.render-seconds is each run's own). */
static bool same_pixels(const char *a, const char *b)
{
    struct image ia, ib;
    struct mcpt_error err;
    if (!image_read_exr(a, &ia, &err))
        return false;
    if (!image_read_exr(b, &ib, &err)) {
        image_free(&ia);
        return false;
    }
    bool same = ia.width == ib.width && ia.height == ib.height && ia.n_channels == ib.n_channels;
    size_t n_pixels = (size_t)ia.width * (size_t)ia.height;
    for (int c = 0; same && c < ia.n_channels; c++)
        same = strcmp(ia.names[c], ib.names[c]) == 0 &&
               memcmp(ia.data[c], ib.data[c], sizeof(float) * n_pixels) == 0;
    image_free(&ia);
    image_free(&ib);
    return same;
}

/* An output naming an input or another output is refused before anything is written: -o or
 * --curve naming the scene (also by another spelling, or a hard link), -o naming the
 * --reference, --heatmap equal to -o or to its preview, -o naming the checkpoint of --resume,
 * the subcommands' outputs naming their inputs (merge -o a part, convert's PNG its EXR,
 * compare --heatmap an image),
 * and -o naming the file given as the scene on standard input.  Exit 2, one line naming the
 * output and what it would overwrite; every input keeps its bytes. */
Test(clobber, outputs_never_overwrite_inputs, .init = setup, .fini = teardown)
{
    char scene[300], scene_alias[300], hard[300], sym[300], ref[300], ckpt[300], out[300];
    char part[300];
    char err[4096];
    snprintf(scene, sizeof scene, "%s/scene.txt", tmpdir);
    snprintf(scene_alias, sizeof scene_alias, "%s/./sub/../hard.exr", tmpdir);
    snprintf(hard, sizeof hard, "%s/hard.exr", tmpdir);
    snprintf(sym, sizeof sym, "%s/sym.png", tmpdir);
    snprintf(ref, sizeof ref, "%s/ref.exr", tmpdir);
    snprintf(ckpt, sizeof ckpt, "%s/c.ckpt", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(part, sizeof part, "%s/part.exr", tmpdir);
    copy_file(TINY, scene);
    cr_assert_eq(link(scene, hard), 0);
    cr_assert_eq(symlink("scene.txt", sym), 0);
    char sub[300];
    snprintf(sub, sizeof sub, "%s/sub", tmpdir);
    cr_assert_eq(mkdir(sub, 0755), 0);
    const char *mk_ref[] = {scene, "--spp", "2", "-o", ref, "--quiet", NULL};
    cr_assert_eq(run(mk_ref, err, sizeof err), 0, "%s", err);
    const char *mk_part[] = {scene, "--spp",   "4", "--sample-range", "0:2", "-o",
                             part,  "--quiet", NULL};
    cr_assert_eq(run(mk_part, err, sizeof err), 0, "%s", err);
    save_checkpoint(ckpt, scene, 4, out);
    char ref_copy[300], part_copy[300], ckpt_copy[300];
    snprintf(ref_copy, sizeof ref_copy, "%s/ref-copy.exr", tmpdir);
    snprintf(part_copy, sizeof part_copy, "%s/part-copy.exr", tmpdir);
    snprintf(ckpt_copy, sizeof ckpt_copy, "%s/c-copy.ckpt", tmpdir);
    copy_file(ref, ref_copy);
    copy_file(part, part_copy);
    copy_file(ckpt, ckpt_copy);
    char ckpt_link[300]; /* the checkpoint by an image's name */
    snprintf(ckpt_link, sizeof ckpt_link, "%s/c-link.exr", tmpdir);
    cr_assert_eq(link(ckpt, ckpt_link), 0);
    char ref_link[300]; /* the reference by a PNG's name */
    snprintf(ref_link, sizeof ref_link, "%s/ref-link.png", tmpdir);
    cr_assert_eq(link(ref, ref_link), 0);
    char alone_png[300]; /* an 8-bit image only (-o NAME.png), and the heat map's name too */
    snprintf(alone_png, sizeof alone_png, "%s/alone.png", tmpdir);

    struct {
        const char *args[12];
        const char *victim; /* the file named first in the message */
        const char *what;   /* the start of the message after "error: " */
    } cases[] = {
        {{scene, "-o", scene, NULL}, "mcpt", "expected an output name ending in .exr"},
        {{scene, "-o", sym, NULL},
         sym,
         "expected the image (-o) to be a file of its own, got the same file as the scene file"},
        {{scene, "-o", scene_alias, NULL},
         scene_alias,
         "expected the image (-o) to be a file of its own, got the same file as the scene file"},
        {{scene, "-o", hard, NULL},
         hard,
         "expected the image (-o) to be a file of its own, got the same file as the scene file"},
        {{scene, "--curve", scene, "-o", out, NULL},
         scene,
         "expected the curve (--curve) to be a file of its own, got the same file as the scene "
         "file"},
        {{scene, "--reference", ref, "-o", ref, NULL},
         ref,
         "expected the image (-o) to be a file of its own, got the same file as the reference"},
        {{scene, "--adaptive", "--heatmap", alone_png, "-o", alone_png, NULL},
         alone_png,
         "expected the sample-count map to be a file of its own, got the same file as the image "
         "(-o)"},
        {{scene, "--resume", ckpt, "-o", ckpt_link, NULL},
         ckpt_link,
         "expected the image (-o) to be a file of its own, got the same file as the checkpoint of "
         "--resume"},
        {{scene, "-o", out, "--checkpoint", scene, NULL},
         scene,
         "expected the checkpoint to be a file of its own, got the same file as the scene file"},
        {{"merge", part, "-o", part, NULL},
         part,
         "expected the merged image (-o) to be a file of its own, got the same file as a part"},
        {{"convert", ref, ref_link, NULL},
         ref_link,
         "expected the PNG (OUT) to be a file of its own, got the same file as the image IN"},
        {{"compare", ref, part, "--heatmap", ref_link, NULL},
         ref_link,
         "expected the heat map (--heatmap) to be a file of its own, got the same file as the "
         "image A"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        int rc = run(cases[i].args, err, sizeof err);
        char want[600];
        snprintf(want, sizeof want, "%s: error: %s", cases[i].victim, cases[i].what);
        cr_assert_eq(rc, 2, "case %zu: exit %d: %s", i, rc, err);
        cr_assert(strncmp(err, want, strlen(want)) == 0, "case %zu:\n  want %s\n  got  %s", i, want,
                  err);
        cr_assert(same_bytes(scene, TINY), "case %zu: the scene changed", i);
        cr_assert(same_bytes(ref, ref_copy), "case %zu: the reference changed", i);
        cr_assert(same_bytes(part, part_copy), "case %zu: the part changed", i);
        cr_assert(same_bytes(ckpt, ckpt_copy), "case %zu: the checkpoint changed", i);
    }
    /* the sample-count map named as the image's preview */
    char png[300];
    snprintf(png, sizeof png, "%s/out.png", tmpdir);
    const char *as_png[] = {scene, "--adaptive", "--heatmap", png, "-o", out, NULL};
    cr_assert_eq(run(as_png, err, sizeof err), 2, "%s", err);
    cr_assert(strstr(err, "expected the sample-count map to be a file of its own, got the same "
                          "file as the PNG preview"),
              "%s", err);
    cr_assert_not(test_exists(png));
    /* a scene on standard input is an input too: the file it was given is checked (the
     * output named by its hard link) */
    int saved_stdin = dup(0);
    int fd = open(scene, O_RDONLY);
    cr_assert(saved_stdin >= 0 && fd >= 0 && dup2(fd, 0) == 0);
    close(fd);
    const char *from_stdin[] = {"-", "-o", hard, NULL};
    int rc = run(from_stdin, err, sizeof err);
    cr_assert(dup2(saved_stdin, 0) == 0);
    close(saved_stdin);
    cr_assert_eq(rc, 2, "exit %d: %s", rc, err);
    cr_assert(strstr(err, "expected the image (-o) to be a file of its own, got the same file as "
                          "the scene file '/dev/stdin'"),
              "%s", err);
    cr_assert(same_bytes(scene, TINY));
}

/* The files a scene loads are inputs too: -o naming its OBJ or the OBJ's MTL (through a link,
 * as an image's name ends in .exr or .png), also by another spelling of the path, is refused and
 * both keep their bytes. */
Test(clobber, outputs_never_overwrite_meshes, .init = setup, .fini = teardown)
{
    char scene[300], obj[300], mtl[300], obj_alias[300], err[4096], want[900];
    snprintf(scene, sizeof scene, "%s/mesh.txt", tmpdir);
    snprintf(obj, sizeof obj, "%s/m.obj", tmpdir);
    snprintf(mtl, sizeof mtl, "%s/m.mtl", tmpdir);
    snprintf(obj_alias, sizeof obj_alias, "%s/../%s/m.obj", tmpdir, strrchr(tmpdir, '/') + 1);
    const char *obj_text = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl w\nf 1 2 3\n";
    const char *mtl_text = "newmtl w\nKd 0.5 0.5 0.5\n";
    FILE *f = fopen(obj, "w");
    fputs(obj_text, f);
    fclose(f);
    f = fopen(mtl, "w");
    fputs(mtl_text, f);
    fclose(f);
    f = fopen(scene, "w");
    fputs("camera eye=0,0,3 look-at=0,0,0 up=0,1,0 fov=45\nmesh file=m.obj\n", f);
    fclose(f);
    /* an image's name must end in .exr or .png: links of those names to the OBJ and MTL */
    char obj_link[300], mtl_link[300];
    snprintf(obj_link, sizeof obj_link, "%s/obj-link.exr", tmpdir);
    snprintf(mtl_link, sizeof mtl_link, "%s/mtl-link.png", tmpdir);
    cr_assert_eq(symlink("m.obj", obj_link), 0);
    cr_assert_eq(link(mtl, mtl_link), 0);
    snprintf(obj_alias, sizeof obj_alias, "%s/../%s/obj-link.exr", tmpdir,
             strrchr(tmpdir, '/') + 1);
    const char *victims[][2] = {{obj_link, "the image (-o)"},
                                {obj_alias, "the image (-o)"},
                                {mtl_link, "the image (-o)"}};
    for (int k = 0; k < 3; k++) {
        const char *args[] = {scene, "--spp", "1", "-o", victims[k][0], NULL};
        int rc = run(args, err, sizeof err);
        snprintf(want, sizeof want,
                 "%s: error: expected %s to be a file of its own, got the same file as a file the "
                 "scene loads",
                 victims[k][0], victims[k][1]);
        cr_assert_eq(rc, 2, "case %d: exit %d: %s", k, rc, err);
        cr_assert(strncmp(err, want, strlen(want)) == 0, "case %d:\n  want %s\n  got  %s", k, want,
                  err);
        char buf[256];
        test_read_file(obj, buf, sizeof buf);
        cr_assert_str_eq(buf, obj_text);
        test_read_file(mtl, buf, sizeof buf);
        cr_assert_str_eq(buf, mtl_text);
    }
}

/* ---- failing late ---- */

/* An output that cannot be created fails before the render (a 10^6-spp render would take
 * minutes): -o into a missing folder, -o naming a directory, --checkpoint into a missing
 * folder, --curve into a missing folder.  Exit 2 within a second or two, nothing written. */
Test(late, uncreatable_outputs_fail_before_the_render, .init = setup, .fini = teardown)
{
    char missing[300], ckpt[300], curve[300], out[300], dir[300], err[4096];
    snprintf(missing, sizeof missing, "%s/no/out.exr", tmpdir);
    snprintf(dir, sizeof dir, "%s/d.exr", tmpdir);
    cr_assert_eq(mkdir(dir, 0755), 0);
    snprintf(ckpt, sizeof ckpt, "%s/no/out.ckpt", tmpdir);
    snprintf(curve, sizeof curve, "%s/no/curve.csv", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    struct {
        const char *args[10];
        const char *victim;
        const char *what;
    } cases[] = {
        {{TINY, "--spp", "1000000", "-o", missing, NULL}, missing, "cannot create: no folder"},
        {{TINY, "--spp", "1000000", "-o", dir, NULL},
         dir,
         "expected a regular file or a new name to write, got a directory"},
        {{TINY, "--spp", "1000000", "-o", out, "--checkpoint", ckpt, NULL},
         ckpt,
         "cannot create: no folder"},
        {{TINY, "--spp", "1000000", "-o", out, "--curve", curve, NULL},
         curve,
         "cannot create: no folder"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        struct timespec t0, t1;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        int rc = run(cases[i].args, err, sizeof err);
        clock_gettime(CLOCK_MONOTONIC, &t1);
        double dt = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
        char want[600];
        snprintf(want, sizeof want, "%s: error: %s", cases[i].victim, cases[i].what);
        cr_assert_eq(rc, 2, "case %zu: exit %d: %s", i, rc, err);
        cr_assert(strncmp(err, want, strlen(want)) == 0, "case %zu:\n  want %s\n  got  %s", i, want,
                  err);
        cr_assert_lt(dt, 5.0, "case %zu took %.1f s: it rendered first", i, dt);
        cr_assert_not(test_exists(out), "case %zu", i);
    }
}

/* A read-only filesystem (a tmpfs mounted read-only, so root too is refused): the output is
 * refused before the render.  Needs the right to mount; skipped, saying so, without it. */
Test(late, read_only_filesystem_fails_before_the_render, .init = setup, .fini = teardown)
{
    char mnt[300], out[320], cmd[700], err[4096];
    snprintf(mnt, sizeof mnt, "%s/ro", tmpdir);
    cr_assert_eq(mkdir(mnt, 0755), 0);
    snprintf(cmd, sizeof cmd, "mount -t tmpfs -o ro,size=64k tmpfs '%s' 2>/dev/null", mnt);
    if (system(cmd) != 0)
        cr_skip_test("cannot mount a tmpfs here (not root?): read-only case not run");
    snprintf(out, sizeof out, "%s/out.exr", mnt);
    const char *args[] = {TINY, "--spp", "1000000", "-o", out, NULL};
    int rc = run(args, err, sizeof err);
    snprintf(cmd, sizeof cmd, "umount '%s'", mnt);
    cr_assert_eq(system(cmd), 0);
    char want[600];
    snprintf(want, sizeof want, "%s: error: cannot create: Read-only file system\n", out);
    cr_assert_eq(rc, 2, "exit %d: %s", rc, err);
    cr_assert_str_eq(err, want);
}

/* ---- an interrupted render is not started over by accident (issue 14, item 5) ---- */

/* Re-running a render whose checkpoint exists is refused (exit 2) with a message that gives
 * the command continuing it, as this binary was invoked, and names --restart; the checkpoint
 * is kept.  The suggested command resumes it; --restart discards it and renders afresh. */
Test(restart, existing_checkpoint_refused_until_resume_or_restart, .init = setup, .fini = teardown)
{
    char scene[300], out[300], ckpt[320], err[4096], want[1200];
    snprintf(scene, sizeof scene, "%s/scene.txt", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(ckpt, sizeof ckpt, "%s.ckpt", out);
    copy_file(TINY, scene);
    save_checkpoint(ckpt, scene, 4, out);
    const char *again[] = {scene, "--spp", "4", "-o", out, NULL};
    cr_assert_eq(run(again, err, sizeof err), 2, "%s", err);
    const char *bin = getenv("MCPT") ? getenv("MCPT") : "./mcpt";
    snprintf(want, sizeof want,
             "%s: error: expected no checkpoint of an interrupted render here, got one: "
             "continue it with '%s %s --resume %s', or discard it with --restart\n",
             ckpt, bin, scene, ckpt);
    cr_assert_str_eq(err, want);
    cr_assert(test_exists(ckpt));
    cr_assert_not(test_exists(out));
    /* the command suggested, word for word */
    const char *resume[] = {scene, "--resume", ckpt, "--quiet", NULL};
    cr_assert_eq(run(resume, err, sizeof err), 0, "%s", err);
    cr_assert(test_exists(out));
    cr_assert_not(test_exists(ckpt), "a finished render removes its checkpoint");
    /* --restart: the old checkpoint goes, the render starts over */
    save_checkpoint(ckpt, scene, 4, out);
    const char *restart[] = {scene, "--spp", "2", "-o", out, "--restart", "--quiet", NULL};
    cr_assert_eq(run(restart, err, sizeof err), 0, "%s", err);
    cr_assert_not(test_exists(ckpt));
    /* a scene on standard input: the command gives it the same way, from the file it was */
    save_checkpoint(ckpt, scene, 4, out);
    int saved_stdin = dup(0);
    int fd = open(scene, O_RDONLY);
    cr_assert(saved_stdin >= 0 && fd >= 0 && dup2(fd, 0) == 0);
    close(fd);
    const char *from_stdin[] = {"-", "--spp", "4", "-o", out, NULL};
    int rc = run(from_stdin, err, sizeof err);
    cr_assert(dup2(saved_stdin, 0) == 0);
    close(saved_stdin);
    char *scene_abs = realpath(scene, NULL);
    cr_assert_not_null(scene_abs);
    snprintf(want, sizeof want, "continue it with '%s - --resume %s < %s'", bin, ckpt, scene_abs);
    free(scene_abs);
    cr_assert_eq(rc, 2, "%s", err);
    cr_assert(strstr(err, want), "want %s\ngot  %s", want, err);
}

/* A file at the checkpoint path that is not a checkpoint (notes, an image: --checkpoint given
 * the wrong word) is refused, with --restart too, and kept: --restart once removed whatever
 * was there, as a finished render would. */
Test(restart, file_that_is_not_a_checkpoint_is_kept, .init = setup, .fini = teardown)
{
    char notes[300], out[300], err[4096], want[600], kept[64];
    snprintf(notes, sizeof notes, "%s/notes.txt", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    FILE *f = fopen(notes, "w");
    cr_assert_not_null(f);
    fputs("my notes\n", f);
    cr_assert_eq(fclose(f), 0);
    snprintf(want, sizeof want,
             "%s: error: expected an mcpt checkpoint or a new name for the checkpoint, got a "
             "file that is not one (it is kept; --checkpoint names another)\n",
             notes);
    for (int restart = 0; restart < 2; restart++) {
        const char *args[] = {TINY,  "--spp",   "1",
                              "-o",  out,       "--checkpoint",
                              notes, "--quiet", restart ? "--restart" : NULL,
                              NULL};
        cr_assert_eq(run(args, err, sizeof err), 2, "restart %d: %s", restart, err);
        cr_assert_str_eq(err, want, "restart %d", restart);
        cr_assert_eq(test_read_file(notes, kept, sizeof kept), 9, "restart %d", restart);
        cr_assert_str_eq(kept, "my notes\n", "restart %d", restart);
        cr_assert_not(test_exists(out), "restart %d", restart);
    }
}

/* The hint to resume names the checkpoint whole however long its path: the message (256 bytes
 * until now) cut the command it suggests, so pasting it named another file. */
Test(restart, resume_hint_names_a_long_path_whole, .init = setup, .fini = teardown)
{
    char dir[700], ckpt[800], out[800], err[8192], want[900];
    char word[201];
    memset(word, 'd', sizeof word - 1);
    word[sizeof word - 1] = '\0';
    snprintf(dir, sizeof dir, "%s/%s", tmpdir, word);
    cr_assert_eq(mkdir(dir, 0700), 0);
    snprintf(dir, sizeof dir, "%s/%s/%s", tmpdir, word, word);
    cr_assert_eq(mkdir(dir, 0700), 0);
    snprintf(ckpt, sizeof ckpt, "%s/c.ckpt", dir);
    snprintf(out, sizeof out, "%s/out.exr", dir);
    FILE *f = fopen(ckpt, "w");
    cr_assert_not_null(f);
    fputs("MCPTCKPT", f); /* what checkpoint_is_one looks at */
    cr_assert_eq(fclose(f), 0);
    const char *args[] = {TINY, "--spp", "1", "-o", out, "--checkpoint", ckpt, "--quiet", NULL};
    cr_assert_eq(run(args, err, sizeof err), 2, "%s", err);
    snprintf(want, sizeof want, " --resume %s', or discard it with --restart\n", ckpt);
    size_t n_err = strlen(err), n_want = strlen(want);
    cr_assert(n_err > n_want && strcmp(err + n_err - n_want, want) == 0, "%s", err);
    cr_assert(test_exists(ckpt) && !test_exists(out));
}

/* ---- a full disk, kill -9: the image and its preview stay a pair ---- */

/* Mounts a tmpfs of size_kib at dir (made here); false when this process may not mount. */
static bool mount_tmpfs(const char *dir, int size_kib)
{
    char cmd[700];
    cr_assert(mkdir(dir, 0755) == 0 || errno == EEXIST);
    snprintf(cmd, sizeof cmd, "mount -t tmpfs -o size=%dk tmpfs '%s' 2>/dev/null", size_kib, dir);
    return system(cmd) == 0;
}

static void umount_tmpfs(const char *dir)
{
    char cmd[700];
    snprintf(cmd, sizeof cmd, "umount '%s'", dir);
    cr_assert_eq(system(cmd), 0);
}

/* Bytes of the file at path, in whole pages of the filesystem at dir. */
static long long pages_bytes(const char *path, long block)
{
    struct stat st;
    cr_assert_eq(stat(path, &st), 0, "%s", path);
    return (st.st_size + block - 1) / block * block;
}

/* Fills the filesystem at dir with the file fill until exactly room bytes are free. */
static void leave_free(const char *dir, const char *fill, long long room)
{
    struct statvfs sv;
    cr_assert_eq(statvfs(dir, &sv), 0);
    long long free_bytes = (long long)sv.f_bavail * (long long)sv.f_frsize;
    cr_assert_geq(free_bytes, room, "only %lld bytes free", free_bytes);
    FILE *f = fopen(fill, "wb");
    cr_assert_not_null(f);
    static char zeros[4096];
    for (long long n = free_bytes - room; n > 0; n -= (long long)sizeof zeros)
        cr_assert_eq(fwrite(zeros, 1, n < (long long)sizeof zeros ? (size_t)n : sizeof zeros, f),
                     n < (long long)sizeof zeros ? (size_t)n : sizeof zeros);
    cr_assert_eq(fclose(f), 0);
    cr_assert_eq(statvfs(dir, &sv), 0);
    cr_assert_eq((long long)sv.f_bavail * (long long)sv.f_frsize, room);
}

/* No file of the pattern "<anything>.tmp.<pid>.<n>" is left in dir. */
static void assert_no_temporaries(const char *dir)
{
    char cmd[600], out[4096];
    snprintf(cmd, sizeof cmd, "%s/ls.txt", tmpdir);
    char ls[700];
    snprintf(ls, sizeof ls, "ls -a '%s' | grep '\\.tmp\\.' > '%s'", dir, cmd);
    cr_assert_neq(system(ls), -1);
    test_read_file(cmd, out, sizeof out);
    cr_assert_str_eq(out, "", "temporaries left in %s: %s", dir, out);
}

/* A disk that holds the new image but not its preview: exit 1 with a message saying exactly
 * what was written (the new image, and the old preview removed, as it showed the old image);
 * a disk that holds neither: exit 1, the old pair untouched.  No temporary is left in either
 * case.  A tmpfs of 1 MiB is the disk; skipped, saying so, where this process may not mount. */
Test(diskfull, image_and_preview_stay_a_pair, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(120))
{
    char mnt[300], out[320], png[320], fill[320], new_exr[300], new_png[300], old_exr[300],
        old_png[300], err[4096];
    snprintf(mnt, sizeof mnt, "%s/disk", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", mnt);
    snprintf(png, sizeof png, "%s/out.png", mnt);
    snprintf(fill, sizeof fill, "%s/fill", mnt);
    snprintf(new_exr, sizeof new_exr, "%s/new.exr", tmpdir);
    snprintf(new_png, sizeof new_png, "%s/new.png", tmpdir);
    snprintf(old_exr, sizeof old_exr, "%s/old.exr", tmpdir);
    snprintf(old_png, sizeof old_png, "%s/old.png", tmpdir);
    if (!mount_tmpfs(mnt, 1024))
        cr_skip_test("cannot mount a tmpfs here (not root?): disk-full cases not run");
    /* the old pair on the small disk, a copy of it, and the new pair's sizes, off it */
    const char *mk_old[] = {SMALL,    "--width", "96", "--height", "64",      "--spp", "2",
                            "--seed", "1",       "-o", out,        "--quiet", NULL};
    const char *mk_new[] = {SMALL,    "--width", "96", "--height", "64",      "--spp", "2",
                            "--seed", "2",       "-o", new_exr,    "--quiet", NULL};
    cr_assert_eq(run(mk_old, err, sizeof err), 0, "%s", err);
    cr_assert_eq(run(mk_new, err, sizeof err), 0, "%s", err);
    copy_file(out, old_exr);
    copy_file(png, old_png);
    struct statvfs sv;
    cr_assert_eq(statvfs(mnt, &sv), 0);
    long block = (long)sv.f_frsize;
    long long exr_bytes = pages_bytes(new_exr, block), png_bytes = pages_bytes(new_png, block);

    /* room for the new image and all but a page of its preview */
    leave_free(mnt, fill, exr_bytes + png_bytes - block);
    const char *again[] = {SMALL,    "--width", "96", "--height", "64",      "--spp", "2",
                           "--seed", "2",       "-o", out,        "--quiet", NULL};
    int rc = run(again, err, sizeof err);
    char want[1000];
    snprintf(want, sizeof want,
             "%s: error: cannot write: No space left on device (the image %s was written; the "
             "old preview was removed, as it showed an older image)\n",
             png, out);
    cr_assert_eq(rc, 1, "exit %d: %s", rc, err);
    cr_assert_str_eq(err, want);
    cr_assert(same_pixels(out, new_exr), "the image is not the new one");
    cr_assert_not(test_exists(png), "the old preview is still beside the new image");
    assert_no_temporaries(mnt);

    /* room for neither: the old pair stays */
    copy_file(old_exr, out);
    copy_file(old_png, png);
    unlink(fill);
    leave_free(mnt, fill, exr_bytes - block);
    rc = run(again, err, sizeof err);
    cr_assert_eq(rc, 1, "exit %d: %s", rc, err);
    snprintf(want, sizeof want, "%s: error: cannot write", out);
    cr_assert(strncmp(err, want, strlen(want)) == 0, "%s", err);
    cr_assert(same_bytes(out, old_exr) && same_bytes(png, old_png), "the old pair changed");
    assert_no_temporaries(mnt);
    umount_tmpfs(mnt);
}

/* Whether the files at a and b have the same bytes (cmp). */
static bool files_equal(const char *a, const char *b)
{
    char cmd[800];
    snprintf(cmd, sizeof cmd, "cmp -s '%s' '%s'", a, b);
    return system(cmd) == 0;
}

/* Sets the times of every "*.tmp.*" file in dir to ago_s seconds ago; returns how many. */
static int age_temporaries(const char *dir, int ago_s)
{
    DIR *d = opendir(dir);
    cr_assert_not_null(d);
    int n = 0;
    for (struct dirent *e; (e = readdir(d));) {
        if (!strstr(e->d_name, ".tmp."))
            continue;
        char path[600];
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        struct timespec times[2];
        clock_gettime(CLOCK_REALTIME, &times[0]);
        times[0].tv_sec -= ago_s;
        times[1] = times[0];
        cr_assert_eq(utimensat(AT_FDCWD, path, times, 0), 0);
        n++;
    }
    closedir(d);
    return n;
}

/* kill -9 while the preview is being written (its temporary has just appeared beside the
 * image's): the image and its preview are still a pair, both old or both new, never the new
 * image beside the old preview.  Killed with the old pair, both of the new pair's temporaries are left; the next run
 * removes them (here aged past FILE_STALE_S, as a later run would find them) and writes the
 * pair.  The kill races the write: on a loaded machine the test can be descheduled between
 * seeing the temporary and the kill while mcpt renames both, so a new pair is a legitimate
 * outcome; such an attempt is repeated (with the old pair restored), up to three times. */
Test(kill9, during_the_preview_leaves_a_pair, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(180))
{
    char out[300], png[300], new_exr[300], new_png[300], old_exr[300], old_png[300], err[4096];
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(png, sizeof png, "%s/out.png", tmpdir);
    snprintf(new_exr, sizeof new_exr, "%s/new/out.exr", tmpdir);
    snprintf(new_png, sizeof new_png, "%s/new/out.png", tmpdir);
    snprintf(old_exr, sizeof old_exr, "%s/old.exr", tmpdir);
    snprintf(old_png, sizeof old_png, "%s/old.png", tmpdir);
    char new_dir[300];
    snprintf(new_dir, sizeof new_dir, "%s/new", tmpdir);
    cr_assert_eq(mkdir(new_dir, 0755), 0);
    const char *mk_old[] = {SMALL,    "--width", "1200", "--height", "1200",    "--spp", "1",
                            "--seed", "1",       "-o",   out,        "--quiet", NULL};
    const char *mk_new[] = {SMALL,    "--width", "1200", "--height", "1200",    "--spp", "1",
                            "--seed", "2",       "-o",   new_exr,    "--quiet", NULL};
    cr_assert_eq(run(mk_old, err, sizeof err), 0, "%s", err);
    cr_assert_eq(run(mk_new, err, sizeof err), 0, "%s", err);
    cr_assert_not(same_pixels(out, new_exr), "seeds 1 and 2 gave one image");
    char save[1300], restore[1300];
    snprintf(save, sizeof save, "cp '%s' '%s' && cp '%s' '%s'", out, old_exr, png, old_png);
    snprintf(restore, sizeof restore, "cp '%s' '%s' && cp '%s' '%s'", old_exr, out, old_png, png);
    cr_assert_eq(system(save), 0);

    const char *again[] = {SMALL,    "--width", "1200", "--height", "1200",    "--spp", "1",
                           "--seed", "2",       "-o",   out,        "--quiet", NULL};
    bool is_mid_write = false; /* killed mid-preview with the old pair in place */
    for (int attempt = 1; attempt <= 3 && !is_mid_write; attempt++) {
        cr_assert_eq(system(restore), 0);
        pid_t pid = test_start_mcpt(again, NULL, NULL, ALARM_S);
        bool caught = false;
        for (int k = 0; k < 20000 && !caught; k++) { /* up to about 20 s */
            /* both temporaries at once: the pair is being written.  The preview's alone is
             * also made at the start, where mcpt checks that it can create each output (an
             * empty temporary, removed at once), and a kill there leaves that one alone. */
            bool has_exr_tmp = false, has_png_tmp = false;
            DIR *d = opendir(tmpdir);
            for (struct dirent *e; d && (e = readdir(d));) {
                has_exr_tmp |= strncmp(e->d_name, "out.exr.tmp.", 12) == 0;
                has_png_tmp |= strncmp(e->d_name, "out.png.tmp.", 12) == 0;
            }
            closedir(d);
            caught = has_exr_tmp && has_png_tmp;
            if (!caught)
                nanosleep(&(struct timespec){0, 1000 * 1000}, NULL);
        }
        kill(pid, SIGKILL);
        cr_assert_eq(test_wait(pid), 128 + SIGKILL);
        bool is_old = files_equal(out, old_exr) && files_equal(png, old_png);
        bool is_new = same_pixels(out, new_exr) && files_equal(png, new_png);
        cr_assert(is_old || is_new, "attempt %d: a mismatched pair after kill -9 (caught: %d)",
                  attempt, caught);
        int n_tmp = age_temporaries(tmpdir, 60);
        cr_log_info("attempt %d: kill -9 %s the preview appeared: the %s pair, %d temporaries",
                    attempt, caught ? "after" : "before", is_old ? "old" : "new", n_tmp);
        if (is_new)
            cr_assert_eq(n_tmp, 0, "attempt %d: the new pair, yet %d temporaries", attempt, n_tmp);
        else if (caught)
            cr_assert_geq(n_tmp, 2,
                          "attempt %d: the old pair, yet %d temporaries (want the "
                          "image's and the preview's)",
                          attempt, n_tmp);
        is_mid_write = caught && is_old;
    }
    cr_assert_eq(run(again, err, sizeof err), 0, "%s", err);
    assert_no_temporaries(tmpdir);
    cr_assert(same_pixels(out, new_exr) && files_equal(png, new_png));
}

/* A memory limit (ulimit -v 1 GiB) that holds the film (748 MiB) but not the film and the
 * writing of its image (341 MiB more): refused before the render, within a second, with a
 * message giving the sizes; before, it rendered, then failed "out of memory writing the
 * image".  A sanitizer build cannot run under such a limit: skipped then, saying so. */
Test(late, memory_limit_fails_before_the_render, .init = setup, .fini = teardown)
{
    char out[300], err[4096];
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    struct rlimit old_lim, lim;
    cr_assert_eq(getrlimit(RLIMIT_AS, &old_lim), 0);
    lim = old_lim;
    lim.rlim_cur = (rlim_t)1 << 30;
    cr_assert_eq(setrlimit(RLIMIT_AS, &lim), 0);
    const char *version[] = {"--version", NULL};
    int rc_version = run(version, err, sizeof err);
    const char *args[] = {SMALL, "--width",   "3500", "--height", "3500", "--spp",
                          "1",   "--threads", "2",    "-o",       out,    NULL};
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    int rc = rc_version == 0 ? run(args, err, sizeof err) : -1;
    clock_gettime(CLOCK_MONOTONIC, &t1);
    cr_assert_eq(setrlimit(RLIMIT_AS, &old_lim), 0);
    if (rc_version != 0)
        cr_skip_test("mcpt does not start under a 1 GiB address-space limit (a sanitizer "
                     "build?): memory-limit case not run");
    double dt = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
    cr_assert_eq(rc, 2, "exit %d: %s", rc, err);
    const char *want = SMALL ": error: expected a render that fits in this process's memory limit";
    cr_assert(strncmp(err, want, strlen(want)) == 0 && strstr(err, "got a 3500x3500 film needing"),
              "%s", err);
    cr_assert_lt(dt, 5.0, "took %.1f s: it rendered first", dt);
    cr_assert_not(test_exists(out));
}

/* The film, 6500x6500 (2579 MiB), under `ulimit -v` in a shell: at 3 GiB the film fits
 * but writing its image (1147 MiB more) does not, so the run is refused before the render, in
 * well under a second.  (At 4 GiB both fit now, as the image's planes and the preview's are
 * freed in turn: that run renders and writes its pair.) */
Test(late, ulimit_v_6500_square_fails_before_the_render, .init = setup, .fini = teardown)
{
    char out[300], err_path[300], cmd[1200], err[4096];
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    const char *bin = getenv("MCPT") ? getenv("MCPT") : "./mcpt";
    snprintf(cmd, sizeof cmd,
             "ulimit -v %d && '%s' --version >/dev/null 2>&1 || exit 99; ulimit -v %d && exec '%s' "
             "%s --width 6500 --height 6500 --spp 1 -o '%s' 2>'%s'",
             3 << 20, bin, 3 << 20, bin, SMALL, out, err_path);
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    int status = system(cmd);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    int rc = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    if (rc == 99)
        cr_skip_test("mcpt does not start under ulimit -v 3 GiB (a sanitizer build?): not run");
    test_read_file(err_path, err, sizeof err);
    double dt = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
    cr_assert_eq(rc, 2, "exit %d: %s", rc, err);
    const char *want = SMALL ": error: expected a render that fits in this process's memory limit";
    cr_assert(strncmp(err, want, strlen(want)) == 0 && strstr(err, "got a 6500x6500 film needing"),
              "%s", err);
    cr_assert_lt(dt, 5.0, "took %.1f s: it rendered first", dt);
    cr_assert_not(test_exists(out));
}

/* ---- lose at most a minute of work ---- */

/* The inode of path, or 0 when it does not exist: a checkpoint is renamed into place whole, so
 * each new one has a new inode. */
static unsigned long long inode_of(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 ? (unsigned long long)st.st_ino : 0;
}

/* --checkpoint-every: a render killed by SIGKILL (nothing can catch it: the OOM killer, a power
 * cut, scancel --signal=KILL) after its third periodic checkpoint resumes from the last one to
 * the very image an uninterrupted run gives, bit for bit (on another thread count), and the
 * finished render removes the checkpoint.  A kill that lands in a checkpoint's write leaves its
 * temporary, aged here as a later run would find it.  A render that ends before the kill (a
 * test descheduled on a loaded machine) has written the whole image: tried again, up to three
 * times. */
Test(kill9, periodic_checkpoints_resume_bit_identical, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(240))
{
    char full[300], out[300], ckpt[320], err[4096];
    snprintf(full, sizeof full, "%s/full.exr", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(ckpt, sizeof ckpt, "%s.ckpt", out);
    const char *a_full[] = {SMALL, "--spp",   "8192", "--threads", "1", "--checkpoint-every",
                            "0",   "--quiet", "-o",   full,        NULL};
    cr_assert_eq(run(a_full, err, sizeof err), 0, "%s", err);
    const char *a_run[] = {SMALL, "--spp",   "8192", "--threads", "2", "--checkpoint-every",
                           "0.2", "--quiet", "-o",   out,         NULL};
    bool is_killed = false; /* killed mid-render, after three periodic checkpoints */
    for (int attempt = 1; attempt <= 3 && !is_killed; attempt++) {
        pid_t pid = test_start_mcpt(a_run, NULL, NULL, 120);
        int n_seen = 0;
        unsigned long long last = 0;
        while (n_seen < 3 && !test_has_ended(pid)) {
            unsigned long long ino = inode_of(ckpt);
            if (ino && ino != last) {
                n_seen++;
                last = ino;
            }
            nanosleep(&(struct timespec){0, 1000 * 1000}, NULL);
        }
        kill(pid, SIGKILL);
        int rc = test_wait(pid);
        is_killed = rc == 128 + SIGKILL && !test_exists(out);
        if (!is_killed) { /* the render ended first: its image is whole */
            cr_log_info("attempt %d: the render ended before the kill (exit %d)", attempt, rc);
            cr_assert(rc == 0 || rc == 128 + SIGKILL, "exit %d", rc);
            cr_assert(same_pixels(out, full), "the finished image differs");
            cr_assert_eq(unlink(out), 0);
            unlink(ckpt); /* there when killed between the image's write and its removal */
            continue;
        }
        cr_assert_eq(n_seen, 3, "saw %d periodic checkpoints", n_seen);
    }
    cr_assert(is_killed, "the render ended before each of three kills: make it longer");
    age_temporaries(tmpdir, 60);
    const char *a_resume[] = {"--resume", ckpt, "--threads", "2", "--quiet", NULL};
    cr_assert_eq(run(a_resume, err, sizeof err), 0, "%s", err);
    cr_assert(same_pixels(out, full), "the resumed image differs from the uninterrupted one");
    cr_assert_not(test_exists(ckpt), "the finished render left its checkpoint");
    assert_no_temporaries(tmpdir);
}

/* A render that ends normally leaves no periodic checkpoint behind, and one whose checkpoint
 * cannot be written (its folder taken away mid-render) warns once and goes on to its image.
 * The folder is renamed away, at once for mcpt, then removed: an `rm -rf` of it could meet a
 * temporary created after its listing and fail.  Its taking away races the render's end: a
 * render whose last checkpoint was due before it (a test descheduled on a loaded machine)
 * warns of nothing; tried again, up to three times. */
Test(kill9, periodic_checkpoint_failure_is_a_warning, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(120))
{
    char dir[300], gone[300], out[300], ckpt[340], err_path[300], cmd[400], err[4096];
    snprintf(dir, sizeof dir, "%s/ck", tmpdir);
    snprintf(gone, sizeof gone, "%s/gone", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(ckpt, sizeof ckpt, "%s/c.ckpt", dir);
    snprintf(err_path, sizeof err_path, "%s/stderr-ck.txt", tmpdir);
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", gone);
    const char *args[] = {SMALL, "--spp",        "4096", "--threads", "2", "--checkpoint-every",
                          "0.1", "--checkpoint", ckpt,   "-o",        out, NULL};
    const char *warning = NULL;
    for (int attempt = 1; attempt <= 3 && !warning; attempt++) {
        cr_assert_eq(mkdir(dir, 0755), 0);
        pid_t pid = test_start_mcpt(args, NULL, err_path, 120);
        while (!test_exists(ckpt) && !test_has_ended(pid))
            nanosleep(&(struct timespec){0, 1000 * 1000}, NULL);
        bool has_checkpoint = test_exists(ckpt);
        cr_assert_eq(rename(dir, gone), 0);
        cr_assert_eq(system(cmd), 0);
        int rc = test_wait(pid);
        test_read_file(err_path, err, sizeof err);
        cr_assert_eq(rc, 0, "exit %d: %s", rc, err);
        cr_assert(test_exists(out));
        warning = strstr(err, ": warning: cannot write: No such file or directory");
        cr_assert(!strstr(err, ": warning: ") || (warning && !strstr(warning + 1, ": warning: ")),
                  "want at most one warning, got: %s", err);
        if (!warning)
            cr_log_info("attempt %d: the render ended %s", attempt,
                        has_checkpoint ? "before another checkpoint was due"
                                       : "before its first checkpoint was seen");
    }
    cr_assert(warning, "want one warning in three attempts, got: %s", err);
}

/* ---- trusting a checkpoint ---- */

/* A checkpoint names its scene by the bytes of the scene file and of every mesh and MTL file
 * it loads: resuming after the MTL was edited is refused (an image of two scenes, otherwise),
 * and accepted again once the MTL is as it was: the resume renders and replaces the checkpoint
 * with one of its own, a state waited for, where a fixed wait was a guess at how long a
 * refusal takes. */
Test(trust, checkpoint_notices_an_edited_mtl, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(120))
{
    char scene[300], obj[300], mtl[300], out[300], ckpt[320], err[4096];
    snprintf(scene, sizeof scene, "%s/mesh.txt", tmpdir);
    snprintf(obj, sizeof obj, "%s/m.obj", tmpdir);
    snprintf(mtl, sizeof mtl, "%s/m.mtl", tmpdir);
    snprintf(out, sizeof out, "%s/out.exr", tmpdir);
    snprintf(ckpt, sizeof ckpt, "%s.ckpt", out);
    FILE *f = fopen(obj, "w");
    fputs("mtllib m.mtl\nv -1 0 -1\nv 1 0 -1\nv 0 0 1\nusemtl w\nf 1 2 3\n", f);
    fclose(f);
    f = fopen(mtl, "w");
    fputs("newmtl w\nKd 0.5 0.5 0.5\n", f);
    fclose(f);
    f = fopen(scene, "w");
    fputs("camera eye=0,1,3 look-at=0,0,0 up=0,1,0 fov=45\nfilm width=16 height=12\n"
          "sky type=constant radiance=1,1,1\nmesh file=m.obj\n",
          f);
    fclose(f);
    const char *args[] = {scene, "--spp", "1000000", "--checkpoint-every", "0.1", "-o", out, NULL};
    pid_t pid = test_start_mcpt(args, NULL, NULL, 120);
    while (!test_exists(ckpt) && !test_has_ended(pid))
        nanosleep(&(struct timespec){0, 1000 * 1000}, NULL);
    kill(pid, SIGKILL);
    test_wait(pid);
    cr_assert(test_exists(ckpt), "no periodic checkpoint");
    f = fopen(mtl, "a");
    fputs("# edited\n", f);
    fclose(f);
    const char *resume[] = {"--resume", ckpt, NULL};
    int rc = run(resume, err, sizeof err);
    cr_assert_eq(rc, 2, "exit %d: %s", rc, err);
    cr_assert(strstr(err, "error: expected the scene the checkpoint was made from") &&
                  strstr(err, "(the scene, or a mesh or MTL file it loads, changed)"),
              "%s", err);
    f = fopen(mtl, "w"); /* as it was: the resume starts */
    fputs("newmtl w\nKd 0.5 0.5 0.5\n", f);
    fclose(f);
    char err_path[300];
    snprintf(err_path, sizeof err_path, "%s/stderr-resume.txt", tmpdir);
    unsigned long long ino = inode_of(ckpt);
    pid = test_start_mcpt(resume, NULL, err_path, 120);
    while (inode_of(ckpt) == ino && !test_has_ended(pid)) /* a checkpoint of its own: rendering */
        nanosleep(&(struct timespec){0, 1000 * 1000}, NULL);
    bool has_ended = test_has_ended(pid);
    kill(pid, SIGKILL);
    rc = test_wait(pid);
    test_read_file(err_path, err, sizeof err);
    cr_assert_not(has_ended, "the resume ended (exit %d) before a checkpoint of its own: %s", rc,
                  err);
}
