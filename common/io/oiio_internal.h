/* oiio_internal.h: the C ABI between imageio.c and the OpenImageIO plug-in
 * (not installed; the plug-in is C++ and includes nothing else of mcpost). */
#ifndef MCP_OIIO_INTERNAL_H
#define MCP_OIIO_INTERNAL_H

#include <stddef.h>

/* The C ABI of the OpenImageIO plug-in (mcpost_oiio.so), resolved with dlsym.
 * read: *data (w*h*c floats, interleaved, top row first) and *names (c strings) are
 * allocated with malloc and released by the caller with free(); *integer_bits is the
 * bit depth of an integer pixel format (8, 16) or 0 for float formats, so that the
 * caller can decide on sRGB decoding.
 * write: data is w*h*c floats; bits 8 writes UINT8, 0 writes float.
 * Both return 0, or -1 with a one-line message in err. */
typedef int (*mcp__oiio_read_fn)(const char *path, int *w, int *h, int *c, float **data,
                                 char ***names, int *integer_bits, char *err,
                                 size_t err_cap);
typedef int (*mcp__oiio_write_fn)(const char *path, int w, int h, int c,
                                  const float *data, int bits, char *err, size_t err_cap);
#define MCP__OIIO_READ "mcp_oiio_plugin_read"
#define MCP__OIIO_WRITE "mcp_oiio_plugin_write"

#endif
