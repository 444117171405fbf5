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

/* <scratch folder>/<name><suffix>.exr into path. */
static void
scratch_exr(const char *name, const char *suffix, char path[4096])
{
    char file[192];
    snprintf(file, sizeof file, "%s%s.exr", name, suffix);
    snprintf(path, 4096, "%s", mcp_test_path(file));
}

void
mcp_test_assert_streamed_is_whole(mcp_test_streamed_fn streamed, mcp_test_whole_fn whole,
                                  const void *ctx, const char *name)
{
    char streamed_path[4096], whole_path[4096];
    scratch_exr(name, "_streamed", streamed_path);
    scratch_exr(name, "_whole", whole_path);
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
    char out[4096], whole_error[2048];
    scratch_exr(name, "_failed", out);
    assert_int_equal(whole(ctx, out), -1);
    assert_int_not_equal(access(out, F_OK), 0);
    snprintf(whole_error, sizeof whole_error, "%s", mcp_error_message());
    int done = 0;
    assert_int_equal(streamed(ctx, out, &done), -1);
    assert_string_equal(mcp_error_message(), whole_error);
    assert_int_not_equal(access(out, F_OK), 0);
    print_message("both: %s\n", whole_error);
}
