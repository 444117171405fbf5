/* internal.h: functions of common/report/ that other library files and the tests call
 * but that libmcpost.so does not export (hidden visibility; not installed). */
#ifndef MCP_REPORT_INTERNAL_H
#define MCP_REPORT_INTERNAL_H

#include <mcpost/plot.h>
#include <mcpost/report.h>
#include <mcpost/wordlist.h>

/* ---- plot.c ---- */

/* "linear", "log", "logit"; "line", "scatter", "line+points", "bars". */
extern const mcp_wordlist mcp_axis_scale_words, mcp_series_style_words;
int mcp_axis_scale_from_name(const char *name, mcp_axis_scale *out);
const char *mcp_axis_scale_name(mcp_axis_scale s);
int mcp_series_style_from_name(const char *name, mcp_series_style *out);
const char *mcp_series_style_name(mcp_series_style s);

/* ---- report.c ---- */

/* 0 when mode is one of mcp_report_display_words; else -1 with "unknown display 'X'
 * (known: ...)". */
int mcp_report_display_mode_check(const char *mode);

/* Until called again with NULL, every section made takes this title (borrowed) in
 * place of the one its stage gives: a job stage's `title:` (job.c, report.c). */
void mcp__report_set_heading(mcp_report *r, const char *title);

/* When channel of img (the picture behind map, a map of mcp_report_add_map) holds one
 * value in every pixel, marks the map so: "one_value" in its scale (10^v for a map of
 * log10 values; 0 for their -30), times factor (the colour bar's unit), and a mark
 * "every pixel" on its colour bar, so that the page says the value instead of showing
 * a flat square (docs/report.md, "The maps"). 0 also when it is not flat. */
int mcp__report_map_one_value(cJSON *map, const mcp_image *img, int channel,
                              int log10_values, double factor);

#endif
