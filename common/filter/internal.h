/* internal.h: functions of common/filter/ that other library files and the tests call
 * but that libmcpost.so does not export (hidden visibility; not installed). They were
 * public once; the exported list is docs/library.md's "Exported symbols". */
#ifndef MCP_FILTER_INTERNAL_H
#define MCP_FILTER_INTERNAL_H

#include <mcpost/filter.h>
#include <mcpost/wordlist.h>

/* ---- colormap.c ---- */

/* Looks a colour map up by name ("viridis", "magma", "inferno", "turbo", "gray"). */
extern const mcp_wordlist mcp_colormap_words;
int mcp_colormap_from_name(const char *name, mcp_colormap *map);
/* The name of a colour map ("viridis", ...), or NULL for an unknown value. */
const char *mcp_colormap_name(mcp_colormap map);
/* mcp_colormap_apply onto the map's first `levels` entries (2 .. 256): lo -> 0, hi ->
 * levels - 1. 255 leaves one colour of a palette PNG's 256 for marks drawn over the
 * map (the estimate's block edges), and the top colour moves by one entry of 256. */
int mcp__colormap_apply_levels(const mcp_image *img, int channel, double lo, double hi,
                               mcp_colormap map, int levels, unsigned char *rgb8);

#endif
