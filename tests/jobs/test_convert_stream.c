/* test_convert_stream.c: jobs/convert_stream.c, `mcpost convert` of an EXR into an EXR
 * a band of rows at a time, against the whole conversion it replaces (mcp_image_read,
 * mcp__convert_pick_channels, mcp_image_write; with --dump, mcp_dump_load and
 * mcp_dump_write): the same channels, attributes and float bits for every channel, a
 * pick of channels in half floats, a tiled input, and a dump in each convention, over
 * bands that do not divide the height; the same one-line errors (a channel the file
 * lacks, a compression that cannot be written, a bad value in a dump, a count map in a
 * convention without one) with no output left; and what it leaves to the whole
 * conversion. */
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
#include "../../jobs/internal.h"

#define W 36
#define H 130 /* bands of 32 rows: four and a last one of 2 */

static const char *
render_to(const char *name, mcp_convention conv, int tile, int bad, int counts)
{
    mcp_proc_scene s = mcp_proc_scene_defaults();
    s.width = W;
    s.height = H;
    mcp_dump *d = NULL;
    if (counts) {
        mcp_image *n = mcp_test_constant(W, H, 1, 0, (const char *[]){"SampleCount"});
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                mcp_image_px(n, x, y)[0] = (float)(4 * (1 + (x + y) % 3));
        assert_int_equal(mcp_proc_render_counts(&s, n, 0, 3, &d), 0);
        mcp_image_free(n);
    } else {
        assert_int_equal(mcp_proc_render(&s, 4, 3, NULL, &d), 0);
    }
    if (bad) mcp_image_px(d->var_of_mean, 4, 97)[2] = NAN;
    static char paths[4][4096];
    static int next;
    char *path = paths[next++ % 4];
    snprintf(path, 4096, "%s", mcp_test_path(name));
    mcp_write_options wo = mcp_write_defaults();
    wo.exr_tiled = tile > 0;
    wo.exr_tile_size = tile;
    assert_int_equal(mcp_dump_write(d, path, conv, &wo), 0);
    mcp_dump_free(d);
    return path;
}

typedef struct convert_case {
    const char *in;
    char **names;
    int count;
    int as_dump;
    mcp_convention conv;
    mcp_write_options wo;
} convert_case;

static convert_case
case_of(const char *in)
{
    convert_case c = {in, NULL, 0, 0, MCP_CONV_AUTO, mcp_write_defaults()};
    return c;
}

static mcp_dump_spec
spec_of(const convert_case *c)
{
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = c->in;
    return spec;
}

static int
convert_streamed(const void *ctx, const char *out, int *done)
{
    const convert_case *c = ctx;
    mcp_dump_spec spec = spec_of(c);
    return mcp__convert_streamed(c->in, out, c->names, c->count,
                                 c->as_dump ? &spec : NULL, c->conv, &c->wo, done);
}

static int
convert_whole(const void *ctx, const char *out)
{
    const convert_case *c = ctx;
    int rc;
    if (c->as_dump) {
        mcp_dump_spec spec = spec_of(c);
        mcp_dump *d = NULL;
        rc = mcp_dump_load(&spec, &d) || mcp_dump_write(d, out, c->conv, &c->wo);
        mcp_dump_free(d);
    } else {
        mcp_image *img = NULL, *picked = NULL;
        rc = mcp_image_read(c->in, NULL, &img) ||
             mcp__convert_pick_channels(img, c->names, c->count, out, &picked) ||
             mcp_image_write(picked, out, &c->wo);
        mcp_image_free(img);
        mcp_image_free(picked);
    }
    return rc ? -1 : 0;
}

static void
test_images(void **state)
{
    (void)state;
    convert_case c = case_of(render_to("pbrt.exr", MCP_CONV_PBRT, 0, 0, 0));
    mcp_test_assert_streamed_is_whole(convert_streamed, convert_whole, &c, "all");
    char *pick[3] = {"Variance.R", "R", "N.Y"};
    c.names = pick;
    c.count = 3;
    c.wo.exr_pixel = MCP_EXR_HALF;
    c.wo.compression = MCP_EXR_PIZ;
    mcp_test_assert_streamed_is_whole(convert_streamed, convert_whole, &c, "picked");
    c.names = NULL;
    c.count = 0;
    c.wo.compression = MCP_EXR_DWAA; /* refused, naming the output, not its temporary */
    mcp_test_assert_same_failure(convert_streamed, convert_whole, &c, "dwaa");
    /* tiles of 24 pixels: two columns of them, and bands that start inside a tile */
    c = case_of(render_to("tiled.exr", MCP_CONV_PBRT, 24, 0, 0));
    mcp_test_assert_streamed_is_whole(convert_streamed, convert_whole, &c, "tiled");
    char *missing[2] = {"R", "Depth.Z"};
    c.names = missing;
    c.count = 2;
    mcp_test_assert_same_failure(convert_streamed, convert_whole, &c, "missing");
}

static void
test_dumps(void **state)
{
    (void)state;
    convert_case c = case_of(render_to("dump.exr", MCP_CONV_PBRT, 0, 0, 0));
    c.as_dump = 1;
    const mcp_convention convs[] = {MCP_CONV_MITSUBA, MCP_CONV_BLENDER, MCP_CONV_MCPOST,
                                    MCP_CONV_PBRT};
    const char *names[] = {"mitsuba", "blender", "mcpost", "pbrt"};
    for (int i = 0; i < 4; i++) {
        c.conv = convs[i];
        mcp_test_assert_streamed_is_whole(convert_streamed, convert_whole, &c, names[i]);
    }
    c = case_of(render_to("counts.exr", MCP_CONV_MCPOST, 0, 0, 1));
    c.as_dump = 1;
    c.conv = MCP_CONV_MCPOST;
    mcp_test_assert_streamed_is_whole(convert_streamed, convert_whole, &c, "counts");
    c.conv = MCP_CONV_BLENDER; /* a count map has no place there */
    mcp_test_assert_same_failure(convert_streamed, convert_whole, &c, "counts_blender");
    c = case_of(render_to("bad.exr", MCP_CONV_PBRT, 0, 1, 0));
    c.as_dump = 1;
    c.conv = MCP_CONV_MITSUBA;
    mcp_test_assert_same_failure(convert_streamed, convert_whole, &c, "bad");
}

static void
test_left_whole(void **state)
{
    (void)state;
    convert_case c = case_of(render_to("left.exr", MCP_CONV_PBRT, 0, 0, 0));
    int done = 1;
    assert_int_equal(convert_streamed(&c, mcp_test_path("left.png"), &done), 0);
    assert_int_equal(done, 0);
    c.wo.exr_tiled = 1;
    c.wo.exr_tile_size = 32;
    done = 1;
    assert_int_equal(convert_streamed(&c, mcp_test_path("left_tiled.exr"), &done), 0);
    assert_int_equal(done, 0);
    assert_int_not_equal(access(mcp_test_path("left_tiled.exr"), F_OK), 0);
    setenv("MCPOST_BAND_ROWS", "whole", 1);
    c = case_of(c.in);
    done = 1;
    assert_int_equal(convert_streamed(&c, mcp_test_path("left_whole.exr"), &done), 0);
    assert_int_equal(done, 0);
    setenv("MCPOST_BAND_ROWS", "32", 1);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_images),
        cmocka_unit_test(test_dumps),
        cmocka_unit_test(test_left_whole),
    };
    return cmocka_run_group_tests(tests, mcp_test_bands_of_32, NULL);
}
