/* make_fixtures.c - one-off program that wrote the malformed checkpoints in this folder with
 * checkpoint_save, then damaged them (see tests/bad/cases.txt for what each must produce).
 * Not part of the build; kept so the fixtures can be re-made from the repo root:
 *     gcc -std=c11 -D_DEFAULT_SOURCE -I. tests/bad/ckpt/make_fixtures.c checkpoint.c file.c \
 *         film.c sample.c -lm -o /tmp/mk
 *     /tmp/mk */
#include "checkpoint.h"

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

/* A valid 8x6 checkpoint of 16 spp with every pixel half done; args as given. */
static void valid(const char *path, const char *args, uint32_t args_bytes, uint32_t n_first)
{
    struct film film;
    struct mcpt_error err;
    if (!film_init(&film, 8, 6, &err))
        exit(1);
    for (int i = 0; i < 48; i++) {
        film.pixels[i].n = 8;
        film.pixels[i].sum[0] = film.pixels[i].sum[1] = film.pixels[i].sum[2] = 4.0;
    }
    film.pixels[0].n = n_first;
    struct checkpoint_info info = {.scene_hash = 0x0123456789abcdefull,
                                   .spp = 16,
                                   .max_depth = 4,
                                   .args_bytes = args_bytes};
    snprintf(info.scene_path, sizeof info.scene_path, "tests/data/resume/small.txt");
    memcpy(info.args, args, args_bytes);
    if (!checkpoint_save(path, &film, &info, &err)) {
        fprintf(stderr, "%s\n", err.msg);
        exit(1);
    }
    film_free(&film);
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

    valid("/tmp/mk_valid.ckpt", "", 0, 8);
    unsigned char *b = slurp("/tmp/mk_valid.ckpt", &n);
    spill(DIR "truncated.ckpt", b, n - 100);
    b[n - 300] ^= 0x10; /* a bit of one pixel's sums */
    spill(DIR "corrupt-checksum.ckpt", b, n);
    b[n - 300] ^= 0x10;
    uint32_t v = 99;
    memcpy(b + 8, &v, 4); /* version */
    spill(DIR "version-99.ckpt", b, n);
    v = 1;
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
