/* umbrella.c: a program of a library user: it includes <mcpost/mcpost.h> and nothing
 * else of mcpost's, is built with -pedantic against the build tree's public headers
 * only (build/include/mcpost, what is installed) and links the shared libmcpost, so
 * that what it calls must be exported (docs/library.md, "Exported symbols"). Each call
 * is checked against a value worked out by hand. */
#include <mcpost/mcpost.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

/* ref = 0 everywhere; test = 0.5 in every channel of a 4 x 4 RGB image but R = 1.5 at
 * (1, 2). MSE over the 48 values: (47 x 0.25 + 2.25) / 48 = 14 / 48. */
static void
mse_through_the_shared_library(void **state)
{
    (void)state;
    const char *const rgb[] = {"R", "G", "B"};
    mcp_image *test = NULL, *ref = NULL;
    assert_int_equal(mcp_image_new(4, 4, 3, rgb, &test), 0);
    assert_int_equal(mcp_image_new(4, 4, 3, rgb, &ref), 0);
    for (int y = 0; y < 4; y++)
        for (int x = 0; x < 4; x++)
            for (int c = 0; c < 3; c++)
                test->data[y * test->row_stride + x * test->pixel_stride + c] = 0.5f;
    test->data[2 * test->row_stride + 1 * test->pixel_stride + 0] = 1.5f;
    double mse = -1.0;
    assert_int_equal(mcp_mse(test, ref, &mse), 0);
    assert_true(fabs(mse - 14.0 / 48.0) < 1e-12);
    mcp_image_free(test);
    mcp_image_free(ref);
}

/* A failure sets the thread's one error line, which the user reads back. */
static void
error_line_through_the_shared_library(void **state)
{
    (void)state;
    mcp_error_clear();
    assert_string_equal(mcp_error_message(), "");
    assert_int_equal(mcp_error("channel %s of %s", "R", "a.exr"), -1);
    assert_string_equal(mcp_error_message(), "channel R of a.exr");
    assert_int_equal(mcp_error_prefix("reading: "), -1);
    assert_string_equal(mcp_error_message(), "reading: channel R of a.exr");
    mcp_error_clear();
}

/* The enums' words and the operation table are data the library exports. */
static void
words_and_tables_through_the_shared_library(void **state)
{
    (void)state;
    assert_string_equal(mcp_perc_method_name(MCP_PERC_HORIZONTAL), "horizontal");
    const mcp_operation *est = mcp_operation_find("estimate");
    assert_non_null(est);
    assert_non_null(mcp_operation_option(est, "tau"));
    assert_null(mcp_operation_option(est, "no_such_option"));
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(mse_through_the_shared_library),
        cmocka_unit_test(error_line_through_the_shared_library),
        cmocka_unit_test(words_and_tables_through_the_shared_library),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
