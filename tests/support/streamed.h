/* streamed.h: a command run a band of rows at a time against the same command run
 * whole (merge, convert: tests/common/test_merge_stream.c, tests/jobs/
 * test_convert_stream.c). */
#ifndef MCP_TEST_STREAMED_H
#define MCP_TEST_STREAMED_H

/* A group setup: bands of 32 rows (MCPOST_BAND_ROWS), so that a small test image
 * goes in several bands, the last one short. */
int mcp_test_bands_of_32(void **state);

/* The command into the file out: streamed (its return; *done 1 when it streamed, 0
 * when it left the work to the whole command) or whole (its return). */
typedef int (*mcp_test_streamed_fn)(const void *ctx, const char *out, int *done);
typedef int (*mcp_test_whole_fn)(const void *ctx, const char *out);

/* Both succeed, the streamed one streaming, into NAME_streamed.exr and NAME_whole.exr
 * of the scratch folder, which hold the same channels, attributes and float bits. */
void mcp_test_assert_streamed_is_whole(mcp_test_streamed_fn streamed,
                                       mcp_test_whole_fn whole, const void *ctx,
                                       const char *name);
/* Both fail with the same error line (one output name for both, which the line may
 * name), and neither leaves its output. */
void mcp_test_assert_same_failure(mcp_test_streamed_fn streamed, mcp_test_whole_fn whole,
                                  const void *ctx, const char *name);

#endif
