/* image_test.c - tests image.c: OpenEXR write/read round trips (bit-exact float data, channel
 * names, partial chunks), reading half/uint/tiled files against values decoded independently,
 * error reports for missing and damaged files, the sRGB transfer function of the PNG preview
 * (IEC 61966-2-1:1999) read back with libpng, and atomic replacement (a failed write,
 * before or in the middle, leaves the old file and no temporary).  Files go only to a mkdtemp
 * folder under /tmp that each test removes. */
#define _POSIX_C_SOURCE 200809L
#define _XOPEN_SOURCE 700

#include "image.h"
#include "test_util.h"

#include <criterion/criterion.h>
#include <dirent.h>
#include <errno.h>
#include <float.h>
#include <png.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

/* ---- scratch folder and file helpers ------------------------------------------------------ */

static char g_dir[64]; /* this test's scratch folder */

static void make_scratch_dir(void)
{
    snprintf(g_dir, sizeof g_dir, "/tmp/mcpt_image_test_XXXXXX");
    cr_assert_not_null(mkdtemp(g_dir), "mkdtemp: %s", strerror(errno));
}

/* Removes the scratch folder and what the tests put in it (files, or empty folders). */
static void remove_scratch_dir(void)
{
    DIR *d = opendir(g_dir);
    if (!d)
        return;
    struct dirent *e;
    char path[512];
    while ((e = readdir(d)) != NULL) {
        if (strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0)
            continue;
        snprintf(path, sizeof path, "%s/%s", g_dir, e->d_name);
        if (unlink(path) != 0)
            rmdir(path);
    }
    closedir(d);
    rmdir(g_dir);
}

TestSuite(image, .init = make_scratch_dir, .fini = remove_scratch_dir);

static const char *scratch_path(char *buf, size_t buf_bytes, const char *name)
{
    snprintf(buf, buf_bytes, "%s/%s", g_dir, name);
    return buf;
}

/* Number of entries in the scratch folder, "." and ".." not counted. */
static int count_entries(void)
{
    DIR *d = opendir(g_dir);
    cr_assert_not_null(d);
    int n = 0;
    struct dirent *e;
    while ((e = readdir(d)) != NULL)
        n += strcmp(e->d_name, ".") != 0 && strcmp(e->d_name, "..") != 0;
    closedir(d);
    return n;
}

static unsigned char *read_bytes(const char *path, size_t *n_bytes)
{
    FILE *f = fopen(path, "rb");
    cr_assert_not_null(f, "cannot open %s", path);
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *buf = malloc((size_t)size + 1);
    cr_assert_not_null(buf);
    cr_assert_eq(fread(buf, 1, (size_t)size, f), (size_t)size);
    fclose(f);
    *n_bytes = (size_t)size;
    return buf;
}

static void write_bytes(const char *path, const void *data, size_t n_bytes)
{
    FILE *f = fopen(path, "wb");
    cr_assert_not_null(f);
    cr_assert_eq(fwrite(data, 1, n_bytes, f), n_bytes);
    cr_assert_eq(fclose(f), 0);
}

/* Decodes a PNG to 8-bit RGB with libpng's simplified API; *w, *h get its size. */
static uint8_t *read_png_rgb8(const char *path, int *w, int *h)
{
    png_image im;
    memset(&im, 0, sizeof im);
    im.version = PNG_IMAGE_VERSION;
    cr_assert(png_image_begin_read_from_file(&im, path), "libpng: %s", im.message);
    im.format = PNG_FORMAT_RGB;
    uint8_t *buf = malloc(PNG_IMAGE_SIZE(im));
    cr_assert_not_null(buf);
    cr_assert(png_image_finish_read(&im, NULL, buf, 0, NULL), "libpng: %s", im.message);
    *w = (int)im.width;
    *h = (int)im.height;
    return buf;
}

static uint32_t xorshift32(uint32_t *state)
{
    uint32_t x = *state;
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    return *state = x;
}

static float float_from_bits(uint32_t bits)
{
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

/* Allocates an image with the given channel names, data uninitialised. */
static void image_make(struct image *img, int width, int height, int n_channels,
                       const char *const *names)
{
    memset(img, 0, sizeof *img);
    img->width = width;
    img->height = height;
    img->n_channels = n_channels;
    for (int c = 0; c < n_channels; c++) {
        snprintf(img->names[c], sizeof img->names[c], "%s", names[c]);
        img->data[c] = malloc((size_t)width * (size_t)height * sizeof(float));
        cr_assert_not_null(img->data[c]);
    }
}

/* ---- EXR round trips ------------------------------------------------------------------------- */

/* Every float bit pattern survives write + read (ZIP is lossless and float channels are stored as
 * is): random bit patterns (so NaN payloads, infinities, denormals, both signs), planted extremes,
 * an odd 37x19 size (19 rows = one full 16-row ZIP chunk and a partial one), and five channels
 * given out of name order.  Names come back as stored: sorted, as the EXR format requires. */
Test(image, exr_round_trip_is_bit_exact)
{
    const char *names[] = {"R", "G", "B", "variance.R", "spp"};
    struct image img;
    image_make(&img, 37, 19, 5, names);
    const size_t n_px = 37 * 19;
    uint32_t state = 0x9E3779B9u;
    for (int c = 0; c < 3; c++)
        for (size_t i = 0; i < n_px; i++)
            img.data[c][i] = float_from_bits(xorshift32(&state));
    const float planted[] = {0x1p-149f, 0x1p-127f, -0x1p-140f,      FLT_MAX,  -FLT_MAX,
                             -0.0f,     1e30f,     -12345.678f,     INFINITY, -INFINITY,
                             NAN,       FLT_MIN,   0x1.fffffep-127f /* largest denormal */};
    const size_t n_planted = sizeof planted / sizeof planted[0];
    for (size_t i = 0; i < n_px; i++) {
        img.data[3][i] = i < n_planted ? planted[i] : (float)i * -1e-3f;
        img.data[4][i] = (float)(i + 1);
    }

    char path[256];
    struct mcpt_error err;
    cr_assert(image_write_exr(scratch_path(path, sizeof path, "rt.exr"), &img, &err), "%s",
              err.msg);
    struct image back;
    cr_assert(image_read_exr(path, &back, &err), "%s", err.msg);
    cr_assert_eq(back.width, 37);
    cr_assert_eq(back.height, 19);
    cr_assert_eq(back.n_channels, 5);
    const char *sorted[] = {"B", "G", "R", "spp", "variance.R"};
    for (int c = 0; c < 5; c++)
        cr_assert_str_eq(back.names[c], sorted[c]);
    for (int c = 0; c < 5; c++) {
        int k = image_find_channel(&back, names[c]);
        cr_assert_geq(k, 0, "channel %s missing", names[c]);
        cr_assert_eq(memcmp(back.data[k], img.data[c], n_px * sizeof(float)), 0,
                     "channel %s differs", names[c]);
    }
    image_free(&back);
    cr_assert_eq(back.n_channels, 0);
    cr_assert_null(back.data[0]);
    for (int c = 0; c < 5; c++)
        free(img.data[c]);
    cr_assert_eq(count_entries(), 1, "a temporary file was left behind");
}

/* The smallest image (1x1, one channel) round-trips. */
Test(image, exr_one_pixel_round_trip)
{
    const char *names[] = {"Y"};
    struct image img;
    image_make(&img, 1, 1, 1, names);
    img.data[0][0] = 0.15625f;
    char path[256];
    struct mcpt_error err;
    cr_assert(image_write_exr(scratch_path(path, sizeof path, "one.exr"), &img, &err), "%s",
              err.msg);
    struct image back;
    cr_assert(image_read_exr(path, &back, &err), "%s", err.msg);
    cr_assert_eq(back.width, 1);
    cr_assert_eq(back.height, 1);
    cr_assert_eq(back.n_channels, 1);
    cr_assert_str_eq(back.names[0], "Y");
    cr_assert_eq(back.data[0][0], 0.15625f);
    image_free(&back);
    free(img.data[0]);
}

/* String attributes go into the header and come back by name (EXR "string" attribute type);
 * a file without them reads with none; IMAGE_MAX_CHANNELS channels write and read. */
Test(image, exr_string_attributes_and_many_channels_round_trip)
{
    const char *names[IMAGE_MAX_CHANNELS];
    char name_buf[IMAGE_MAX_CHANNELS][16];
    for (int c = 0; c < IMAGE_MAX_CHANNELS; c++) {
        snprintf(name_buf[c], sizeof name_buf[c], "c%02d", c);
        names[c] = name_buf[c];
    }
    struct image img;
    image_make(&img, 3, 2, IMAGE_MAX_CHANNELS, names);
    for (int c = 0; c < IMAGE_MAX_CHANNELS; c++)
        for (int i = 0; i < 6; i++)
            img.data[c][i] = (float)(c * 10 + i);
    img.n_attrs = 2;
    snprintf(img.attr_names[0], sizeof img.attr_names[0], "mcpt.sample-ranges");
    snprintf(img.attr_values[0], sizeof img.attr_values[0], "0:16,32:48");
    snprintf(img.attr_names[1], sizeof img.attr_names[1], "mcpt.render");
    memset(img.attr_values[1], 'x', IMAGE_ATTR_BYTES - 1); /* the longest value kept */
    img.attr_values[1][IMAGE_ATTR_BYTES - 1] = '\0';
    char path[256];
    struct mcpt_error err;
    cr_assert(image_write_exr(scratch_path(path, sizeof path, "attrs.exr"), &img, &err), "%s",
              err.msg);
    struct image back;
    cr_assert(image_read_exr(path, &back, &err), "%s", err.msg);
    cr_assert_eq(back.n_channels, IMAGE_MAX_CHANNELS);
    for (int c = 0; c < IMAGE_MAX_CHANNELS; c++)
        cr_assert_eq(back.data[image_find_channel(&back, names[c])][5], (float)(c * 10 + 5));
    cr_assert_str_eq(image_find_attr(&back, "mcpt.sample-ranges"), "0:16,32:48");
    cr_assert_str_eq(image_find_attr(&back, "mcpt.render"), img.attr_values[1]);
    cr_assert_null(image_find_attr(&back, "mcpt.nothing"));
    image_free(&back);

    img.n_attrs = 0;
    cr_assert(image_write_exr(path, &img, &err), "%s", err.msg);
    cr_assert(image_read_exr(path, &back, &err), "%s", err.msg);
    cr_assert_eq(back.n_attrs, 0);
    cr_assert_null(image_find_attr(&back, "mcpt.sample-ranges"));
    image_free(&back);
    for (int c = 0; c < IMAGE_MAX_CHANNELS; c++)
        free(img.data[c]);
}

/* A second write replaces the first (rename over an existing file) and leaves one file. */
Test(image, exr_overwrite_replaces_file)
{
    const char *names[] = {"R"};
    struct image img;
    image_make(&img, 5, 3, 1, names);
    char path[256];
    scratch_path(path, sizeof path, "over.exr");
    struct mcpt_error err;
    for (int pass = 0; pass < 2; pass++) {
        for (int i = 0; i < 15; i++)
            img.data[0][i] = (float)(pass * 100 + i);
        cr_assert(image_write_exr(path, &img, &err), "%s", err.msg);
    }
    struct image back;
    cr_assert(image_read_exr(path, &back, &err), "%s", err.msg);
    for (int i = 0; i < 15; i++)
        cr_assert_eq(back.data[0][i], (float)(100 + i));
    image_free(&back);
    free(img.data[0]);
    cr_assert_eq(count_entries(), 1);
}

/* image_find_channel matches the whole name exactly (case, no prefixes). */
Test(image, find_channel_is_exact)
{
    struct image img;
    memset(&img, 0, sizeof img);
    img.n_channels = 3;
    strcpy(img.names[0], "R");
    strcpy(img.names[1], "variance.R");
    strcpy(img.names[2], "spp");
    cr_assert_eq(image_find_channel(&img, "R"), 0);
    cr_assert_eq(image_find_channel(&img, "variance.R"), 1);
    cr_assert_eq(image_find_channel(&img, "spp"), 2);
    cr_assert_eq(image_find_channel(&img, "r"), -1);
    cr_assert_eq(image_find_channel(&img, "variance"), -1);
    cr_assert_eq(image_find_channel(&img, "variance.R2"), -1);
    cr_assert_eq(image_find_channel(&img, ""), -1);
}

/* ---- EXR files from elsewhere ---------------------------------------------------------------- */

static float half_to_float_ref(uint16_t h)
{
    int exponent = (h >> 10) & 31;
    int mantissa = h & 1023;
    float v;
    if (exponent == 0)
        v = ldexpf((float)mantissa, -24); /* denormal: m 2^-24 */
    else if (exponent == 31)
        v = mantissa ? NAN : INFINITY;
    else
        v = ldexpf((float)(mantissa | 1024), exponent - 25); /* (1 + m/1024) 2^(e-15) */
    return (h & 0x8000) ? -v : v;
}

static uint32_t le32(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* A 16x16 uncompressed half-float A,B,G,R scanline file written by the C++ OpenEXR library
 * (CPython's imghdr test image) reads as the values decoded here by hand from its bytes,
 * following "OpenEXR File Layout": header attributes up to an empty name, one 8-byte offset per
 * scanline, then each line as int32 y, int32 size, and each channel's 16 halves in name order. */
Test(image, exr_reads_half_scanline_file_from_cpp_library)
{
    const char *path = "tests/data/image/python.exr";
    struct image img;
    struct mcpt_error err;
    cr_assert(image_read_exr(path, &img, &err), "%s", err.msg);
    cr_assert_eq(img.width, 16);
    cr_assert_eq(img.height, 16);
    cr_assert_eq(img.n_channels, 4);
    const char *names[] = {"A", "B", "G", "R"};
    for (int c = 0; c < 4; c++)
        cr_assert_str_eq(img.names[c], names[c]);

    size_t n_bytes;
    unsigned char *buf = read_bytes(path, &n_bytes);
    size_t pos = 8; /* magic and version */
    while (buf[pos] != 0) {
        pos += strlen((const char *)buf + pos) + 1; /* name */
        pos += strlen((const char *)buf + pos) + 1; /* type */
        pos += 4 + le32(buf + pos);                 /* size and value */
    }
    pos += 1; /* the empty name ending the header */
    int n_nonzero = 0;
    for (int y = 0; y < 16; y++) {
        size_t chunk = le32(buf + pos + 8 * (size_t)y); /* offsets are < 4 GiB here */
        cr_assert_eq(le32(buf + chunk), (uint32_t)y);
        cr_assert_eq(le32(buf + chunk + 4), 4u * 16u * 2u);
        const unsigned char *p = buf + chunk + 8;
        for (int c = 0; c < 4; c++) {
            for (int x = 0; x < 16; x++, p += 2) {
                float expected = half_to_float_ref((uint16_t)(p[0] | p[1] << 8));
                cr_assert_eq(img.data[c][y * 16 + x], expected, "%s(%d, %d)", names[c], x, y);
                n_nonzero += expected != 0.0f;
            }
        }
    }
    cr_assert_gt(n_nonzero, 100, "the comparison must not be all zeros");
    free(buf);
    image_free(&img);
}

/* A tiled, mip-mapped, ZIP file (tests/data/image/README) with a half channel Y, a float channel
 * Z and a uint channel id, 21x13 pixels in 8x4 tiles (partial tiles at the right and bottom),
 * data window origin (-3, 5): the full-resolution level is read, uint converts to the nearest
 * float, and the lower mip levels (all -1) are ignored. */
Test(image, exr_reads_tiled_half_float_uint_file)
{
    struct image img;
    struct mcpt_error err;
    cr_assert(image_read_exr("tests/data/image/tiled_mixed.exr", &img, &err), "%s", err.msg);
    cr_assert_eq(img.width, 21);
    cr_assert_eq(img.height, 13);
    cr_assert_eq(img.n_channels, 3);
    cr_assert_str_eq(img.names[0], "Y");
    cr_assert_str_eq(img.names[1], "Z");
    cr_assert_str_eq(img.names[2], "id");
    for (int y = 0; y < 13; y++) {
        for (int x = 0; x < 21; x++) {
            int i = y * 21 + x;
            cr_assert_eq(img.data[0][i], (float)(x - 10) * 0.25f + (float)y * 8.0f, "Y(%d, %d)", x,
                         y);
            cr_assert_eq(img.data[1][i], (float)x * 1000.5f - (float)y * 0.125f, "Z(%d, %d)", x, y);
            float id = (x == 0 && y == 0) ? (float)4294967295u : (float)(x + 100 * y);
            cr_assert_eq(img.data[2][i], id, "id(%d, %d)", x, y);
        }
    }
    image_free(&img);
}

/* A scanline RLE file of half R, G, B (one scanline a chunk), 11x9 pixels, data window origin
 * (2, -7): each chunk lands on its own row, counted from the window's top-left corner. */
Test(image, exr_reads_half_scanline_file_with_offset_window)
{
    struct image img;
    struct mcpt_error err;
    cr_assert(image_read_exr("tests/data/image/scanline_half.exr", &img, &err), "%s", err.msg);
    cr_assert_eq(img.width, 11);
    cr_assert_eq(img.height, 9);
    cr_assert_eq(img.n_channels, 3);
    int r = image_find_channel(&img, "R");
    int g = image_find_channel(&img, "G");
    int b = image_find_channel(&img, "B");
    cr_assert(r >= 0 && g >= 0 && b >= 0);
    for (int y = 0; y < 9; y++) {
        for (int x = 0; x < 11; x++) {
            int i = y * 11 + x;
            cr_assert_eq(img.data[r][i], (float)x + 0.5f * (float)y, "R(%d, %d)", x, y);
            cr_assert_eq(img.data[g][i], -0.25f * (float)x, "G(%d, %d)", x, y);
            cr_assert_eq(img.data[b][i], 16.0f * (float)y + 0.125f, "B(%d, %d)", x, y);
        }
    }
    image_free(&img);
}

/* ---- EXR errors ------------------------------------------------------------------------------ */

/* A missing file is reported with the path, no line, and strerror. */
Test(image, exr_read_missing_file_fails)
{
    char path[256];
    scratch_path(path, sizeof path, "missing.exr");
    struct image img;
    struct mcpt_error err;
    cr_assert_not(image_read_exr(path, &img, &err));
    cr_assert_str_eq(err.file, path);
    cr_assert_eq(err.line, 0);
    cr_assert_str_eq(err.msg, "cannot open: No such file or directory");
    cr_assert_eq(img.n_channels, 0);
    cr_assert_null(img.data[0]);
}

/* Garbage bytes, an empty file, a PNG and a folder are refused with a message, not a crash. */
Test(image, exr_read_non_exr_fails)
{
    char path[256];
    struct image img;
    struct mcpt_error err;
    unsigned char garbage[1000];
    uint32_t state = 12345;
    for (size_t i = 0; i < sizeof garbage; i++)
        garbage[i] = (unsigned char)xorshift32(&state);
    write_bytes(scratch_path(path, sizeof path, "garbage.exr"), garbage, sizeof garbage);
    cr_assert_not(image_read_exr(path, &img, &err));
    cr_assert_str_eq(err.file, path);
    cr_assert(strncmp(err.msg, "cannot read OpenEXR header: ", 28) == 0, "%s", err.msg);
    cr_assert_eq(img.n_channels, 0);

    write_bytes(scratch_path(path, sizeof path, "empty.exr"), "", 0);
    cr_assert_not(image_read_exr(path, &img, &err));
    cr_assert(strncmp(err.msg, "cannot read OpenEXR header: ", 28) == 0, "%s", err.msg);

    const uint8_t rgb8[3] = {1, 2, 3};
    cr_assert(image_write_png_rgb8(scratch_path(path, sizeof path, "a.png"), 1, 1, rgb8, &err));
    cr_assert_not(image_read_exr(path, &img, &err));
    cr_assert(strncmp(err.msg, "cannot read OpenEXR header: ", 28) == 0, "%s", err.msg);

    cr_assert_not(image_read_exr(g_dir, &img, &err));
    cr_assert_str_eq(err.msg, "expected a regular file, got a directory");
}

/* A valid file cut short (its chunk table points past the end) fails in the pixel data, and the
 * partly read image is freed. */
Test(image, exr_read_truncated_file_fails)
{
    const char *names[] = {"R", "G", "B"};
    struct image img;
    image_make(&img, 64, 40, 3, names);
    uint32_t state = 7;
    for (int c = 0; c < 3; c++)
        for (int i = 0; i < 64 * 40; i++)
            img.data[c][i] = float_from_bits(xorshift32(&state));
    char path[256];
    struct mcpt_error err;
    cr_assert(image_write_exr(scratch_path(path, sizeof path, "cut.exr"), &img, &err), "%s",
              err.msg);
    for (int c = 0; c < 3; c++)
        free(img.data[c]);
    size_t n_bytes;
    unsigned char *buf = read_bytes(path, &n_bytes);
    write_bytes(path, buf, n_bytes * 6 / 10);
    free(buf);
    struct image back;
    cr_assert_not(image_read_exr(path, &back, &err));
    cr_assert(strncmp(err.msg, "cannot read OpenEXR", 19) == 0, "%s", err.msg);
    cr_assert_eq(back.n_channels, 0);
    cr_assert_null(back.data[0]);
}

/* Images the writer cannot store are refused before any file is made (golden messages). */
Test(image, exr_write_rejects_invalid_images)
{
    const char *names[] = {"R", "R"};
    struct image img;
    image_make(&img, 4, 4, 2, names);
    char path[256];
    scratch_path(path, sizeof path, "bad.exr");
    struct mcpt_error err;
    cr_assert_not(image_write_exr(path, &img, &err));
    cr_assert_str_eq(err.msg, "expected unique channel names, got 'R' twice");
    img.n_channels = IMAGE_MAX_CHANNELS + 1;
    cr_assert_not(image_write_exr(path, &img, &err));
    char want[64];
    snprintf(want, sizeof want, "expected 1 to %d channels, got %d", IMAGE_MAX_CHANNELS,
             IMAGE_MAX_CHANNELS + 1);
    cr_assert_str_eq(err.msg, want);
    img.n_channels = 1;
    img.width = 0;
    cr_assert_not(image_write_exr(path, &img, &err));
    cr_assert_str_eq(err.msg, "expected a positive image size, got 0x4");
    cr_assert_str_eq(err.file, path);
    cr_assert_eq(err.line, 0);
    cr_assert_eq(count_entries(), 0);
    free(img.data[0]);
    free(img.data[1]);
}

/* ---- atomic replacement ---------------------------------------------------------------------- */

/* A destination in a folder that does not exist fails with strerror and creates nothing. */
Test(image, write_into_missing_folder_fails)
{
    char path[256];
    scratch_path(path, sizeof path, "no/such/folder/out.exr");
    const char *names[] = {"R"};
    struct image img;
    image_make(&img, 2, 2, 1, names);
    memset(img.data[0], 0, 4 * sizeof(float));
    struct mcpt_error err;
    cr_assert_not(image_write_exr(path, &img, &err));
    cr_assert_str_eq(err.msg, "cannot write: No such file or directory");
    cr_assert_str_eq(err.file, path);
    const uint8_t rgb8[12] = {0};
    scratch_path(path, sizeof path, "no/such/folder/out.png");
    cr_assert_not(image_write_png_rgb8(path, 2, 2, rgb8, &err));
    cr_assert_str_eq(err.msg, "cannot write: No such file or directory");
    const float rgb[12] = {0};
    cr_assert_not(image_write_png_srgb(path, 2, 2, rgb, NULL, &err));
    cr_assert_str_eq(err.msg, "cannot write: No such file or directory");
    cr_assert_eq(count_entries(), 0);
    free(img.data[0]);
}

/* A write refused up front (width 0) leaves the existing file byte for byte and no temporary. */
Test(image, refused_write_keeps_existing_file)
{
    char path[256];
    scratch_path(path, sizeof path, "keep.png");
    const uint8_t rgb8[3 * 6] = {10, 20, 30, 40, 50, 60, 70, 80, 90, 1, 2, 3, 4, 5, 6, 7, 8, 9};
    struct mcpt_error err;
    cr_assert(image_write_png_rgb8(path, 3, 2, rgb8, &err), "%s", err.msg);
    size_t n_before;
    unsigned char *before = read_bytes(path, &n_before);
    cr_assert_not(image_write_png_rgb8(path, 0, 2, rgb8, &err));
    cr_assert_str_eq(err.msg, "expected a positive image size, got 0x2");
    const float rgb[3 * 6] = {0};
    cr_assert_not(image_write_png_srgb(path, 3, -1, rgb, NULL, &err));
    size_t n_after;
    unsigned char *after = read_bytes(path, &n_after);
    cr_assert_eq(n_after, n_before);
    cr_assert_eq(memcmp(before, after, n_before), 0);
    cr_assert_eq(count_entries(), 1);
    free(before);
    free(after);
}

/* A write that fails in the middle (the file size limit RLIMIT_FSIZE makes write() fail with
 * EFBIG after 4 KiB) reports strerror, leaves the existing file intact and removes the
 * temporary: the EXR and both PNG writers. */
Test(image, failed_write_midway_keeps_existing_file, .timeout = TEST_TIMEOUT_S(30))
{
    char exr_path[256];
    char png_path[256];
    scratch_path(exr_path, sizeof exr_path, "big.exr");
    scratch_path(png_path, sizeof png_path, "big.png");
    const int w = 128;
    const int h = 128;
    const char *names[] = {"R", "G", "B"};
    struct image img;
    image_make(&img, w, h, 3, names);
    uint32_t state = 99;
    for (int c = 0; c < 3; c++)
        for (int i = 0; i < w * h; i++)
            img.data[c][i] = float_from_bits(xorshift32(&state) & 0x3FFFFFFFu);
    uint8_t *rgb8 = malloc((size_t)w * h * 3);
    float *rgb = malloc((size_t)w * h * 3 * sizeof(float));
    for (int i = 0; i < w * h * 3; i++) {
        rgb8[i] = (uint8_t)xorshift32(&state);
        rgb[i] = (float)(xorshift32(&state) >> 8) * 0x1p-24f;
    }
    /* small old files, under the limit */
    const uint8_t old_rgb8[3] = {1, 2, 3};
    struct mcpt_error err;
    cr_assert(image_write_png_rgb8(png_path, 1, 1, old_rgb8, &err), "%s", err.msg);
    struct image old_img;
    image_make(&old_img, 1, 1, 1, names);
    old_img.data[0][0] = 42.0f;
    cr_assert(image_write_exr(exr_path, &old_img, &err), "%s", err.msg);
    size_t n_old_png;
    size_t n_old_exr;
    unsigned char *old_png = read_bytes(png_path, &n_old_png);
    unsigned char *old_exr = read_bytes(exr_path, &n_old_exr);

    /* EFBIG instead of the signal; Criterion runs each test in its own process, and both are
     * restored below for runs without fork */
    void (*old_handler)(int) = signal(SIGXFSZ, SIG_IGN);
    struct rlimit old_lim;
    cr_assert_eq(getrlimit(RLIMIT_FSIZE, &old_lim), 0);
    struct rlimit lim = old_lim;
    lim.rlim_cur = 4096;
    cr_assert_eq(setrlimit(RLIMIT_FSIZE, &lim), 0);

    char efbig[128];
    snprintf(efbig, sizeof efbig, "cannot write: %s", strerror(EFBIG));
    cr_assert_not(image_write_exr(exr_path, &img, &err));
    cr_assert_str_eq(err.msg, efbig);
    cr_assert_not(image_write_png_rgb8(png_path, w, h, rgb8, &err));
    cr_assert_str_eq(err.msg, efbig);
    cr_assert_not(image_write_png_srgb(png_path, w, h, rgb, NULL, &err));
    cr_assert_str_eq(err.msg, efbig);
    /* no byte at all: the EXR header's write fails, inside the library's locked call, whose
     * error report once waited for that lock forever (a full disk hung mcpt; issue 15) */
    lim.rlim_cur = 0;
    cr_assert_eq(setrlimit(RLIMIT_FSIZE, &lim), 0);
    cr_assert_not(image_write_exr(exr_path, &img, &err));
    cr_assert_str_eq(err.msg, efbig);
    cr_assert_eq(setrlimit(RLIMIT_FSIZE, &old_lim), 0);
    signal(SIGXFSZ, old_handler);

    size_t n;
    unsigned char *now = read_bytes(png_path, &n);
    cr_assert(n == n_old_png && memcmp(now, old_png, n) == 0, "old PNG changed");
    free(now);
    now = read_bytes(exr_path, &n);
    cr_assert(n == n_old_exr && memcmp(now, old_exr, n) == 0, "old EXR changed");
    free(now);
    cr_assert_eq(count_entries(), 2, "a temporary file was left behind");
    struct image back;
    cr_assert(image_read_exr(exr_path, &back, &err), "%s", err.msg);
    cr_assert_eq(back.data[0][0], 42.0f);
    image_free(&back);

    free(old_png);
    free(old_exr);
    free(rgb8);
    free(rgb);
    free(old_img.data[0]);
    for (int c = 0; c < 3; c++)
        free(img.data[c]);
}

/* When the final rename fails (the destination is a folder), the finished temporary is removed
 * and the folder is left alone. */
Test(image, failed_rename_removes_temporary)
{
    char path[256];
    scratch_path(path, sizeof path, "dir.png");
    cr_assert_eq(mkdir(path, 0755), 0);
    const uint8_t rgb8[3] = {9, 9, 9};
    struct mcpt_error err;
    cr_assert_not(image_write_png_rgb8(path, 1, 1, rgb8, &err));
    cr_assert_str_eq(err.msg, "cannot write: Is a directory");
    cr_assert_eq(count_entries(), 1);
    struct stat st;
    cr_assert_eq(stat(path, &st), 0);
    cr_assert(S_ISDIR(st.st_mode));
}

/* ---- PNG ------------------------------------------------------------------------------------- */

/* The sRGB encoding of IEC 61966-2-1:1999 in double, clamped, rounded to 8 bits: the reference. */
static int srgb_byte_ref(double v)
{
    double V = v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
    V = fmin(fmax(V, 0.0), 1.0);
    return (int)floor(255.0 * V + 0.5);
}

/* Known values: 0 -> 0, 1 -> 255, 0.5 -> 188, 18% grey -> 118; the linear toe (0.0031308 ->
 * 10, 0.001 -> 3, 0.0002 -> 1, which the power branch would send to 0); clamping of negative,
 * above-one and infinite values; NaN -> 0.  Read back with libpng. */
Test(image, png_srgb_known_values)
{
    const float in[] = {0.0f,    1.0f,  0.5f, 0.18f,    0.0031308f, 0.001f, 0.0002f,
                        0.0001f, -1.0f, 2.0f, INFINITY, -INFINITY,  NAN,    1.0f / 255.0f};
    const int expected[] = {0, 255, 188, 118, 10, 3, 1, 0, 0, 255, 255, 0, 0, 13};
    const int n = (int)(sizeof in / sizeof in[0]);
    float rgb[3 * 14];
    for (int i = 0; i < n; i++)
        for (int c = 0; c < 3; c++)
            rgb[3 * i + c] = in[i];
    char path[256];
    struct mcpt_error err;
    cr_assert(image_write_png_srgb(scratch_path(path, sizeof path, "k.png"), n, 1, rgb, NULL, &err),
              "%s", err.msg);
    int w;
    int h;
    uint8_t *px = read_png_rgb8(path, &w, &h);
    cr_assert_eq(w, n);
    cr_assert_eq(h, 1);
    for (int i = 0; i < n; i++) {
        for (int c = 0; c < 3; c++)
            cr_assert_eq(px[3 * i + c], expected[i], "in %g: got %d, expected %d", in[i],
                         px[3 * i + c], expected[i]);
        if (isfinite(in[i]))
            cr_assert_eq(srgb_byte_ref(in[i]), expected[i], "table entry %d", i);
    }
    free(px);
    size_t n_bytes;
    unsigned char *file = read_bytes(path, &n_bytes);
    bool has_srgb_chunk = false;
    for (size_t i = 0; i + 4 <= n_bytes; i++)
        has_srgb_chunk |= memcmp(file + i, "sRGB", 4) == 0;
    cr_assert(has_srgb_chunk, "the sRGB preview should carry an sRGB chunk");
    free(file);
}

/* Exposure multiplies by 2^exposure before encoding: 0.25 at +1, 1 at -1 and 0.125 at +2 all
 * encode like 0.5 (188); 0.5 at +1 is 1.0 (255). */
Test(image, png_srgb_exposure_scales_by_powers_of_two)
{
    const struct {
        float v;
        float exposure;
        int expected;
    } cases[] = {{0.25f, 1.0f, 188}, {1.0f, -1.0f, 188}, {0.125f, 2.0f, 188}, {0.5f, 1.0f, 255}};
    char path[256];
    scratch_path(path, sizeof path, "e.png");
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        const float rgb[3] = {cases[k].v, cases[k].v, cases[k].v};
        struct mcpt_error err;
        struct image_look look = {.exposure = cases[k].exposure};
        cr_assert(image_write_png_srgb(path, 1, 1, rgb, &look, &err), "%s", err.msg);
        int w;
        int h;
        uint8_t *px = read_png_rgb8(path, &w, &h);
        cr_assert_eq(px[0], cases[k].expected, "%g at %+g stops: got %d", cases[k].v,
                     cases[k].exposure, px[0]);
        free(px);
    }
}

/* Over a dense ramp (4096 values over [-0.05, 1.2] in R, half that in G, twice in B) and at a
 * fractional exposure, every byte equals the double-precision reference encoding: the
 * threshold search in image.c rounds exactly like floor(255 V + 0.5). */
Test(image, png_srgb_matches_reference_on_ramp)
{
    const int w = 64;
    const int h = 64;
    float *rgb = malloc((size_t)w * h * 3 * sizeof(float));
    cr_assert_not_null(rgb);
    for (int i = 0; i < w * h; i++) {
        float v = -0.05f + 1.25f * (float)i / (float)(w * h - 1);
        rgb[3 * i + 0] = v;
        rgb[3 * i + 1] = 0.5f * v;
        rgb[3 * i + 2] = 2.0f * v;
    }
    const float exposures[] = {0.0f, 0.5f, -1.25f};
    char path[256];
    scratch_path(path, sizeof path, "ramp.png");
    for (int e = 0; e < 3; e++) {
        struct mcpt_error err;
        struct image_look look = {.exposure = exposures[e]};
        cr_assert(image_write_png_srgb(path, w, h, rgb, &look, &err), "%s", err.msg);
        int rw;
        int rh;
        uint8_t *px = read_png_rgb8(path, &rw, &rh);
        cr_assert_eq(rw, w);
        cr_assert_eq(rh, h);
        const float scale = exp2f(exposures[e]);
        for (int i = 0; i < w * h * 3; i++) {
            int expected = srgb_byte_ref((double)(rgb[i] * scale));
            cr_assert_eq(px[i], expected, "value %.9g at %+g stops: got %d, expected %d", rgb[i],
                         exposures[e], px[i], expected);
        }
        free(px);
    }
    free(rgb);
}

/* image_write_png_rgb8 stores the bytes as given (odd 13x7 size, random bytes), with no sRGB
 * chunk. */
Test(image, png_rgb8_round_trip)
{
    const int w = 13;
    const int h = 7;
    uint8_t rgb8[13 * 7 * 3];
    uint32_t state = 2024;
    for (size_t i = 0; i < sizeof rgb8; i++)
        rgb8[i] = (uint8_t)xorshift32(&state);
    char path[256];
    struct mcpt_error err;
    cr_assert(image_write_png_rgb8(scratch_path(path, sizeof path, "b.png"), w, h, rgb8, &err),
              "%s", err.msg);
    int rw;
    int rh;
    uint8_t *px = read_png_rgb8(path, &rw, &rh);
    cr_assert_eq(rw, w);
    cr_assert_eq(rh, h);
    cr_assert_eq(memcmp(px, rgb8, sizeof rgb8), 0);
    free(px);
    cr_assert_eq(count_entries(), 1);
}

/* image_srgb8 on doubles agrees with the reference encoding on a fine ramp over [0, 1] (and
 * beyond: clamped), and sends NaN and negative values to 0. */
Test(image, srgb8_matches_reference_on_doubles)
{
    struct image_srgb s;
    image_srgb_init(&s);
    for (int i = -100; i <= 110000; i++) {
        double v = i * 1e-5;
        cr_assert_eq(image_srgb8(&s, v), srgb_byte_ref(v), "v = %.17g", v);
    }
    cr_assert_eq(image_srgb8(&s, NAN), 0);
    cr_assert_eq(image_srgb8(&s, -INFINITY), 0);
    cr_assert_eq(image_srgb8(&s, INFINITY), 255);
}

/* The tone curves on known inputs (image.h): clamp passes values through; reinhard is
 * Reinhard et al. 2002's eq. 3, L / (1 + L), on the Rec. 709 luminance Y, every channel scaled
 * by 1 / (1 + Y) (grey 1 -> 0.5, red 3 -> 3 / 1.6378, blue 4 -> 4 / 1.2888); aces is
 * Narkowicz 2016's fit x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14) per channel, clamped to
 * [0, 1] (1 -> 2.54 / 3.16, 0.18 -> 0.086724 / 0.324932, 10 -> 1, -1 -> 0, inf -> 1); NaN
 * stays NaN. */
Test(image, tone_curves_on_known_values)
{
    const struct {
        enum image_tonemap t;
        double in[3];
        double out[3];
    } cases[] = {
        {IMAGE_TONEMAP_CLAMP, {2.0, 0.5, -1.0}, {2.0, 0.5, -1.0}},
        {IMAGE_TONEMAP_REINHARD, {1.0, 1.0, 1.0}, {0.5, 0.5, 0.5}},
        {IMAGE_TONEMAP_REINHARD, {3.0, 0.0, 0.0}, {3.0 / 1.6378, 0.0, 0.0}},
        {IMAGE_TONEMAP_REINHARD, {0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}},
        {IMAGE_TONEMAP_REINHARD, {0.0, 0.0, 4.0}, {0.0, 0.0, 4.0 / 1.2888}},
        {IMAGE_TONEMAP_ACES, {1.0, 0.18, 0.0}, {2.54 / 3.16, 0.086724 / 0.324932, 0.0}},
        {IMAGE_TONEMAP_ACES, {10.0, -1.0, INFINITY}, {1.0, 0.0, 1.0}},
    };
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        double out[3];
        image_tonemap_rgb(cases[k].t, cases[k].in, out);
        for (int c = 0; c < 3; c++)
            cr_assert(fabs(out[c] - cases[k].out[c]) <= 1e-12 * fmax(1.0, fabs(cases[k].out[c])),
                      "case %zu channel %d: %.17g, expected %.17g", k, c, out[c], cases[k].out[c]);
    }
    const enum image_tonemap all[] = {IMAGE_TONEMAP_CLAMP, IMAGE_TONEMAP_REINHARD,
                                      IMAGE_TONEMAP_ACES};
    for (int k = 0; k < 3; k++) {
        double out[3];
        image_tonemap_rgb(all[k], (const double[3]){NAN, 0.5, 0.5}, out);
        cr_assert(isnan(out[0]), "%s: NaN in, %g out", image_tonemap_name(all[k]), out[0]);
        enum image_tonemap back;
        cr_assert(image_tonemap_parse(image_tonemap_name(all[k]), &back) && back == all[k]);
    }
    enum image_tonemap t;
    cr_assert_not(image_tonemap_parse("filmic", &t));
    cr_assert_not(image_tonemap_parse("ACES", &t));
}

/* A Blender multilayer EXR with every render pass (96 channels, tests/data/image/README): more
 * than an image holds, so the reader keeps the colour image_find_rgb takes (the layer named
 * Combined) and leaves the passes out; its pixels are those of the same render saved as plain
 * R, G, B.  With no layer named Combined among the many it refuses the file, naming what it
 * expected.  Before, both were refused for having more than IMAGE_MAX_CHANNELS channels. */
Test(image, exr_reads_the_colour_of_a_file_with_many_channels)
{
    struct image layers, plain;
    struct mcpt_error err;
    cr_assert(image_read_exr("tests/data/image/blender-passes.exr", &layers, &err), "%s", err.msg);
    cr_assert(image_read_exr("tests/data/image/blender-single.exr", &plain, &err), "%s", err.msg);
    cr_assert_eq(layers.n_channels, 3);
    const char *names[3] = {"ViewLayer.Combined.R", "ViewLayer.Combined.G", "ViewLayer.Combined.B"};
    int idx[3], plain_idx[3];
    size_t prefix_len;
    cr_assert(image_find_rgb(&layers, idx, &prefix_len));
    cr_assert_eq(prefix_len, strlen("ViewLayer.Combined."));
    cr_assert(image_find_rgb(&plain, plain_idx, &prefix_len));
    cr_assert_eq(prefix_len, 0);
    cr_assert_eq(layers.width, plain.width);
    cr_assert_eq(layers.height, plain.height);
    double sum = 0.0;
    for (int c = 0; c < 3; c++) {
        cr_assert_str_eq(layers.names[idx[c]], names[c]);
        for (int i = 0; i < layers.width * layers.height; i++) {
            cr_assert_eq(layers.data[idx[c]][i], plain.data[plain_idx[c]][i], "%s[%d]", names[c],
                         i);
            sum += plain.data[plain_idx[c]][i];
        }
    }
    cr_assert_gt(sum, 0.0); /* a lit render, not an empty plane */
    image_free(&layers);
    image_free(&plain);

    const char *renamed = "tests/data/image/blender-passes-renamed.exr";
    cr_assert_not(image_read_exr(renamed, &layers, &err));
    cr_assert_str_eq(err.file, renamed);
    cr_assert_str_eq(err.msg,
                     "expected at most 32 channels, or among more: channels R, G and B, or one "
                     "layer's (LAYER.R, LAYER.G, LAYER.B; of several, the one named Combined), "
                     "got 96 channels without them");
    cr_assert_eq(layers.n_channels, 0);
}
