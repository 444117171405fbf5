/* report.c: the run report -- JSON document and self-contained HTML page (see
 * report.h for the section format). The HTML renders every section generically:
 * key figures, tables, images (embedded as base64 data URIs) and plots (inline SVG
 * from plot.c), with inline CSS, so the page opens offline and can be mailed as one
 * file. */
#define _POSIX_C_SOURCE 200809L /* strcasecmp */
#include <mcpost/report.h>
#include <mcpost/imageio.h>

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#ifndef MCP_VERSION
#define MCP_VERSION "?"
#endif

/* Images larger than this are linked instead of embedded. */
#define EMBED_MAX_BYTES (64L << 20)

struct mcp_report {
    cJSON *root;
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

cJSON *
mcp_report_json(mcp_report *r)
{
    return r->root;
}

cJSON *
mcp_report_section(mcp_report *r, const char *stage, const char *title)
{
    cJSON *s = cJSON_CreateObject();
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
    if ((unsigned)style > MCP_SERIES_LINE_POINTS || n < 0) {
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

/* ---- the HTML page ---- */

typedef struct {
    char *s;
    size_t len, cap;
    int failed;
} sbuf;

static void
sb_put(sbuf *b, const char *s, size_t n)
{
    if (b->failed) return;
    if (b->len + n + 1 > b->cap) {
        size_t cap = b->cap ? b->cap : 65536;
        while (cap < b->len + n + 1)
            cap *= 2;
        char *p = realloc(b->s, cap);
        if (!p) {
            b->failed = 1;
            return;
        }
        b->s = p;
        b->cap = cap;
    }
    memcpy(b->s + b->len, s, n);
    b->len += n;
    b->s[b->len] = '\0';
}

static void MCP_PRINTF(2, 3) sb_printf(sbuf *b, const char *fmt, ...)
{
    char small[512];
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(small, sizeof small, fmt, ap);
    va_end(ap);
    if (n < 0) {
        b->failed = 1;
        return;
    }
    if ((size_t)n < sizeof small) {
        sb_put(b, small, (size_t)n);
        return;
    }
    char *big = malloc((size_t)n + 1);
    if (!big) {
        b->failed = 1;
        return;
    }
    va_start(ap, fmt);
    vsnprintf(big, (size_t)n + 1, fmt, ap);
    va_end(ap);
    sb_put(b, big, (size_t)n);
    free(big);
}

/* HTML-escaped text. */
static void
sb_text(sbuf *b, const char *t)
{
    for (; t && *t; t++) {
        switch (*t) {
        case '&':
            sb_put(b, "&amp;", 5);
            break;
        case '<':
            sb_put(b, "&lt;", 4);
            break;
        case '>':
            sb_put(b, "&gt;", 4);
            break;
        case '"':
            sb_put(b, "&quot;", 6);
            break;
        default:
            sb_put(b, t, 1);
            break;
        }
    }
}

static void
sb_base64(sbuf *b, const unsigned char *d, size_t n)
{
    static const char tab[] =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    char out[4];
    for (size_t i = 0; i < n; i += 3) {
        unsigned v = (unsigned)d[i] << 16;
        if (i + 1 < n) v |= (unsigned)d[i + 1] << 8;
        if (i + 2 < n) v |= d[i + 2];
        out[0] = tab[(v >> 18) & 63];
        out[1] = tab[(v >> 12) & 63];
        out[2] = i + 1 < n ? tab[(v >> 6) & 63] : '=';
        out[3] = i + 2 < n ? tab[v & 63] : '=';
        sb_put(b, out, 4);
    }
}

/* A JSON value as display text. */
static void
sb_value(sbuf *b, const cJSON *v)
{
    if (cJSON_IsNumber(v)) {
        double d = v->valuedouble;
        if (d == floor(d) && fabs(d) < 1e15)
            sb_printf(b, "%.0f", d);
        else
            sb_printf(b, "%.6g", d);
    } else if (cJSON_IsString(v)) {
        sb_text(b, v->valuestring);
    } else if (cJSON_IsBool(v)) {
        sb_put(b, cJSON_IsTrue(v) ? "yes" : "no", cJSON_IsTrue(v) ? 3 : 2);
    } else if (cJSON_IsNull(v)) {
        sb_put(b, "&mdash;", 7);
    } else {
        char *t = cJSON_PrintUnformatted(v);
        sb_text(b, t ? t : "");
        free(t);
    }
}

static int
is_reserved(const char *key)
{
    static const char *const reserved[] = {"title", "stage", "tables", "images", "plots"};
    for (int i = 0; i < 5; i++)
        if (!strcmp(key, reserved[i])) return 1;
    return 0;
}

static int
scalar_list(const cJSON *a)
{
    const cJSON *i;
    cJSON_ArrayForEach(i, a) if (cJSON_IsObject(i) || cJSON_IsArray(i)) return 0;
    return 1;
}

/* Key-figure rows for the members of obj, nested objects flattened as prefix.key. */
static void
figure_rows(sbuf *b, const cJSON *obj, const char *prefix, int top, int *rows)
{
    const cJSON *m;
    cJSON_ArrayForEach(m, obj)
    {
        if (!m->string || (top && is_reserved(m->string))) continue;
        char key[512];
        snprintf(key, sizeof key, "%s%s%s", prefix, *prefix ? "." : "", m->string);
        if (cJSON_IsObject(m)) {
            figure_rows(b, m, key, 0, rows);
            continue;
        }
        sb_put(b, "<tr><th>", 8);
        sb_text(b, key);
        sb_put(b, "</th><td>", 9);
        if (cJSON_IsArray(m) && scalar_list(m)) {
            const cJSON *i;
            int first = 1;
            cJSON_ArrayForEach(i, m)
            {
                if (!first) sb_put(b, ", ", 2);
                sb_value(b, i);
                first = 0;
            }
        } else {
            sb_value(b, m);
        }
        sb_put(b, "</td></tr>\n", 11);
        (*rows)++;
    }
}

static void
render_figures(sbuf *b, const cJSON *section)
{
    sbuf rows = {0};
    int n = 0;
    figure_rows(&rows, section, "", 1, &n);
    if (rows.failed) b->failed = 1;
    if (n && rows.s) {
        sb_printf(b, "<table class=\"figures\">\n");
        sb_put(b, rows.s, rows.len);
        sb_printf(b, "</table>\n");
    }
    free(rows.s);
}

static void
render_tables(sbuf *b, const cJSON *section)
{
    const cJSON *t;
    cJSON_ArrayForEach(t, cJSON_GetObjectItem(section, "tables"))
    {
        const cJSON *title = cJSON_GetObjectItem(t, "title"), *c, *r;
        sb_printf(b, "<table class=\"data\">\n");
        if (cJSON_IsString(title) && *title->valuestring) {
            sb_printf(b, "<caption>");
            sb_text(b, title->valuestring);
            sb_printf(b, "</caption>\n");
        }
        sb_printf(b, "<tr>");
        cJSON_ArrayForEach(c, cJSON_GetObjectItem(t, "columns"))
        {
            sb_printf(b, "<th>");
            sb_value(b, c);
            sb_printf(b, "</th>");
        }
        sb_printf(b, "</tr>\n");
        cJSON_ArrayForEach(r, cJSON_GetObjectItem(t, "rows"))
        {
            sb_printf(b, "<tr>");
            cJSON_ArrayForEach(c, r)
            {
                sb_printf(b, cJSON_IsNumber(c) ? "<td class=\"num\">" : "<td>");
                sb_value(b, c);
                sb_printf(b, "</td>");
            }
            sb_printf(b, "</tr>\n");
        }
        sb_printf(b, "</table>\n");
    }
}

static const char *
mime_of(const char *path)
{
    static const char *const map[][2] = {
        {"png", "image/png"}, {"jpg", "image/jpeg"},    {"jpeg", "image/jpeg"},
        {"gif", "image/gif"}, {"svg", "image/svg+xml"}, {"webp", "image/webp"}};
    const char *dot = strrchr(path, '.');
    for (size_t i = 0; dot && i < sizeof map / sizeof map[0]; i++)
        if (!strcasecmp(dot + 1, map[i][0])) return map[i][1];
    return NULL;
}

/* Reads a whole file (at most EMBED_MAX_BYTES); NULL when absent or too large. */
static unsigned char *
read_file(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    unsigned char *data = NULL;
    long n = -1;
    if (fseek(f, 0, SEEK_END) == 0 && (n = ftell(f)) >= 0 && n <= EMBED_MAX_BYTES &&
        fseek(f, 0, SEEK_SET) == 0 && (data = malloc((size_t)n + 1)) &&
        fread(data, 1, (size_t)n, f) != (size_t)n) {
        free(data);
        data = NULL;
    }
    fclose(f);
    *size = n > 0 ? (size_t)n : 0;
    return data;
}

static void
render_images(sbuf *b, const cJSON *section, const char *dir)
{
    const cJSON *images = cJSON_GetObjectItem(section, "images"), *im;
    if (!cJSON_GetArraySize(images)) return;
    sb_printf(b, "<div class=\"images\">\n");
    cJSON_ArrayForEach(im, images)
    {
        const cJSON *path = cJSON_GetObjectItem(im, "path"),
                    *cap = cJSON_GetObjectItem(im, "caption");
        if (!cJSON_IsString(path)) continue;
        const char *rel = path->valuestring, *mime = mime_of(rel);
        sb_printf(b, "<figure>");
        char full[4096];
        snprintf(full, sizeof full, "%s/%s", dir, rel);
        size_t size = 0;
        unsigned char *data = mime ? read_file(full, &size) : NULL;
        if (data) {
            sb_printf(b, "<img alt=\"");
            sb_text(b, rel);
            sb_printf(b, "\" src=\"data:%s;base64,", mime);
            sb_base64(b, data, size);
            sb_printf(b, "\">");
            free(data);
        } else {
            sb_printf(b, "<div class=\"noimg\">%s <code>",
                      mime ? "missing or too large to embed:"
                           : "not viewable in a browser:");
            sb_text(b, rel);
            sb_printf(b, "</code></div>");
        }
        sb_printf(b, "<figcaption>");
        sb_text(b, cJSON_IsString(cap) && *cap->valuestring ? cap->valuestring : rel);
        sb_printf(b, "</figcaption></figure>\n");
    }
    sb_printf(b, "</div>\n");
}

static double *
json_doubles(const cJSON *a, int *n)
{
    *n = cJSON_GetArraySize(a);
    double *v = malloc(((size_t)*n + 1) * sizeof *v);
    const cJSON *i;
    int k = 0;
    if (!v) return NULL;
    cJSON_ArrayForEach(i, a) v[k++] = cJSON_IsNumber(i) ? i->valuedouble : NAN;
    return v;
}

static void
render_plots(sbuf *b, const cJSON *section)
{
    const cJSON *pj;
    cJSON_ArrayForEach(pj, cJSON_GetObjectItem(section, "plots"))
    {
        const cJSON *xa = cJSON_GetObjectItem(pj, "x"),
                    *ya = cJSON_GetObjectItem(pj, "y");
        const cJSON *title = cJSON_GetObjectItem(pj, "title");
        const cJSON *xl = cJSON_GetObjectItem(xa, "label"),
                    *yl = cJSON_GetObjectItem(ya, "label");
        mcp_plot p = {0};
        p.title =
            cJSON_IsString(title) && *title->valuestring ? title->valuestring : NULL;
        p.x_label = cJSON_IsString(xl) ? xl->valuestring : NULL;
        p.y_label = cJSON_IsString(yl) ? yl->valuestring : NULL;
        const cJSON *xs = cJSON_GetObjectItem(xa, "scale"),
                    *ys = cJSON_GetObjectItem(ya, "scale");
        if (!cJSON_IsString(xs) || mcp_axis_scale_from_name(xs->valuestring, &p.x_scale))
            p.x_scale = MCP_AXIS_LINEAR;
        if (!cJSON_IsString(ys) || mcp_axis_scale_from_name(ys->valuestring, &p.y_scale))
            p.y_scale = MCP_AXIS_LINEAR;
        const cJSON *series = cJSON_GetObjectItem(pj, "series"), *sj;
        int n = cJSON_GetArraySize(series), k = 0;
        mcp_plot_series *ps = calloc((size_t)n + 1, sizeof *ps);
        if (!ps) {
            b->failed = 1;
            return;
        }
        cJSON_ArrayForEach(sj, series)
        {
            const cJSON *name = cJSON_GetObjectItem(sj, "name"),
                        *style = cJSON_GetObjectItem(sj, "style");
            int nx, ny;
            double *x = json_doubles(cJSON_GetObjectItem(sj, "x"), &nx);
            double *y = json_doubles(cJSON_GetObjectItem(sj, "y"), &ny);
            ps[k].name = cJSON_IsString(name) ? name->valuestring : NULL;
            if (!cJSON_IsString(style) ||
                mcp_series_style_from_name(style->valuestring, &ps[k].style))
                ps[k].style = MCP_SERIES_LINE;
            ps[k].dashed = cJSON_IsTrue(cJSON_GetObjectItem(sj, "dashed"));
            ps[k].x = x;
            ps[k].y = y;
            ps[k].n = x && y ? (nx < ny ? nx : ny) : 0;
            k++;
        }
        p.series = ps;
        p.n_series = k;
        char *svg = NULL;
        sb_printf(b, "<div class=\"plot\">");
        if (mcp_plot_svg(&p, &svg) == 0) {
            sb_put(b, svg, strlen(svg));
        } else {
            sb_printf(b, "<div class=\"noimg\">");
            sb_text(b, mcp_error_message());
            sb_printf(b, "</div>");
            mcp_error_clear();
        }
        sb_printf(b, "</div>\n");
        free(svg);
        for (int i = 0; i < k; i++) {
            free((void *)ps[i].x);
            free((void *)ps[i].y);
        }
        free(ps);
    }
}

static const char css[] =
    "body{font-family:-apple-system,'Segoe UI',Helvetica,Arial,sans-serif;margin:0;"
    "color:#222;background:#fafafa}\n"
    "header{background:#263238;color:#fff;padding:16px 28px}\n"
    "header h1{margin:0;font-size:22px}header p{margin:4px 0 "
    "0;color:#b0bec5;font-size:13px}\n"
    "nav{padding:10px 28px;font-size:13px;border-bottom:1px solid #ddd;background:#fff}\n"
    "nav a{margin-right:14px;color:#1565c0;text-decoration:none}\n"
    "section{background:#fff;margin:18px 28px;padding:8px 20px 18px;border:1px solid "
    "#ddd;"
    "border-radius:6px}\n"
    "h2{font-size:18px;margin:12px 0}h2 "
    "small{color:#888;font-weight:normal;font-size:12px;"
    "margin-left:8px}\n"
    "table{border-collapse:collapse;margin:10px 0;font-size:13px}\n"
    "th,td{border:1px solid #e0e0e0;padding:4px "
    "10px;text-align:left;vertical-align:top}\n"
    "table.figures th{background:#f5f5f5;font-weight:600}\n"
    "table.data th{background:#eceff1}td.num{text-align:right;"
    "font-variant-numeric:tabular-nums}\n"
    "caption{text-align:left;font-weight:600;padding:4px 0}\n"
    ".images{display:flex;flex-wrap:wrap;gap:14px}\n"
    "figure{margin:0;max-width:100%}figure img{max-width:min(100%,720px);"
    "border:1px solid #ccc;image-rendering:pixelated}\n"
    "figcaption{font-size:12px;color:#555;margin-top:3px}\n"
    ".plot{display:inline-block;margin:8px 12px 8px 0}.plot "
    "svg{max-width:100%;height:auto}\n"
    ".noimg{padding:20px;border:1px dashed #bbb;color:#777;font-size:13px}\n";

int
mcp_report_html(mcp_report *r, const char *dir, char **html)
{
    *html = NULL;
    const cJSON *title = cJSON_GetObjectItem(r->root, "title");
    const char *t = cJSON_IsString(title) ? title->valuestring : "mcpost report";
    const cJSON *sections = cJSON_GetObjectItem(r->root, "sections"), *s;
    sbuf b = {0};
    sb_printf(&b,
              "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n"
              "<meta name=\"viewport\" content=\"width=device-width,initial-scale=1\">\n"
              "<title>");
    sb_text(&b, t);
    sb_printf(&b, "</title>\n<style>\n%s</style>\n</head><body>\n<header><h1>", css);
    sb_text(&b, t);
    sb_printf(&b,
              "</h1><p>mcpost %s &middot; %d section%s &middot; every figure is also in "
              "report.json</p></header>\n",
              MCP_VERSION, cJSON_GetArraySize(sections),
              cJSON_GetArraySize(sections) == 1 ? "" : "s");
    if (cJSON_GetArraySize(sections) > 1) {
        int i = 0;
        sb_printf(&b, "<nav>");
        cJSON_ArrayForEach(s, sections)
        {
            const cJSON *st = cJSON_GetObjectItem(s, "title");
            sb_printf(&b, "<a href=\"#s%d\">", i++);
            sb_text(&b, cJSON_IsString(st) ? st->valuestring : "section");
            sb_printf(&b, "</a>");
        }
        sb_printf(&b, "</nav>\n");
    }
    int i = 0;
    cJSON_ArrayForEach(s, sections)
    {
        const cJSON *st = cJSON_GetObjectItem(s, "title"),
                    *sg = cJSON_GetObjectItem(s, "stage");
        sb_printf(&b, "<section id=\"s%d\"><h2>", i++);
        sb_text(&b, cJSON_IsString(st) ? st->valuestring : "");
        if (cJSON_IsString(sg)) {
            sb_printf(&b, "<small>");
            sb_text(&b, sg->valuestring);
            sb_printf(&b, "</small>");
        }
        sb_printf(&b, "</h2>\n");
        render_figures(&b, s);
        render_tables(&b, s);
        render_plots(&b, s);
        render_images(&b, s, dir);
        sb_printf(&b, "</section>\n");
    }
    sb_printf(&b, "</body></html>\n");
    if (b.failed) {
        free(b.s);
        return oom();
    }
    *html = b.s;
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
