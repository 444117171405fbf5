/* report.h: what a run found, for people and for programs.
 *
 * A report is a JSON document (report.json: every figure) plus a self-contained HTML
 * page (report.html) built from the same content: sections, each with tables, images
 * and plots. Stages add one section each.
 *
 * A section is a JSON object. Besides "title" and "stage" it may hold:
 *   "verdict": {"level": "good"|"bad"|"info", "text"}
 *                          one line in words: what the figures mean (the first thing
 *                          the page shows of the section)
 *   any other members      key figures: numbers, strings, booleans, and nested objects
 *                          and lists (shown as nested tables and lists)
 *   "tables": [{"title", "columns": [names], "rows": [[number|string|null, ...]]}]
 *   "images": [{"path" (relative to the report's folder), "caption",
 *               "scale": {"colormap", "min", "max", "axis": "linear"|"log", "unit",
 *                         "marks": [{"value", "label"}]} (false-colour maps only),
 *               "hdr": a file with the linear values behind the picture (EXR, PFM):
 *                      the page can re-expose it (renders only)}]
 *   "plots":  [{"title", "x": {"label", "scale"}, "y": {...},
 *               "series": [{"name", "style", "dashed", "x": [...], "y": [...]}]}]
 * report.html renders every section generically from that, so a stage only fills
 * the JSON. The page needs no network: CSS and a small script (the image comparison)
 * are inline, images are embedded as base64 data URIs (PNG, JPEG, GIF, SVG, WebP;
 * other files are listed by name), shown at their pixel size or an integer multiple
 * of it (nearest neighbour), maps with their colour bar, and plots are inline SVG
 * drawn by plot.h. An image with "hdr" gets the page's display controls (an exposure
 * slider; clamp, ACES, Hable, Reinhard or false colour), which start as the document's
 *   "display": {"exposure" (stops), "mode"}
 * says (exposure 0, clamp when absent). docs/report.md describes the page for its
 * readers. */
#ifndef MCP_REPORT_H
#define MCP_REPORT_H

#include <cjson/cJSON.h>
#include <mcpost/error.h>
#include <mcpost/filter.h>
#include <mcpost/plot.h>
#include <mcpost/wordlist.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct mcp_report mcp_report;

MCP_API int mcp_report_new(const char *title, mcp_report **out);
MCP_API void mcp_report_free(mcp_report *r);

/* Adds key: v to o, or key: null when v is not finite (JSON has no NaN or Inf). */
MCP_API void mcp_report_add_number(cJSON *o, const char *key, double v);

/* The whole JSON document: {"title": ..., "sections": [...]}. */
MCP_API cJSON *mcp_report_json(mcp_report *r);

/* Appends a section {"title": title, "stage": stage} and returns it (owned by the
 * report); stages put their figures into it as JSON members. NULL on failure. */
MCP_API cJSON *mcp_report_section(mcp_report *r, const char *stage, const char *title);

/* Adds an image (a file path relative to the report's folder) to a section's
 * "images" list. */
MCP_API int mcp_report_add_image(cJSON *section, const char *rel_path,
                                 const char *caption);

/* Adds a false-colour map to a section's "images" list, with its scale: the colour map,
 * the values at the ramp's two ends (lo at its first colour, hi at its last), whether
 * the colours step linearly or by log10 of the value (then 0 < lo), and what the
 * values are (unit, e.g. "relative squared error"). Returns the image's object (owned
 * by the section; see mcp_report_map_add_mark), or NULL on failure. */
MCP_API cJSON *mcp_report_add_map(cJSON *section, const char *rel_path,
                                  const char *caption, mcp_colormap map, double lo,
                                  double hi, mcp_axis_scale axis, const char *unit);

/* Adds a render to a section's "images" list: rel_png is its picture as a screen shows
 * it (clamped, sRGB), rel_hdr a file of its linear values (EXR, PFM; relative to the
 * report's folder) that the page re-exposes and tone-maps with its display controls.
 * Returns the image's object (owned by the section), or NULL on failure. */
MCP_API cJSON *mcp_report_add_hdr_image(cJSON *section, const char *rel_png,
                                        const char *rel_hdr, const char *caption);

/* How the page first shows its HDR images: exposure in stops (2^exposure scales the
 * values) and the mode, one of clamp, aces, hable, reinhard (tonemap.h's curves, then
 * sRGB) or false-colour (log10 luminance). A reader changes both on the page. */
MCP_API int mcp_report_set_display(mcp_report *r, double exposure, const char *mode);
/* The display modes' words, value i the i-th: clamp, aces, hable, reinhard,
 * false-colour. */
MCP_API extern const mcp_wordlist mcp_report_display_words;

/* Marks a value on a map's colour bar (e.g. the threshold tau). */
MCP_API int mcp_report_map_add_mark(cJSON *map, double value, const char *label);

typedef enum { MCP_VERDICT_INFO, MCP_VERDICT_GOOD, MCP_VERDICT_BAD } mcp_verdict;

/* Sets the section's verdict: one line in words saying what its figures mean (e.g.
 * "stop: yes, 99.9% of values below tau = 0.01"), shown first; GOOD and BAD colour it.
 * A second call replaces the first. */
MCP_API int mcp_report_set_verdict(cJSON *section, mcp_verdict level, const char *fmt,
                                   ...) MCP_PRINTF(3, 4);

/* Leaves the section's member `key` out of report.html: it stays in report.json, for
 * programs, while a table of the page shows the same figures for people (e.g. the
 * adaptive loop's whole result beside its per-pass table). The keys are listed in the
 * section's "json_only". */
MCP_API int mcp_report_json_only(cJSON *section, const char *key);

/* Adds a table to a section's "tables" list and returns it (owned by the section),
 * or NULL on failure. */
MCP_API cJSON *mcp_report_add_table(cJSON *section, const char *title,
                                    const char *const *columns, int n_columns);

/* Appends a row to a table. fmt has one letter per column: 'd' a double (NaN is
 * written as null, +-inf as the strings "inf" / "-inf"), 'i' an int, 's' a string
 * (NULL: null). Fails when fmt does not have one letter per column. */
MCP_API int mcp_report_table_add_row(cJSON *table, const char *fmt, ...);

/* Adds a plot to a section's "plots" list and returns it (owned by the section), or
 * NULL on failure. Labels may be NULL. */
MCP_API cJSON *mcp_report_add_plot(cJSON *section, const char *title, const char *x_label,
                                   mcp_axis_scale x_scale, const char *y_label,
                                   mcp_axis_scale y_scale);

/* Adds a named series of n points (x[i], y[i]) to a plot and returns it, or NULL on
 * failure. Values an axis cannot show (NaN, <= 0 on log) are kept in the JSON and
 * skipped in the drawing. */
MCP_API cJSON *mcp_report_plot_add_series(cJSON *plot, const char *name,
                                          mcp_series_style style, const double *x,
                                          const double *y, int n);

/* Draws the series dashed (e.g. an estimate beside the truth). */
MCP_API int mcp_report_series_set_dashed(cJSON *series, int dashed);

/* The HTML page of the report (malloc'd); image paths are read relative to dir
 * (report_html.c). */
MCP_API int mcp_report_html(mcp_report *r, const char *dir, char **html);

/* Writes report.json and report.html into dir (atomically). */
MCP_API int mcp_report_write(mcp_report *r, const char *dir);

#ifdef __cplusplus
}
#endif
#endif
