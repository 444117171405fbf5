/* internal.h: helpers shared inside common/ (not installed). */
#ifndef MCP_COMMON_INTERNAL_H
#define MCP_COMMON_INTERNAL_H

#include <stddef.h>

#include "oiio_internal.h"



/* Format back ends behind mcp_image_read / mcp_image_write (imageio.c). The writers
 * write exactly `path` (imageio.c passes a temporary name and renames). */
#include <mcpost/imageio.h>
int mcp__exr_read(const char *path, mcp_image **out);
int mcp__exr_write(const mcp_image *img, const char *path, const mcp_write_options *opt);
int mcp__pfm_read(const char *path, mcp_image **out);
int mcp__pfm_write(const mcp_image *img, const char *path);
#endif
