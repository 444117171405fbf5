/* test_png.c: common/png.c, the libpng reader and writer, against values computed
 * here: the 8-bit quantisation of written floats, 16-bit, palette and grey+alpha files
 * made with libpng itself, and files that must be refused before allocation. */
#include "testing.h"

#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <mcpost/imageio.h>

#define tmp_path mcp_test_path

/* CRC-32 as PNG chunks carry it (ISO 3309), bit by bit: for patching a header. */
static uint32_t
crc32_of(const unsigned char *p, size_t n)
{
    uint32_t c = 0xffffffffu;
    for (size_t i = 0; i < n; i++) {
        c ^= p[i];
        for (int k = 0; k < 8; k++)
            c = c & 1 ? 0xedb88320u ^ (c >> 1) : c >> 1;
    }
    return c ^ 0xffffffffu;
}

/* A PNG written by libpng directly: rows of `bytes_per_row` bytes. */
static void
write_raw_png(const char *path, int w, int h, int bit_depth, int color_type,
              const unsigned char *data, size_t bytes_per_row, const png_color *palette,
              int n_palette)
{
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png_create_info_struct(png);
    png_init_io(png, f);
    png_set_IHDR(png, info, (png_uint_32)w, (png_uint_32)h, bit_depth, color_type,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    if (palette) png_set_PLTE(png, info, palette, n_palette);
    png_write_info(png, info);
    if (bit_depth == 16) png_set_swap(png); /* data holds host-order samples */
    for (int y = 0; y < h; y++)
        png_write_row(png, data + (size_t)y * bytes_per_row);
    png_write_end(png, info);
    png_destroy_write_struct(&png, &info);
    fclose(f);
}

static void
test_float_round_trip(void **state)
{
    (void)state;
    static const char *const rgba[] = {"R", "G", "B", "A"};
    for (int c = 1; c <= 4; c += (c == 1 ? 2 : 1)) {
        mcp_image *img = mcp_test_random(37, 23, c, -0.2f, 1.3f, 40 + c, c == 1 ? NULL : rgba);
        const char *path = tmp_path("round.png");
        assert_int_equal(mcp_image_write(img, path, NULL), 0);
        mcp_image *back = NULL;
        assert_int_equal(mcp_image_read(path, NULL, &back), 0);
        assert_int_equal(back->channels, c);
        assert_string_equal(back->names[0], c == 1 ? "Y" : "R");
        for (int i = 0; i < 37 * 23 * c; i++) {
            int alpha = c == 4 && i % 4 == 3;
            float v = img->data[i];
            v = v < 0 ? 0 : v > 1 ? 1 : v;
            if (!alpha) v = mcp_linear_to_srgb(v);
            float q = (float)(unsigned char)(v * 255.0f + 0.5f) / 255.0f;
            float want = alpha ? q : mcp_srgb_to_linear(q);
            assert_true(back->data[i] == want);
        }
        mcp_image_free(back);
        mcp_image_free(img);
    }
}

static void
test_bytes_and_decoding(void **state)
{
    (void)state;
    unsigned char rgb[5 * 3 * 3];
    for (int i = 0; i < 45; i++)
        rgb[i] = (unsigned char)(i * 5 + 3);
    const char *path = tmp_path("bytes.png");
    assert_int_equal(mcp_write_rgb8(rgb, 5, 3, path), 0);
    mcp_read_options ro = mcp_read_defaults();
    ro.srgb_decode = 0;
    mcp_image *back = NULL;
    assert_int_equal(mcp_image_read(path, &ro, &back), 0);
    for (int i = 0; i < 45; i++)
        assert_true(back->data[i] == rgb[i] / 255.0f);
    mcp_image_free(back);
}

static void
test_other_layouts(void **state)
{
    (void)state;
    mcp_read_options ro = mcp_read_defaults();
    ro.srgb_decode = 0;
    mcp_image *back = NULL;
    /* 16-bit RGB */
    uint16_t deep[4 * 2 * 3];
    for (int i = 0; i < 24; i++)
        deep[i] = (uint16_t)(i * 2731 + 7);
    const char *path = tmp_path("deep.png");
    write_raw_png(path, 4, 2, 16, PNG_COLOR_TYPE_RGB, (const unsigned char *)deep, 4 * 6,
                  NULL, 0);
    assert_int_equal(mcp_image_read(path, &ro, &back), 0);
    for (int i = 0; i < 24; i++)
        assert_true(back->data[i] == deep[i] / 65535.0f);
    mcp_image_free(back);
    /* a palette of 2-bit indices expands to RGB */
    png_color pal[4] = {{0, 0, 0}, {255, 0, 0}, {0, 128, 0}, {1, 2, 3}};
    unsigned char idx[2] = {0x1b, 0xe4}; /* indices 0 1 2 3 / 3 2 1 0 */
    path = tmp_path("palette.png");
    write_raw_png(path, 4, 2, 2, PNG_COLOR_TYPE_PALETTE, idx, 1, pal, 4);
    assert_int_equal(mcp_image_read(path, &ro, &back), 0);
    assert_int_equal(back->channels, 3);
    const int order[8] = {0, 1, 2, 3, 3, 2, 1, 0};
    for (int p = 0; p < 8; p++) {
        assert_true(back->data[3 * p] == pal[order[p]].red / 255.0f);
        assert_true(back->data[3 * p + 1] == pal[order[p]].green / 255.0f);
        assert_true(back->data[3 * p + 2] == pal[order[p]].blue / 255.0f);
    }
    mcp_image_free(back);
    /* grey + alpha: Y, A; alpha is never sRGB-decoded */
    unsigned char ga[2 * 2 * 2] = {10, 20, 30, 40, 50, 60, 70, 80};
    path = tmp_path("ga.png");
    write_raw_png(path, 2, 2, 8, PNG_COLOR_TYPE_GRAY_ALPHA, ga, 4, NULL, 0);
    assert_int_equal(mcp_image_read(path, NULL, &back), 0);
    assert_int_equal(back->channels, 2);
    assert_string_equal(back->names[1], "A");
    for (int i = 0; i < 8; i++)
        assert_true(back->data[i] == (i % 2 ? ga[i] / 255.0f
                                            : mcp_srgb_to_linear(ga[i] / 255.0f)));
    mcp_image_free(back);
}

static void
test_bad_files(void **state)
{
    (void)state;
    mcp_image *img = NULL;
    /* not a PNG */
    const char *path = tmp_path("text.png");
    FILE *f = fopen(path, "wb");
    fputs("hello, this is no image\n", f);
    fclose(f);
    assert_error_contains(mcp_image_read(path, NULL, &img), "text.png: not a readable PNG");
    /* a 12000 x 12000 header (under the pixel ceiling) in a 70-byte file: refused
     * before allocation */
    unsigned char one[3] = {1, 2, 3};
    path = tmp_path("huge.png");
    write_raw_png(path, 1, 1, 8, PNG_COLOR_TYPE_RGB, one, 3, NULL, 0);
    f = fopen(path, "r+b");
    unsigned char ihdr[4 + 13 + 4]; /* "IHDR", its data, its CRC */
    fseek(f, 12, SEEK_SET);
    assert_int_equal(fread(ihdr, 1, sizeof ihdr, f), sizeof ihdr);
    const unsigned char size[8] = {0, 0, 0x2e, 0xe0, 0, 0, 0x2e, 0xe0}; /* 12000 */
    memcpy(ihdr + 4, size, 8);
    uint32_t crc = crc32_of(ihdr, 17);
    for (int i = 0; i < 4; i++)
        ihdr[17 + i] = (unsigned char)(crc >> (24 - 8 * i));
    fseek(f, 12, SEEK_SET);
    fwrite(ihdr, 1, sizeof ihdr, f);
    fclose(f);
    assert_error_contains(mcp_image_read(path, NULL, &img),
                          "huge.png: truncated PNG (12000x12000 pixels cannot come from");
    assert_null(img);
    /* a real file cut short */
    mcp_image *big = mcp_test_random(64, 64, 3, 0.0f, 1.0f, 9, NULL);
    path = tmp_path("cut.png");
    assert_int_equal(mcp_image_write(big, path, NULL), 0);
    assert_int_equal(truncate(path, 200), 0);
    assert_error_contains(mcp_image_read(path, NULL, &img), "cut.png: not a readable PNG");
    assert_null(img);
    /* 2 channels cannot be written */
    mcp_image *two = mcp_test_random(4, 4, 2, 0.0f, 1.0f, 3, NULL);
    assert_error_contains(mcp_image_write(two, tmp_path("two.png"), NULL),
                          "two.png: png takes 1, 3 or 4 channels, not 2");
    mcp_image_free(two);
    mcp_image_free(big);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_float_round_trip),
        cmocka_unit_test(test_bytes_and_decoding),
        cmocka_unit_test(test_other_layouts),
        cmocka_unit_test(test_bad_files),
    };
    return cmocka_run_group_tests_name("common/png", tests, NULL, NULL);
}
