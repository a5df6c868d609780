/* make_fixtures.c - one-off program that wrote the malformed checkpoints in this folder with
 * checkpoint_save, then damaged them (see tests/bad/cases.txt for what each must produce).
 * Not part of the build; kept so the fixtures can be re-made from the repo root:
 *     gcc -std=c11 -D_DEFAULT_SOURCE -I. tests/bad/ckpt/make_fixtures.c checkpoint.c file.c \
 *         film.c sample.c -lm -o /tmp/mk
 *     /tmp/mk */
#include "checkpoint.h"

#include <math.h>
#include <stdlib.h>

#define DIR "tests/bad/ckpt/"

static unsigned char *slurp(const char *path, long *n)
{
    FILE *f = fopen(path, "rb");
    fseek(f, 0, SEEK_END);
    *n = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *b = malloc((size_t)*n);
    if (fread(b, 1, (size_t)*n, f) != (size_t)*n)
        exit(1);
    fclose(f);
    return b;
}

static void spill(const char *path, const void *b, long n)
{
    FILE *f = fopen(path, "wb");
    fwrite(b, 1, (size_t)n, f);
    fclose(f);
}

/* Sets pixel p to n samples of 0.5 grey, as a render would. */
static void grey(struct film_pixel *p, uint32_t n)
{
    memset(p, 0, sizeof *p);
    for (uint32_t k = 0; k < n; k++)
        film_add(p, (vec3){0.5f, 0.5f, 0.5f});
}

/* What a crafted checkpoint changes in pixel 0 after it is made valid (checksum and all). */
enum tamper { NONE, NAN_SUM, INF_SQUARES, NEGATIVE_SQUARES, SUM_TOO_BIG, EMPTY_NOT_ZERO };

/* A valid 8x6 checkpoint of 16 spp with every pixel half done, args as given, pixel 0 with
 * n_first samples, then damaged as t says, with a valid checksum; info as given otherwise. */
static void crafted(const char *path, const char *args, uint32_t args_bytes, uint32_t n_first,
                    enum tamper t, uint32_t sampler, uint32_t spp)
{
    struct film film;
    struct mcpt_error err;
    if (!film_init(&film, 8, 6, &err))
        exit(1);
    for (int i = 0; i < 48; i++)
        grey(&film.pixels[i], i == 0 ? n_first : 8);
    struct film_pixel *p = &film.pixels[0];
    if (t == NAN_SUM)
        p->sum[1] = NAN;
    else if (t == INF_SQUARES)
        p->sum_sq[2] = INFINITY;
    else if (t == NEGATIVE_SQUARES)
        p->sum_sq[0] = -1.0;
    else if (t == SUM_TOO_BIG)
        p->sum[0] = 100.0; /* 8 samples, squares summing to 2: the sum is at most 4 */
    else if (t == EMPTY_NOT_ZERO)
        grey(p, 0), p->sum_lum_sq = 1.0;
    struct checkpoint_info info = {.scene_hash = 0x0123456789abcdefull,
                                   .spp = spp,
                                   .max_depth = 4,
                                   .sampler = sampler,
                                   .args_bytes = args_bytes};
    snprintf(info.scene_path, sizeof info.scene_path, "tests/data/resume/small.txt");
    memcpy(info.args, args, args_bytes);
    if (!checkpoint_save(path, &film, &info, &err)) {
        fprintf(stderr, "%s\n", err.msg);
        exit(1);
    }
    film_free(&film);
}

/* A valid 8x6 checkpoint of 16 spp with every pixel half done; args as given. */
static void valid(const char *path, const char *args, uint32_t args_bytes, uint32_t n_first)
{
    crafted(path, args, args_bytes, n_first, NONE, 0, 16);
}

int main(void)
{
    long n;
    spill(DIR "empty.ckpt", "", 0);
    spill(DIR "text.ckpt", "camera eye=0,1,3 look-at=0,0,0 up=0,1,0 fov=45\n", 48);

    valid(DIR "scene-changed.ckpt", "--quiet", 8, 8);
    valid(DIR "bad-stored-option.ckpt", "--spp=0", 8, 8);
    valid(DIR "args-unterminated.ckpt", "--quiet", 7, 8);
    valid(DIR "spp-exceeded.ckpt", "", 0, 17);
    /* issue 15: valid checksums over values no render writes, and stored words that are not
     * options */
    crafted(DIR "nan-sum.ckpt", "", 0, 8, NAN_SUM, 0, 16);
    crafted(DIR "inf-squares.ckpt", "", 0, 8, INF_SQUARES, 0, 16);
    crafted(DIR "negative-squares.ckpt", "", 0, 8, NEGATIVE_SQUARES, 0, 16);
    crafted(DIR "sum-beyond-squares.ckpt", "", 0, 8, SUM_TOO_BIG, 0, 16);
    crafted(DIR "empty-pixel-not-zero.ckpt", "", 0, 0, EMPTY_NOT_ZERO, 0, 16);
    crafted(DIR "sampler-99.ckpt", "", 0, 8, NONE, 99, 16);
    crafted(DIR "spp-zero.ckpt", "", 0, 0, NONE, 0, 0);
    valid(DIR "stored-bare-word.ckpt", "--quiet\0stray", 14, 8);
    valid(DIR "stored-unknown-option.ckpt", "--frobnicate=3", 15, 8);
    valid(DIR "stored-value-missing.ckpt", "--spp", 6, 8);
    valid(DIR "stored-resume.ckpt", "--resume=x.ckpt", 16, 8);

    valid("/tmp/mk_valid.ckpt", "", 0, 8);
    unsigned char *b = slurp("/tmp/mk_valid.ckpt", &n);
    spill(DIR "truncated.ckpt", b, n - 100);
    b[n - 300] ^= 0x10; /* a bit of one pixel's sums */
    spill(DIR "corrupt-checksum.ckpt", b, n);
    b[n - 300] ^= 0x10;
    uint32_t v = 99;
    memcpy(b + 8, &v, 4); /* version */
    spill(DIR "version-99.ckpt", b, n);
    v = CHECKPOINT_VERSION;
    memcpy(b + 8, &v, 4);
    v = 0;
    memcpy(b + 20, &v, 4); /* width */
    spill(DIR "film-zero.ckpt", b, n);
    v = 65535;
    memcpy(b + 20, &v, 4);
    memcpy(b + 24, &v, 4); /* height: 65535 x 65535 needs 256 GiB; the length check comes first */
    spill(DIR "film-huge.ckpt", b, n);
    free(b);
    remove("/tmp/mk_valid.ckpt");
    return 0;
}
