/* test_merge_stream.c: common/dump/merge_stream.c, `mcpost merge` a band of rows at a
 * time, against the whole merge it replaces (mcp_dump_load, mcp_dump_merge,
 * mcp_dump_write): the same channels, attributes and float bits in every value, for
 * replicates and pooled passes, per-pixel sample counts, covariances, Mitsuba 3's
 * moments and half floats, the variance pooled over windows that reach into other
 * bands (radius 1 to 40), over bands that do not divide the height; the same one-line
 * errors for bad values, a negative sample count, unequal sizes and a missing file,
 * with no output left; and the merges it leaves to the whole path. */
#include "streamed.h"
#include "testing.h"

#include <mcpost/dump.h>
#include <mcpost/imageio.h>
#include <procedural.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "../../common/dump/internal.h"

#define W 40
#define H 150 /* bands of 32 rows: four and a last one of 22 */

static mcp_proc_scene
scene(void)
{
    mcp_proc_scene s = mcp_proc_scene_defaults();
    s.width = W;
    s.height = H;
    return s;
}

/* Input k of a test, written in convention conv, in scanlines, or in tiles of `tile`
 * pixels (> 0), whose rows do not end where the bands of 32 do. */
static const char *
write_input_tiled(mcp_dump *d, const char *name, int k, mcp_convention conv, int tile)
{
    static char paths[8][4096];
    char file[64];
    snprintf(file, sizeof file, "%s_%d.exr", name, k);
    snprintf(paths[k], sizeof paths[k], "%s", mcp_test_path(file));
    mcp_write_options wo = mcp_write_defaults();
    wo.exr_tiled = tile > 0;
    wo.exr_tile_size = tile;
    assert_int_equal(mcp_dump_write(d, paths[k], conv, &wo), 0);
    mcp_dump_free(d);
    return paths[k];
}

static const char *
write_input(mcp_dump *d, const char *name, int k, mcp_convention conv)
{
    return write_input_tiled(d, name, k, conv, 0);
}

static mcp_dump *
render(int spp, int k)
{
    mcp_proc_scene s = scene();
    mcp_dump *d = NULL;
    assert_int_equal(mcp_proc_render(&s, spp, mcp_proc_realization_seed(5, k), NULL, &d),
                     0);
    return d;
}

/* A pass with per-pixel counts: 4 to 16 samples, varying over the image. */
static mcp_dump *
render_counts(int k)
{
    mcp_proc_scene s = scene();
    mcp_image *counts = mcp_test_constant(W, H, 1, 0, (const char *[]){"SampleCount"});
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            mcp_image_px(counts, x, y)[0] = (float)(4 * (1 + (x + 3 * y + k) % 4));
    mcp_dump *d = NULL;
    assert_int_equal(mcp_proc_render_counts(&s, counts, k, 9, &d), 0);
    mcp_image_free(counts);
    return d;
}

typedef struct merge_case {
    int count;
    const char *const *paths;
    mcp_merge_options opt;
    mcp_dump_spec spec; /* path set per input */
    mcp_write_options wo;
} merge_case;

static merge_case
merge_case_of(int count, const char *const *paths)
{
    merge_case c = {count, paths, mcp_merge_defaults(), mcp_dump_spec_defaults(),
                    mcp_write_defaults()};
    return c;
}

/* The streamed merge into out; its return, *done as it says. */
static int
merge_streamed(const void *ctx, const char *out, int *done)
{
    const merge_case *c = ctx;
    mcp_dump_spec specs[8];
    for (int k = 0; k < c->count; k++) {
        specs[k] = c->spec;
        specs[k].path = c->paths[k];
    }
    mcp_dump *last = NULL;
    int rc = mcp__dump_merge_streamed(specs, c->count, &c->opt, out, &c->wo, &last, done);
    if (rc == 0 && *done) assert_non_null(last);
    mcp_dump_free(last);
    return rc;
}

/* The whole merge into out, as `mcpost merge` made it before. */
static int
merge_whole(const void *ctx, const char *out)
{
    const merge_case *c = ctx;
    mcp_dump *parts[8] = {0}, *m = NULL;
    int rc = 0;
    for (int k = 0; k < c->count && !rc; k++) {
        mcp_dump_spec spec = c->spec;
        spec.path = c->paths[k];
        rc = mcp_dump_load(&spec, &parts[k]);
    }
    rc = rc || mcp_dump_merge((const mcp_dump *const *)parts, c->count, &c->opt, &m) ||
         mcp_dump_write(m, out, MCP_CONV_MCPOST, &c->wo);
    for (int k = 0; k < c->count; k++)
        mcp_dump_free(parts[k]);
    mcp_dump_free(m);
    return rc ? -1 : 0;
}

static void
test_replicates_and_passes(void **state)
{
    (void)state;
    const char *paths[3];
    for (int k = 0; k < 3; k++) /* pbrt: per-sample variance, albedo, normal */
        paths[k] = write_input(render(4, k), "rep", k, MCP_CONV_PBRT);
    merge_case c = merge_case_of(3, paths);
    mcp_test_assert_streamed_is_whole(merge_streamed, merge_whole, &c, "rep");
    /* pooled over windows that reach into the bands above and below: radius 1, and 40,
       more than a band of 32 rows */
    c.opt.pool_radius = 1;
    mcp_test_assert_streamed_is_whole(merge_streamed, merge_whole, &c, "rep_pool1");
    c.opt.pool_radius = 40;
    mcp_test_assert_streamed_is_whole(merge_streamed, merge_whole, &c, "rep_pool40");
    c.opt.pool_radius = 0;
    c.opt.variance = MCP_MERGE_POOLED;
    mcp_test_assert_streamed_is_whole(merge_streamed, merge_whole, &c, "pooled");
    c.opt.pool_radius = 2;
    mcp_test_assert_streamed_is_whole(merge_streamed, merge_whole, &c, "pooled_pool2");
    c.opt.pool_radius = 0;
    c.wo.exr_pixel = MCP_EXR_HALF;
    mcp_test_assert_streamed_is_whole(merge_streamed, merge_whole, &c, "pooled_half");
    /* tiles of 48 rows: a band's rows start inside a tile */
    for (int k = 0; k < 3; k++)
        paths[k] = write_input_tiled(render(4, k), "tiled", k, MCP_CONV_PBRT, 48);
    c = merge_case_of(3, paths);
    mcp_test_assert_streamed_is_whole(merge_streamed, merge_whole, &c, "tiled");
}

static void
test_counts_covariance_moments(void **state)
{
    (void)state;
    const char *paths[3];
    for (int k = 0; k < 3; k++) /* mcpost: a SampleCount channel */
        paths[k] = write_input(render_counts(k), "counts", k, MCP_CONV_MCPOST);
    merge_case c = merge_case_of(3, paths);
    mcp_test_assert_streamed_is_whole(merge_streamed, merge_whole, &c, "counts");
    c.opt.pool_radius = 2;
    mcp_test_assert_streamed_is_whole(merge_streamed, merge_whole, &c, "counts_pool2");
    /* merged replicates hold a covariance and say where their variance came from */
    const char *twice[2];
    for (int k = 0; k < 2; k++) {
        mcp_dump *parts[3], *m = NULL;
        for (int j = 0; j < 3; j++)
            parts[j] = render(2, 10 * k + j);
        assert_int_equal(mcp_dump_merge((const mcp_dump *const *)parts, 3, NULL, &m), 0);
        for (int j = 0; j < 3; j++)
            mcp_dump_free(parts[j]);
        assert_non_null(m->cov_of_mean);
        twice[k] = write_input(m, "cov", k, MCP_CONV_MCPOST);
    }
    c = merge_case_of(2, twice);
    mcp_test_assert_streamed_is_whole(merge_streamed, merge_whole, &c, "cov");
    c.opt.pool_radius = 3; /* the covariance pooled beside the variance */
    mcp_test_assert_streamed_is_whole(merge_streamed, merge_whole, &c, "cov_pool3");
    /* Mitsuba 3's moments (m2_*): no sample count in the file, so one is given */
    for (int k = 0; k < 2; k++)
        paths[k] = write_input(render(8, 20 + k), "mitsuba", k, MCP_CONV_MITSUBA);
    c = merge_case_of(2, paths);
    c.spec.spp = 8;
    mcp_test_assert_streamed_is_whole(merge_streamed, merge_whole, &c, "mitsuba");
}

static void
test_same_errors(void **state)
{
    (void)state;
    const char *paths[3];
    /* NaN in the colour of the second input, in its fourth band */
    for (int k = 0; k < 3; k++) {
        mcp_dump *d = render(4, 30 + k);
        if (k == 1) {
            mcp_image_px(d->color, 7, 101)[1] = NAN;
            mcp_image_px(d->color, 2, 140)[0] = INFINITY;
        }
        paths[k] = write_input(d, "bad", k, MCP_CONV_PBRT);
    }
    merge_case c = merge_case_of(3, paths);
    mcp_test_assert_same_failure(merge_streamed, merge_whole, &c, "bad");
    c.spec.bad_values = MCP_BADVAL_ZERO; /* replaced, in every band */
    mcp_test_assert_streamed_is_whole(merge_streamed, merge_whole, &c, "bad_zero");
    /* a negative sample count in the last band */
    for (int k = 0; k < 2; k++) {
        mcp_dump *d = render_counts(k);
        if (k == 1) mcp_image_px(d->spp_map, 5, 133)[0] = -4;
        paths[k] = write_input(d, "negative", k, MCP_CONV_MCPOST);
    }
    c = merge_case_of(2, paths);
    mcp_test_assert_same_failure(merge_streamed, merge_whole, &c, "negative");
    /* unequal sizes */
    mcp_proc_scene s = scene();
    s.height = H - 10;
    mcp_dump *d = NULL;
    assert_int_equal(mcp_proc_render(&s, 4, 3, NULL, &d), 0);
    paths[0] = write_input(render(4, 40), "sizes", 0, MCP_CONV_PBRT);
    paths[1] = write_input(d, "sizes", 1, MCP_CONV_PBRT);
    c = merge_case_of(2, paths);
    mcp_test_assert_same_failure(merge_streamed, merge_whole, &c, "sizes");
    /* a missing input */
    paths[1] = mcp_test_path("no_such_dump.exr");
    mcp_test_assert_same_failure(merge_streamed, merge_whole, &c, "missing");
}

/* What the streamed merge leaves to the whole one: inputs in another format, an output
 * in another format, and MCPOST_BAND_ROWS=whole. */
static void
test_left_whole(void **state)
{
    (void)state;
    const char *paths[2];
    for (int k = 0; k < 2; k++)
        paths[k] = write_input(render(4, 50 + k), "left", k, MCP_CONV_PBRT);
    merge_case c = merge_case_of(2, paths);
    int done = 1;
    const char *out = mcp_test_path("left_out.exr");
    assert_int_equal(merge_streamed(&c, mcp_test_path("left_out.pfm"), &done), 0);
    assert_int_equal(done, 0);
    mcp_image *pfm = NULL;
    assert_int_equal(mcp_image_read(paths[0], NULL, &pfm), 0);
    int rgb[3] = {0, 1, 2};
    mcp_image *colour = NULL;
    assert_int_equal(mcp_image_copy_channels(pfm, rgb, 3, &colour), 0);
    mcp_write_options wo = mcp_write_defaults();
    const char *pfm_path = mcp_test_path("left_in.pfm");
    assert_int_equal(mcp_image_write(colour, pfm_path, &wo), 0);
    mcp_image_free(pfm);
    mcp_image_free(colour);
    const char *mixed[2] = {paths[0], pfm_path};
    c = merge_case_of(2, mixed);
    c.spec.spp = 4;
    done = 1;
    assert_int_equal(merge_streamed(&c, out, &done), 0);
    assert_int_equal(done, 0);
    assert_int_not_equal(access(out, F_OK), 0);
    setenv("MCPOST_BAND_ROWS", "whole", 1);
    c = merge_case_of(2, paths);
    done = 1;
    assert_int_equal(merge_streamed(&c, out, &done), 0);
    assert_int_equal(done, 0);
    setenv("MCPOST_BAND_ROWS", "32", 1);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_replicates_and_passes),
        cmocka_unit_test(test_counts_covariance_moments),
        cmocka_unit_test(test_same_errors),
        cmocka_unit_test(test_left_whole),
    };
    return cmocka_run_group_tests(tests, mcp_test_bands_of_32, NULL);
}
