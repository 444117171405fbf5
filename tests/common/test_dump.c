/* test_dump.c: render dumps in every convention -- written, detected, read back with
 * the right semantics (per-sample variance divided by n) -- and each bad-input class. */
#include "testing.h"

#include "../../common/dump/internal.h" /* a dump without its features */
#include <mcpost/dump.h>
#include <mcpost/imageio.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A dump with known values: colour ramp, variance of the mean v, albedo, normal. */
static mcp_dump *
make_dump(int w, int h, double spp)
{
    mcp_dump *d = calloc(1, sizeof *d);
    d->color = mcp_test_random(w, h, 3, 0.0f, 4.0f, 1, (const char *[]){"R", "G", "B"});
    d->var_of_mean =
        mcp_test_random(w, h, 3, 0.0f, 0.5f, 2, (const char *[]){"R", "G", "B"});
    d->albedo = mcp_test_random(w, h, 3, 0.0f, 1.0f, 3, (const char *[]){"R", "G", "B"});
    d->normal = mcp_test_random(w, h, 3, -1.0f, 1.0f, 4, (const char *[]){"X", "Y", "Z"});
    d->spp = spp;
    d->source = strdup("made");
    return d;
}

static void
assert_images_close(const mcp_image *a, const mcp_image *b, double rtol, double atol)
{
    assert_int_equal(a->width, b->width);
    for (int y = 0; y < a->height; y++)
        for (int x = 0; x < a->width; x++)
            for (int c = 0; c < 3; c++)
                assert_close(mcp_image_px(a, x, y)[c], mcp_image_px(b, x, y)[c], rtol,
                             atol + 1e-12);
}

static void
roundtrip(mcp_convention conv, const char *file, int give_spp)
{
    mcp_dump *d = make_dump(19, 11, 64), *back = NULL;
    const char *path = mcp_test_path(file);
    assert_int_equal(mcp_dump_write(d, path, conv, NULL), 0);
    mcp_image *raw = NULL;
    assert_int_equal(mcp_image_read(path, NULL, &raw), 0);
    assert_int_equal(mcp_dump_detect(raw), conv);
    mcp_image_free(raw);
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = path;
    if (give_spp) spec.spp = 64;
    assert_int_equal(mcp_dump_load(&spec, &back), 0);
    assert_int_equal(back->convention, conv);
    assert_true(back->spp == 64);
    assert_int_equal(back->variance_in_file, MCP_VAR_PER_SAMPLE);
    assert_images_close(back->color, d->color, 0, 0);
    /* stored per-sample (x64), read as of-mean. Mitsuba stores the second moment
     * m2 = 64 v + mean^2 in float: recovering v cancels mean^2 <= 16, so its absolute
     * error is about 2 ulp(16) / 64 = 2 * 2^-19 / 64 ~ 6e-8 */
    assert_images_close(back->var_of_mean, d->var_of_mean, 1e-6,
                        conv == MCP_CONV_MITSUBA ? 6e-8 : 0);
    assert_images_close(back->albedo, d->albedo, 0, 0);
    assert_images_close(back->normal, d->normal, 0, 0);
    mcp_dump_free(back);
    mcp_dump_free(d);
}

static void
test_pbrt_roundtrip(void **state)
{
    (void)state;
    roundtrip(MCP_CONV_PBRT, "pbrt.exr", 0);
}

static void
test_blender_roundtrip(void **state)
{
    (void)state;
    roundtrip(MCP_CONV_BLENDER, "blender.exr", 0);
}

static void
test_mitsuba_roundtrip_needs_spp(void **state)
{
    (void)state;
    roundtrip(MCP_CONV_MITSUBA, "mitsuba.exr", 1);
    mcp_dump *back = NULL;
    assert_error_contains(mcp_dump_read(mcp_test_path("mitsuba.exr"), &back),
                          "mitsuba.exr: no sample count");
}

static void
test_per_sample_variance_semantics(void **state)
{
    (void)state;
    /* A pbrt file with Variance = 8 (per sample) at 32 spp holds variance of the
     * mean 0.25; declared of-mean, the same file gives 8. */
    const char *names[] = {"R", "G", "B", "Variance.R", "Variance.G", "Variance.B"};
    mcp_image *img = mcp_test_constant(5, 4, 6, 8.0f, names);
    mcp_attrs_set_int(&img->attrs, "samplesPerPixel", 32);
    const char *path = mcp_test_path("semantics.exr");
    assert_int_equal(mcp_image_write(img, path, NULL), 0);
    mcp_dump *d = NULL;
    assert_int_equal(mcp_dump_read(path, &d), 0);
    assert_true(mcp_image_px(d->var_of_mean, 2, 3)[1] == 0.25f);
    mcp_dump_free(d);
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = path;
    assert_int_equal(mcp_variance_kind_from_name("of-mean", &spec.variance), 0);
    assert_int_equal(mcp_dump_load(&spec, &d), 0);
    assert_true(mcp_image_px(d->var_of_mean, 2, 3)[1] == 8.0f);
    mcp_dump_free(d);
    mcp_image_free(img);
}

static void
test_mcpost_convention_per_pixel_spp_and_covariance(void **state)
{
    (void)state;
    mcp_dump *d = make_dump(8, 6, 0), *back = NULL;
    d->spp_map = mcp_test_random(8, 6, 1, 1.0f, 100.0f, 9, (const char *[]){"n"});
    for (int i = 0; i < 48; i++)
        d->spp_map->data[i] = floorf(d->spp_map->data[i]);
    d->cov_of_mean =
        mcp_test_random(8, 6, 3, -0.1f, 0.1f, 5, (const char *[]){"RG", "RB", "GB"});
    const char *path = mcp_test_path("mcpost.exr");
    assert_int_equal(mcp_dump_write(d, path, MCP_CONV_MCPOST, NULL), 0);
    assert_int_equal(mcp_dump_read(path, &back), 0);
    assert_int_equal(back->convention, MCP_CONV_MCPOST);
    assert_non_null(back->spp_map);
    assert_true(mcp_dump_spp_at(back, 3, 4) == mcp_dump_spp_at(d, 3, 4));
    assert_images_close(back->var_of_mean, d->var_of_mean, 1e-6, 0);
    assert_images_close(back->cov_of_mean, d->cov_of_mean, 1e-6, 0);
    /* pbrt cannot hold per-pixel counts */
    assert_error_contains(mcp_dump_write(d, mcp_test_path("no.exr"), MCP_CONV_PBRT, NULL),
                          "per-pixel sample counts");
    mcp_dump_free(back);
    mcp_dump_free(d);
}

/* Every part, bit for bit, and what the dump says of itself. */
static void
assert_same_dump(const mcp_dump *a, const mcp_dump *b)
{
    mcp_test_assert_same_image(a->color, b->color);
    mcp_test_assert_same_image(a->var_of_mean, b->var_of_mean);
    mcp_test_assert_same_image(a->cov_of_mean, b->cov_of_mean);
    mcp_test_assert_same_image(a->albedo, b->albedo);
    mcp_test_assert_same_image(a->normal, b->normal);
    mcp_test_assert_same_image(a->spp_map, b->spp_map);
    assert_true(a->spp == b->spp);
    assert_int_equal(a->convention, b->convention);
    assert_int_equal(a->variance_in_file, b->variance_in_file);
    assert_int_equal(a->attrs.count, b->attrs.count);
    assert_string_equal(a->source, b->source);
}

/* mcp_dump_load decodes an EXR's parts straight into the dump's images; reading the
 * whole image and splitting it (mcp_dump_from_image) must give the same dump, bit for
 * bit, in every convention, with a data window that does not start at 0,0, with bad
 * values replaced, and when a spec names one channel for two parts (which the direct
 * reader cannot route and hands back to the whole-image path). */
static void
test_direct_read_matches_whole_image(void **state)
{
    (void)state;
    const mcp_convention convs[] = {MCP_CONV_PBRT, MCP_CONV_BLENDER, MCP_CONV_MITSUBA,
                                    MCP_CONV_MCPOST};
    for (size_t i = 0; i < sizeof convs / sizeof *convs; i++)
        for (int variant = 0; variant < 3; variant++) {
            /* tall enough for many chunks, so that they are decoded in parallel */
            mcp_dump *d = make_dump(37, 150, convs[i] == MCP_CONV_MCPOST ? 0 : 16);
            if (convs[i] == MCP_CONV_MCPOST) {
                d->spp_map =
                    mcp_test_random(37, 150, 1, 1.0f, 9.0f, 9, (const char *[]){"n"});
                d->cov_of_mean = mcp_test_random(37, 150, 3, -0.1f, 0.1f, 5,
                                                 (const char *[]){"RG", "RB", "GB"});
            }
            if (variant == 1) /* a NaN and an Inf to replace */
                d->color->data[100] = NAN, d->albedo->data[7] = INFINITY;
            mcp_write_options wo = mcp_write_defaults();
            wo.exr_data_x = 5;
            wo.exr_data_y = -3;
            const char *path = mcp_test_path("direct.exr");
            assert_int_equal(mcp_dump_write(d, path, convs[i], &wo), 0);
            mcp_dump_spec spec = mcp_dump_spec_defaults();
            spec.path = path;
            spec.spp = convs[i] == MCP_CONV_MITSUBA ? 16 : 0;
            spec.bad_values = variant == 1 ? MCP_BADVAL_ZERO : MCP_BADVAL_FAIL;
            static char names[3]
                             [64]; /* variant 2: the colour's channels for the albedo */
            for (int k = 0; variant == 2 && k < 3; k++) {
                snprintf(names[k], sizeof names[k], "%s%c",
                         convs[i] == MCP_CONV_BLENDER ? "ViewLayer.Combined." : "",
                         "RGB"[k]);
                spec.albedo[k] = names[k];
            }
            mcp_dump *direct = NULL, *whole = NULL;
            mcp_image *raw = NULL;
            assert_int_equal(mcp_dump_load(&spec, &direct), 0);
            assert_int_equal(mcp_image_read(path, NULL, &raw), 0);
            assert_int_equal(mcp_dump_from_image(raw, &spec, &whole), 0);
            assert_same_dump(direct, whole);
            assert_int_equal(direct->n_bad_values, whole->n_bad_values);
            /* Mitsuba's second moment carries the colour's NaN into the variance too */
            assert_true(variant == 1 ? direct->n_bad_values >= 2
                                     : direct->n_bad_values == 0);
            if (variant == 2) mcp_test_assert_same_image(direct->albedo, direct->color);
            mcp_image_free(raw);
            mcp_dump_free(whole);
            mcp_dump_free(direct);
            mcp_dump_free(d);
        }
}

/* mcp__dump_load_without: the parts left out are NULL, neither read nor checked (an
 * Inf in the albedo fails the whole load and not the one without it), from the main
 * EXR, from separate files and through the whole-image path; the rest is the whole
 * load's, bit for bit. */
static void
test_load_without_features(void **state)
{
    (void)state;
    mcp_dump *d = make_dump(37, 150, 16);
    d->albedo->data[7] = INFINITY;
    const char *path = mcp_test_path("without.exr");
    assert_int_equal(mcp_dump_write(d, path, MCP_CONV_PBRT, NULL), 0);
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = path;
    mcp_dump *all = NULL, *some = NULL;
    assert_error_contains(mcp_dump_load(&spec, &all), "albedo");
    spec.bad_values = MCP_BADVAL_ZERO;
    assert_int_equal(mcp_dump_load(&spec, &all), 0);
    spec.bad_values = MCP_BADVAL_FAIL;
    const unsigned both = MCP__DUMP_NO_ALBEDO | MCP__DUMP_NO_NORMAL;
    assert_int_equal(mcp__dump_load_without(&spec, both, &some), 0);
    assert_null(some->albedo);
    assert_null(some->normal);
    assert_int_equal(some->n_bad_values, 0);
    mcp_test_assert_same_image(some->color, all->color);
    mcp_test_assert_same_image(some->var_of_mean, all->var_of_mean);
    mcp_dump_free(some);
    assert_int_equal(mcp__dump_load_without(&spec, MCP__DUMP_NO_NORMAL, &some), -1);
    spec.bad_values = MCP_BADVAL_ZERO;
    assert_int_equal(mcp__dump_load_without(&spec, MCP__DUMP_NO_NORMAL, &some), 0);
    mcp_test_assert_same_image(some->albedo, all->albedo);
    assert_null(some->normal);
    mcp_dump_free(some);
    /* the whole-image path (the direct reader hands back a channel named for two
       parts): the colour's channels as the normal */
    static const char *const rgb[3] = {"R", "G", "B"};
    for (int k = 0; k < 3; k++)
        spec.normal[k] = rgb[k];
    mcp_dump *clash = NULL;
    assert_int_equal(mcp_dump_load(&spec, &clash), 0);
    assert_int_equal(mcp__dump_load_without(&spec, MCP__DUMP_NO_ALBEDO, &some), 0);
    assert_null(some->albedo);
    assert_non_null(clash->albedo);
    mcp_test_assert_same_image(some->normal, clash->normal);
    mcp_test_assert_same_image(some->color, clash->color);
    mcp_dump_free(clash);
    mcp_dump_free(some);
    /* separate files are left unread: a missing one is no error */
    mcp_dump_spec sep = mcp_dump_spec_defaults();
    sep.path = path;
    sep.albedo_path = mcp_test_path("no-such-albedo.exr");
    sep.normal_path = mcp_test_path("no-such-normal.exr");
    assert_error_contains(mcp_dump_load(&sep, &some), "no-such-albedo.exr");
    assert_int_equal(mcp__dump_load_without(&sep, both, &some), 0);
    assert_null(some->albedo);
    assert_null(some->normal);
    mcp_dump_free(some);
    mcp_dump_free(all);
    mcp_dump_free(d);
}

static void
test_plain_with_separate_files(void **state)
{
    (void)state;
    mcp_image *color = mcp_test_constant(6, 6, 3, 1, (const char *[]){"R", "G", "B"});
    mcp_image *var = mcp_test_constant(6, 6, 3, 0.5f, (const char *[]){"R", "G", "B"});
    mcp_image *alb = mcp_test_constant(6, 6, 3, 0.7f, (const char *[]){"R", "G", "B"});
    mcp_image *small = mcp_test_constant(5, 6, 3, 0.7f, (const char *[]){"X", "Y", "Z"});
    assert_int_equal(mcp_image_write(color, mcp_test_path("c.pfm"), NULL), 0);
    assert_int_equal(mcp_image_write(var, mcp_test_path("v.pfm"), NULL), 0);
    assert_int_equal(mcp_image_write(alb, mcp_test_path("a.pfm"), NULL), 0);
    assert_int_equal(mcp_image_write(small, mcp_test_path("n.exr"), NULL), 0);
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = mcp_test_path("c.pfm");
    spec.variance_path = mcp_test_path("v.pfm");
    spec.albedo_path = mcp_test_path("a.pfm");
    spec.spp = 16;
    mcp_dump *d = NULL;
    assert_int_equal(mcp_dump_load(&spec, &d), 0);
    assert_int_equal(d->convention, MCP_CONV_PLAIN);
    /* a separate variance file is of-mean unless said otherwise */
    assert_true(d->var_of_mean->data[0] == 0.5f);
    assert_true(d->albedo->data[4] == 0.7f);
    mcp_dump_free(d);
    spec.variance = MCP_VAR_PER_SAMPLE;
    assert_int_equal(mcp_dump_load(&spec, &d), 0);
    assert_true(d->var_of_mean->data[0] == 0.5f / 16);
    mcp_dump_free(d);
    spec.normal_path = mcp_test_path("n.exr");
    assert_error_contains(mcp_dump_load(&spec, &d), "n.exr: size 5x6 does not match");
    mcp_image_free(color);
    mcp_image_free(var);
    mcp_image_free(alb);
    mcp_image_free(small);
}

static void
test_bad_values(void **state)
{
    (void)state;
    const char *names[] = {"R", "G", "B", "Variance.R", "Variance.G", "Variance.B"};
    mcp_image *img = mcp_test_constant(5, 4, 6, 1.0f, names);
    mcp_attrs_set_int(&img->attrs, "samplesPerPixel", 4);
    mcp_image_set_source(img, "bad.exr");
    mcp_image_px(img, 2, 1)[1] = NAN;
    mcp_image_px(img, 3, 1)[1] = INFINITY;
    mcp_dump *d = NULL;
    assert_error_contains(
        mcp_dump_from_image(img, NULL, &d),
        "bad.exr: colour channel 'G' has 2 NaN/Inf values (first nan at "
        "pixel 2,1");
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.bad_values = MCP_BADVAL_ZERO;
    assert_int_equal(mcp_dump_from_image(img, &spec, &d), 0);
    assert_int_equal(d->n_bad_values, 2);
    assert_true(mcp_image_px(d->color, 2, 1)[1] == 0);
    mcp_dump_free(d);
    mcp_image_px(img, 2, 1)[1] = 1;
    mcp_image_px(img, 3, 1)[1] = 1;
    mcp_image_px(img, 4, 3)[5] = -0.5f;
    assert_error_contains(mcp_dump_from_image(img, NULL, &d),
                          "variance channel 'B' has 1 negative value");
    mcp_image_px(img, 4, 3)[5] = 1;
    /* zero / missing sample counts */
    mcp_attrs_set_int(&img->attrs, "samplesPerPixel", 0);
    assert_error_contains(mcp_dump_from_image(img, NULL, &d), "bad.exr: no sample count");
    spec = mcp_dump_spec_defaults();
    spec.spp = -3;
    assert_error_contains(mcp_dump_from_image(img, &spec, &d), "sample count -3 given");
    /* missing colour channels */
    mcp_image *nocolor = mcp_test_constant(4, 4, 1, 0, (const char *[]){"Y"});
    mcp_image_set_source(nocolor, "grey.exr");
    assert_error_contains(mcp_dump_from_image(nocolor, NULL, &d),
                          "grey.exr: no channel 'R'");
    mcp_image_free(nocolor);
    mcp_image_free(img);
}

static void
test_series_pattern(void **state)
{
    (void)state;
    mcp_series *s = NULL;
    assert_int_equal(mcp_series_from_pattern("r/x_%04d.exr", (int[]){1, 2, 4}, 3, &s), 0);
    assert_string_equal(s->paths[2], "r/x_0004.exr");
    assert_true(s->spp[1] == 2);
    mcp_series_free(s);
    assert_error_contains(mcp_series_from_pattern("x_%s.exr", (int[]){1}, 1, &s),
                          "exactly one integer conversion");
    assert_error_contains(mcp_series_from_pattern("x_%d_%d.exr", (int[]){1}, 1, &s),
                          "exactly one integer conversion");
    assert_error_contains(mcp_series_from_pattern("x_%d.exr", (int[]){4, 2}, 2, &s),
                          "must increase");
    assert_error_contains(mcp_series_from_pattern("x_%d.exr", (int[]){0}, 1, &s),
                          "sample count 0");
    /* regression (issue 15): widths are bounded (16 is the most), and so are paths */
    assert_int_equal(mcp_series_from_pattern("x_%16d.exr", (int[]){7}, 1, &s), 0);
    assert_string_equal(s->paths[0], "x_               7.exr");
    mcp_series_free(s);
    assert_error_contains(
        mcp_series_from_pattern("x_%2147483640d.exr", (int[]){1}, 1, &s),
        "series pattern 'x_%2147483640d.exr': field widths over 16 are "
        "refused");
    assert_error_contains(mcp_series_from_pattern("x_%017d.exr", (int[]){1}, 1, &s),
                          "field widths over 16");
    /* a bad conversion after a good one is still refused */
    assert_error_contains(mcp_series_from_pattern("x_%d_%q", (int[]){1}, 1, &s),
                          "exactly one integer conversion");
    char *longest = malloc(4200);
    assert_non_null(longest);
    memset(longest, 'a', 4200);
    strcpy(longest + 4091, "%d"); /* 4091 + 4 digits = 4095 characters: fits */
    assert_int_equal(mcp_series_from_pattern(longest, (int[]){1000}, 1, &s), 0);
    assert_int_equal(strlen(s->paths[0]), 4095);
    mcp_series_free(s);
    assert_error_contains(mcp_series_from_pattern(longest, (int[]){1000, 10000}, 2, &s),
                          "the path for 10000 spp is longer than 4095 characters");
    free(longest);
}

/* ---- dumps in memory (mcp_dump_read_memory) ---- */

/* The bytes of a file, *size of them; NULL-free (fails the test). */
static unsigned char *
slurp(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    assert_int_equal(fseek(f, 0, SEEK_END), 0);
    long n = ftell(f);
    assert_true(n > 0);
    rewind(f);
    unsigned char *buf = malloc((size_t)n);
    assert_non_null(buf);
    assert_int_equal(fread(buf, 1, (size_t)n, f), (size_t)n);
    fclose(f);
    *size = (size_t)n;
    return buf;
}

/* A committed render (Blender's convention: colour, variance, albedo, normal, sample
 * count in the header) from its path and from its bytes. */
static void
test_read_memory_fixture(void **state)
{
    (void)state;
    char path[4096];
    snprintf(path, sizeof path, "%s/samples/fixtures/cornell/series/cornell_spp0016.exr",
             MCP_TEST_SOURCE_DIR);
    size_t size;
    unsigned char *bytes = slurp(path, &size);
    mcp_dump *from_file = NULL, *from_memory = NULL;
    assert_int_equal(mcp_dump_read(path, &from_file), 0);
    assert_non_null(from_file->var_of_mean);
    assert_non_null(from_file->albedo);
    assert_non_null(from_file->normal);
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = path; /* names it only */
    mcp_dump_buffers parts = {.main = {bytes, size}};
    assert_int_equal(mcp_dump_read_memory(&spec, &parts, &from_memory), 0);
    assert_same_dump(from_file, from_memory);
    mcp_dump_free(from_memory);
    /* without a path the buffer is named by its part */
    assert_int_equal(mcp_dump_read_memory(NULL, &parts, &from_memory), 0);
    assert_string_equal(from_memory->source, "main (in memory)");
    mcp_test_assert_same_image(from_file->color, from_memory->color);
    mcp_dump_free(from_memory);

    /* every separate part, in both formats, from files and from memory */
    static const char *const files[5] = {"m_main.pfm", "m_var.exr", "m_alb.pfm",
                                         "m_nrm.exr", "m_spp.pfm"};
    mcp_image *spp_map =
        mcp_test_random(from_file->color->width, from_file->color->height, 1, 1.0f, 64.0f,
                        7, (const char *[]){"n"});
    const mcp_image *images[5] = {from_file->color, from_file->var_of_mean,
                                  from_file->albedo, from_file->normal, spp_map};
    for (int i = 0; i < 5; i++)
        assert_int_equal(mcp_image_write(images[i], mcp_test_path(files[i]), NULL), 0);
    spec = mcp_dump_spec_defaults();
    spec.variance = MCP_VAR_PER_SAMPLE; /* per-sample, over the map's counts */
    const char **paths[5] = {&spec.path, &spec.variance_path, &spec.albedo_path,
                             &spec.normal_path, &spec.spp_map_path};
    mcp_dump_buffer *bufs[5] = {&parts.main, &parts.variance, &parts.albedo,
                                &parts.normal, &parts.spp_map};
    unsigned char *data[5];
    size_t sizes[5];
    for (int i = 0; i < 5; i++) {
        *paths[i] = mcp_test_path(files[i]);
        data[i] = slurp(*paths[i], &sizes[i]);
        *bufs[i] = (mcp_dump_buffer){data[i], sizes[i]};
    }
    mcp_dump *separate = NULL;
    assert_int_equal(mcp_dump_load(&spec, &separate), 0);
    assert_non_null(separate->spp_map);
    assert_int_equal(mcp_dump_read_memory(&spec, &parts, &from_memory), 0);
    assert_same_dump(separate, from_memory);
    mcp_dump_free(from_memory);
    /* some parts in memory, the others from their files */
    parts.main = parts.normal = (mcp_dump_buffer){0};
    assert_int_equal(mcp_dump_read_memory(&spec, &parts, &from_memory), 0);
    assert_same_dump(separate, from_memory);
    mcp_dump_free(from_memory);
    mcp_dump_free(separate);

    /* a truncated or corrupt buffer: one line that names the part */
    static const char *const roles[5] = {"main", "variance", "albedo", "normal",
                                         "spp map"};
    for (int i = 0; i < 5; i++)
        for (int corrupt = 0; corrupt < 2; corrupt++) {
            spec = mcp_dump_spec_defaults();
            spec.spp = 16;
            mcp_dump_buffers bad = {.main = {data[0], sizes[0]}};
            mcp_dump_buffer *b = (mcp_dump_buffer *[]){
                &bad.main, &bad.variance, &bad.albedo, &bad.normal, &bad.spp_map}[i];
            unsigned char *copy = malloc(sizes[i]);
            assert_non_null(copy);
            memcpy(copy, data[i], sizes[i]);
            size_t n = sizes[i] / 2; /* truncated in its pixels */
            if (corrupt)             /* a PFM header that promises more than it holds */
                n = (size_t)snprintf((char *)copy, sizes[i], "PF\n3 99999\n-1\n");
            *b = (mcp_dump_buffer){copy, n};
            char needle[64];
            snprintf(needle, sizeof needle, "%s (in memory): ", roles[i]);
            assert_error_contains(mcp_dump_read_memory(&spec, &bad, &from_memory),
                                  needle);
            assert_null(from_memory);
            assert_null(strchr(mcp_error_message(), '\n'));
            free(copy);
        }
    assert_error_contains(mcp_dump_read_memory(NULL, NULL, &from_memory),
                          "render dump: no file given");
    for (int i = 0; i < 5; i++)
        free(data[i]);
    mcp_image_free(spp_map);
    mcp_dump_free(from_file);
    free(bytes);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_pbrt_roundtrip),
        cmocka_unit_test(test_blender_roundtrip),
        cmocka_unit_test(test_mitsuba_roundtrip_needs_spp),
        cmocka_unit_test(test_per_sample_variance_semantics),
        cmocka_unit_test(test_mcpost_convention_per_pixel_spp_and_covariance),
        cmocka_unit_test(test_direct_read_matches_whole_image),
        cmocka_unit_test(test_plain_with_separate_files),
        cmocka_unit_test(test_bad_values),
        cmocka_unit_test(test_series_pattern),
        cmocka_unit_test(test_read_memory_fixture),
        cmocka_unit_test(test_load_without_features),
    };
    return cmocka_run_group_tests_name("common/dump", tests, NULL, NULL);
}
