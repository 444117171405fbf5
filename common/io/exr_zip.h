/* exr_zip.h: OpenEXR's ZIP/ZIPS chunk codec on libdeflate (exr_zip.c), for exr.c.
 * A codec holds one thread's state and buffers: one per thread, never shared. */
#ifndef MCP_EXR_ZIP_H
#define MCP_EXR_ZIP_H

#include <stddef.h>

typedef struct mcp__zip_codec mcp__zip_codec;

/* An encoder at a deflate level (1 fastest .. 12 smallest), or a decoder; NULL when
 * out of memory. */
mcp__zip_codec *mcp__zip_encoder_new(int level);
mcp__zip_codec *mcp__zip_decoder_new(void);
void mcp__zip_codec_free(mcp__zip_codec *c);

/* Encodes a chunk's n packed bytes; *out points at the stream (owned by c, valid until
 * its next use). Returns the stream's size, or -1 when out of memory. */
long long mcp__zip_encode(mcp__zip_codec *c, const void *packed, size_t n,
                          const void **out);

/* Decodes a stream that must give exactly out_bytes bytes into out. Returns 0, -1
 * when the stream is corrupt or of another size, -2 when out of memory. */
int mcp__zip_decode(mcp__zip_codec *c, const void *in, size_t in_bytes, void *out,
                    size_t out_bytes);

#endif
