/* plot.h: small line, scatter and bar plots as standalone SVG text, for report.html.
 *
 * Our own code rather than a plotting library: it adds no dependency, the SVG goes
 * inline into a self-contained page that needs no network or scripts, and vector
 * output stays crisp at any zoom. Axes are linear, logarithmic (base 10) or logit
 * (log(p / (1 - p)), for percentiles: Firmino et al. 2024's error-percentile plot puts
 * the percentile on a logit axis and the error on a log axis). Points that an axis
 * cannot show (NaN, <= 0 on log, outside (0, 1) on logit) are left out and break the
 * line there. */
#ifndef MCP_PLOT_H
#define MCP_PLOT_H

#include <mcpost/error.h>
#include <mcpost/wordlist.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum { MCP_AXIS_LINEAR, MCP_AXIS_LOG, MCP_AXIS_LOGIT } mcp_axis_scale;

/* BARS: a histogram, one bar per point centred on x, as wide as the smallest gap
 * between neighbouring x, up from 0 on a linear y axis (the axis bottom otherwise);
 * translucent, so that bars of several series overlap visibly (FLIP's overlapped
 * histogram of two tests). */
typedef enum {
    MCP_SERIES_LINE,
    MCP_SERIES_SCATTER,
    MCP_SERIES_LINE_POINTS,
    MCP_SERIES_BARS
} mcp_series_style;

typedef struct mcp_plot_series {
    const char *name; /* legend text */
    mcp_series_style style;
    const double *x, *y; /* n points, drawn in the order given */
    int n;
    int dashed; /* draw the line dashed (e.g. an estimate beside a truth) */
} mcp_plot_series;

typedef struct mcp_plot {
    const char *title;
    const char *x_label, *y_label;
    mcp_axis_scale x_scale, y_scale;
    const mcp_plot_series *series;
    int n_series;
    int width, height; /* pixels of the SVG viewport [640 x 400 when 0] */
} mcp_plot;

/* The plot as an SVG document (malloc'd, NUL-terminated). Fails when no series has
 * a point the axes can show ("plot 'T': no points to show on log/logit axes"). */
MCP_API int mcp_plot_svg(const mcp_plot *plot, char **svg);

/* The value of p on a logit axis, and back. */
MCP_API double mcp_logit(double p);
MCP_API double mcp_logistic(double z);

#ifdef __cplusplus
}
#endif
#endif
