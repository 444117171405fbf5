/* streamed.c: see streamed.h. */
#include "streamed.h"
#include "testing.h"

#include <mcpost/error.h>

#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

int
mcp_test_bands_of_32(void **state)
{
    (void)state;
    return setenv("MCPOST_BAND_ROWS", "32", 1);
}

void
mcp_test_assert_streamed_is_whole(mcp_test_streamed_fn streamed, mcp_test_whole_fn whole,
                                  const void *ctx, const char *name)
{
    char streamed_path[4096], whole_path[4096], file[160];
    snprintf(file, sizeof file, "%s_streamed.exr", name);
    snprintf(streamed_path, sizeof streamed_path, "%s", mcp_test_path(file));
    snprintf(file, sizeof file, "%s_whole.exr", name);
    snprintf(whole_path, sizeof whole_path, "%s", mcp_test_path(file));
    int done = 0;
    assert_int_equal(streamed(ctx, streamed_path, &done), 0);
    assert_int_equal(done, 1);
    assert_int_equal(whole(ctx, whole_path), 0);
    mcp_test_assert_same_image_files(streamed_path, whole_path);
}

void
mcp_test_assert_same_failure(mcp_test_streamed_fn streamed, mcp_test_whole_fn whole,
                             const void *ctx, const char *name)
{
    char out[4096], file[160], whole_error[2048];
    snprintf(file, sizeof file, "%s_failed.exr", name);
    snprintf(out, sizeof out, "%s", mcp_test_path(file));
    assert_int_equal(whole(ctx, out), -1);
    assert_int_not_equal(access(out, F_OK), 0);
    snprintf(whole_error, sizeof whole_error, "%s", mcp_error_message());
    int done = 0;
    assert_int_equal(streamed(ctx, out, &done), -1);
    assert_string_equal(mcp_error_message(), whole_error);
    assert_int_not_equal(access(out, F_OK), 0);
    print_message("both: %s\n", whole_error);
}
