/* test_png.c: common/io/png.c, the libpng reader, and common/io/png_encode.c, the writer,
 * against values computed here: the 8-bit quantisation of written floats, 16-bit,
 * palette and grey+alpha files made with libpng itself, files that must be refused
 * before allocation, and the writer's files decoded by libpng directly. */
#include "testing.h"

#include <libdeflate.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <mcpost/imageio.h>

#include "../../common/filter/internal.h" /* colour maps on fewer levels */
#include "../../common/io/internal.h"     /* sRGB bytes from the step edges */

#include <math.h>

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
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
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
        mcp_image *img =
            mcp_test_random(37, 23, c, -0.2f, 1.3f, 40 + c, c == 1 ? NULL : rgba);
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

/* Rows that each make one of PNG's five filters the best (smallest sum of magnitudes),
 * in a cycle of seven: noise, a copy of it (Up: zeros), a ramp of step 7 (Sub: sevens),
 * zeros (None: zeros, and first on a tie), noise, a row that Average predicts exactly,
 * and one that Paeth predicts exactly after a first pixel of noise. */
static unsigned char *
filter_picture(int w, int h, int c, unsigned seed)
{
    size_t rb = (size_t)w * c;
    unsigned char *px = malloc(rb * h);
    for (int y = 0; y < h; y++) {
        unsigned char *r = px + (size_t)y * rb, *up = y ? r - rb : NULL;
        for (size_t i = 0; i < rb; i++) {
            int a = i >= (size_t)c ? r[i - c] : 0, b = up ? up[i] : 0;
            int cc = up && i >= (size_t)c ? up[i - c] : 0;
            int p = a + b - cc, pa = abs(p - a), pb = abs(p - b), pc = abs(p - cc);
            int paeth = pa <= pb && pa <= pc ? a : pb <= pc ? b : cc;
            seed = seed * 1664525u + 1013904223u;
            switch (y % 7) {
            case 1:
                r[i] = (unsigned char)b;
                break;
            case 2:
                r[i] = (unsigned char)(7 * (i / c) + 40 * (i % c));
                break;
            case 3:
                r[i] = 0;
                break;
            case 5:
                r[i] = (unsigned char)((a + b) >> 1);
                break;
            case 6: /* its first pixel is noise: a copy of the row above would tie */
                r[i] = (unsigned char)(i < (size_t)c ? seed >> 24 : (unsigned)paeth);
                break;
            default:
                r[i] = (unsigned char)(seed >> 24);
            }
        }
    }
    return px;
}

/* The filter-type byte of every row of a PNG the writer made, from its IDAT chunks
 * inflated by libdeflate; returns a bit per filter type seen. */
static unsigned
filter_types_used(const char *path, int w, int h, int c)
{
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *file = malloc((size_t)size), *stream = malloc((size_t)size);
    assert_int_equal(fread(file, 1, (size_t)size, f), (size_t)size);
    fclose(f);
    size_t at = 8, stream_bytes = 0;
    while (at + 12 <= (size_t)size) {
        size_t len = (size_t)file[at] << 24 | (size_t)file[at + 1] << 16 |
                     (size_t)file[at + 2] << 8 | file[at + 3];
        if (memcmp(file + at + 4, "IDAT", 4) == 0) {
            memcpy(stream + stream_bytes, file + at + 8, len);
            stream_bytes += len;
        }
        at += 12 + len;
    }
    size_t rb = (size_t)w * c, n = (rb + 1) * h, got = 0;
    unsigned char *rows = malloc(n);
    struct libdeflate_decompressor *d = libdeflate_alloc_decompressor();
    assert_int_equal(libdeflate_zlib_decompress(d, stream, stream_bytes, rows, n, &got),
                     LIBDEFLATE_SUCCESS);
    assert_int_equal(got, n);
    unsigned used = 0;
    for (int y = 0; y < h; y++) {
        assert_true(rows[(size_t)y * (rb + 1)] < 5);
        used |= 1u << rows[(size_t)y * (rb + 1)];
    }
    libdeflate_free_decompressor(d);
    free(rows);
    free(stream);
    free(file);
    return used;
}

/* The writer's files, decoded by libpng's own reader (which checks every CRC and the
 * zlib stream's checksum), give back the bytes written, for 1, 3 and 4 channels, sizes
 * from one pixel up to one filtered in parallel, and pictures where every filter is
 * chosen somewhere. */
static void
test_encoder_decoded_by_libpng(void **state)
{
    (void)state;
    static const int sizes[][2] = {{1, 1}, {2, 3}, {1, 9}, {37, 23}, {301, 211}};
    static const int formats[5] = {0, PNG_FORMAT_GRAY, 0, PNG_FORMAT_RGB,
                                   PNG_FORMAT_RGBA};
    static const char *const names[4][4] = {
        {"Y"}, {0}, {"R", "G", "B"}, {"R", "G", "B", "A"}};
    for (int c = 1; c <= 4; c += c == 1 ? 2 : 1)
        for (size_t k = 0; k < sizeof sizes / sizeof *sizes; k++) {
            int w = sizes[k][0], h = sizes[k][1];
            unsigned char *px = filter_picture(w, h, c, (unsigned)(17 * k + c));
            /* the writer takes floats; linear values i/255 round back to byte i */
            mcp_image *img = NULL;
            assert_int_equal(mcp_image_new(w, h, c, names[c - 1], &img), 0);
            for (size_t i = 0; i < (size_t)w * h * c; i++)
                img->data[i] = px[i] / 255.0f;
            mcp_write_options wo = mcp_write_defaults();
            wo.srgb_encode = 0;
            const char *path = tmp_path("encoded.png");
            assert_int_equal(mcp_image_write(img, path, &wo), 0);
            png_image pi;
            memset(&pi, 0, sizeof pi);
            pi.version = PNG_IMAGE_VERSION;
            assert_true(png_image_begin_read_from_file(&pi, path));
            assert_int_equal(pi.width, w);
            assert_int_equal(pi.height, h);
            pi.format = (png_uint_32)formats[c];
            unsigned char *back = malloc(PNG_IMAGE_SIZE(pi));
            assert_true(png_image_finish_read(&pi, NULL, back, 0, NULL));
            assert_memory_equal(back, px, (size_t)w * h * c);
            if (w * h >= 37 * 23)
                assert_int_equal(filter_types_used(path, w, h, c), 0x1f);
            free(back);
            mcp_image_free(img);
            free(px);
        }
}

/* The colour type in a PNG's IHDR (byte 25 of the file). */
static int
colour_type_of(const char *path)
{
    unsigned char head[26];
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    assert_int_equal(fread(head, 1, sizeof head, f), sizeof head);
    fclose(f);
    return head[25];
}

/* An RGB picture of at most 256 colours (a colour map's) is written as a palette and an
 * index a pixel, and libpng decodes it to the bytes given; one more colour, and it is
 * written as RGB. Rows that repeat the row above (a false-colour picture's blocks) and
 * a colour map with marks on 255 levels (the estimate's error picture) too. */
static void
test_palette(void **state)
{
    (void)state;
    const int w = 301, h = 211;
    mcp_image *ramp = NULL;
    assert_int_equal(mcp_image_new(w, h, 1, (const char *[]){"v"}, &ramp), 0);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) /* every level, noisy, and a repeated band */
            ramp->data[(size_t)y * w + x] =
                y >= 100 && y < 140 ? 0.3f : (float)((x * 7 + y * 13) % 256) / 255.0f;
    unsigned char *rgb = malloc((size_t)w * h * 3), *back = malloc((size_t)w * h * 3);
    for (int marks = 0; marks <= 2; marks++) {
        /* 0: 256 levels; 1: 255 levels and white marks; 2: 256 levels and white */
        const int levels = marks == 1 ? 255 : 256;
        assert_int_equal(mcp__colormap_apply_levels(ramp, 0, 0.0, 1.0,
                                                    MCP_COLORMAP_INFERNO, levels, rgb),
                         0);
        if (marks)
            for (int x = 0; x < w; x += 10)
                memset(rgb + 3 * ((size_t)50 * w + x), 255, 3);
        const char *path = tmp_path("palette.png");
        assert_int_equal(mcp_write_rgb8(rgb, w, h, path), 0);
        assert_int_equal(colour_type_of(path), marks == 2 ? 2 : 3);
        png_image pi;
        memset(&pi, 0, sizeof pi);
        pi.version = PNG_IMAGE_VERSION;
        assert_true(png_image_begin_read_from_file(&pi, path));
        pi.format = PNG_FORMAT_RGB;
        assert_true(png_image_finish_read(&pi, NULL, back, 0, NULL));
        assert_memory_equal(back, rgb, (size_t)w * h * 3);
    }
    /* 255 levels: lo and hi on the first and the 255th of the map's 256 colours, the
       same as the 256-level map's first and 255th */
    unsigned char full[6], part[6];
    mcp_image *ends = NULL;
    assert_int_equal(mcp_image_new(2, 1, 1, (const char *[]){"v"}, &ends), 0);
    ends->data[0] = 0.0f, ends->data[1] = 1.0f;
    assert_int_equal(
        mcp__colormap_apply_levels(ends, 0, 0.0, 1.0, MCP_COLORMAP_INFERNO, 255, part),
        0);
    ends->data[1] = 254.0f / 255.0f;
    assert_int_equal(mcp_colormap_apply(ends, 0, 0.0, 1.0, MCP_COLORMAP_INFERNO, full),
                     0);
    assert_memory_equal(part, full, 6);
    assert_error_contains(
        mcp__colormap_apply_levels(ends, 0, 0.0, 1.0, MCP_COLORMAP_INFERNO, 1, part),
        "levels must be in [2, 256]");
    mcp_image_free(ends);
    mcp_image_free(ramp);
    free(rgb);
    free(back);
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
        assert_true(back->data[i] ==
                    (i % 2 ? ga[i] / 255.0f : mcp_srgb_to_linear(ga[i] / 255.0f)));
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
    assert_error_contains(mcp_image_read(path, NULL, &img),
                          "text.png: not a readable PNG");
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
    assert_error_contains(mcp_image_read(path, NULL, &img),
                          "cut.png: not a readable PNG");
    assert_null(img);
    /* 2 channels cannot be written */
    mcp_image *two = mcp_test_random(4, 4, 2, 0.0f, 1.0f, 3, NULL);
    assert_error_contains(mcp_image_write(two, tmp_path("two.png"), NULL),
                          "two.png: png takes 1, 3 or 4 channels, not 2");
    mcp_image_free(two);
    mcp_image_free(big);
}

/* The sRGB bytes from the step edges (srgb8.c) are the formula's,
 * (unsigned char)(mcp_linear_to_srgb(v) * 255 + 0.5) of v clamped: for every float in
 * [2^-9, 1] (all of powf's range, 0.0031308 up; 75 million values), for every 97th
 * below it (the formula is 12.92 v there, monotone), and at the edges of [0, 1]. */
static void
test_srgb_bytes_are_the_formula(void **state)
{
    (void)state;
    const mcp__srgb8_table *t = mcp__srgb8_table_get();
    const uint32_t low = 0x3b000000u /* 2^-9 */, one = 0x3f800000u;
    long wrong = 0;
    for (uint32_t b = 0; b <= one; b += b < low ? 97 : 1) {
        float v;
        memcpy(&v, &b, sizeof v);
        wrong += mcp__srgb8_byte(t, v) != mcp__srgb8_formula(v);
    }
    assert_int_equal(wrong, 0);
    const float odd[] = {-0.0f,     -1.0f, 1.0f,       1.5f,  INFINITY,
                         -INFINITY, NAN,   0.0031308f, 1e-40f};
    for (size_t i = 0; i < sizeof odd / sizeof *odd; i++)
        assert_int_equal(mcp__srgb8_byte(t, odd[i]), mcp__srgb8_formula(odd[i]));
    assert_int_equal(mcp__srgb8_byte(t, 1.0f), 255);
    assert_int_equal(mcp__srgb8_byte(t, NAN), 0);
    assert_int_equal(t->edge[128] > 0.2f && t->edge[128] < 0.22f, 1); /* 0.216 */
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_float_round_trip),
        cmocka_unit_test(test_bytes_and_decoding),
        cmocka_unit_test(test_encoder_decoded_by_libpng),
        cmocka_unit_test(test_palette),
        cmocka_unit_test(test_srgb_bytes_are_the_formula),
        cmocka_unit_test(test_other_layouts),
        cmocka_unit_test(test_bad_files),
    };
    return cmocka_run_group_tests_name("common/png", tests, NULL, NULL);
}
