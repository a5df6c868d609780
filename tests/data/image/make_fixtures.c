/* make_fixtures.c - one-off program that wrote tiled_mixed.exr and scanline_half.exr (see README)
 * with OpenEXRCore 3.1.5.  Not part of the build; kept so the fixtures can be re-made:
 *     gcc -std=c11 $(pkg-config --cflags OpenEXR) make_fixtures.c -lOpenEXRCore-3_1 -o /tmp/mk
 *     cd tests/data/image && /tmp/mk */
#include <openexr.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CHECK(call)                                                                                \
    do {                                                                                           \
        exr_result_t rv_ = (call);                                                                 \
        if (rv_ != EXR_ERR_SUCCESS) {                                                              \
            fprintf(stderr, "%s: %s\n", #call, exr_get_default_error_message(rv_));                \
            return 1;                                                                              \
        }                                                                                          \
    } while (0)

/* Points each encoder channel at its plane: base[k] for the channel named names[k]. */
static void set_channels(exr_encode_pipeline_t *enc, const char *const *names, void *const *base,
                         const int *is_uint, size_t offset_px, int line_px)
{
    for (int c = 0; c < enc->channel_count; c++) {
        int k = 0;
        while (strcmp(names[k], enc->channels[c].channel_name) != 0)
            k++;
        enc->channels[c].encode_from_ptr = (const uint8_t *)base[k] + 4 * offset_px;
        enc->channels[c].user_pixel_stride = 4;
        enc->channels[c].user_line_stride = 4 * line_px;
        enc->channels[c].user_bytes_per_element = 4;
        enc->channels[c].user_data_type = is_uint[k] ? EXR_PIXEL_UINT : EXR_PIXEL_FLOAT;
    }
}

/* 21x13, 8x4 tiles, mip-mapped, ZIP, window origin (-3, 5): Y half, Z float, id uint. */
static int write_tiled(void)
{
    const int w = 21, h = 13, tile_w = 8, tile_h = 4;
    const char *names[] = {"Y", "Z", "id"};
    const int is_uint[] = {0, 0, 1};
    exr_context_t ctx;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    CHECK(exr_start_write(&ctx, "tiled_mixed.exr", EXR_WRITE_FILE_DIRECTLY, &init));
    int part;
    CHECK(exr_add_part(ctx, "", EXR_STORAGE_TILED, &part));
    exr_attr_box2i_t dw;
    dw.min.x = -3;
    dw.min.y = 5;
    dw.max.x = -3 + w - 1;
    dw.max.y = 5 + h - 1;
    exr_attr_v2f_t center = {0};
    CHECK(exr_initialize_required_attr(ctx, part, &dw, &dw, 1.0f, &center, 1.0f,
                                       EXR_LINEORDER_INCREASING_Y, EXR_COMPRESSION_ZIP));
    CHECK(exr_set_tile_descriptor(ctx, part, tile_w, tile_h, EXR_TILE_MIPMAP_LEVELS,
                                  EXR_TILE_ROUND_DOWN));
    CHECK(exr_add_channel(ctx, part, "Y", EXR_PIXEL_HALF, EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1));
    CHECK(exr_add_channel(ctx, part, "Z", EXR_PIXEL_FLOAT, EXR_PERCEPTUALLY_LINEAR, 1, 1));
    CHECK(exr_add_channel(ctx, part, "id", EXR_PIXEL_UINT, EXR_PERCEPTUALLY_LINEAR, 1, 1));
    CHECK(exr_write_header(ctx));
    int n_levels_x, n_levels_y;
    CHECK(exr_get_tile_levels(ctx, part, &n_levels_x, &n_levels_y));
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    int is_ready = 0;
    for (int level = 0; level < n_levels_x; level++) {
        int lw, lh;
        CHECK(exr_get_level_sizes(ctx, part, level, level, &lw, &lh));
        /* tile_h spare rows: OpenEXRCore 3.1.5 reads a row past the last one when encoding
         * the bottom tiles of level 1 (seen with valgrind) */
        float *y_plane = malloc((size_t)lw * (lh + tile_h) * 4);
        float *z_plane = malloc((size_t)lw * (lh + tile_h) * 4);
        unsigned *id_plane = malloc((size_t)lw * (lh + tile_h) * 4);
        for (int y = 0; y < lh + tile_h; y++) {
            for (int x = 0; x < lw; x++) {
                int i = y * lw + x;
                y_plane[i] = level ? -1.0f : (float)(x - 10) * 0.25f + (float)y * 8.0f;
                z_plane[i] = level ? -1.0f : (float)x * 1000.5f - (float)y * 0.125f;
                id_plane[i] = level                ? 7u
                              : (x == 0 && y == 0) ? 4294967295u
                                                   : (unsigned)(x + 100 * y);
            }
        }
        void *base[] = {y_plane, z_plane, id_plane};
        for (int ty = 0; ty < (lh + tile_h - 1) / tile_h; ty++) {
            for (int tx = 0; tx < (lw + tile_w - 1) / tile_w; tx++) {
                exr_chunk_info_t chunk;
                CHECK(exr_write_tile_chunk_info(ctx, part, tx, ty, level, level, &chunk));
                CHECK(is_ready ? exr_encoding_update(ctx, part, &chunk, &enc)
                               : exr_encoding_initialize(ctx, part, &chunk, &enc));
                set_channels(&enc, names, base, is_uint,
                             (size_t)ty * tile_h * lw + (size_t)tx * tile_w, lw);
                if (!is_ready)
                    CHECK(exr_encoding_choose_default_routines(ctx, part, &enc));
                is_ready = 1;
                CHECK(exr_encoding_run(ctx, part, &enc));
            }
        }
        free(y_plane);
        free(z_plane);
        free(id_plane);
    }
    exr_encoding_destroy(ctx, &enc);
    CHECK(exr_finish(&ctx));
    return 0;
}

/* 11x9 scanline, RLE (one line a chunk), window origin (2, -7): R, G, B half. */
static int write_scanline(void)
{
    const int w = 11, h = 9;
    const char *names[] = {"R", "G", "B"};
    const int is_uint[] = {0, 0, 0};
    exr_context_t ctx;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    CHECK(exr_start_write(&ctx, "scanline_half.exr", EXR_WRITE_FILE_DIRECTLY, &init));
    int part;
    CHECK(exr_add_part(ctx, "", EXR_STORAGE_SCANLINE, &part));
    exr_attr_box2i_t dw;
    dw.min.x = 2;
    dw.min.y = -7;
    dw.max.x = 2 + w - 1;
    dw.max.y = -7 + h - 1;
    exr_attr_v2f_t center = {0};
    CHECK(exr_initialize_required_attr(ctx, part, &dw, &dw, 1.0f, &center, 1.0f,
                                       EXR_LINEORDER_INCREASING_Y, EXR_COMPRESSION_RLE));
    for (int c = 0; c < 3; c++)
        CHECK(exr_add_channel(ctx, part, names[c], EXR_PIXEL_HALF, EXR_PERCEPTUALLY_LOGARITHMIC, 1,
                              1));
    CHECK(exr_write_header(ctx));
    float *plane[3];
    for (int c = 0; c < 3; c++)
        plane[c] = malloc((size_t)w * h * 4);
    for (int y = 0; y < h; y++) {
        for (int x = 0; x < w; x++) {
            plane[0][y * w + x] = (float)x + 0.5f * (float)y;
            plane[1][y * w + x] = -0.25f * (float)x;
            plane[2][y * w + x] = 16.0f * (float)y + 0.125f;
        }
    }
    void *base[] = {plane[0], plane[1], plane[2]};
    int lines_per_chunk;
    CHECK(exr_get_scanlines_per_chunk(ctx, part, &lines_per_chunk));
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    int is_ready = 0;
    for (int y = 0; y < h; y += lines_per_chunk) {
        exr_chunk_info_t chunk;
        CHECK(exr_write_scanline_chunk_info(ctx, part, dw.min.y + y, &chunk));
        CHECK(is_ready ? exr_encoding_update(ctx, part, &chunk, &enc)
                       : exr_encoding_initialize(ctx, part, &chunk, &enc));
        set_channels(&enc, names, base, is_uint, (size_t)y * w, w);
        if (!is_ready)
            CHECK(exr_encoding_choose_default_routines(ctx, part, &enc));
        is_ready = 1;
        CHECK(exr_encoding_run(ctx, part, &enc));
    }
    exr_encoding_destroy(ctx, &enc);
    CHECK(exr_finish(&ctx));
    for (int c = 0; c < 3; c++)
        free(plane[c]);
    return 0;
}

int main(void) { return write_tiled() || write_scanline(); }
