/* error.h: how mcpost reports failure.
 *
 * Every fallible function returns 0 on success or -1 on failure, after setting one
 * thread-local line that says what went wrong (lower case, no final period, naming the
 * file, channel, field or job-file line and the offending value). Callers either return
 * -1 unchanged or put context in front with mcp_error_prefix(). The CLI prints
 * "mcpost: <message>" and exits non-zero.
 *
 * OpenMP workers are other threads: never set an error inside a parallel loop; check
 * before it, or count failures and report after it. */
#ifndef MCP_ERROR_H
#define MCP_ERROR_H

#include <stddef.h>

#if defined(_WIN32)
#define MCP_API __declspec(dllexport)
#elif defined(__GNUC__)
#define MCP_API __attribute__((visibility("default")))
#else
#define MCP_API
#endif

#if defined(__GNUC__)
#define MCP_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#define MCP_PRINTF(a, b)
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* Sets the thread's error line; always returns -1 so that `return mcp_error(...)` works.
 */
MCP_API int mcp_error(const char *fmt, ...) MCP_PRINTF(1, 2);

/* Puts formatted text in front of the current error line; returns -1. */
MCP_API int mcp_error_prefix(const char *fmt, ...) MCP_PRINTF(1, 2);

/* The thread's current error line ("" when none was set). */
MCP_API const char *mcp_error_message(void);

MCP_API void mcp_error_clear(void);

/* Multiplies sizes with overflow checks: *out = a*b (*c); returns -1 (no message) on
 * overflow or a negative factor. */
MCP_API int mcp_size_mul(size_t a, size_t b, size_t *out);
MCP_API int mcp_size_mul3(size_t a, size_t b, size_t c, size_t *out);

/* Allocation that sets "out of memory (N bytes)" on failure (free with free()).
 * mcp_realloc leaves p as it was when it fails, as realloc does. */
MCP_API void *mcp_malloc(size_t bytes);
MCP_API void *mcp_calloc(size_t count, size_t size);
MCP_API void *mcp_realloc(void *p, size_t bytes);
MCP_API char *mcp_strdup(const char *s);

/* Images larger than this on either side are refused as corrupt rather than allocated. */
#define MCP_MAX_DIM (1 << 16)

#ifdef __cplusplus
}
#endif
#endif
