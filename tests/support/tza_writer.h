/* tza_writer.h: a test-only writer of OIDN .tza archives (docs/oidn-network.md §2),
 * and the float16 rounding the writer uses. */
#ifndef MCP_TEST_TZA_WRITER_H
#define MCP_TEST_TZA_WRITER_H

#include <stddef.h>

typedef struct mcp_test_tza_tensor {
    const char *name;
    int ndims; /* 1 ("x") or 4 ("oihw") */
    int dims[4];
    const float *data; /* dims product values */
} mcp_test_tza_tensor;

/* Writes n tensors with dtype 'f' (float32) or 'h' (float16, rounded to nearest
 * even); any other dtype char is written as given with 1-byte zero elements (for
 * error tests). Asserts on I/O failure. */
void mcp_test_tza_write(const char *path, const mcp_test_tza_tensor *t, int n,
                        char dtype);

/* float -> float16 bits, round to nearest even (overflow to infinity). */
unsigned short mcp_test_float_to_half(float f);

/* Writes raw bytes to a file (asserts on failure). */
void mcp_test_write_bytes(const char *path, const void *data, size_t n);

#endif
