/* tests/bad_test.c - main.c, scene.c, obj.c and the checkpoint reader against the bad-input
 * corpus tests/bad/cases.txt: malformed scenes, OBJ, MTL and checkpoint files and bad options.
 * For every case the binary ($MCPT, default ./mcpt) must exit with the listed status (2) within
 * a time bound, print exactly one line on stderr that starts with the listed
 * "file:line:col: error: expected ..." prefix, print nothing on stdout, and leave the output
 * folder as it was: an existing OUT.exr untouched, no PNG, checkpoint or temporary file made.
 * (The STYLE guide, §5: user input never crashes the program or leaves a half-built result.) */
#include <criterion/criterion.h>

#include <dirent.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/stat.h>

#include "test_util.h"

#define CASES_PATH "tests/bad/cases.txt"
#define TIME_LIMIT_S 10u /* a case running longer (x TEST_TIMEOUT_SCALE) counts as a hang */
#define SENTINEL "precious: not an image"

static char tmpdir[256];

static void setup(void) { test_make_dir(tmpdir, sizeof tmpdir, "bad"); }
static void teardown(void) { test_remove_dir(tmpdir); }

/* Runs mcpt -o OUT followed by args (split at spaces) under an alarm of TIME_LIMIT_S seconds,
 * stdout and stderr to files in tmpdir; returns the exit status, or 128 + signal. */
static int run_case(const char *args, const char *out_path)
{
    char out_file[300], err_file[300], words[4096];
    snprintf(out_file, sizeof out_file, "%s/stdout.txt", tmpdir);
    snprintf(err_file, sizeof err_file, "%s/stderr.txt", tmpdir);
    snprintf(words, sizeof words, "%s", args);
    const char *argv[TEST_MAX_ARGS + 1] = {"-o", out_path};
    int argc = 2;
    for (char *w = strtok(words, " "); w && argc < TEST_MAX_ARGS; w = strtok(NULL, " "))
        argv[argc++] = w;
    argv[argc] = NULL;
    return test_run_mcpt(argv, out_file, err_file, TIME_LIMIT_S);
}

/* Trims leading and trailing blanks in place. */
static char *trim(char *s)
{
    while (*s == ' ' || *s == '\t')
        s++;
    size_t n = strlen(s);
    while (n > 0 && (s[n - 1] == ' ' || s[n - 1] == '\t' || s[n - 1] == '\n'))
        s[--n] = '\0';
    return s;
}

/* Every case of the corpus: status, one stderr line with the prefix, no stdout, no file made or
 * changed in the output folder. */
Test(bad, corpus, .init = setup, .fini = teardown, .timeout = TEST_TIMEOUT_S(600))
{
    FILE *f = fopen(CASES_PATH, "r");
    cr_assert_not_null(f, "cannot open " CASES_PATH);
    char out_dir[300], out_path[320], line[4096];
    snprintf(out_dir, sizeof out_dir, "%s/out", tmpdir);
    snprintf(out_path, sizeof out_path, "%s/out.exr", out_dir);
    cr_assert_eq(mkdir(out_dir, 0755), 0);
    int n_cases = 0, n_scene = 0, n_obj = 0, n_mtl = 0, n_ckpt = 0, n_exr = 0;
    for (int line_no = 1; fgets(line, sizeof line, f); line_no++) {
        char *s = trim(line);
        if (*s == '\0' || *s == '#')
            continue;
        char *bar1 = strchr(s, '|');
        char *bar2 = bar1 ? strchr(bar1 + 1, '|') : NULL;
        cr_assert(bar1 && bar2, CASES_PATH ":%d: expected ARGS | STATUS | PREFIX", line_no);
        *bar1 = *bar2 = '\0';
        char *args = trim(s), *prefix = trim(bar2 + 1);
        int want_status = atoi(trim(bar1 + 1));
        n_scene += strstr(args, "tests/bad/scene/") != NULL;
        n_obj += strstr(args, "tests/bad/obj/") != NULL;
        n_mtl += strstr(args, "tests/bad/mtl/") != NULL;
        n_ckpt += strstr(args, "tests/bad/ckpt/") != NULL;
        n_exr += strstr(args, "tests/bad/exr/") != NULL;

        FILE *o = fopen(out_path, "w"); /* an earlier image the failed run must not touch */
        cr_assert_not_null(o);
        fputs(SENTINEL, o);
        fclose(o);

        int status = run_case(args, out_path);
        char err[8192], out[1024], path[400];
        snprintf(path, sizeof path, "%s/stderr.txt", tmpdir);
        long n_err = test_read_file(path, err, sizeof err);
        snprintf(path, sizeof path, "%s/stdout.txt", tmpdir);
        long n_out = test_read_file(path, out, sizeof out);
        cr_assert_neq(status, 128 + SIGALRM, "line %d '%s': no exit within %u s", line_no, args,
                      TEST_TIMEOUT_S(TIME_LIMIT_S));
        cr_assert_eq(status, want_status, "line %d '%s': exit %d, want %d; stderr: %s", line_no,
                     args, status, want_status, err);
        cr_assert(n_err > 0 && err[n_err - 1] == '\n' && strchr(err, '\n') == err + n_err - 1,
                  "line %d '%s': want exactly one stderr line, got: %s", line_no, args, err);
        cr_assert(strncmp(err, prefix, strlen(prefix)) == 0,
                  "line %d '%s':\n  want: %s\n  got:  %s", line_no, args, prefix, err);
        cr_assert(strstr(err, "error: "), "line %d: %s", line_no, err);
        cr_assert_eq(n_out, 0, "line %d '%s': stdout not empty: %s", line_no, args, out);

        /* the output folder holds the sentinel OUT.exr and nothing else */
        char buf[64];
        cr_assert_eq(test_read_file(out_path, buf, sizeof buf), (long)strlen(SENTINEL));
        cr_assert_str_eq(buf, SENTINEL, "line %d '%s': OUT.exr overwritten", line_no, args);
        DIR *d = opendir(out_dir);
        cr_assert_not_null(d);
        for (struct dirent *e; (e = readdir(d));)
            cr_assert(strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0 ||
                          strcmp(e->d_name, "out.exr") == 0,
                      "line %d '%s': made %s", line_no, args, e->d_name);
        closedir(d);
        n_cases++;
    }
    fclose(f);
    /* the issue asks for at least 60 malformed files; keep every kind represented */
    cr_assert_geq(n_scene + n_obj + n_mtl + n_ckpt, 60, "only %d file cases",
                  n_scene + n_obj + n_mtl + n_ckpt);
    cr_assert(n_scene >= 40 && n_obj >= 15 && n_mtl >= 10 && n_ckpt >= 8,
              "scene %d, obj %d, mtl %d, ckpt %d", n_scene, n_obj, n_mtl, n_ckpt);
    cr_log_info("bad corpus: %d cases (%d scene, %d OBJ, %d MTL, %d checkpoint, %d EXR, %d "
                "options)",
                n_cases, n_scene, n_obj, n_mtl, n_ckpt, n_exr,
                n_cases - n_scene - n_obj - n_mtl - n_ckpt - n_exr);
}

/* Every malformed file in tests/bad/ has a case: a file added without an expectation is an
 * untested file.  (OBJ and MTL files are reached through the scene of the same name.) */
Test(bad, every_file_listed)
{
    char cases[65536];
    cr_assert(test_read_file(CASES_PATH, cases, sizeof cases) > 0);
    const char *dirs[] = {"scene", "obj", "mtl", "ckpt", "exr"};
    for (int k = 0; k < 5; k++) {
        char dir[64];
        snprintf(dir, sizeof dir, "tests/bad/%s", dirs[k]);
        DIR *d = opendir(dir);
        cr_assert_not_null(d, "%s", dir);
        for (struct dirent *e; (e = readdir(d));) {
            const char *dot = strrchr(e->d_name, '.');
            if (!dot ||
                (strcmp(dot, ".txt") != 0 && strcmp(dot, ".ckpt") != 0 && strcmp(dot, ".exr") != 0))
                continue; /* the .obj and .mtl behind a wrapper scene, fixtures, the generator */
            char want[600];
            snprintf(want, sizeof want, "%s/%s ", dir, e->d_name);
            cr_assert(strstr(cases, want), "%s/%s has no line in " CASES_PATH, dir, e->d_name);
        }
        closedir(d);
    }
}

/* A FIFO with no writer as mesh, as mtllib or as the scene (issue 15): mcpt never waits in
 * open() for a writer that will not come.  Mesh and MTL must be regular files (exit 2, one
 * line at the scene or OBJ line naming the FIFO); the scene may be a pipe, and one with no
 * writer reads as empty.  FIFOs cannot live in git, so they are made here. */
Test(bad, fifo_inputs_refused_at_once, .init = setup, .fini = teardown,
     .timeout = TEST_TIMEOUT_S(60))
{
    char path[400], out_path[400], err_path[400], err[1024];
    const char *fifos[] = {"pipe.obj", "pipe.mtl", "pipe.txt"};
    for (int i = 0; i < 3; i++) {
        snprintf(path, sizeof path, "%s/%s", tmpdir, fifos[i]);
        cr_assert_eq(mkfifo(path, 0600), 0, "%s", path);
    }
    const char *files[][2] = {
        {"mesh.txt", "camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=40\nmesh file=pipe.obj\n"},
        {"lib.txt", "camera eye=0,0,5 look-at=0,0,0 up=0,1,0 fov=40\nmesh file=lib.obj\n"},
        {"lib.obj", "mtllib pipe.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
    };
    for (int i = 0; i < 3; i++) {
        snprintf(path, sizeof path, "%s/%s", tmpdir, files[i][0]);
        FILE *f = fopen(path, "w");
        cr_assert_not_null(f);
        fputs(files[i][1], f);
        fclose(f);
    }
    const char *scenes[] = {"mesh.txt", "lib.txt", "pipe.txt"};
    const char *wants[] = {"mesh.txt:2:11: error: expected a regular file for mesh 'pipe.obj' ",
                           "lib.obj:1:8: error: expected a regular file for mtllib 'pipe.mtl' ",
                           "pipe.txt: error: expected a 'camera' statement, got none"};
    snprintf(out_path, sizeof out_path, "%s/stdout.txt", tmpdir);
    snprintf(err_path, sizeof err_path, "%s/stderr.txt", tmpdir);
    for (int i = 0; i < 3; i++) {
        char scene[400], exr[400];
        snprintf(scene, sizeof scene, "%s/%s", tmpdir, scenes[i]);
        snprintf(exr, sizeof exr, "%s/out.exr", tmpdir);
        const char *argv[] = {scene, "-o", exr, NULL};
        int status = test_run_mcpt(argv, out_path, err_path, TIME_LIMIT_S);
        test_read_file(err_path, err, sizeof err);
        cr_assert_neq(status, 128 + SIGALRM, "%s: blocked for %u s", scenes[i],
                      TEST_TIMEOUT_S(TIME_LIMIT_S));
        cr_assert_eq(status, 2, "%s: exit %d: %s", scenes[i], status, err);
        char want[600];
        snprintf(want, sizeof want, "%s/%s", tmpdir, wants[i]);
        cr_assert(strncmp(err, want, strlen(want)) == 0, "%s:\n  want: %s\n  got:  %s", scenes[i],
                  want, err);
    }
}
