/* report.c: the run report's JSON document -- sections, verdicts, tables, images,
 * maps and plots (see report.h for the section format) -- and writing it with its
 * HTML page (report_html.c). */
#include <mcpost/report.h>
#include <mcpost/imageio.h>

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "internal.h"
#include "../filter/internal.h"

struct mcp_report {
    cJSON *root;
    const char *heading; /* mcp__report_set_heading: the title of sections made now */
};

static int
oom(void)
{
    return mcp_error("out of memory for the report");
}

int
mcp_report_new(const char *title, mcp_report **out)
{
    mcp_report *r = mcp_calloc(1, sizeof *r);
    if (!r) return -1;
    r->root = cJSON_CreateObject();
    if (!r->root || !cJSON_AddStringToObject(r->root, "title", title) ||
        !cJSON_AddArrayToObject(r->root, "sections")) {
        mcp_report_free(r);
        return oom();
    }
    *out = r;
    return 0;
}

void
mcp_report_free(mcp_report *r)
{
    if (!r) return;
    cJSON_Delete(r->root);
    free(r);
}

void
mcp__report_set_heading(mcp_report *r, const char *title)
{
    r->heading = title;
}

cJSON *
mcp_report_json(mcp_report *r)
{
    return r->root;
}

cJSON *
mcp_report_section(mcp_report *r, const char *stage, const char *title)
{
    cJSON *s = cJSON_CreateObject();
    if (r->heading) title = r->heading;
    if (!s || !cJSON_AddStringToObject(s, "stage", stage) ||
        !cJSON_AddStringToObject(s, "title", title)) {
        cJSON_Delete(s);
        oom();
        return NULL;
    }
    cJSON_AddItemToArray(cJSON_GetObjectItem(r->root, "sections"), s);
    return s;
}

/* The section's list called name, created on first use. */
static cJSON *
section_list(cJSON *section, const char *name)
{
    cJSON *list = cJSON_GetObjectItem(section, name);
    if (!list) list = cJSON_AddArrayToObject(section, name);
    return list;
}

int
mcp_report_add_image(cJSON *section, const char *rel_path, const char *caption)
{
    cJSON *images = section_list(section, "images");
    if (!images) return oom();
    cJSON *img = cJSON_CreateObject();
    if (!img || !cJSON_AddStringToObject(img, "path", rel_path) ||
        !cJSON_AddStringToObject(img, "caption", caption ? caption : "")) {
        cJSON_Delete(img);
        return oom();
    }
    cJSON_AddItemToArray(images, img);
    return 0;
}

cJSON *
mcp_report_add_hdr_image(cJSON *section, const char *rel_png, const char *rel_hdr,
                         const char *caption)
{
    if (mcp_report_add_image(section, rel_png, caption)) return NULL;
    cJSON *images = cJSON_GetObjectItem(section, "images");
    cJSON *img = cJSON_GetArrayItem(images, cJSON_GetArraySize(images) - 1);
    if (!cJSON_AddStringToObject(img, "hdr", rel_hdr)) {
        oom();
        return NULL;
    }
    return img;
}

static const char *const display_modes[] = {"clamp", "aces", "hable", "reinhard",
                                            "false-colour"};
const mcp_wordlist mcp_report_display_words = {"display", display_modes, 5};

int
mcp_report_display_mode_check(const char *mode)
{
    for (size_t i = 0; i < sizeof display_modes / sizeof *display_modes; i++)
        if (!strcmp(mode, display_modes[i])) return 0;
    int v;
    return mcp_wordlist_find(&mcp_report_display_words, mode, &v);
}

int
mcp_report_set_display(mcp_report *r, double exposure, const char *mode)
{
    if (!isfinite(exposure) || exposure < -20 || exposure > 20)
        return mcp_error("exposure %g: want stops in [-20, 20]", exposure);
    if (mcp_report_display_mode_check(mode)) return -1;
    cJSON_DeleteItemFromObject(r->root, "display");
    cJSON *d = cJSON_AddObjectToObject(r->root, "display");
    if (!d || !cJSON_AddNumberToObject(d, "exposure", exposure) ||
        !cJSON_AddStringToObject(d, "mode", mode))
        return oom();
    return 0;
}

cJSON *
mcp_report_add_map(cJSON *section, const char *rel_path, const char *caption,
                   mcp_colormap map, double lo, double hi, mcp_axis_scale axis,
                   const char *unit)
{
    const char *name = mcp_colormap_name(map);
    if (!name || (axis != MCP_AXIS_LINEAR && axis != MCP_AXIS_LOG) || !(lo < hi) ||
        !isfinite(lo) || !isfinite(hi) || (axis == MCP_AXIS_LOG && !(lo > 0))) {
        mcp_error("report: map '%s': need a known colour map, a linear or log axis and "
                  "finite lo < hi (lo > 0 on log; got %g to %g)",
                  rel_path, lo, hi);
        return NULL;
    }
    if (mcp_report_add_image(section, rel_path, caption)) return NULL;
    cJSON *img = cJSON_GetArrayItem(
        cJSON_GetObjectItem(section, "images"),
        cJSON_GetArraySize(cJSON_GetObjectItem(section, "images")) - 1);
    cJSON *sc = cJSON_AddObjectToObject(img, "scale");
    if (!sc || !cJSON_AddStringToObject(sc, "colormap", name) ||
        !cJSON_AddNumberToObject(sc, "min", lo) ||
        !cJSON_AddNumberToObject(sc, "max", hi) ||
        !cJSON_AddStringToObject(sc, "axis", mcp_axis_scale_name(axis)) ||
        !cJSON_AddStringToObject(sc, "unit", unit ? unit : "")) {
        oom();
        return NULL;
    }
    return img;
}

int
mcp_report_map_add_mark(cJSON *map, double value, const char *label)
{
    cJSON *sc = cJSON_GetObjectItem(map, "scale");
    if (!sc) return mcp_error("report: not a map");
    if (!isfinite(value)) return mcp_error("report: mark '%s': value %g", label, value);
    cJSON *marks = cJSON_GetObjectItem(sc, "marks");
    if (!marks) marks = cJSON_AddArrayToObject(sc, "marks");
    cJSON *m = cJSON_CreateObject();
    if (!marks || !m || !cJSON_AddNumberToObject(m, "value", value) ||
        !cJSON_AddStringToObject(m, "label", label ? label : "")) {
        cJSON_Delete(m);
        return oom();
    }
    cJSON_AddItemToArray(marks, m);
    return 0;
}

int
mcp__report_map_one_value(cJSON *map, const mcp_image *img, int channel, int log10_values,
                          double factor)
{
    if (!map || !img || channel < 0 || channel >= img->channels) return 0;
    float first = img->data[channel];
    size_t n = (size_t)img->width * img->height;
    for (size_t i = 0; i < n; i++) {
        float v = img->data[i * (size_t)img->channels + (size_t)channel];
        if (!(v == first)) return 0; /* NaN too: not one value */
    }
    /* log10 maps hold -30 for a zero (metrics.c's relse.png) */
    double v =
        factor * (log10_values ? (first <= -30.0f ? 0.0 : pow(10.0, first)) : first);
    cJSON *sc = cJSON_GetObjectItem(map, "scale");
    if (!sc) return mcp_error("report: not a map");
    if (!cJSON_AddNumberToObject(sc, "one_value", v)) return oom();
    return mcp_report_map_add_mark(map, v, "every pixel");
}

int
mcp_report_set_verdict(cJSON *section, mcp_verdict level, const char *fmt, ...)
{
    static const char *const levels[] = {"info", "good", "bad"};
    if ((unsigned)level > MCP_VERDICT_BAD)
        return mcp_error("report: unknown verdict level");
    char text[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    cJSON_DeleteItemFromObject(section, "verdict");
    cJSON *v = cJSON_AddObjectToObject(section, "verdict");
    if (!v || !cJSON_AddStringToObject(v, "level", levels[level]) ||
        !cJSON_AddStringToObject(v, "text", text))
        return oom();
    return 0;
}

int
mcp_report_json_only(cJSON *section, const char *key)
{
    cJSON *keys = section_list(section, "json_only"), *k = cJSON_CreateString(key);
    if (!keys || !k) {
        cJSON_Delete(k);
        return oom();
    }
    cJSON_AddItemToArray(keys, k);
    return 0;
}

/* ---- tables ---- */

cJSON *
mcp_report_add_table(cJSON *section, const char *title, const char *const *columns,
                     int n_columns)
{
    cJSON *tables = section_list(section, "tables"), *t = cJSON_CreateObject(), *cols;
    if (!tables || !t || !cJSON_AddStringToObject(t, "title", title ? title : "") ||
        !(cols = cJSON_AddArrayToObject(t, "columns")) ||
        !cJSON_AddArrayToObject(t, "rows")) {
        cJSON_Delete(t);
        oom();
        return NULL;
    }
    for (int i = 0; i < n_columns; i++)
        cJSON_AddItemToArray(cols, cJSON_CreateString(columns[i] ? columns[i] : ""));
    cJSON_AddItemToArray(tables, t);
    return t;
}

/* A number as JSON: NaN is null; +-inf, which JSON cannot hold, become strings. */
static cJSON *
number_item(double v)
{
    if (isnan(v)) return cJSON_CreateNull();
    if (isinf(v)) return cJSON_CreateString(v > 0 ? "inf" : "-inf");
    return cJSON_CreateNumber(v);
}

int
mcp_report_table_add_row(cJSON *table, const char *fmt, ...)
{
    cJSON *cols = cJSON_GetObjectItem(table, "columns"),
          *rows = cJSON_GetObjectItem(table, "rows");
    const cJSON *title = cJSON_GetObjectItem(table, "title");
    if (!cols || !rows) return mcp_error("report: not a table");
    int n = cJSON_GetArraySize(cols);
    if ((int)strlen(fmt) != n)
        return mcp_error("report: table '%s' has %d columns, row format '%s' gives %d",
                         cJSON_IsString(title) ? title->valuestring : "", n, fmt,
                         (int)strlen(fmt));
    cJSON *row = cJSON_CreateArray();
    if (!row) return oom();
    va_list ap;
    va_start(ap, fmt);
    for (const char *f = fmt; *f; f++) {
        cJSON *item = NULL;
        if (*f == 'd') {
            item = number_item(va_arg(ap, double));
        } else if (*f == 'i') {
            item = cJSON_CreateNumber(va_arg(ap, int));
        } else if (*f == 's') {
            const char *s = va_arg(ap, const char *);
            item = s ? cJSON_CreateString(s) : cJSON_CreateNull();
        } else {
            va_end(ap);
            cJSON_Delete(row);
            return mcp_error("report: bad row format letter '%c' (use d, i or s)", *f);
        }
        if (!item) {
            va_end(ap);
            cJSON_Delete(row);
            return oom();
        }
        cJSON_AddItemToArray(row, item);
    }
    va_end(ap);
    cJSON_AddItemToArray(rows, row);
    return 0;
}

/* ---- plots ---- */

static cJSON *
axis_object(const char *label, mcp_axis_scale scale)
{
    cJSON *a = cJSON_CreateObject();
    if (!a || !cJSON_AddStringToObject(a, "label", label ? label : "") ||
        !cJSON_AddStringToObject(a, "scale", mcp_axis_scale_name(scale))) {
        cJSON_Delete(a);
        return NULL;
    }
    return a;
}

cJSON *
mcp_report_add_plot(cJSON *section, const char *title, const char *x_label,
                    mcp_axis_scale x_scale, const char *y_label, mcp_axis_scale y_scale)
{
    if ((unsigned)x_scale > MCP_AXIS_LOGIT || (unsigned)y_scale > MCP_AXIS_LOGIT) {
        mcp_error("report: plot '%s': unknown axis scale", title ? title : "");
        return NULL;
    }
    cJSON *plots = section_list(section, "plots"), *p = cJSON_CreateObject();
    cJSON *x = axis_object(x_label, x_scale), *y = axis_object(y_label, y_scale);
    if (!plots || !p || !x || !y ||
        !cJSON_AddStringToObject(p, "title", title ? title : "")) {
        cJSON_Delete(p);
        cJSON_Delete(x);
        cJSON_Delete(y);
        oom();
        return NULL;
    }
    cJSON_AddItemToObject(p, "x", x);
    cJSON_AddItemToObject(p, "y", y);
    if (!cJSON_AddArrayToObject(p, "series")) {
        cJSON_Delete(p);
        oom();
        return NULL;
    }
    cJSON_AddItemToArray(plots, p);
    return p;
}

static cJSON *
number_array(const double *v, int n)
{
    cJSON *a = cJSON_CreateArray();
    for (int i = 0; a && i < n; i++) {
        cJSON *item = isfinite(v[i]) ? cJSON_CreateNumber(v[i]) : cJSON_CreateNull();
        if (!item) {
            cJSON_Delete(a);
            return NULL;
        }
        cJSON_AddItemToArray(a, item);
    }
    return a;
}

cJSON *
mcp_report_plot_add_series(cJSON *plot, const char *name, mcp_series_style style,
                           const double *x, const double *y, int n)
{
    cJSON *series = cJSON_GetObjectItem(plot, "series");
    if (!series) {
        mcp_error("report: not a plot");
        return NULL;
    }
    if ((unsigned)style > MCP_SERIES_BARS || n < 0) {
        mcp_error("report: series '%s': bad style or count", name ? name : "");
        return NULL;
    }
    cJSON *s = cJSON_CreateObject(), *xs = number_array(x, n), *ys = number_array(y, n);
    if (!s || !xs || !ys || !cJSON_AddStringToObject(s, "name", name ? name : "") ||
        !cJSON_AddStringToObject(s, "style", mcp_series_style_name(style))) {
        cJSON_Delete(s);
        cJSON_Delete(xs);
        cJSON_Delete(ys);
        oom();
        return NULL;
    }
    cJSON_AddItemToObject(s, "x", xs);
    cJSON_AddItemToObject(s, "y", ys);
    cJSON_AddItemToArray(series, s);
    return s;
}

int
mcp_report_series_set_dashed(cJSON *series, int dashed)
{
    cJSON_DeleteItemFromObject(series, "dashed");
    if (!cJSON_AddBoolToObject(series, "dashed", dashed)) return oom();
    return 0;
}

static int
write_text(const char *dir, const char *name, const char *text)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    return mcp_write_file_atomic(path, text, strlen(text));
}

int
mcp_report_write(mcp_report *r, const char *dir)
{
    char *json = cJSON_Print(r->root), *html = NULL;
    int rc = -1;
    if (!json)
        oom();
    else if (mcp_report_html(r, dir, &html) == 0 &&
             !write_text(dir, "report.json", json) &&
             !write_text(dir, "report.html", html))
        rc = 0;
    free(json);
    free(html);
    return rc;
}

void
mcp_report_add_number(cJSON *o, const char *key, double v)
{
    if (isfinite(v))
        cJSON_AddNumberToObject(o, key, v);
    else
        cJSON_AddNullToObject(o, key);
}
