/* test_exr.c: the parallel EXR writer and reader (common/io/exr.c). Every compression the
 * writer takes round-trips bit for bit on 1, 2 and 5 threads, scanline and tiled, with
 * partial last chunks and nasty values, and the files do not depend on the thread
 * count; the raw-storage probe keeps pixels and picks raw only for data that does not
 * compress; a corrupt chunk gives the same one-line error on any thread count. Zip
 * chunks go through libdeflate (common/io/exr_zip.c): OpenEXR Core's own zlib decoder
 * reads what it writes, and it reads what zlib wrote (a renderer's file), value for
 * value the same as Core. The row reader and writer of a streamed denoise give the
 * bits of a whole read and of a whole write, band by band, and refuse what they must. */
#include "testing.h"
#include "../../common/io/internal.h"

#include <mcpost/imageio.h>
#include <openexr.h>
#include <float.h>
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static const char *names5[] = {"R", "G", "B", "Variance.R", "albedo.G"};
static const int thread_counts[] = {1, 2, 5};

static long
file_size(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 ? (long)st.st_size : -1;
}

static uint32_t
bits(float v)
{
    uint32_t u;
    memcpy(&u, &v, sizeof u);
    return u;
}

/* A random image of odd size with the values that break careless copies: NaN with a
 * payload, ±Inf, -0, FLT_MAX, the smallest denormal, in scattered pixels. */
static mcp_image *
nasty_image(int w, int h, uint64_t seed)
{
    mcp_image *img = mcp_test_random(w, h, 5, -3.0f, 7.0f, seed, names5);
    uint32_t nan_payload = 0x7fc01234u;
    float nan;
    memcpy(&nan, &nan_payload, sizeof nan);
    const float special[] = {nan,     INFINITY, -INFINITY, -0.0f,
                             FLT_MAX, -FLT_MAX, 1e-45f,    FLT_MIN};
    uint64_t s = seed;
    for (int k = 0; k < 64; k++) {
        int x = (int)(mcp_test_rand_u64(&s) % (uint64_t)w);
        int y = (int)(mcp_test_rand_u64(&s) % (uint64_t)h);
        int c = (int)(mcp_test_rand_u64(&s) % 5);
        mcp_image_px(img, x, y)[c] = special[k % 8];
    }
    return img;
}

/* Every value of a equals the channel of the same name in b, bit for bit. */
static void
assert_same_bits(const mcp_image *a, const mcp_image *b)
{
    assert_int_equal(a->width, b->width);
    assert_int_equal(a->height, b->height);
    assert_int_equal(a->channels, b->channels);
    for (int c = 0; c < a->channels; c++) {
        int cb = mcp_image_channel(b, a->names[c]);
        assert_true(cb >= 0);
        for (int y = 0; y < a->height; y++)
            for (int x = 0; x < a->width; x++)
                if (bits(mcp_image_px(a, x, y)[c]) != bits(mcp_image_px(b, x, y)[cb]))
                    fail_msg("channel %s pixel (%d, %d): %08x read back as %08x",
                             a->names[c], x, y, bits(mcp_image_px(a, x, y)[c]),
                             bits(mcp_image_px(b, x, y)[cb]));
    }
}

static int
same_file_bytes(const char *p, const char *q)
{
    long n = file_size(p);
    if (n < 0 || n != file_size(q)) return 0;
    char *a = mcp_test_read_text(p), *b = mcp_test_read_text(q);
    int same = memcmp(a, b, (size_t)n) == 0;
    free(a);
    free(b);
    return same;
}

/* Writes img with o on every thread count and reads each file back on every thread
 * count: the files are byte for byte the 1-thread file, and (lossless) the pixels are
 * img's bits, or (pxr24, half) those of the 1-thread read. */
static void
roundtrip_all_threads(const mcp_image *img, const mcp_write_options *o, int lossless)
{
    char first[4096];
    snprintf(first, sizeof first, "%s", mcp_test_path("par_t1.exr"));
    mcp_image *ref = NULL;
    for (size_t i = 0; i < sizeof thread_counts / sizeof *thread_counts; i++) {
        omp_set_num_threads(thread_counts[i]);
        const char *path = i == 0 ? first : mcp_test_path("par_tn.exr");
        assert_int_equal(mcp_image_write(img, path, o), 0);
        if (i > 0) assert_true(same_file_bytes(first, path));
        for (size_t j = 0; j < sizeof thread_counts / sizeof *thread_counts; j++) {
            omp_set_num_threads(thread_counts[j]);
            mcp_image *back = NULL;
            assert_int_equal(mcp_image_read(path, NULL, &back), 0);
            if (lossless)
                assert_same_bits(img, back);
            else if (!ref)
                ref = back, back = NULL;
            else
                assert_same_bits(ref, back);
            mcp_image_free(back);
        }
    }
    mcp_image_free(ref);
    omp_set_num_threads(omp_get_num_procs());
}

static void
test_every_compression_every_thread_count(void **state)
{
    (void)state;
    /* 61 x 75: zip's 16-line chunks end with 11 lines, piz's 32 with 11, zips has 75
       chunks (enough for the raw-storage probe); tiles of 16 leave 13 x 11 corners */
    mcp_image *img = nasty_image(61, 75, 17);
    mcp_attrs_set_int(&img->attrs, "samplesPerPixel", 32);
    const char *lossless[] = {"none", "rle", "zips", "zip", "piz"};
    for (int tiled = 0; tiled <= 1; tiled++)
        for (size_t k = 0; k < sizeof lossless / sizeof *lossless; k++) {
            mcp_write_options o = mcp_write_defaults();
            assert_int_equal(mcp_exr_compression_from_name(lossless[k], &o.compression),
                             0);
            o.exr_tiled = tiled;
            o.exr_tile_size = 16;
            roundtrip_all_threads(img, &o, 1);
            /* zip without the probe, and at the old level: the same pixels */
            if (o.compression == MCP_EXR_ZIP || o.compression == MCP_EXR_ZIPS) {
                o.exr_min_saving = -1;
                o.exr_zip_level = 9;
                roundtrip_all_threads(img, &o, 1);
            }
        }
    /* lossy or half: not img's bits, but the same bits on any thread count */
    mcp_write_options o = mcp_write_defaults();
    o.compression = MCP_EXR_PXR24;
    roundtrip_all_threads(img, &o, 0);
    o.compression = MCP_EXR_ZIP;
    o.exr_pixel = MCP_EXR_HALF;
    o.exr_tiled = 1;
    o.exr_tile_size = 16;
    roundtrip_all_threads(img, &o, 0);
    mcp_image_free(img);
}

/* A crop of a channel range (strides unlike a packed image) on many threads. */
static void
test_view_on_many_threads(void **state)
{
    (void)state;
    mcp_image *img = nasty_image(80, 90, 5), *crop, *view;
    assert_int_equal(mcp_image_crop_view(img, 7, 3, 61, 83, &crop), 0);
    assert_int_equal(mcp_image_channel_view(crop, 1, 3, &view), 0);
    mcp_write_options o = mcp_write_defaults();
    o.compression = MCP_EXR_ZIPS;
    roundtrip_all_threads(view, &o, 1);
    mcp_image_free(view);
    mcp_image_free(crop);
    mcp_image_free(img);
}

/* Raw bytes of a w x h x c float image's pixels. */
static long
pixel_bytes(int w, int h, int c)
{
    return (long)w * h * c * (long)sizeof(float);
}

static void
test_probe_stores_raw_only_what_does_not_compress(void **state)
{
    (void)state;
    const int w = 64, h = 256;
    const char *path = mcp_test_path("probe.exr");
    mcp_write_options o = mcp_write_defaults();
    /* uniform random floats: their mantissas do not compress, so every chunk is raw
       (the file holds at least the pixel bytes), and the pixels come back */
    mcp_image *noise = mcp_test_random(w, h, 3, 0.0f, 1.0f, 3, NULL), *back = NULL;
    assert_int_equal(mcp_image_write(noise, path, &o), 0);
    assert_true(file_size(path) >= pixel_bytes(w, h, 3));
    assert_int_equal(mcp_image_read(path, NULL, &back), 0);
    assert_same_bits(noise, back);
    mcp_image_free(back);
    /* a ramp compresses well: zip keeps it far below the raw size */
    mcp_image *ramp = mcp_test_ramp(w, h, 3, NULL);
    assert_int_equal(mcp_image_write(ramp, path, &o), 0);
    assert_true(file_size(path) < pixel_bytes(w, h, 3) / 4);
    assert_int_equal(mcp_image_read(path, NULL, &back), 0);
    assert_same_bits(ramp, back);
    mcp_image_free(back);
    /* every other row constant: zip saves about half; a threshold below the saving
       compresses, one above it stores raw */
    mcp_image *half = mcp_test_random(w, h, 3, 0.0f, 1.0f, 4, NULL);
    for (int y = 1; y < h; y += 2)
        for (int x = 0; x < w; x++)
            for (int c = 0; c < 3; c++)
                mcp_image_px(half, x, y)[c] = 0.25f;
    o.exr_min_saving = 0.01;
    assert_int_equal(mcp_image_write(half, path, &o), 0);
    long compressed = file_size(path);
    assert_true(compressed < pixel_bytes(w, h, 3) * 0.9);
    o.exr_min_saving = 0.9;
    assert_int_equal(mcp_image_write(half, path, &o), 0);
    assert_true(file_size(path) >= pixel_bytes(w, h, 3));
    assert_int_equal(mcp_image_read(path, NULL, &back), 0);
    assert_same_bits(half, back);
    mcp_image_free(back);
    /* bad settings name the file and the field */
    o.exr_min_saving = 1;
    assert_error_contains(mcp_image_write(half, path, &o),
                          "probe.exr: bad exr_min_saving 1");
    o = mcp_write_defaults();
    o.exr_zip_level = 10;
    assert_error_contains(mcp_image_write(half, path, &o), "probe.exr: bad zip level 10");
    mcp_image_free(half);
    mcp_image_free(ramp);
    mcp_image_free(noise);
}

/* Overwrites 64 bytes in the middle of a many-chunk zips file: the error is one line
 * naming the file, and the same on every thread count (the first bad chunk's). */
static void
test_corrupt_chunk_same_error_any_thread_count(void **state)
{
    (void)state;
    mcp_image *img = mcp_test_ramp(61, 200, 3, NULL);
    mcp_write_options o = mcp_write_defaults();
    o.compression = MCP_EXR_ZIPS;
    const char *path = mcp_test_path("corrupt.exr");
    assert_int_equal(mcp_image_write(img, path, &o), 0);
    long n = file_size(path);
    char *bytes = mcp_test_read_text(path);
    memset(bytes + n / 2, 0x5a, 64);
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(bytes, 1, (size_t)n, f), (size_t)n);
    fclose(f);
    free(bytes);
    char first[1024] = "";
    for (size_t i = 0; i < sizeof thread_counts / sizeof *thread_counts; i++) {
        omp_set_num_threads(thread_counts[i]);
        mcp_image *back = NULL;
        assert_int_equal(mcp_image_read(path, NULL, &back), -1);
        assert_null(back);
        const char *msg = mcp_error_message();
        assert_non_null(strstr(msg, "corrupt.exr: "));
        assert_null(strchr(msg, '\n'));
        if (i == 0)
            snprintf(first, sizeof first, "%s", msg);
        else
            assert_string_equal(msg, first);
    }
    omp_set_num_threads(omp_get_num_procs());
    mcp_image_free(img);
}

/* Reads a scanline file with OpenEXR Core's default routines only (its zlib, its
 * unpacking): the independent decoder for test_zip_streams_agree_with_core. */
static mcp_image *
read_with_core_only(const char *path)
{
    exr_context_t f = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    assert_int_equal(exr_start_read(&f, path, &init), EXR_ERR_SUCCESS);
    exr_attr_box2i_t dw;
    const exr_attr_chlist_t *chans;
    int32_t lines;
    assert_int_equal(exr_get_data_window(f, 0, &dw), EXR_ERR_SUCCESS);
    assert_int_equal(exr_get_channels(f, 0, &chans), EXR_ERR_SUCCESS);
    assert_int_equal(exr_get_scanlines_per_chunk(f, 0, &lines), EXR_ERR_SUCCESS);
    const char *names[64];
    assert_true(chans->num_channels <= 64);
    for (int c = 0; c < chans->num_channels; c++)
        names[c] = chans->entries[c].name.str;
    int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
    mcp_image *img = NULL;
    assert_int_equal(mcp_image_new(w, h, chans->num_channels, names, &img), 0);
    for (int y = dw.min.y; y <= dw.max.y; y += lines) {
        exr_chunk_info_t ci;
        exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
        assert_int_equal(exr_read_scanline_chunk_info(f, 0, y, &ci), EXR_ERR_SUCCESS);
        assert_int_equal(exr_decoding_initialize(f, 0, &ci, &dec), EXR_ERR_SUCCESS);
        for (int k = 0; k < dec.channel_count; k++) {
            exr_coding_channel_info_t *ch = &dec.channels[k];
            int ic = mcp_image_channel(img, ch->channel_name);
            ch->decode_to_ptr = (uint8_t *)(mcp_image_px(img, 0, y - dw.min.y) + ic);
            ch->user_pixel_stride =
                (int32_t)(img->pixel_stride * (ptrdiff_t)sizeof(float));
            ch->user_line_stride = (int32_t)(img->row_stride * (ptrdiff_t)sizeof(float));
            ch->user_data_type = EXR_PIXEL_FLOAT;
            ch->user_bytes_per_element = 4;
        }
        assert_int_equal(exr_decoding_choose_default_routines(f, 0, &dec),
                         EXR_ERR_SUCCESS);
        assert_int_equal(exr_decoding_run(f, 0, &dec), EXR_ERR_SUCCESS);
        exr_decoding_destroy(f, &dec);
    }
    exr_finish(&f);
    return img;
}

/* Our zip and zips files, every chunk compressed (a smooth ramp and nasty values, no
 * raw-storage probe, levels 1, 4 and 9), decode through Core's zlib to the written
 * bits; a renderer's zip file (the cornell reference, written with zlib) reads the
 * same through libdeflate as through Core. */
static void
test_zip_streams_agree_with_core(void **state)
{
    (void)state;
    mcp_image *ramp = mcp_test_ramp(61, 75, 5, names5), *nasty = nasty_image(61, 75, 3);
    const mcp_image *images[] = {ramp, nasty};
    const int levels[] = {1, 4, 9};
    const char *path = mcp_test_path("zip_vs_core.exr");
    for (int i = 0; i < 2; i++)
        for (int zips = 0; zips <= 1; zips++)
            for (int l = 0; l < 3; l++) {
                mcp_write_options o = mcp_write_defaults();
                o.compression = zips ? MCP_EXR_ZIPS : MCP_EXR_ZIP;
                o.exr_min_saving = -1;
                o.exr_zip_level = levels[l];
                assert_int_equal(mcp_image_write(images[i], path, &o), 0);
                mcp_image *core = read_with_core_only(path);
                assert_same_bits(images[i], core);
                mcp_image_free(core);
            }
    /* the ramp's chunks were compressed, not stored raw: Core inflated them */
    mcp_write_options o = mcp_write_defaults();
    assert_int_equal(mcp_image_write(ramp, path, &o), 0);
    assert_true(file_size(path) < 61L * 75 * 5 * 4 / 2);
    char renders[4096];
    snprintf(renders, sizeof renders, "%s/samples/fixtures/cornell/cornell_reference.exr",
             MCP_TEST_SOURCE_DIR);
    mcp_image *ours = NULL, *core = read_with_core_only(renders);
    assert_int_equal(mcp_image_read(renders, NULL, &ours), 0);
    assert_same_bits(core, ours);
    mcp_image_free(ours);
    mcp_image_free(core);
    mcp_image_free(ramp);
    mcp_image_free(nasty);
}

/* A map constant per block repeats whole chunks, which take the last chunk's stream
 * instead of a compression (common/io/exr.c, repeat_of_last): on every thread count the
 * file is the 1-thread file, it reads back to the map's bits through libdeflate and
 * through Core's zlib, and its chunks were compressed, not stored raw. Blocks of 40
 * rows against zip's 16-row chunks and zips' 1-row chunks: repeats, and chunks that
 * differ from the last (or the one before) in one value. */
static void
test_repeated_chunks(void **state)
{
    (void)state;
    mcp_image *img = mcp_test_constant(53, 200, 3, 0.0f, NULL);
    for (int y = 0; y < 200; y++)
        for (int x = 0; x < 53; x++)
            for (int c = 0; c < 3; c++)
                mcp_image_px(img, x, y)[c] =
                    (float)(y / 40 + 1) * 0.3f + (float)c + (x >= 30 ? 0.5f : 0.0f);
    mcp_image_px(img, 7, 70)[1] = 123.0f; /* one chunk unlike its neighbours */
    const char *path = mcp_test_path("blocks.exr");
    for (int zips = 0; zips <= 1; zips++) {
        mcp_write_options o = mcp_write_defaults();
        o.compression = zips ? MCP_EXR_ZIPS : MCP_EXR_ZIP;
        roundtrip_all_threads(img, &o, 1);
        assert_int_equal(mcp_image_write(img, path, &o), 0);
        mcp_image *core = read_with_core_only(path);
        assert_same_bits(img, core);
        mcp_image_free(core);
        assert_true(file_size(path) < 53L * 200 * 3 * 4 / 5); /* 3.4 and 12.9 kB */
    }
    mcp_image_free(img);
}

/* Rows at a time (common/io/exr.c, the streamed denoise's reader and writer): any band
 * of rows read from a file is the whole read's rows, bit for bit, scanline and tiled,
 * for every compression; a file written band by band (bands on multiples of 64 rows and
 * a short last one) reads back as the image; a band that ends inside a chunk is
 * refused in one line, and a truncated file is refused before any row is read. */
static void
test_rows_at_a_time(void **state)
{
    (void)state;
    mcp_image *img = nasty_image(61, 200, 11);
    const char *path = mcp_test_path("rows.exr"), *out = mcp_test_path("rows_out.exr");
    const mcp_exr_compression comps[] = {MCP_EXR_NONE, MCP_EXR_ZIP, MCP_EXR_PIZ,
                                         MCP_EXR_ZIPS, MCP_EXR_RLE};
    for (size_t k = 0; k < sizeof comps / sizeof *comps; k++)
        for (int tiled = 0; tiled < 2; tiled++) {
            mcp_write_options o = mcp_write_defaults();
            o.compression = comps[k];
            o.exr_tiled = tiled;
            o.exr_tile_size = 32;
            mcp_image *whole = NULL;
            assert_int_equal(mcp_image_write(img, path, &o), 0);
            assert_int_equal(mcp_image_read(path, NULL, &whole), 0);
            mcp__exr_rows *r = NULL;
            assert_int_equal(mcp__exr_rows_open(path, &r), 0);
            int w, h;
            const mcp_image *header = mcp__exr_rows_header(r, &w, &h);
            assert_int_equal(w, 61);
            assert_int_equal(h, 200);
            const int bands[][2] = {{0, 1},    {0, 37},    {37, 100},
                                    {99, 200}, {150, 151}, {0, 200}};
            for (size_t b = 0; b < sizeof bands / sizeof *bands; b++) {
                const int y0 = bands[b][0], y1 = bands[b][1];
                int a0, a1;
                mcp__exr_rows_span(r, y0, y1, &a0, &a1);
                assert_true(a0 <= y0 && a1 >= y1 && a1 <= h);
                mcp_image *rows = NULL;
                assert_int_equal(mcp_image_new(w, a1 - a0, header->channels,
                                               (const char *const *)header->names, &rows),
                                 0);
                mcp__exr_route routes[5];
                for (int c = 0; c < header->channels; c++)
                    routes[c] = (mcp__exr_route){rows->data + c, rows->pixel_stride,
                                                 rows->row_stride};
                assert_int_equal(mcp__exr_rows_read(r, y0, y1, a0, routes), 0);
                mcp_image *want = NULL, *got = NULL;
                assert_int_equal(mcp_image_crop_view(whole, 0, y0, w, y1 - y0, &want), 0);
                assert_int_equal(mcp_image_crop_view(rows, 0, y0 - a0, w, y1 - y0, &got),
                                 0);
                assert_same_bits(want, got);
                mcp_image_free(want), mcp_image_free(got), mcp_image_free(rows);
            }
            mcp__exr_rows_close(r);
            /* written band by band: the image, whatever chunks were stored raw */
            mcp__exr_writer *wr = NULL;
            assert_int_equal(mcp__exr_writer_open(out, w, h, img->channels, img->names,
                                                  &img->attrs, &o, &wr),
                             0);
            for (int y0 = 0; y0 < h; y0 += 64) {
                mcp_image *band = NULL;
                const int n = y0 + 64 < h ? 64 : h - y0;
                assert_int_equal(mcp_image_crop_view(img, 0, y0, w, n, &band), 0);
                assert_int_equal(mcp__exr_writer_rows(wr, band, y0), 0);
                mcp_image_free(band);
            }
            assert_int_equal(mcp__exr_writer_close(wr), 0);
            mcp_image *back = NULL;
            assert_int_equal(mcp_image_read(out, NULL, &back), 0);
            assert_same_bits(img, back);
            mcp_image_free(back);
            mcp_image_free(whole);
        }
    /* a band that ends inside a zip chunk of 16 rows; a file left unfinished */
    mcp_write_options o = mcp_write_defaults();
    mcp__exr_writer *wr = NULL;
    assert_int_equal(mcp__exr_writer_open(out, 61, 200, img->channels, img->names,
                                          &img->attrs, &o, &wr),
                     0);
    mcp_image *band = NULL;
    assert_int_equal(mcp_image_crop_view(img, 0, 0, 61, 10, &band), 0);
    assert_int_equal(mcp__exr_writer_rows(wr, band, 0), -1);
    assert_non_null(strstr(mcp_error_message(), "end inside a chunk of 16 rows"));
    assert_int_equal(mcp__exr_writer_close(wr), -1);
    assert_non_null(strstr(mcp_error_message(), "0 of 200 rows written"));
    mcp_image_free(band);
    /* truncated: the chunk table points past the end */
    assert_int_equal(mcp_image_write(img, path, &o), 0);
    assert_int_equal(truncate(path, file_size(path) / 2), 0);
    mcp__exr_rows *r = NULL;
    assert_int_equal(mcp__exr_rows_open(path, &r), -1);
    assert_null(r);
    assert_non_null(strstr(mcp_error_message(), "rows.exr: "));
    assert_null(strchr(mcp_error_message(), '\n'));
    mcp_image_free(img);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_every_compression_every_thread_count),
        cmocka_unit_test(test_view_on_many_threads),
        cmocka_unit_test(test_probe_stores_raw_only_what_does_not_compress),
        cmocka_unit_test(test_corrupt_chunk_same_error_any_thread_count),
        cmocka_unit_test(test_zip_streams_agree_with_core),
        cmocka_unit_test(test_repeated_chunks),
        cmocka_unit_test(test_rows_at_a_time),
    };
    return cmocka_run_group_tests_name("common/exr", tests, NULL, NULL);
}
