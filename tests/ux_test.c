/* tests/ux_test.c - a new user's first hour (issue 14), through the binary ($MCPT) and the
 * scripts as a user meets them: setup.sh installs what `make test` runs and skips a fresh
 * render; skipped tests are listed with their reasons; the progress line fits 80 and 60
 * columns on a pty and in tmux; -o picks the format by its extension; mcpt convert with its
 * tone curves; --scale and --width alone keep the framing; the EXR header (chromaticities and
 * mcpt's attributes, also as exrheader reads them); make install / uninstall with DESTDIR; a
 * scene from standard input; --no-preview; mcpt merge writing a plain EXR for a whole set. */
#include <criterion/criterion.h>

#include <limits.h>
#include <png.h>
#include <pty.h>
#include <stdarg.h>

#include "image.h"
#include "test_util.h"

static char tmpdir[256];

static void setup(void) { test_make_dir(tmpdir, sizeof tmpdir, "ux"); }
static void teardown(void) { test_remove_dir(tmpdir); }

/* The binary under test as an absolute path, for commands run from another folder. */
static const char *mcpt_abs(void)
{
    static char path[PATH_MAX];
    const char *bin = getenv("MCPT") ? getenv("MCPT") : "./mcpt";
    cr_assert_not_null(realpath(bin, path), "no binary at %s", bin);
    return path;
}

/* Runs a shell command (printf-style); returns its exit status. */
static int shell(const char *fmt, ...)
{
    char cmd[4096];
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(cmd, sizeof cmd, fmt, ap);
    va_end(ap);
    cr_assert(n > 0 && (size_t)n < sizeof cmd, "command too long");
    int status = system(cmd);
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128;
}

/* tmpdir/name into buf. */
static const char *scratch(char *buf, size_t buf_bytes, const char *name)
{
    snprintf(buf, buf_bytes, "%s/%s", tmpdir, name);
    return buf;
}

static int count_lines(const char *s)
{
    int n = 0;
    for (; *s; s++)
        n += *s == '\n';
    return n;
}

/* The repository's root: the suite runs from there. */
static const char *repo_root(void)
{
    static char path[PATH_MAX];
    cr_assert_not_null(getcwd(path, sizeof path));
    return path;
}

/* Whether a program is on the PATH. */
static bool has_program(const char *name) { return shell("command -v %s >/dev/null", name) == 0; }

/* Reads an 8-bit RGB PNG (libpng's simplified API); the caller frees the pixels. */
static uint8_t *read_png(const char *path, int *w, int *h)
{
    png_image im;
    memset(&im, 0, sizeof im);
    im.version = PNG_IMAGE_VERSION;
    cr_assert(png_image_begin_read_from_file(&im, path), "%s: %s", path, im.message);
    im.format = PNG_FORMAT_RGB;
    uint8_t *buf = malloc(PNG_IMAGE_SIZE(im));
    cr_assert_not_null(buf);
    cr_assert(png_image_finish_read(&im, NULL, buf, 0, NULL), "%s: %s", path, im.message);
    *w = (int)im.width;
    *h = (int)im.height;
    return buf;
}

/* ---- item 1: setup.sh installs what make test runs; skips are listed ---- */

/* The package list of setup.sh holds what the suite builds with and the programs it runs
 * (parallel, tmux, exrheader), and .ci/run takes its list from setup.sh, so the two agree. */
Test(ux, setup_installs_what_make_test_runs, .init = setup, .fini = teardown)
{
    char path[300], list[1024], ci[8192];
    cr_assert_eq(shell("sh scripts/setup.sh --packages > %s", scratch(path, sizeof path, "p")), 0);
    test_read_file(path, list, sizeof list);
    /* build: compiler, make, pkg-config, libraries; test: Criterion and the three programs */
    const char *need[] = {"gcc",
                          "make",
                          "pkg-config",
                          "libc6-dev",
                          "libopenexr-dev",
                          "libpng-dev",
                          "libcriterion-dev",
                          "parallel",
                          "tmux",
                          "openexr"};
    for (size_t i = 0; i < sizeof need / sizeof need[0]; i++) {
        char word[64];
        snprintf(word, sizeof word, " %s ", need[i]);
        char padded[1100];
        snprintf(padded, sizeof padded, " %.*s ", (int)strcspn(list, "\n"), list);
        cr_assert(strstr(padded, word), "setup.sh --packages lacks %s: %s", need[i], list);
    }
    cr_assert(test_read_file(".ci/run", ci, sizeof ci) > 0);
    cr_assert(strstr(ci, "PKGS=\"$(sh scripts/setup.sh --packages)\""),
              ".ci/run does not take setup.sh's list");
}

/* Runs only when ux_probe_skips is set: the probe the next test starts. */
Test(ux_probe, skips_when_asked)
{
    if (getenv("MCPT_UX_PROBE_SKIP"))
        cr_skip_test("asked to by MCPT_UX_PROBE_SKIP (tests/ux_test.c's probe of the skip list)");
}

/* A skipped test is listed at the end of the run with its reason (tests/report.c), and the
 * count of skipped tests follows; without skips the count is 0. */
Test(ux, skipped_tests_are_listed_with_their_reason, .init = setup, .fini = teardown)
{
    char self[PATH_MAX], err_path[300], text[4096];
    ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
    cr_assert(n > 0);
    self[n] = '\0';
    scratch(err_path, sizeof err_path, "stderr.txt");
    /* env -u BXFI_MAP: Criterion runs this test in a worker that BoxFort marks with it, and the
     * inner run would take itself for one */
    int rc = shell("env -u BXFI_MAP MCPT_UX_PROBE_SKIP=1 '%s' --filter 'ux_probe/*' 2>%s", self,
                   err_path);
    test_read_file(err_path, text, sizeof text);
    cr_assert_eq(rc, 0, "%s: %s", self, text);
    cr_assert(strstr(text, "[SKIP] ux_probe::skips_when_asked: asked to by MCPT_UX_PROBE_SKIP "
                           "(tests/ux_test.c's probe of the skip list)\n"),
              "%s", text);
    cr_assert(strstr(text, "[====] Skipped: 1 of 1 tests (listed above, each with its reason); "),
              "%s", text);
    cr_assert(strstr(text, " not selected (--filter, or disabled)\n"), "%s", text);
    cr_assert_eq(shell("env -u BXFI_MAP '%s' --filter 'ux_probe/*' 2>%s", self, err_path), 0);
    test_read_file(err_path, text, sizeof text);
    cr_assert(strstr(text, "[====] Skipped: 0 of 1 tests; "), "%s", text);
}

/* setup.sh --render renders when the image is missing or older than the binary or the scene,
 * and skips the render otherwise.  The binary is a wrapper that logs each call and renders
 * with the real mcpt at 16x16, 1 spp. */
Test(ux, setup_skips_a_fresh_render, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(120))
{
    cr_assert_eq(shell("cd %s && mkdir -p scripts scenes/models && cp '%s/scripts/setup.sh' "
                       "scripts/ && cp '%s/scenes/cornell-box.txt' scenes/ && "
                       "cp '%s'/scenes/models/CornellBox-Original.* scenes/models/",
                       tmpdir, repo_root(), repo_root(), repo_root()),
                 0);
    char path[300], log[1024];
    FILE *f = fopen(scratch(path, sizeof path, "mcpt"), "w");
    cr_assert_not_null(f);
    fprintf(f,
            "#!/bin/sh\necho render >> calls.log\nexec '%s' \"$@\" --width 16 --height 16 "
            "--spp 1 --quiet\n",
            mcpt_abs());
    fclose(f);
    cr_assert_eq(chmod(path, 0755), 0);
    const char *run = "cd %s && sh scripts/setup.sh --render > setup.out";
    cr_assert_eq(shell(run, tmpdir), 0);
    cr_assert(test_exists(scratch(path, sizeof path, "cornell-box.exr")));
    cr_assert(test_exists(scratch(path, sizeof path, "cornell-box.png")));
    cr_assert_eq(shell(run, tmpdir), 0); /* fresh: skipped */
    test_read_file(scratch(path, sizeof path, "calls.log"), log, sizeof log);
    cr_assert_str_eq(log, "render\n");
    test_read_file(scratch(path, sizeof path, "setup.out"), log, sizeof log);
    cr_assert(strstr(log, "not rendered again"), "%s", log);
    /* a scene newer than the image: rendered again (touch -d: later than the image's time) */
    cr_assert_eq(shell("cd %s && touch -d '+2 seconds' scenes/cornell-box.txt", tmpdir), 0);
    cr_assert_eq(shell(run, tmpdir), 0);
    test_read_file(scratch(path, sizeof path, "calls.log"), log, sizeof log);
    cr_assert_str_eq(log, "render\nrender\n");
}

/* ---- item 2: the progress line fits the terminal ---- */

/* What a terminal `columns` wide (autowrap on, as terminals start) makes of the bytes mcpt wrote
 * to it: how often the cursor wrapped to a new row by itself, the line feeds, the redraws
 * (carriage returns), the widest row written, and the last row of text. */
struct screen {
    int n_wraps;
    int n_newlines;
    int n_redraws;
    int max_col;
    char last[512];
};

static void emulate(const char *bytes, size_t n, int columns, struct screen *s)
{
    memset(s, 0, sizeof *s);
    char row[512] = ""; /* the text of the cursor's row */
    int col = 0;
    for (size_t i = 0; i < n; i++) {
        char c = bytes[i];
        cr_assert(c != '\033', "an escape sequence in the progress output");
        if (c == '\r') {
            s->n_redraws++;
            col = 0;
        } else if (c == '\n') { /* the row is done: keep it, start an empty one */
            s->n_newlines++;
            if (row[0])
                snprintf(s->last, sizeof s->last, "%s", row);
            memset(row, 0, sizeof row);
            col = 0;
        } else {
            if (col == columns) { /* the cursor sits past the last column: autowrap */
                s->n_wraps++;
                memset(row, 0, sizeof row);
                col = 0;
            }
            if (col < (int)sizeof row - 1)
                row[col] = c;
            col++;
            s->max_col = col > s->max_col ? col : s->max_col;
        }
    }
    if (row[0])
        snprintf(s->last, sizeof s->last, "%s", row);
}

/* Renders on a pty of the given width (stderr only; stdout to a file) and returns what the
 * terminal would show. */
static void render_on_pty(int columns, struct screen *s)
{
    struct winsize ws = {.ws_row = 24, .ws_col = (unsigned short)columns};
    int master, slave;
    cr_assert_eq(openpty(&master, &slave, NULL, NULL, &ws), 0);
    char out[300];
    scratch(out, sizeof out, "pty.exr");
    pid_t pid = fork();
    cr_assert(pid >= 0);
    if (pid == 0) {
        int null_fd = open("/dev/null", O_WRONLY);
        if (null_fd < 0 || dup2(null_fd, 1) < 0 || dup2(slave, 2) < 0)
            _exit(127);
        close(master);
        alarm(TEST_TIMEOUT_S(60)); /* a hang cap, like test_start_mcpt's */
        execl(mcpt_abs(), "mcpt", "tests/data/cli/tiny.txt", "--width", "64", "--spp", "256",
              "--threads", "1", "-o", out, (char *)NULL);
        _exit(127);
    }
    close(slave);
    static char bytes[1 << 20];
    size_t n = 0;
    for (;;) {
        ssize_t r = read(master, bytes + n, sizeof bytes - 1 - n);
        if (r <= 0) /* EIO once the child has closed the pty */
            break;
        n += (size_t)r;
    }
    close(master);
    cr_assert_eq(test_wait(pid), 0);
    emulate(bytes, n, columns, s);
}

/* On a pty 80, 60, 40 or 24 columns wide the bar is redrawn in place: no line reaches the last
 * column (so none wraps or scrolls), one line feed ends it, and the fields that fit are there:
 * elapsed time and ETA at 80 and 60, the speed at 80; percent always. */
Test(ux, progress_line_fits_80_and_60_columns_on_a_pty, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(120))
{
    const int widths[] = {80, 60, 40, 24};
    for (size_t i = 0; i < sizeof widths / sizeof widths[0]; i++) {
        int w = widths[i];
        struct screen s;
        render_on_pty(w, &s);
        cr_assert_eq(s.n_wraps, 0, "%d columns: %d wraps", w, s.n_wraps);
        cr_assert_leq(s.max_col, w - 1, "%d columns: a line of %d", w, s.max_col);
        cr_assert_eq(s.n_newlines, 1, "%d columns: %d line feeds", w, s.n_newlines);
        /* trace_render reports every 100 ms and at the end; the render takes about 1 s here */
        cr_assert_geq(s.n_redraws, 2, "%d columns: %d redraws", w, s.n_redraws);
        cr_assert(strstr(s.last, "100.0%"), "%d columns: last line '%s'", w, s.last);
        if (w >= 60)
            cr_assert(strstr(s.last, "elapsed ") && strstr(s.last, "ETA "), "%d: '%s'", w, s.last);
        if (w >= 80)
            cr_assert(strstr(s.last, "Msamples/s") && s.last[0] == '[', "%d: '%s'", w, s.last);
    }
}

/* The same in a real terminal emulator (tmux) 80 and 60 columns wide: after the render the
 * screen holds one progress line, at 100%, and the shell's next line right below it. */
Test(ux, progress_line_fits_80_and_60_columns_in_tmux, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(120))
{
    if (!has_program("tmux"))
        cr_skip_test("tmux is not installed (Debian package tmux, which scripts/setup.sh "
                     "installs): the progress line was checked on a pty only");
    const int widths[] = {80, 60};
    for (size_t i = 0; i < 2; i++) {
        char sock[64], screen_path[300], screen[8192];
        snprintf(sock, sizeof sock, "mcpt-ux-%d-%d", (int)getpid(), widths[i]);
        scratch(screen_path, sizeof screen_path, "screen.txt");
        cr_assert_eq(shell("TERM=xterm tmux -L %s -f /dev/null new-session -d -x %d -y 12 "
                           "\"'%s' tests/data/cli/tiny.txt --width 64 --spp 256 --threads 1 -o "
                           "%s/t.exr >/dev/null; echo mcpt-exit=\\$?; sleep 60\"",
                           sock, widths[i], mcpt_abs(), tmpdir),
                     0);
        bool done = false;
        for (int k = 0; k < TEST_TIMEOUT_S(600) && !done; k++) { /* 60 s (scaled) at most */
            usleep(100000);
            shell("tmux -L %s capture-pane -p > %s", sock, screen_path);
            test_read_file(screen_path, screen, sizeof screen);
            done = strstr(screen, "mcpt-exit=") != NULL;
        }
        shell("tmux -L %s kill-server", sock);
        cr_assert(done, "%d columns: no exit within %d s: %s", widths[i], TEST_TIMEOUT_S(60),
                  screen);
        char *second = strchr(screen, '\n');
        cr_assert_not_null(second);
        *second++ = '\0';
        cr_assert(strstr(screen, "100.0%") && strstr(screen, "elapsed "), "%d columns: '%s'",
                  widths[i], screen);
        cr_assert((int)strlen(screen) <= widths[i] - 1, "%d columns: '%s'", widths[i], screen);
        cr_assert(strncmp(second, "mcpt-exit=0", 11) == 0,
                  "%d columns: the progress took more than one line: '%s' / '%s'", widths[i],
                  screen, second);
    }
}

/* ---- item 3: the output's format follows its name ---- */

/* -o x.png writes a PNG and nothing else (the same bytes as the preview of -o x.exr), and says
 * so; -o with any other extension exits 2 with one line and writes nothing. */
Test(ux, output_format_follows_the_extension, .init = setup, .fini = teardown)
{
    char dir[300], exr[340], png[340], png2[340], out_path[300], err_path[300], text[4096];
    scratch(dir, sizeof dir, "out");
    cr_assert_eq(mkdir(dir, 0755), 0);
    snprintf(exr, sizeof exr, "%s/a.exr", dir);
    snprintf(png, sizeof png, "%s/a.png", dir);
    snprintf(png2, sizeof png2, "%s/b.png", dir);
    scratch(out_path, sizeof out_path, "stdout.txt");
    scratch(err_path, sizeof err_path, "stderr.txt");
    const char *a[] = {"tests/data/cli/tiny.txt", "--spp", "3", "-o", exr, NULL};
    cr_assert_eq(test_run_mcpt(a, out_path, err_path, 60), 0);
    const char *b[] = {"tests/data/cli/tiny.txt", "--spp", "3", "-o", png2, NULL};
    cr_assert_eq(test_run_mcpt(b, out_path, err_path, 60), 0);
    test_read_file(out_path, text, sizeof text);
    cr_assert(strstr(text, "; wrote ") && strstr(text, "/b.png (8-bit sRGB only: -o OUT.exr "
                                                       "keeps the float image)\n"),
              "%s", text);
    cr_assert_eq(shell("cmp -s %s %s", png, png2), 0, "the PNG differs from the preview");
    char b_exr[340];
    snprintf(b_exr, sizeof b_exr, "%s/b.exr", dir);
    cr_assert_not(test_exists(b_exr));
    unsigned char sig[8] = {0};
    FILE *f = fopen(png2, "rb");
    cr_assert(f && fread(sig, 1, 8, f) == 8);
    fclose(f);
    cr_assert_eq(memcmp(sig, "\x89PNG\r\n\x1a\n", 8), 0);

    const char *names[] = {"c.jpg", "c", "c.exr.gz", ".png"};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
        char bad[340];
        snprintf(bad, sizeof bad, "%s/%s", dir, names[i]);
        const char *args[] = {"tests/data/cli/tiny.txt", "--spp", "1", "-o", bad, NULL};
        cr_assert_eq(test_run_mcpt(args, NULL, err_path, 60), 2, "%s", names[i]);
        test_read_file(err_path, text, sizeof text);
        cr_assert_eq(count_lines(text), 1, "%s", text);
        cr_assert(strncmp(text, "mcpt: error: expected an output name ending in .exr", 51) == 0,
                  "%s", text);
        cr_assert_not(test_exists(bad), "%s written", bad);
    }
    cr_assert_eq(shell("test $(ls %s | wc -l) -eq 3", dir), 0, "files beyond a.exr/.png, b.png");
}

/* ---- item 4: mcpt convert and the tone curves ---- */

/* mcpt convert writes, for every tone curve and a fractional exposure, exactly the bytes of
 * the sRGB encoding of image_tonemap_rgb(2^E v) (whose values are checked in image_test.c),
 * from an EXR with a ramp over [0, 16]; --tonemap on a render gives its preview the same. */
Test(ux, convert_applies_exposure_and_tone_curve, .init = setup, .fini = teardown)
{
    enum { W = 64, H = 2 };
    static float planes[3][W * H];
    struct image img = {.width = W, .height = H, .n_channels = 3};
    for (int i = 0; i < W * H; i++) {
        float v = 16.0f * (float)(i % W) / (W - 1) * (i < W ? 1.0f : 0.05f);
        planes[0][i] = v;
        planes[1][i] = 0.5f * v;
        planes[2][i] = 0.25f * v + 0.01f;
    }
    const char *names = "RGB";
    for (int c = 0; c < 3; c++) {
        img.names[c][0] = names[c];
        img.data[c] = planes[c];
    }
    char in[300], out[300], err_path[300], text[4096];
    struct mcpt_error err;
    cr_assert(image_write_exr(scratch(in, sizeof in, "in.exr"), &img, &err), "%s", err.msg);
    scratch(out, sizeof out, "out.png");
    scratch(err_path, sizeof err_path, "stderr.txt");
    struct image_srgb srgb;
    image_srgb_init(&srgb);
    const char *curves[] = {"clamp", "reinhard", "aces"};
    for (int t = 0; t < 3; t++) {
        const char *args[] = {"convert",   in,        out,       "--exposure", "0.5",
                              "--tonemap", curves[t], "--quiet", NULL};
        cr_assert_eq(test_run_mcpt(args, NULL, err_path, 60), 0, "%s", curves[t]);
        int w, h;
        uint8_t *px = read_png(out, &w, &h);
        cr_assert(w == W && h == H);
        enum image_tonemap kind;
        cr_assert(image_tonemap_parse(curves[t], &kind));
        for (int i = 0; i < W * H; i++) {
            double v[3], d[3];
            for (int c = 0; c < 3; c++)
                v[c] = planes[c][i] * exp2f(0.5f);
            image_tonemap_rgb(kind, v, d);
            for (int c = 0; c < 3; c++)
                cr_assert_eq(px[3 * i + c], image_srgb8(&srgb, d[c]), "%s pixel %d channel %d",
                             curves[t], i, c);
        }
        free(px);
    }
    /* bad uses: one line, exit 2 */
    const char *bad[][6] = {
        {"convert", in, NULL},
        {"convert", in, out, "--tonemap", "filmic", NULL},
        {"convert", in, "out.exr", NULL},
        {"convert", "tests/data/cli/tiny.txt", out, NULL},
    };
    const char *want[] = {
        "mcpt: error: expected two files, IN.exr and OUT.png, got 1 (see mcpt --help)\n",
        "mcpt: error: expected --tonemap to be clamp, reinhard or aces, got 'filmic' (see mcpt "
        "--help)\n",
        "mcpt: error: expected OUT to end in .png, got 'out.exr' (see mcpt --help)\n",
        NULL,
    };
    for (size_t i = 0; i < 4; i++) {
        cr_assert_eq(test_run_mcpt(bad[i], NULL, err_path, 60), 2, "case %zu", i);
        test_read_file(err_path, text, sizeof text);
        cr_assert_eq(count_lines(text), 1, "case %zu: %s", i, text);
        if (want[i])
            cr_assert_str_eq(text, want[i]);
    }
    /* a render's preview with --tonemap is the convert of its EXR with the same curve */
    char exr[300], png[300];
    scratch(exr, sizeof exr, "r.exr");
    scratch(png, sizeof png, "r.png");
    const char *r[] = {"tests/data/cli/tiny.txt",
                       "--spp",
                       "3",
                       "--tonemap",
                       "aces",
                       "--exposure",
                       "1",
                       "--quiet",
                       "-o",
                       exr,
                       NULL};
    cr_assert_eq(test_run_mcpt(r, NULL, err_path, 60), 0);
    const char *c[] = {"convert",    exr, out,       "--tonemap", "aces",
                       "--exposure", "1", "--quiet", NULL};
    cr_assert_eq(test_run_mcpt(c, NULL, err_path, 60), 0);
    cr_assert_eq(shell("cmp -s %s %s", png, out), 0);
}

/* ---- item 7: --scale, and --width alone ---- */

static void assert_film(const char *const *extra, int width, int height)
{
    char out[300], err_path[300], text[1024];
    scratch(out, sizeof out, "s.exr");
    scratch(err_path, sizeof err_path, "stderr.txt");
    const char *args[16] = {"tests/data/cli/tiny.txt", "--spp", "1", "--quiet", "-o", out};
    int n = 6;
    for (; extra[n - 6]; n++)
        args[n] = extra[n - 6];
    args[n] = NULL;
    cr_assert_eq(test_run_mcpt(args, NULL, err_path, 60), 0, "%s", extra[0]);
    struct image img;
    struct mcpt_error err;
    cr_assert(image_read_exr(out, &img, &err), "%s", err.msg);
    test_read_file(err_path, text, sizeof text);
    cr_assert(img.width == width && img.height == height, "%s %s: %dx%d, not %dx%d", extra[0],
              extra[1], img.width, img.height, width, height);
    image_free(&img);
}

/* The 16x12 scene: --width or --height alone keeps 4:3, --scale scales both (after them),
 * both sides given are taken as they are; a film past 65535 is refused. */
Test(ux, scale_and_one_side_keep_the_aspect_ratio, .init = setup, .fini = teardown)
{
    assert_film((const char *[]){"--width", "8", NULL}, 8, 6);
    assert_film((const char *[]){"--height", "3", NULL}, 4, 3);
    assert_film((const char *[]){"--width", "10", NULL}, 10, 8); /* 7.5 rounds to 8 */
    assert_film((const char *[]){"--scale", "0.5", NULL}, 8, 6);
    assert_film((const char *[]){"--scale", "2.5", NULL}, 40, 30);
    assert_film((const char *[]){"--width", "8", "--scale", "2", NULL}, 16, 12);
    assert_film((const char *[]){"--width", "10", "--height", "10", NULL}, 10, 10);
    char err_path[300], text[1024];
    scratch(err_path, sizeof err_path, "stderr.txt");
    const char *big[] = {"tests/data/cli/tiny.txt", "--width", "4000", "--scale", "20", NULL};
    cr_assert_eq(test_run_mcpt(big, NULL, err_path, 60), 2);
    test_read_file(err_path, text, sizeof text);
    cr_assert_str_eq(text, "mcpt: error: expected a film of at most 65535x65535 pixels, got "
                           "80000x60000 (see mcpt --help)\n");
    const char *zero[] = {"tests/data/cli/tiny.txt", "--scale", "0", NULL};
    cr_assert_eq(test_run_mcpt(zero, NULL, err_path, 60), 2);
    test_read_file(err_path, text, sizeof text);
    cr_assert_str_eq(text,
                     "mcpt: error: expected --scale to be a number in (0, 64], got '0' (see mcpt "
                     "--help)\n");
}

/* ---- item 9: the EXR header ---- */

/* A render's EXR carries the Rec. 709 chromaticities and mcpt's attributes; an adaptive one's
 * mcpt.spp is the mean of its samples channel. */
Test(ux, exr_header_records_the_render, .init = setup, .fini = teardown)
{
    char out[300], err_path[300];
    scratch(out, sizeof out, "m.exr");
    scratch(err_path, sizeof err_path, "stderr.txt");
    const char *args[] = {"tests/data/cli/tiny.txt",
                          "--spp",
                          "5",
                          "--seed",
                          "3",
                          "--sampler",
                          "stratified",
                          "--max-depth",
                          "4",
                          "--quiet",
                          "-o",
                          out,
                          NULL};
    cr_assert_eq(test_run_mcpt(args, NULL, err_path, 60), 0);
    struct image img;
    struct mcpt_error err;
    cr_assert(image_read_exr(out, &img, &err), "%s", err.msg);
    const char *want[][2] = {{"mcpt.scene", "tests/data/cli/tiny.txt"},
                             {"mcpt.spp", "5"},
                             {"mcpt.sampler", "stratified"},
                             {"mcpt.seed", "3"},
                             {"mcpt.max-depth", "4"},
                             {"mcpt.version", MCPT_VERSION}};
    for (size_t i = 0; i < sizeof want / sizeof want[0]; i++) {
        const char *v = image_find_attr(&img, want[i][0]);
        cr_assert(v && strcmp(v, want[i][1]) == 0, "%s: %s", want[i][0], v ? v : "(none)");
    }
    const char *seconds = image_find_attr(&img, "mcpt.render-seconds");
    cr_assert(seconds && strtod(seconds, NULL) >= 0.0);
    const float rec709[8] = IMAGE_REC709_CHROMATICITIES;
    cr_assert(img.has_chromaticities);
    cr_assert_eq(memcmp(img.chromaticities, rec709, sizeof rec709), 0);
    image_free(&img);

    const char *adaptive[] = {"tests/data/cli/tiny.txt",
                              "--spp",
                              "64",
                              "--adaptive",
                              "--min-spp",
                              "8",
                              "--batch",
                              "8",
                              "--tolerance",
                              "0.3",
                              "--quiet",
                              "-o",
                              out,
                              NULL};
    cr_assert_eq(test_run_mcpt(adaptive, NULL, err_path, 60), 0);
    cr_assert(image_read_exr(out, &img, &err), "%s", err.msg);
    int s = image_find_channel(&img, "samples");
    double total = 0.0;
    for (int i = 0; i < img.width * img.height; i++)
        total += img.data[s][i];
    char mean[32];
    snprintf(mean, sizeof mean, "%.6g", total / (img.width * img.height));
    cr_assert_str_eq(image_find_attr(&img, "mcpt.spp"), mean);
    cr_assert_lt(total / (img.width * img.height), 64.0, "adaptive: expected fewer than 64");
    image_free(&img);
}

/* The same header as OpenEXR's own exrheader (Debian package openexr) prints it. */
Test(ux, exr_header_as_exrheader_reads_it, .init = setup, .fini = teardown)
{
    if (!has_program("exrheader"))
        cr_skip_test("exrheader is not installed (Debian package openexr, which "
                     "scripts/setup.sh installs): the header was checked with mcpt's reader only");
    char out[300], text_path[300], text[8192];
    scratch(out, sizeof out, "h.exr");
    const char *args[] = {
        "tests/data/cli/tiny.txt", "--spp", "2", "--seed", "9", "--quiet", "-o", out, NULL};
    cr_assert_eq(test_run_mcpt(args, NULL, NULL, 60), 0);
    cr_assert_eq(shell("exrheader %s > %s", out, scratch(text_path, sizeof text_path, "h.txt")), 0);
    test_read_file(text_path, text, sizeof text);
    const char *lines[] = {"chromaticities (type chromaticities):",
                           "red   (0.64 0.33)",
                           "green (0.3 0.6)",
                           "blue  (0.15 0.06)",
                           "white (0.3127 0.329)",
                           "mcpt.spp (type string): \"2\"",
                           "mcpt.seed (type string): \"9\"",
                           "mcpt.sampler (type string): \"sobol\"",
                           "mcpt.max-depth (type string): \"3\"",
                           "mcpt.scene (type string): \"tests/data/cli/tiny.txt\"",
                           "mcpt.render-seconds (type string): \"",
                           "mcpt.version (type string): \"" MCPT_VERSION "\""};
    for (size_t i = 0; i < sizeof lines / sizeof lines[0]; i++)
        cr_assert(strstr(text, lines[i]), "no '%s' in:\n%s", lines[i], text);
}

/* ---- item 10: make install and uninstall ---- */

/* make install with DESTDIR and PREFIX=/opt/mcpt puts the binary, the man page (pointing at
 * the installed docs and scenes), the docs and the scenes with their models in place; the
 * installed scene renders from its installed path; make uninstall leaves no file behind. */
Test(ux, install_renders_the_installed_scene_and_uninstall_removes_all, .init = setup,
     .fini = teardown, .timeout = TEST_TIMEOUT_S(120))
{
    char dest[300], path[600], text[1 << 16];
    scratch(dest, sizeof dest, "dest");
    /* a make of its own: not the jobserver of a make that may have started this suite */
    const char *make = "env -u MAKEFLAGS -u MFLAGS -u MAKELEVEL make -s %s DESTDIR=%s "
                       "PREFIX=/opt/mcpt INSTALL_BIN='%s' > /dev/null";
    cr_assert_eq(shell(make, "install", dest, mcpt_abs()), 0);
    const char *files[] = {"bin/mcpt",
                           "share/man/man1/mcpt.1",
                           "share/doc/mcpt/README.md",
                           "share/doc/mcpt/architecture.md",
                           "share/doc/mcpt/scene-format.md",
                           "share/doc/mcpt/gallery/cornell-box.png",
                           "share/mcpt/scenes/cornell-box.txt",
                           "share/mcpt/scenes/models/CornellBox-Original.obj",
                           "share/mcpt/scenes/models/CornellBox-Original.mtl",
                           "share/mcpt/scenes/models/README.md"};
    for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
        snprintf(path, sizeof path, "%s/opt/mcpt/%s", dest, files[i]);
        cr_assert(test_exists(path), "not installed: %s", files[i]);
    }
    snprintf(path, sizeof path, "%s/opt/mcpt/share/man/man1/mcpt.1", dest);
    test_read_file(path, text, sizeof text);
    cr_assert(strstr(text, "/opt/mcpt/share/mcpt/scenes") &&
                  strstr(text, "/opt/mcpt/share/doc/mcpt"),
              "the man page does not name the installed scenes and docs");
    cr_assert_null(strstr(text, "/usr/local/"), "the man page still names /usr/local/");
    /* from another folder, the installed binary renders the installed scene */
    cr_assert_eq(
        shell("cd %s && %s/opt/mcpt/bin/mcpt %s/opt/mcpt/share/mcpt/scenes/cornell-box.txt "
              "--width 16 --spp 2 --quiet",
              tmpdir, dest, dest),
        0);
    cr_assert(test_exists(scratch(path, sizeof path, "cornell-box.exr")));
    cr_assert_eq(shell(make, "uninstall", dest, mcpt_abs()), 0);
    cr_assert_eq(shell("test -z \"$(find %s -type f)\"", dest), 0, "files left after uninstall");
}

/* ---- item 11: standard input, --no-preview, merge ---- */

/* mcpt - reads the scene from standard input: the same pixels as the file, outputs named
 * stdin.exr/.png by default, errors naming <stdin>, and meshes found from the working
 * directory. */
Test(ux, scene_from_standard_input, .init = setup, .fini = teardown)
{
    const char *bin = mcpt_abs();
    char path[300], text[4096];
    const char *cwd = repo_root();
    cr_assert_eq(shell("'%s' tests/data/cli/tiny.txt --spp 3 --quiet -o %s/file.exr", bin, tmpdir),
                 0);
    cr_assert_eq(shell("cd %s && '%s' - --spp 3 --quiet < '%s/tests/data/cli/tiny.txt'", tmpdir,
                       bin, cwd),
                 0);
    struct image a, b;
    struct mcpt_error err;
    cr_assert(image_read_exr(scratch(path, sizeof path, "file.exr"), &a, &err), "%s", err.msg);
    cr_assert(image_read_exr(scratch(path, sizeof path, "stdin.exr"), &b, &err), "%s", err.msg);
    cr_assert(test_exists(scratch(path, sizeof path, "stdin.png")));
    for (int c = 0; c < a.n_channels; c++) {
        int k = image_find_channel(&b, a.names[c]);
        cr_assert(k >= 0 && memcmp(a.data[c], b.data[k], sizeof(float) * 16 * 12) == 0, "%s",
                  a.names[c]);
    }
    cr_assert_str_eq(image_find_attr(&b, "mcpt.scene"), "<stdin>");
    image_free(&a);
    image_free(&b);
    /* a bad line */
    cr_assert_eq(shell("'%s' - -o %s/x.exr < tests/data/cli/bad-statement.txt 2> %s", bin, tmpdir,
                       scratch(path, sizeof path, "e.txt")),
                 2);
    test_read_file(path, text, sizeof text);
    cr_assert(strncmp(text, "<stdin>:2:1: error: expected ", 29) == 0, "%s", text);
    cr_assert_eq(count_lines(text), 1, "%s", text);
    /* meshes are relative to the working directory: from scenes/ the box renders, from the
     * repository's root its models/ are not there */
    cr_assert_eq(shell("cd scenes && '%s' - --width 16 --spp 1 --quiet -o %s/box.exr < "
                       "cornell-box.txt",
                       bin, tmpdir),
                 0);
    cr_assert_eq(shell("'%s' - --width 16 --spp 1 -o %s/box2.exr < scenes/cornell-box.txt 2> %s",
                       bin, tmpdir, path),
                 2);
    test_read_file(path, text, sizeof text);
    cr_assert_str_eq(text,
                     "<stdin>:6:11: error: cannot open mesh 'models/CornellBox-Original.obj': "
                     "No such file or directory\n");
}

/* --no-preview writes the EXR alone (also for a partial render); with -o OUT.png it is
 * refused, as is --sample-range. */
Test(ux, no_preview_writes_the_exr_alone, .init = setup, .fini = teardown)
{
    char exr[300], png[300], part[300], part_png[300], err_path[300], text[1024];
    scratch(exr, sizeof exr, "n.exr");
    scratch(png, sizeof png, "n.png");
    scratch(part, sizeof part, "p.exr");
    scratch(part_png, sizeof part_png, "p.png");
    scratch(err_path, sizeof err_path, "stderr.txt");
    const char *a[] = {
        "tests/data/cli/tiny.txt", "--spp", "2", "--no-preview", "--quiet", "-o", exr, NULL};
    cr_assert_eq(test_run_mcpt(a, NULL, err_path, 60), 0);
    cr_assert(test_exists(exr));
    cr_assert_not(test_exists(png));
    const char *b[] = {"tests/data/cli/tiny.txt",
                       "--spp",
                       "8",
                       "--sample-range",
                       "0:4",
                       "--no-preview",
                       "--quiet",
                       "-o",
                       part,
                       NULL};
    cr_assert_eq(test_run_mcpt(b, NULL, err_path, 60), 0);
    cr_assert(test_exists(part));
    cr_assert_not(test_exists(part_png));
    const char *c[] = {"tests/data/cli/tiny.txt", "--no-preview", "-o", png, NULL};
    cr_assert_eq(test_run_mcpt(c, NULL, err_path, 60), 2);
    test_read_file(err_path, text, sizeof text);
    const char *want = "mcpt: error: expected -o OUT.exr with --no-preview, got '";
    cr_assert(strncmp(text, want, strlen(want)) == 0, "%s", text);
    cr_assert_eq(count_lines(text), 1, "%s", text);
}

/* mcpt merge of parts that make the whole render writes a plain EXR (7 channels, with the
 * parts' settings and ranges in its header) whose R, G, B are those of the --partial merge;
 * an incomplete set stays a partial render; --partial with a PNG is refused. */
Test(ux, merge_of_a_whole_set_is_a_plain_exr, .init = setup, .fini = teardown)
{
    const char *bin = mcpt_abs();
    const char *common = "tests/data/cli/tiny.txt --spp 8 --quiet --no-preview";
    cr_assert_eq(shell("'%s' %s --sample-range 0:3 -o %s/a.exr && '%s' %s --sample-range 3:8 -o "
                       "%s/b.exr",
                       bin, common, tmpdir, bin, common, tmpdir),
                 0);
    char path[300], text[2048];
    cr_assert_eq(shell("'%s' merge %s/a.exr %s/b.exr -o %s/m.exr > %s", bin, tmpdir, tmpdir, tmpdir,
                       scratch(path, sizeof path, "out.txt")),
                 0);
    test_read_file(path, text, sizeof text);
    cr_assert(strstr(text, "(8 spp, the whole render); wrote ") &&
                  strstr(text, "/m.exr (R, G, B, variance, samples) and "),
              "%s", text);
    cr_assert_eq(shell("'%s' merge --quiet --partial %s/b.exr %s/a.exr -o %s/mp.exr", bin, tmpdir,
                       tmpdir, tmpdir),
                 0);
    struct image plain, part;
    struct mcpt_error err;
    cr_assert(image_read_exr(scratch(path, sizeof path, "m.exr"), &plain, &err), "%s", err.msg);
    cr_assert(image_read_exr(scratch(path, sizeof path, "mp.exr"), &part, &err), "%s", err.msg);
    cr_assert_eq(plain.n_channels, 7);
    cr_assert_gt(part.n_channels, 7);
    cr_assert_str_eq(image_find_attr(&plain, "mcpt.sample-ranges"), "0:8");
    cr_assert_str_eq(image_find_attr(&plain, "mcpt.spp"), "8");
    cr_assert_str_eq(image_find_attr(&plain, "mcpt.render"), image_find_attr(&part, "mcpt.render"));
    for (int c = 0; c < plain.n_channels; c++) {
        int k = image_find_channel(&part, plain.names[c]);
        cr_assert(k >= 0 && memcmp(plain.data[c], part.data[k], sizeof(float) * 16 * 12) == 0, "%s",
                  plain.names[c]);
    }
    image_free(&plain);
    image_free(&part);
    cr_assert_eq(shell("'%s' merge %s/a.exr -o %s/half.exr > %s", bin, tmpdir, tmpdir, path), 0);
    test_read_file(path, text, sizeof text);
    cr_assert(strstr(text, "not yet the whole render") &&
                  strstr(text, "a partial render, mergeable"),
              "%s", text);
    cr_assert(image_read_exr(scratch(path, sizeof path, "half.exr"), &part, &err), "%s", err.msg);
    cr_assert_geq(image_find_channel(&part, "sum.R"), 0);
    image_free(&part);
    cr_assert_eq(shell("'%s' merge --partial %s/a.exr -o %s/x.png 2> %s", bin, tmpdir, tmpdir,
                       path),
                 2);
    test_read_file(path, text, sizeof text);
    cr_assert(strstr(text, "expected -o OUT.exr with --partial"), "%s", text);
}
