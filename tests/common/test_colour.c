/* test_colour.c: colour is taken by channel name, whatever a file's channel order
 * (docs/conventions.md, "Channel order"; issue 29, "Red becomes blue"). Pure red, green
 * and blue images, laid out in memory with their channels in many orders (B,G,R as EXR
 * stores them, R,G,B, with A or Z before or after, lower-case names, a layer's
 * "<p>.B/G/R"), go through EXR, PNG, PFM and HDR by the library and by `mcpost
 * convert`. The truth is the primary itself: the PNG bytes are decoded by libpng and
 * the PFM floats parsed here, not by mcpost's readers. */
#include "testing.h"

#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mcpost/imageio.h>
#include <mcpost/tonemap.h>

#define W 3
#define H 2

static char out[8192], err[8192];
#define run(...) mcp_test_run_mcpostf(out, sizeof out, err, sizeof err, __VA_ARGS__)

/* A layout: channel names in memory order; the colour is where R, G, B (in any case,
 * or as "<p>.R" ...) stand, A is 0.5 and Z is 7. */
typedef struct {
    const char *label;
    int n;
    const char *names[5];
} layout;

static const layout layouts[] = {
    {"rgb", 3, {"R", "G", "B"}},
    {"bgr", 3, {"B", "G", "R"}},
    {"gbr", 3, {"G", "B", "R"}},
    {"abgr", 4, {"A", "B", "G", "R"}},
    {"rgba", 4, {"R", "G", "B", "A"}},
    {"bgrz", 4, {"B", "G", "R", "Z"}},
    {"zrgb", 4, {"Z", "R", "G", "B"}},
    {"abgrz", 5, {"A", "B", "G", "R", "Z"}},
    {"lower", 3, {"b", "g", "r"}},
    {"layer", 3, {"diffuse.B", "diffuse.G", "diffuse.R"}},
};
#define N_LAYOUTS (int)(sizeof layouts / sizeof *layouts)

/* 0, 1, 2 for a colour channel's name (R, G, B), 3 for A, 4 for Z. */
static int
role(const char *name)
{
    size_t n = strlen(name);
    char last = name[n - 1];
    return last == 'R' || last == 'r'   ? 0
           : last == 'G' || last == 'g' ? 1
           : last == 'B' || last == 'b' ? 2
           : last == 'A'                ? 3
                                        : 4;
}

/* The value of a channel of the given role in an image of primary p (0 R, 1 G, 2 B). */
static float
truth(int r, int p)
{
    return r < 3 ? (r == p ? 1.0f : 0.0f) : r == 3 ? 0.5f : 7.0f;
}

static mcp_image *
primary(const layout *l, int p)
{
    mcp_image *img = NULL;
    assert_int_equal(mcp_image_new(W, H, l->n, l->names, &img), 0);
    for (int i = 0; i < W * H; i++)
        for (int c = 0; c < l->n; c++)
            img->data[i * l->n + c] = truth(role(l->names[c]), p);
    return img;
}

/* img (read back) holds primary p: R, G, B first, by name and value, then the rest,
 * each channel with its own value. */
static void
assert_primary(const mcp_image *img, const layout *l, int p)
{
    assert_int_equal(img->channels, l->n);
    for (int c = 0; c < img->channels; c++) {
        if (c < 3) assert_int_equal(role(img->names[c]), c);
        for (int i = 0; i < W * H; i++)
            assert_true(img->data[i * img->channels + c] ==
                        truth(role(img->names[c]), p));
    }
}

/* The 8-bit pixels of a PNG, as libpng decodes them, in the file's own channels
 * (RGB or RGBA); *alpha says which. */
static unsigned char *
png_bytes(const char *path, int *alpha)
{
    png_image pi;
    memset(&pi, 0, sizeof pi);
    pi.version = PNG_IMAGE_VERSION;
    assert_true(png_image_begin_read_from_file(&pi, path));
    assert_int_equal(pi.width, W);
    assert_int_equal(pi.height, H);
    *alpha = (pi.format & PNG_FORMAT_FLAG_ALPHA) != 0;
    pi.format = *alpha ? PNG_FORMAT_RGBA : PNG_FORMAT_RGB;
    unsigned char *b = malloc(PNG_IMAGE_SIZE(pi));
    assert_non_null(b);
    assert_true(png_image_finish_read(&pi, NULL, b, 0, NULL));
    return b;
}

/* A PNG holds primary p as (255, 0, 0) etc., and alpha 128 (0.5) where the source had
 * A (and only then: Z is no alpha). */
static void
assert_png_primary(const char *path, int p, int has_alpha)
{
    int alpha;
    unsigned char *b = png_bytes(path, &alpha);
    assert_int_equal(alpha, has_alpha);
    int c = 3 + alpha;
    for (int i = 0; i < W * H; i++) {
        for (int k = 0; k < 3; k++)
            assert_int_equal(b[i * c + k], k == p ? 255 : 0);
        if (alpha) assert_int_equal(b[i * c + 3], 128);
    }
    free(b);
}

/* A PFM holds primary p, parsed here: "PF", width, height, a negative scale (little
 * endian), then rows bottom to top of R, G, B floats. */
static void
assert_pfm_primary(const char *path, int p)
{
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    char kind[3] = "";
    int w = 0, h = 0;
    double scale = 0;
    assert_int_equal(fscanf(f, "%2s %d %d %lf", kind, &w, &h, &scale), 4);
    assert_int_equal(fgetc(f), '\n');
    assert_string_equal(kind, "PF");
    assert_int_equal(w, W);
    assert_int_equal(h, H);
    assert_true(scale < 0);
    float v[W * H * 3];
    assert_int_equal(fread(v, sizeof *v, W * H * 3, f), W * H * 3);
    fclose(f);
    for (int i = 0; i < W * H; i++)
        for (int k = 0; k < 3; k++)
            assert_true(v[i * 3 + k] == (k == p ? 1.0f : 0.0f));
}

/* An HDR (RGBE: 1 and 0 are exact) read back holds primary p as R, G, B. */
static void
assert_hdr_primary(const char *path, int p)
{
    mcp_image *img = NULL;
    assert_int_equal(mcp_image_read(path, NULL, &img), 0);
    assert_int_equal(img->channels, 3);
    for (int i = 0; i < W * H; i++)
        for (int k = 0; k < 3; k++)
            assert_true(img->data[i * 3 + k] == (k == p ? 1.0f : 0.0f));
    mcp_image_free(img);
}

static int
has_alpha(const layout *l)
{
    for (int c = 0; c < l->n; c++)
        if (!strcmp(l->names[c], "A")) return 1;
    return 0;
}

/* The order itself, on names alone: colour first, a layer's triple as R, G, B where
 * its first channel stood, the rest in their order. */
static void
test_colour_order(void **state)
{
    (void)state;
    static const struct {
        int n;
        const char *names[8];
        int moved, order[8];
    } cases[] = {
        {3, {"R", "G", "B"}, 0, {0, 1, 2}},
        {3, {"B", "G", "R"}, 1, {2, 1, 0}},
        {5, {"A", "B", "G", "R", "Z"}, 1, {3, 2, 1, 0, 4}},
        {3, {"b", "g", "r"}, 1, {2, 1, 0}},
        {3, {"X", "Y", "Z"}, 0, {0, 1, 2}},
        {1, {"Y"}, 0, {0}},
        /* a pbrt-style dump: colour, then each layer R, G, B */
        {8,
         {"Albedo.B", "Albedo.G", "Albedo.R", "B", "G", "R", "Variance.B", "Variance.G"},
         1,
         {5, 4, 3, 2, 1, 0, 6, 7}},
        /* Blender: the Combined triple is the colour */
        {6,
         {"L.Combined.B", "L.Combined.G", "L.Combined.R", "L.Depth.Z", "L.Normal.X",
          "L.Normal.Y"},
         1,
         {2, 1, 0, 3, 4, 5}},
        /* two of the three named alike: left alone */
        {3, {"R", "r", "G"}, 0, {0, 1, 2}},
    };
    for (size_t k = 0; k < sizeof cases / sizeof *cases; k++) {
        mcp_image *img = NULL;
        assert_int_equal(mcp_image_new(1, 1, cases[k].n, cases[k].names, &img), 0);
        int order[8];
        assert_int_equal(mcp_image_colour_order(img, order), cases[k].moved);
        assert_memory_equal(order, cases[k].order, (size_t)cases[k].n * sizeof *order);
        mcp_image_free(img);
    }
}

/* In place, names and pixels together (as an OpenImageIO read is reordered), each
 * pixel's values follow their names. */
static void
test_colour_first_in_place(void **state)
{
    (void)state;
    static const char *const names[] = {"Z", "B", "G", "R"}, *const want[] = {"R", "G",
                                                                              "B", "Z"};
    mcp_image *img = mcp_test_ramp(W, H, 4, names); /* x + 10 y + 100 c */
    assert_int_equal(mcp_image_colour_first(img), 0);
    static const int from[4] = {3, 2, 1, 0}; /* the ramp's channel now at each place */
    for (int c = 0; c < 4; c++) {
        assert_string_equal(img->names[c], want[c]);
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                assert_true(mcp_image_px(img, x, y)[c] == x + 10 * y + 100 * from[c]);
    }
    /* already in order: nothing moves */
    assert_int_equal(mcp_image_colour_first(img), 0);
    assert_string_equal(img->names[0], "R");
    assert_true(mcp_image_px(img, 1, 1)[0] == 1 + 10 + 300);
    mcp_image_free(img);
}

/* Every layout of every primary: written as EXR and read back with R, G, B first;
 * written directly as PNG, PFM and HDR (formats that store colour by place). */
static void
test_library_round_trips(void **state)
{
    (void)state;
    mcp_write_options lin = mcp_write_defaults();
    lin.srgb_encode = 0;
    for (int li = 0; li < N_LAYOUTS; li++)
        for (int p = 0; p < 3; p++) {
            const layout *l = &layouts[li];
            mcp_image *img = primary(l, p), *back = NULL;
            const char *exr = mcp_test_path("primary.exr");
            assert_int_equal(mcp_image_write(img, exr, NULL), 0);
            assert_int_equal(mcp_image_read(exr, NULL, &back), 0);
            assert_primary(back, l, p);
            int rgb[3];
            assert_int_equal(mcp_rgb_channels(back, rgb), 0);
            assert_int_equal(rgb[0], 0);
            assert_int_equal(rgb[2], 2);
            mcp_image_free(back);
            if (l->n == 3) { /* PFM and HDR take 3 channels, PNG also takes 4 */
                const char *pfm = mcp_test_path("primary.pfm");
                assert_int_equal(mcp_image_write(img, pfm, NULL), 0);
                assert_pfm_primary(pfm, p);
                const char *hdr = mcp_test_path("primary.hdr");
                assert_int_equal(mcp_image_write(img, hdr, NULL), 0);
                assert_hdr_primary(hdr, p);
            }
            if (l->n == 3 || (has_alpha(l) && l->n == 4)) {
                const char *png = mcp_test_path("primary.png");
                assert_int_equal(mcp_image_write(img, png, &lin), 0);
                assert_png_primary(png, p, has_alpha(l));
            }
            mcp_image_free(img);
        }
}

/* `mcpost convert` of each layout's EXR to PNG, PFM and HDR, and back: PNG to EXR to
 * PNG and PFM to EXR to PFM keep the primary. */
static void
test_convert_keeps_colour(void **state)
{
    (void)state;
    for (int li = 0; li < N_LAYOUTS; li++)
        for (int p = 0; p < 3; p++) {
            const layout *l = &layouts[li];
            mcp_image *img = primary(l, p);
            /* mcp_test_path's buffers rotate: each path is kept here */
            char exr[4096], png[4096], pfm[4096], hdr[4096], exr2[4096], png2[4096],
                pfm2[4096];
            snprintf(exr, sizeof exr, "%s", mcp_test_path("in.exr"));
            assert_int_equal(mcp_image_write(img, exr, NULL), 0);
            mcp_image_free(img);
            snprintf(png, sizeof png, "%s", mcp_test_path("out.png"));
            snprintf(pfm, sizeof pfm, "%s", mcp_test_path("out.pfm"));
            snprintf(hdr, sizeof hdr, "%s", mcp_test_path("out.hdr"));
            snprintf(exr2, sizeof exr2, "%s", mcp_test_path("back.exr"));
            snprintf(png2, sizeof png2, "%s", mcp_test_path("back.png"));
            snprintf(pfm2, sizeof pfm2, "%s", mcp_test_path("back.pfm"));
            assert_int_equal(run("convert '%s' '%s'", exr, png), 0);
            assert_png_primary(png, p, has_alpha(l));
            assert_int_equal(run("convert '%s' '%s'", exr, pfm), 0);
            assert_pfm_primary(pfm, p);
            assert_int_equal(run("convert '%s' '%s'", exr, hdr), 0);
            assert_hdr_primary(hdr, p);
            /* the PNG's colour survives a trip through EXR */
            assert_int_equal(run("convert '%s' '%s'", png, exr2), 0);
            assert_int_equal(run("convert '%s' '%s'", exr2, png2), 0);
            assert_png_primary(png2, p, has_alpha(l));
            assert_int_equal(run("convert '%s' '%s'", pfm, exr2), 0);
            assert_int_equal(run("convert '%s' '%s'", exr2, pfm2), 0);
            assert_pfm_primary(pfm2, p);
        }
}

/* --channels in a B, G, R order still writes colour by name to a format without names,
 * and a 5-channel file's PNG is its R, G, B, A. */
static void
test_convert_channels_by_name(void **state)
{
    (void)state;
    const layout *l = &layouts[7]; /* A, B, G, R, Z */
    mcp_image *img = primary(l, 0);
    const char *exr = mcp_test_path("abgrz.exr");
    assert_int_equal(mcp_image_write(img, exr, NULL), 0);
    mcp_image_free(img);
    char png[4096];
    snprintf(png, sizeof png, "%s", mcp_test_path("picked.png"));
    assert_int_equal(run("convert '%s' '%s' --channels B,G,R", exr, png), 0);
    assert_png_primary(png, 0, 0);
    assert_int_equal(run("convert '%s' '%s' --channels A,B,G,R", exr, png), 0);
    assert_png_primary(png, 0, 1);
    assert_int_equal(run("convert '%s' '%s'", exr, png), 0);
    assert_png_primary(png, 0, 1);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_colour_order),
        cmocka_unit_test(test_colour_first_in_place),
        cmocka_unit_test(test_library_round_trips),
        cmocka_unit_test(test_convert_keeps_colour),
        cmocka_unit_test(test_convert_channels_by_name),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
