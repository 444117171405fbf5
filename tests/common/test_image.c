/* test_image.c: the shared image type -- creation, views, channel lookup, attributes. */
#include "testing.h"

#include <mcpost/image.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "../../common/core/internal.h"

static void
test_new_is_zeroed_and_packed(void **state)
{
    (void)state;
    mcp_image *img = NULL;
    assert_int_equal(mcp_image_new(5, 3, 2, (const char *[]){"a", "b"}, &img), 0);
    assert_true(mcp_image_is_packed(img));
    for (int i = 0; i < 30; i++)
        assert_true(img->data[i] == 0.0f);
    assert_string_equal(img->names[1], "b");
    mcp_image_free(img);
    mcp_image_free(NULL);
}

static void
test_bad_sizes_are_refused(void **state)
{
    (void)state;
    mcp_image *img = (mcp_image *)1;
    assert_error_contains(mcp_image_new(0, 3, 1, NULL, &img), "bad image size 0x3x1");
    assert_null(img);
    assert_error_contains(mcp_image_new(MCP_MAX_DIM + 1, 1, 1, NULL, &img),
                          "bad image size");
    assert_error_contains(mcp_image_new(4, 4, -1, NULL, &img), "bad image size");
}

/* Regression (issue 15): every image is held under a ceiling on its pixels and bytes,
 * 2^28 and 2^34 unless the environment says otherwise. */
static void
test_size_ceiling(void **state)
{
    (void)state;
    mcp_image *img = NULL;
    unsetenv("MCPOST_MAX_PIXELS");
    unsetenv("MCPOST_MAX_BYTES");
    assert_int_equal(mcp_image_check_size(16384, 16384, 16), 0);
    assert_error_contains(
        mcp_image_check_size(16385, 16384, 1),
        "image of 16385x16384 pixels is over the limit of 268435456 pixels "
        "(MCPOST_MAX_PIXELS raises it)");
    assert_error_contains(
        mcp_image_check_size(16384, 16384, 17),
        "image of 16384x16384x17 values (18253611008 bytes) is over the "
        "limit of 17179869184 bytes (MCPOST_MAX_BYTES raises it)");
    setenv("MCPOST_MAX_PIXELS", "100", 1);
    assert_int_equal(mcp_image_new(10, 10, 3, NULL, &img), 0);
    mcp_image_free(img);
    assert_error_contains(mcp_image_new(10, 11, 1, NULL, &img),
                          "image of 10x11 pixels is over the limit of 100 pixels");
    assert_null(img);
    setenv("MCPOST_MAX_BYTES", "1200", 1); /* 10 x 10 x 3 floats exactly */
    assert_int_equal(mcp_image_new(10, 10, 3, NULL, &img), 0);
    mcp_image_free(img);
    assert_error_contains(
        mcp_image_new(10, 10, 4, NULL, &img),
        "image of 10x10x4 values (1600 bytes) is over the limit of 1200 bytes");
    static const char *const bad[] = {"lots", "0", "-5", "12k", " 7"};
    for (int i = 0; i < 5; i++) {
        char want[96];
        setenv("MCPOST_MAX_PIXELS", bad[i], 1);
        snprintf(want, sizeof want,
                 "MCPOST_MAX_PIXELS must be a positive whole number (got '%s')", bad[i]);
        assert_error_contains(mcp_image_new(1, 1, 1, NULL, &img), want);
    }
    unsetenv("MCPOST_MAX_PIXELS");
    unsetenv("MCPOST_MAX_BYTES");
}

static void
test_crop_view_shares_pixels(void **state)
{
    (void)state;
    mcp_image *img = mcp_test_ramp(8, 6, 3, NULL), *view = NULL, *copy = NULL;
    assert_int_equal(mcp_image_crop_view(img, 2, 1, 4, 3, &view), 0);
    assert_false(mcp_image_is_packed(view));
    /* ramp value = x + 10 y + 100 c, in parent coordinates */
    assert_true(mcp_image_px(view, 0, 0)[1] == 2 + 10 * 1 + 100);
    assert_true(mcp_image_px(view, 3, 2)[2] == 5 + 10 * 3 + 200);
    mcp_image_px(view, 1, 1)[0] = -7;
    assert_true(mcp_image_px(img, 3, 2)[0] == -7);
    assert_int_equal(mcp_image_copy(view, &copy), 0);
    assert_true(mcp_image_is_packed(copy));
    assert_true(mcp_test_max_abs_diff(copy, view) == 0);
    mcp_image_free(view);
    assert_error_contains(mcp_image_crop_view(img, 6, 0, 4, 1, &view), "lies outside");
    assert_null(view);
    mcp_image_free(copy);
    mcp_image_free(img);
}

/* A view of the caller's pixels: strides as given, the pixels never freed. */
static void
test_wrap_borrows_pixels(void **state)
{
    (void)state;
    float px[2 * 3 * 4]; /* 2 rows, 3 pixels of 4 floats, of which 2 channels are used */
    for (int i = 0; i < 24; i++)
        px[i] = (float)i;
    mcp_image *img = NULL;
    assert_int_equal(mcp_image_wrap(px + 1, 3, 2, 2, 4, 12, (const char *[]){"u", "v"},
                                    "buffer", &img),
                     0);
    assert_false(img->owns_data);
    assert_string_equal(img->names[1], "v");
    assert_string_equal(img->source, "buffer");
    /* pixel (2, 1), channel 1: 1 + 1 * 12 + 2 * 4 + 1 */
    assert_true(mcp_image_px(img, 2, 1)[1] == 22.0f);
    mcp_image_free(img); /* px is on the stack: freeing it would crash */
    assert_error_contains(mcp_image_wrap(px, 3, 2, 4, 2, 12, NULL, "buffer", &img),
                          "buffer: bad pixel layout (pixel stride 2");
    assert_null(img);
    assert_error_contains(mcp_image_wrap(px, 0, 2, 1, 1, 1, NULL, NULL, &img),
                          "bad image size 0x2x1");
}

static void
test_channel_view_and_subset(void **state)
{
    (void)state;
    const char *names[] = {"R", "G", "B", "Variance.R", "Variance.G", "Variance.B"};
    mcp_image *img = mcp_test_ramp(4, 4, 6, names), *var = NULL, *sub = NULL;
    assert_int_equal(mcp_image_channel_view(img, 3, 3, &var), 0);
    assert_string_equal(var->names[0], "Variance.R");
    assert_true(mcp_image_px(var, 2, 3)[1] == 2 + 30 + 400);
    int idx[3];
    assert_int_equal(
        mcp_image_channels(img, (const char *[]){"B", "R", "Variance.G"}, 3, idx), 0);
    assert_int_equal(idx[0], 2);
    assert_int_equal(mcp_image_copy_channels(img, idx, 3, &sub), 0);
    assert_string_equal(sub->names[2], "Variance.G");
    assert_true(mcp_image_px(sub, 1, 2)[0] == 1 + 20 + 200);
    assert_true(mcp_image_px(sub, 1, 2)[2] == 1 + 20 + 400);
    assert_int_equal(mcp_image_channel(img, "A"), -1);
    mcp_image_set_source(img, "x.exr");
    assert_error_contains(mcp_image_channels(img, (const char *[]){"R", "A"}, 2, idx),
                          "x.exr: no channel 'A'");
    mcp_image_free(sub);
    mcp_image_free(var);
    mcp_image_free(img);
}

static void
test_attributes(void **state)
{
    (void)state;
    mcp_attrs a = {0}, b = {0};
    assert_int_equal(mcp_attrs_set_int(&a, "samplesPerPixel", 64), 0);
    assert_int_equal(mcp_attrs_set_string(&a, "renderer", "pbrt"), 0);
    assert_int_equal(mcp_attrs_set_double(&a, "exposure", 0.25), 0);
    assert_int_equal(mcp_attrs_set_int(&a, "samplesPerPixel", 128), 0);
    assert_int_equal(a.count, 3);
    assert_int_equal(mcp_attrs_copy(&a, &b), 0);
    mcp_attrs_clear(&a);
    assert_int_equal(mcp_attrs_find(&b, "samplesPerPixel")->i, 128);
    assert_string_equal(mcp_attrs_find(&b, "renderer")->s, "pbrt");
    assert_null(mcp_attrs_find(&b, "nope"));
    mcp_attrs_clear(&b);
}

static void
test_same_size_message(void **state)
{
    (void)state;
    mcp_image *a = mcp_test_constant(4, 4, 1, 0, NULL),
              *b = mcp_test_constant(4, 5, 1, 0, NULL);
    mcp_image_set_source(a, "a.exr");
    mcp_image_set_source(b, "b.exr");
    assert_false(mcp_image_same_size(a, b));
    assert_string_equal(mcp_error_message(),
                        "a.exr: size 4x4 does not match b.exr (4x5)");
    mcp_image_free(a);
    mcp_image_free(b);
}

/* A colour triple: the first name triple present, in the triple's order whatever the
 * file's channel order; else exactly 3 channels in order; else none. */
static void
test_find_triple(void **state)
{
    (void)state;
    static const char *const triples[][3] = {{"R", "G", "B"}, {"X", "Y", "Z"}};
    static const char *const sorted[] = {"A", "B", "G", "R", "Z"};
    static const char *const xyz[] = {"Z", "Y", "X", "W"};
    static const char *const three[] = {"u", "v", "w"};
    mcp_image *a = NULL, *b = NULL, *c = NULL, *d = NULL;
    assert_int_equal(mcp_image_new(2, 2, 5, sorted, &a), 0);
    assert_int_equal(mcp_image_new(2, 2, 4, xyz, &b), 0);
    assert_int_equal(mcp_image_new(2, 2, 3, three, &c), 0);
    assert_int_equal(mcp_image_new(2, 2, 2, NULL, &d), 0);
    int idx[3];
    assert_int_equal(mcp_image_find_triple(a, triples, 2, idx), 0);
    assert_int_equal(idx[0], 3);
    assert_int_equal(idx[1], 2);
    assert_int_equal(idx[2], 1);
    assert_int_equal(mcp_image_find_triple(b, triples, 2, idx), 0);
    assert_int_equal(idx[0], 2);
    assert_int_equal(idx[2], 0);
    assert_int_equal(mcp_image_find_triple(b, triples, 1, idx), -1); /* R,G,B only */
    assert_int_equal(mcp_image_find_triple(c, triples, 2, idx), 0);
    assert_int_equal(idx[0] + 10 * idx[1] + 100 * idx[2], 210);
    assert_int_equal(mcp_image_find_triple(d, triples, 2, idx), -1);
    mcp_image_free(a), mcp_image_free(b), mcp_image_free(c), mcp_image_free(d);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_new_is_zeroed_and_packed),
        cmocka_unit_test(test_bad_sizes_are_refused),
        cmocka_unit_test(test_size_ceiling),
        cmocka_unit_test(test_crop_view_shares_pixels),
        cmocka_unit_test(test_wrap_borrows_pixels),
        cmocka_unit_test(test_channel_view_and_subset),
        cmocka_unit_test(test_attributes),
        cmocka_unit_test(test_same_size_message),
        cmocka_unit_test(test_find_triple),
    };
    return cmocka_run_group_tests_name("common/image", tests, NULL, NULL);
}
