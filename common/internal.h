/* internal.h: helpers shared inside common/ (not installed). */
#ifndef MCP_COMMON_INTERNAL_H
#define MCP_COMMON_INTERNAL_H

#include <stddef.h>

#include "oiio_internal.h"

#include <mcpost/image.h>

/* Fault injection, for tests only (alloc.c): allocation number n (0-based) through
 * mcp_malloc, mcp_calloc and mcp_strdup from now on fails as if memory were out, the
 * others succeed; n < 0 turns it off. mcp__alloc_count() is how many allocations were
 * counted since (a run that finishes with count <= n met no failure). */
void mcp__alloc_fail_after(long n);
long mcp__alloc_count(void);

/* Window sums over 3 channels (stats.c): a summed-area table of (width + 1) x
 * (height + 1) x 3 doubles (malloc'd), and the sum over the (2r + 1)² window around
 * (x, y) clipped at the borders, with its pixel count. */
double *mcp__window_table(const mcp_image *img);
void mcp__window_sum(const double *table, int w, int h, int x, int y, int r, double out[3],
                     int *count);

/* Where mcpost's own files are (paths.c): the folder of the file that holds this code
 * (the shared library, or the executable it is linked into; -1 when unknown), and a
 * data file of share/mcpost/ found relative to it, else in the build tree, else in the
 * configured install folder (-1 and buf "" when none has it). */
int mcp__code_dir(char *buf, size_t cap);
int mcp__find_data_file(const char *name, char *buf, size_t cap);

/* A series member as its file holds it, whatever the series' variance_from (dump.c). */
#include <mcpost/dump.h>
int mcp__series_load_file(const mcp_series *s, int i, mcp_dump **out);

/* Format back ends behind mcp_image_read / mcp_image_write (imageio.c). The writers
 * write exactly `path` (imageio.c passes a temporary name and renames). */
#include <mcpost/imageio.h>
int mcp__exr_read(const char *path, mcp_image **out);
int mcp__exr_write(const mcp_image *img, const char *path, const mcp_write_options *opt);
int mcp__pfm_read(const char *path, mcp_image **out);
int mcp__pfm_write(const mcp_image *img, const char *path);
#endif
