/* report_html.c: report.html, one self-contained page built from the report's JSON
 * (report.h gives the section format; docs/report.md tells a reader what each part
 * shows). Every section is rendered generically, in the order a reader needs it: the
 * verdict in words, the key figures (nested objects and lists as nested tables and
 * lists, never JSON text), the images -- at their pixel size or a whole multiple of it,
 * nearest neighbour, false-colour maps with their colour bar, and a wipe comparison
 * of the images that share a size -- then tables and plots (inline SVG, plot.c).
 * CSS and the comparison's few lines of script are inline and images are base64 data
 * URIs, so the page opens offline and can be mailed as one file. */
#define _POSIX_C_SOURCE 200809L /* strcasecmp */
#include <mcpost/report.h>
#include <mcpost/image.h>
#include <mcpost/imageio.h>
#include <mcpost/tonemap.h>

#include "internal.h"
#include "../core/internal.h"
#include "../filter/internal.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#ifndef MCP_VERSION
#define MCP_VERSION "?"
#endif

/* Images larger than this are listed by name instead of embedded. */
#define EMBED_MAX_BYTES (64L << 20)
/* Small images are scaled up by a whole factor (nearest neighbour) to about this
 * many pixels across in the grid, and in the comparison. */
#define GRID_PX 320
#define COMPARE_PX 640
/* Nesting deeper than this is shown as text. */
#define MAX_DEPTH 8
/* Colour stops of a colour bar's gradient. */
#define RAMP_STOPS 33
/* HDR data larger than this many pixels is left out (the page keeps the PNG). */
#define HDR_MAX_PIXELS (4L << 20)
/* The false-colour display: log10 of luminance x 2^exposure from LO to HI. */
#define FALSE_LO (-3.0)
#define FALSE_HI 2.0

/* ---- a growing string (common/strbuf.c; a failure sticks in b->failed) ---- */

typedef mcp__strbuf sbuf;

static void
sb_str(sbuf *b, const char *s)
{
    mcp__strbuf_str(b, s);
}

/* Base64 (RFC 4648) of n bytes, written straight into the buffer: a report embeds
 * its pictures and HDR values this way, 17 MB of text for a 1080p estimate, which
 * four bytes at a time through sb_put took 30 ms to build. Large inputs are encoded
 * by threads over whole groups of 3 bytes, each its own 4 characters: the same text. */
static void
sb_base64(sbuf *b, const unsigned char *d, size_t n)
{
    static const char tab[] =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    const size_t groups = n / 3, rest = n % 3, len = 4 * (groups + (rest > 0));
    char *out = mcp__strbuf_reserve(b, len);
    if (!out) return;
#pragma omp parallel for schedule(static) if (groups > (1u << 20))
    for (size_t g = 0; g < groups; g++) {
        const unsigned char *s = d + 3 * g;
        const unsigned v = (unsigned)s[0] << 16 | (unsigned)s[1] << 8 | s[2];
        char *o = out + 4 * g;
        o[0] = tab[v >> 18];
        o[1] = tab[(v >> 12) & 63];
        o[2] = tab[(v >> 6) & 63];
        o[3] = tab[v & 63];
    }
    if (rest) {
        const unsigned char *s = d + 3 * groups;
        const unsigned v = (unsigned)s[0] << 16 | (rest > 1 ? (unsigned)s[1] << 8 : 0);
        char *o = out + 4 * groups;
        o[0] = tab[v >> 18];
        o[1] = tab[(v >> 12) & 63];
        o[2] = rest > 1 ? tab[(v >> 6) & 63] : '=';
        o[3] = '=';
    }
    b->len += len;
    b->s[b->len] = '\0';
}

static const char *
json_string(const cJSON *obj, const char *key)
{
    const cJSON *v = cJSON_GetObjectItem(obj, key);
    return cJSON_IsString(v) ? v->valuestring : NULL;
}

/* ---- values: scalars, nested objects and lists ---- */

/* A number for people: integers in full, others to 6 significant digits. */
static void
sb_number(sbuf *b, double d)
{
    if (d == floor(d) && fabs(d) < 1e15)
        mcp__strbuf_printf(b, "%.0f", d);
    else
        mcp__strbuf_printf(b, "%.6g", d);
}

static void
sb_scalar(sbuf *b, const cJSON *v)
{
    if (cJSON_IsNumber(v))
        sb_number(b, v->valuedouble);
    else if (cJSON_IsString(v))
        mcp__strbuf_markup_text(b, v->valuestring);
    else if (cJSON_IsBool(v))
        sb_str(b, cJSON_IsTrue(v) ? "yes" : "no");
    else
        sb_str(b, "&mdash;");
}

static int
is_scalar(const cJSON *v)
{
    return !cJSON_IsObject(v) && !cJSON_IsArray(v);
}

/* 1 when every element of list a passes test. */
static int
all_of(const cJSON *a, int (*test)(const cJSON *))
{
    const cJSON *i;
    cJSON_ArrayForEach(i, a) if (!test(i)) return 0;
    return 1;
}

static int
is_object(const cJSON *v)
{
    return cJSON_IsObject(v);
}

static void render_value(sbuf *b, const cJSON *v, int depth);

/* A list of objects: one table, a column per key that any of them has. */
static void
render_object_list(sbuf *b, const cJSON *a, int depth)
{
    cJSON *cols = cJSON_CreateArray();
    const cJSON *o, *m, *c;
    if (!cols) {
        b->failed = 1;
        return;
    }
    cJSON_ArrayForEach(o, a) cJSON_ArrayForEach(m, o)
    {
        int seen = 0;
        cJSON_ArrayForEach(c, cols) seen |= !strcmp(c->valuestring, m->string);
        if (!seen) cJSON_AddItemToArray(cols, cJSON_CreateString(m->string));
    }
    sb_str(b, "<div class=\"scroll\"><table class=\"data nested\"><tr>");
    cJSON_ArrayForEach(c, cols)
    {
        sb_str(b, "<th>");
        mcp__strbuf_markup_text(b, c->valuestring);
        sb_str(b, "</th>");
    }
    sb_str(b, "</tr>\n");
    cJSON_ArrayForEach(o, a)
    {
        sb_str(b, "<tr>");
        cJSON_ArrayForEach(c, cols)
        {
            const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, c->valuestring);
            sb_str(b, cJSON_IsNumber(v) ? "<td class=\"num\">" : "<td>");
            if (v) render_value(b, v, depth + 1);
            sb_str(b, "</td>");
        }
        sb_str(b, "</tr>\n");
    }
    sb_str(b, "</table></div>");
    cJSON_Delete(cols);
}

static void
render_list(sbuf *b, const cJSON *a, int depth)
{
    const cJSON *i;
    int n = cJSON_GetArraySize(a), long_text = 0;
    if (n == 0) {
        sb_str(b, "<span class=\"dim\">none</span>");
        return;
    }
    if (all_of(a, is_object)) {
        render_object_list(b, a, depth);
        return;
    }
    if (all_of(a, is_scalar)) {
        cJSON_ArrayForEach(i, a) long_text |=
            cJSON_IsString(i) && strlen(i->valuestring) > 24;
        if (!long_text && n <= 16) { /* short values: one line */
            int first = 1;
            cJSON_ArrayForEach(i, a)
            {
                if (!first) sb_str(b, ", ");
                sb_scalar(b, i);
                first = 0;
            }
            return;
        }
    }
    sb_str(b, "<ul class=\"list\">");
    cJSON_ArrayForEach(i, a)
    {
        sb_str(b, "<li>");
        render_value(b, i, depth + 1);
        sb_str(b, "</li>");
    }
    sb_str(b, "</ul>");
}

/* 1 for an object whose members are all scalars (a record). */
static int
is_record(const cJSON *v)
{
    return cJSON_IsObject(v) && v->child && all_of(v, is_scalar);
}

/* An object with two or more records among its members (e.g. the blend's final
 * errors per method) shows those as one table, a row per record, after the rest. */
static void
render_records(sbuf *b, const cJSON *o, int depth)
{
    cJSON *records = cJSON_CreateArray();
    const cJSON *m;
    if (!records) {
        b->failed = 1;
        return;
    }
    cJSON_ArrayForEach(m, o) if (is_record(m))
    {
        cJSON *row = cJSON_CreateObject();
        if (!row) break;
        cJSON_AddStringToObject(row, "", m->string);
        const cJSON *f;
        cJSON_ArrayForEach(f, m)
            cJSON_AddItemToObject(row, f->string, cJSON_Duplicate(f, 0));
        cJSON_AddItemToArray(records, row);
    }
    render_object_list(b, records, depth);
    cJSON_Delete(records);
}

static int
count_records(const cJSON *o)
{
    int n = 0;
    const cJSON *m;
    cJSON_ArrayForEach(m, o) n += is_record(m);
    return n;
}

/* An object: a two-column table of its members. */
static void
render_object(sbuf *b, const cJSON *o, int depth)
{
    const cJSON *m;
    if (!o->child) {
        sb_str(b, "<span class=\"dim\">none</span>");
        return;
    }
    int records = count_records(o) >= 2, others = 0;
    cJSON_ArrayForEach(m, o) others += !(records && is_record(m));
    if (others) sb_str(b, "<table class=\"kv\">");
    cJSON_ArrayForEach(m, o)
    {
        if (records && is_record(m)) continue;
        sb_str(b, "<tr><th>");
        mcp__strbuf_markup_text(b, m->string);
        sb_str(b, cJSON_IsNumber(m) ? "</th><td class=\"num\">" : "</th><td>");
        render_value(b, m, depth + 1);
        sb_str(b, "</td></tr>");
    }
    if (others) sb_str(b, "</table>");
    if (records) render_records(b, o, depth);
}

static void
render_value(sbuf *b, const cJSON *v, int depth)
{
    if (depth > MAX_DEPTH && !is_scalar(v)) {
        char *t = cJSON_PrintUnformatted(v);
        sb_str(b, "<code>");
        mcp__strbuf_markup_text(b, t ? t : "");
        sb_str(b, "</code>");
        free(t);
    } else if (cJSON_IsArray(v)) {
        render_list(b, v, depth);
    } else if (cJSON_IsObject(v)) {
        render_object(b, v, depth);
    } else {
        sb_scalar(b, v);
    }
}

/* 1 for the members a section's figures table leaves out: the lists drawn elsewhere
 * on the page, and those the section keeps for report.json only (its "json_only"). */
static int
is_reserved(const cJSON *section, const char *key)
{
    static const char *const reserved[] = {"title", "stage",   "tables",   "images",
                                           "plots", "verdict", "json_only"};
    for (size_t i = 0; i < sizeof reserved / sizeof *reserved; i++)
        if (!strcmp(key, reserved[i])) return 1;
    const cJSON *k;
    cJSON_ArrayForEach(
        k, cJSON_GetObjectItem(section,
                               "json_only")) if (cJSON_IsString(k) &&
                                                 !strcmp(key, k->valuestring)) return 1;
    return 0;
}

static void
render_verdict(sbuf *b, const cJSON *section)
{
    const cJSON *v = cJSON_GetObjectItem(section, "verdict");
    const char *text = json_string(v, "text"), *level = json_string(v, "level");
    if (!text) return;
    if (!level || (strcmp(level, "good") && strcmp(level, "bad"))) level = "info";
    mcp__strbuf_printf(b, "<p class=\"verdict %s\">", level);
    mcp__strbuf_markup_text(b, text);
    sb_str(b, "</p>\n");
}

/* The section's key figures: every member that is not one of the reserved lists. */
static void
render_figures(sbuf *b, const cJSON *section)
{
    const cJSON *m;
    int n = 0;
    cJSON_ArrayForEach(m, section)
    {
        if (!m->string || is_reserved(section, m->string)) continue;
        if (n++ == 0) sb_str(b, "<table class=\"figures\">\n");
        sb_str(b, "<tr><th>");
        mcp__strbuf_markup_text(b, m->string);
        sb_str(b, cJSON_IsNumber(m) ? "</th><td class=\"num\">" : "</th><td>");
        render_value(b, m, 1);
        sb_str(b, "</td></tr>\n");
    }
    if (n) sb_str(b, "</table>\n");
}

/* A table cell that names a page beside this one ("0017/report.html", as collect's
 * table of frames has): a relative path ending in .html, shown as a link. */
static int
is_page_link(const cJSON *v)
{
    if (!cJSON_IsString(v)) return 0;
    const char *t = v->valuestring;
    size_t n = strlen(t);
    return n > 5 && !strcmp(t + n - 5, ".html") && t[0] != '/' && !strchr(t, ':') &&
           !strpbrk(t, " \t\n\"'<>");
}

static void
render_tables(sbuf *b, const cJSON *section)
{
    const cJSON *t;
    cJSON_ArrayForEach(t, cJSON_GetObjectItem(section, "tables"))
    {
        const char *title = json_string(t, "title");
        const cJSON *c, *r;
        sb_str(b, "<div class=\"scroll\"><table class=\"data\">\n");
        if (title && *title) {
            sb_str(b, "<caption>");
            mcp__strbuf_markup_text(b, title);
            sb_str(b, "</caption>\n");
        }
        sb_str(b, "<tr>");
        cJSON_ArrayForEach(c, cJSON_GetObjectItem(t, "columns"))
        {
            sb_str(b, "<th>");
            sb_scalar(b, c);
            sb_str(b, "</th>");
        }
        sb_str(b, "</tr>\n");
        cJSON_ArrayForEach(r, cJSON_GetObjectItem(t, "rows"))
        {
            sb_str(b, "<tr>");
            cJSON_ArrayForEach(c, r)
            {
                sb_str(b, cJSON_IsNumber(c) ? "<td class=\"num\">" : "<td>");
                if (is_page_link(c)) { /* another report beside this one */
                    sb_str(b, "<a href=\"");
                    mcp__strbuf_markup_text(b, c->valuestring);
                    sb_str(b, "\">");
                    mcp__strbuf_markup_text(b, c->valuestring);
                    sb_str(b, "</a>");
                } else {
                    render_value(b, c, 1);
                }
                sb_str(b, "</td>");
            }
            sb_str(b, "</tr>\n");
        }
        sb_str(b, "</table></div>\n");
    }
}

/* ---- images ---- */

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

/* Reads a whole file (at most EMBED_MAX_BYTES) into *data, which stays NULL when the
 * file is absent or too large (the page then goes without it). -1 only when memory
 * runs out: that must fail the page, not drop the image. */
static int
read_file(const char *path, unsigned char **data, size_t *size)
{
    *data = NULL;
    FILE *f = fopen(path, "rb");
    if (!f) return 0;
    long n = -1;
    int rc = 0;
    if (fseek(f, 0, SEEK_END) == 0 && (n = ftell(f)) >= 0 && n <= EMBED_MAX_BYTES &&
        fseek(f, 0, SEEK_SET) == 0) {
        if (!(*data = mcp_malloc((size_t)n + 1))) {
            rc = -1;
        } else if (fread(*data, 1, (size_t)n, f) != (size_t)n) {
            free(*data);
            *data = NULL;
        }
    }
    fclose(f);
    *size = n > 0 ? (size_t)n : 0;
    return rc;
}

/* One image of a section, read for embedding. */
typedef struct {
    const char *rel, *caption, *mime;
    const cJSON *scale; /* a map's colour scale, or NULL */
    unsigned char *data;
    size_t size;
    int width, height; /* pixels, from a PNG's header; 0 when unknown */
    char id[32];
    unsigned char *rgbe; /* the linear values ("hdr"), 4 bytes a pixel, or NULL */
} page_image;

static uint32_t
be32(const unsigned char *p)
{
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

/* The pixel size from a PNG's IHDR chunk (the first after the signature). */
static void
png_size(page_image *im)
{
    static const unsigned char sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    if (im->size < 24 || memcmp(im->data, sig, 8) || memcmp(im->data + 12, "IHDR", 4))
        return;
    uint32_t w = be32(im->data + 16), h = be32(im->data + 20);
    if (w > 0 && h > 0 && w <= (1u << 20) && h <= (1u << 20)) {
        im->width = (int)w;
        im->height = (int)h;
    }
}

/* The whole factor that brings an image near px pixels across (at least 1). */
static int
upscale(const page_image *im, int px)
{
    int side = im->width > im->height ? im->width : im->height;
    return side > 0 && side < px ? px / side : 1;
}

/* The image's "hdr" file as RGBE (Ward's shared exponent: R, G, B mantissas and the
 * exponent + 128 of the largest, 4 bytes a pixel), which the page's script decodes
 * and re-exposes; values <= 0 or NaN are black. Left out (NULL, no error) when the file
 * cannot be read, has no RGB or differs in size from the picture. -1 only when memory
 * runs out. */
static int
read_rgbe(page_image *im, const char *path)
{
    mcp_image *img = NULL;
    int rgb[3];
    if (mcp_image_read(path, NULL, &img) || mcp_rgb_channels(img, rgb) ||
        (im->width > 0 && (img->width != im->width || img->height != im->height)) ||
        (long)img->width * img->height > HDR_MAX_PIXELS) {
        mcp_image_free(img);
        /* out of memory must fail the page, not drop the values */
        if (strstr(mcp_error_message(), "out of memory")) return -1;
        mcp_error_clear();
        return 0;
    }
    size_t n = (size_t)img->width * img->height;
    if (!(im->rgbe = mcp_malloc(4 * n))) {
        mcp_image_free(img);
        return -1;
    }
    im->width = img->width;
    im->height = img->height;
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < n; i++) {
        const float *p = mcp_image_px(img, (int)(i % img->width), (int)(i / img->width));
        float v[3], m = 0;
        for (int k = 0; k < 3; k++) {
            v[k] = p[rgb[k]] > 0 ? p[rgb[k]] : 0; /* NaN too */
            if (v[k] > m) m = v[k];
        }
        unsigned char *o = im->rgbe + 4 * i;
        int e;
        if (!(m > 1e-32f) || !isfinite(m)) {
            memset(o, 0, 4);
            continue;
        }
        double scale = frexp(m, &e) * 256.0 / m;
        for (int k = 0; k < 3; k++)
            o[k] = (unsigned char)(v[k] * scale > 255 ? 255 : v[k] * scale);
        o[3] = (unsigned char)(e + 128);
    }
    mcp_image_free(img);
    return 0;
}

/* The value at fraction t of a colour bar. */
static double
bar_value(const cJSON *scale, double t)
{
    const cJSON *lo = cJSON_GetObjectItem(scale, "min"),
                *hi = cJSON_GetObjectItem(scale, "max");
    const char *axis = json_string(scale, "axis");
    double a = cJSON_IsNumber(lo) ? lo->valuedouble : 0,
           z = cJSON_IsNumber(hi) ? hi->valuedouble : 1;
    if (axis && !strcmp(axis, "log") && a > 0 && z > 0)
        return pow(10.0, log10(a) + t * (log10(z) - log10(a)));
    return a + t * (z - a);
}

/* Where value v lies on a colour bar, 0 to 1 (clamped), NaN when it cannot be shown. */
static double
bar_position(const cJSON *scale, double v)
{
    double a = bar_value(scale, 0), z = bar_value(scale, 1), t;
    const char *axis = json_string(scale, "axis");
    if (axis && !strcmp(axis, "log"))
        t = v > 0 ? (log10(v) - log10(a)) / (log10(z) - log10(a)) : NAN;
    else
        t = (v - a) / (z - a);
    return isnan(t) ? t : t < 0 ? 0 : t > 1 ? 1 : t;
}

static int
decade_exponent(double v)
{
    return (int)lround(log10(v));
}

/* A colour bar's label at fraction t: the value, or 10^e for a decade (short enough
 * for six of them under a 256-pixel map). */
static void
bar_tick(sbuf *b, double t, double v, int decade)
{
    const char *cls = t < 0.01 ? "first" : t > 0.99 ? "last" : "mid";
    mcp__strbuf_printf(b, "<span class=\"%s\" style=\"left:%.2f%%\">", cls, 100 * t);
    if (decade && decade_exponent(v) != 0)
        mcp__strbuf_printf(b, "10<sup>%d</sup></span>", decade_exponent(v));
    else /* three digits: six ran into each other under a 256-pixel map ("10.7213") */
        mcp__strbuf_printf(b, "%.3g</span>", v);
}

/* A map's colour bar: the ramp of its colour map, the values at its ends and between,
 * the marks, and the unit. */
static void
render_colour_bar(sbuf *b, const cJSON *scale)
{
    mcp_colormap map;
    const char *name = json_string(scale, "colormap"), *unit = json_string(scale, "unit");
    const char *axis = json_string(scale, "axis");
    mcp_image *ramp = NULL;
    unsigned char rgb[RAMP_STOPS * 3];
    if (mcp_colormap_from_name(name, &map)) { /* not a scale we can draw */
        mcp_error_clear();
        return;
    }
    if (mcp_image_new(RAMP_STOPS, 1, 1, (const char *const[]){"t"}, &ramp)) {
        b->failed = 1; /* out of memory: the page fails as a whole */
        return;
    }
    for (int i = 0; i < RAMP_STOPS; i++)
        ramp->data[i] = (float)i / (RAMP_STOPS - 1);
    int rc = mcp_colormap_apply(ramp, 0, 0.0, 1.0, map, rgb);
    mcp_image_free(ramp);
    if (rc) {
        b->failed = 1;
        return;
    }
    sb_str(b,
           "<div class=\"cbar\"><div class=\"ramp\" style=\"background:linear-gradient("
           "to right");
    for (int i = 0; i < RAMP_STOPS; i++)
        mcp__strbuf_printf(b, ",#%02x%02x%02x %.1f%%", rgb[3 * i], rgb[3 * i + 1],
                           rgb[3 * i + 2], 100.0 * i / (RAMP_STOPS - 1));
    sb_str(b, ")\">");
    const cJSON *m;
    cJSON_ArrayForEach(m, cJSON_GetObjectItem(scale, "marks"))
    {
        const cJSON *v = cJSON_GetObjectItem(m, "value");
        double t = cJSON_IsNumber(v) ? bar_position(scale, v->valuedouble) : NAN;
        if (!isnan(t))
            mcp__strbuf_printf(b, "<i class=\"mark\" style=\"left:%.2f%%\"></i>",
                               100 * t);
    }
    sb_str(b, "</div><div class=\"ticks\">");
    if (axis && !strcmp(axis, "log")) { /* every decade, at most 7 labels */
        double a = log10(bar_value(scale, 0)), z = log10(bar_value(scale, 1));
        int first = (int)ceil(a - 1e-9), last = (int)floor(z + 1e-9);
        int step = (last - first) / 6 + 1;
        for (int e = first; e <= last; e += step)
            bar_tick(b, (e - a) / (z - a), pow(10.0, e), 1);
    } else {
        for (int i = 0; i <= 4; i++)
            bar_tick(b, i / 4.0, bar_value(scale, i / 4.0), 0);
    }
    sb_str(b, "</div>");
    cJSON_ArrayForEach(m, cJSON_GetObjectItem(scale, "marks"))
    {
        const cJSON *v = cJSON_GetObjectItem(m, "value");
        if (!cJSON_IsNumber(v) || isnan(bar_position(scale, v->valuedouble))) continue;
        sb_str(b, "<div class=\"marklabel\">&#9650; ");
        mcp__strbuf_markup_text(b, json_string(m, "label"));
        mcp__strbuf_printf(b, " = %g</div>", v->valuedouble);
    }
    if (unit && *unit) {
        sb_str(b, "<div class=\"unit\">");
        mcp__strbuf_markup_text(b, unit);
        sb_str(b, "</div>");
    }
    sb_str(b, "</div>");
}

static void
render_figure(sbuf *b, const page_image *im)
{
    int k = upscale(im, GRID_PX);
    if (im->data && im->width > 0) /* caption and colour bar as wide as the picture */
        mcp__strbuf_printf(b, "<figure style=\"width:%dpx\">", k * im->width);
    else
        sb_str(b, "<figure>");
    /* a map with one value in every pixel would be a flat square: the value is written
       across it (its mark on the colour bar shows where it sits) */
    const cJSON *one = cJSON_GetObjectItem(im->scale, "one_value");
    if (im->data && cJSON_IsNumber(one)) sb_str(b, "<div class=\"flat\">");
    if (im->data) {
        mcp__strbuf_printf(b, "<img id=\"%s\" class=\"px\" alt=\"", im->id);
        mcp__strbuf_markup_text(b, im->rel);
        if (im->width > 0)
            mcp__strbuf_printf(b, "\" width=\"%d\" height=\"%d", k * im->width,
                               k * im->height);
        if (im->rgbe) { /* the linear values, for the display controls */
            mcp__strbuf_printf(b, "\" data-hdr=\"%d,%d,", im->width, im->height);
            sb_base64(b, im->rgbe, 4 * (size_t)im->width * im->height);
        }
        mcp__strbuf_printf(b, "\" src=\"data:%s;base64,", im->mime);
        sb_base64(b, im->data, im->size);
        sb_str(b, "\">");
        if (cJSON_IsNumber(one))
            mcp__strbuf_printf(b,
                               "<span class=\"onevalue\">one value in every pixel: %g<br>"
                               "no map to show</span></div>",
                               one->valuedouble);
        if (im->scale) render_colour_bar(b, im->scale);
    } else {
        mcp__strbuf_printf(b, "<div class=\"noimg\">%s <code>",
                           im->mime ? "missing or too large to embed:"
                                    : "not viewable in a browser:");
        mcp__strbuf_markup_text(b, im->rel);
        sb_str(b, "</code></div>");
    }
    sb_str(b, "<figcaption>");
    mcp__strbuf_markup_text(b, im->caption && *im->caption ? im->caption : im->rel);
    if (im->rgbe) sb_str(b, " <span title=\"the display controls apply\">&#9788;</span>");
    if (im->data && im->width > 0) {
        mcp__strbuf_printf(b, " <span class=\"dim\">%d&times;%d px", im->width,
                           im->height);
        if (k > 1) mcp__strbuf_printf(b, ", shown %d&times;", k);
        sb_str(b, "</span>");
    }
    sb_str(b, "</figcaption></figure>\n");
}

static void
render_options(sbuf *b, const page_image *ims, int n, const int *members, int chosen)
{
    for (int i = 0; i < n; i++) {
        const page_image *im = &ims[members[i]];
        mcp__strbuf_printf(b, "<option value=\"%s\"%s>", im->id,
                           members[i] == chosen ? " selected" : "");
        mcp__strbuf_markup_text(b, im->caption && *im->caption ? im->caption : im->rel);
        sb_str(b, "</option>");
    }
}

/* The wipe comparison of the n images members[] (all of one pixel size): two of them
 * overlaid, split where the reader drags, both magnified at the same spot. The script
 * fills it from the grid's images, so no image is embedded twice; without scripts it
 * stays hidden. */
static void
render_compare(sbuf *b, const page_image *ims, const int *members, int n)
{
    /* left: the first photo (an image without a colour scale); right: the last */
    int left = -1, right = -1;
    for (int i = 0; i < n; i++)
        if (!ims[members[i]].scale) {
            if (left < 0) left = members[i];
            right = members[i];
        }
    if (left < 0) left = members[0];
    if (right < 0 || right == left) right = members[members[0] == left ? 1 : 0];
    const page_image *im = &ims[left];
    int k = upscale(im, COMPARE_PX), w = k * im->width;
    sb_str(b, "<div class=\"compare\" hidden><div class=\"cmp-bar\">left <select "
              "class=\"cmp-a\">");
    render_options(b, ims, n, members, left);
    sb_str(b, "</select> right <select class=\"cmp-b\">");
    render_options(b, ims, n, members, right);
    sb_str(b,
           "</select> zoom <select class=\"cmp-z\"><option>1</option><option>2</option>"
           "<option>4</option><option>8</option></select></div>\n");
    mcp__strbuf_printf(
        b,
        "<div class=\"cmp-view\" style=\"width:%dpx;aspect-ratio:%d/%d\">"
        "<div class=\"cmp-in\"><img class=\"px cmp-b\" alt=\"right\"></div>"
        "<div class=\"cmp-clip\"><div class=\"cmp-in\"><img class=\"px cmp-a\" "
        "alt=\"left\"></div></div><div class=\"cmp-line\"></div></div>\n"
        "<input class=\"cmp-pos\" type=\"range\" min=\"0\" max=\"100\" step=\"0.5\" "
        "value=\"50\" style=\"width:%dpx\" aria-label=\"split\">\n",
        w, im->width, im->height, w);
    mcp__strbuf_printf(
        b,
        "<p class=\"hint\">%d&times;%d px shown %d&times;: drag across the picture "
        "(or the slider) to move the split between left and right; with zoom "
        "both are magnified at the pointer.</p></div>\n",
        im->width, im->height, k);
}

static void
render_images(sbuf *b, const cJSON *section, const char *dir, int section_index)
{
    const cJSON *images = cJSON_GetObjectItem(section, "images"), *ij;
    int n = cJSON_GetArraySize(images), k = 0;
    if (!n) return;
    page_image *ims = mcp_calloc((size_t)n, sizeof *ims);
    int *members = mcp_calloc((size_t)n, sizeof *members);
    if (!ims || !members) {
        free(ims);
        free(members);
        b->failed = 1;
        return;
    }
    cJSON_ArrayForEach(ij, images)
    {
        page_image *im = &ims[k];
        im->rel = json_string(ij, "path");
        if (!im->rel) continue;
        im->caption = json_string(ij, "caption");
        im->mime = mime_of(im->rel);
        im->scale = cJSON_GetObjectItem(ij, "scale");
        snprintf(im->id, sizeof im->id, "im%d_%d", section_index, k);
        char full[4096];
        snprintf(full, sizeof full, "%s/%s", dir, im->rel);
        im->data = NULL;
        if (im->mime && read_file(full, &im->data, &im->size)) b->failed = 1;
        if (im->data) png_size(im);
        const char *hdr = json_string(ij, "hdr");
        if (im->data && hdr) {
            snprintf(full, sizeof full, "%s/%s", dir, hdr);
            if (read_rgbe(im, full)) b->failed = 1;
        }
        k++;
    }
    /* the comparison: the first pixel size that two or more images share */
    for (int i = 0; i < k; i++) {
        int m = 0;
        for (int j = 0; j < k && ims[i].width > 0; j++)
            if (ims[j].width == ims[i].width && ims[j].height == ims[i].height)
                members[m++] = j;
        if (m >= 2) {
            render_compare(b, ims, members, m);
            break;
        }
    }
    sb_str(b, "<div class=\"images\">\n");
    for (int i = 0; i < k; i++)
        render_figure(b, &ims[i]);
    sb_str(b, "</div>\n");
    for (int i = 0; i < k; i++) {
        free(ims[i].data);
        free(ims[i].rgbe);
    }
    free(ims);
    free(members);
}

/* ---- plots ---- */

static double *
json_doubles(const cJSON *a, int *n)
{
    *n = cJSON_GetArraySize(a);
    double *v = mcp_malloc(((size_t)*n + 1) * sizeof *v);
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
        const char *title = json_string(pj, "title"), *xs = json_string(xa, "scale"),
                   *ys = json_string(ya, "scale");
        mcp_plot p = {0};
        p.title = title && *title ? title : NULL;
        p.x_label = json_string(xa, "label");
        p.y_label = json_string(ya, "label");
        if (!xs || mcp_axis_scale_from_name(xs, &p.x_scale)) p.x_scale = MCP_AXIS_LINEAR;
        if (!ys || mcp_axis_scale_from_name(ys, &p.y_scale)) p.y_scale = MCP_AXIS_LINEAR;
        mcp_error_clear();
        const cJSON *series = cJSON_GetObjectItem(pj, "series"), *sj;
        int n = cJSON_GetArraySize(series), k = 0;
        mcp_plot_series *ps = mcp_calloc((size_t)n + 1, sizeof *ps);
        if (!ps) {
            b->failed = 1;
            return;
        }
        cJSON_ArrayForEach(sj, series)
        {
            const char *style = json_string(sj, "style");
            int nx, ny;
            double *x = json_doubles(cJSON_GetObjectItem(sj, "x"), &nx);
            double *y = json_doubles(cJSON_GetObjectItem(sj, "y"), &ny);
            ps[k].name = json_string(sj, "name");
            if (!style || mcp_series_style_from_name(style, &ps[k].style))
                ps[k].style = MCP_SERIES_LINE;
            ps[k].dashed = cJSON_IsTrue(cJSON_GetObjectItem(sj, "dashed"));
            ps[k].x = x;
            ps[k].y = y;
            ps[k].n = x && y ? (nx < ny ? nx : ny) : 0;
            if (!x || !y) b->failed = 1; /* out of memory (json_doubles) */
            k++;
        }
        mcp_error_clear();
        p.series = ps;
        p.n_series = k;
        char *svg = NULL;
        sb_str(b, "<div class=\"plot\">");
        if (mcp_plot_svg(&p, &svg) == 0) {
            sb_str(b, svg);
        } else if (strstr(mcp_error_message(), "out of memory")) {
            b->failed = 1; /* not a plot that cannot be drawn: no page */
        } else {
            sb_str(b, "<div class=\"noimg\">");
            mcp__strbuf_markup_text(b, mcp_error_message());
            sb_str(b, "</div>");
            mcp_error_clear();
        }
        sb_str(b, "</div>\n");
        free(svg);
        for (int i = 0; i < k; i++) {
            free((void *)ps[i].x);
            free((void *)ps[i].y);
        }
        free(ps);
    }
}

/* ---- the display of HDR images ---- */

/* 1 when a section has an image with linear values ("hdr"). */
static int
page_has_hdr(const cJSON *sections)
{
    const cJSON *s, *im;
    cJSON_ArrayForEach(s, sections) cJSON_ArrayForEach(
        im, cJSON_GetObjectItem(s, "images")) if (json_string(im, "hdr")) return 1;
    return 0;
}

/* The display controls of the HDR images: exposure in stops, and clamp, the tone maps
 * of tonemap.h or false colour (log10 luminance on viridis, with its colour bar). The
 * script (display_script) redraws every image that has data-hdr, and the comparison
 * with them. */
static void
render_display_bar(sbuf *b, const cJSON *root)
{
    static const char *const modes[][2] = {
        {"clamp", "clamp (as the PNG files)"},
        {"aces", "ACES"},
        {"hable", "Hable"},
        {"reinhard", "Reinhard"},
        {"false-colour", "false colour: log luminance"}};
    const cJSON *d = cJSON_GetObjectItem(root, "display");
    const cJSON *ej = cJSON_GetObjectItem(d, "exposure");
    const char *mode = json_string(d, "mode");
    double ev = cJSON_IsNumber(ej) ? ej->valuedouble : 0;
    if (!mode) mode = "clamp";
    /* the false-colour ramp, 256 colours, for the script */
    mcp_image *ramp = NULL;
    unsigned char rgb[256 * 3];
    if (mcp_image_new(256, 1, 1, (const char *const[]){"t"}, &ramp)) {
        b->failed = 1;
        return;
    }
    for (int i = 0; i < 256; i++)
        ramp->data[i] = (float)i / 255;
    int rc = mcp_colormap_apply(ramp, 0, 0.0, 1.0, MCP_COLORMAP_VIRIDIS, rgb);
    mcp_image_free(ramp);
    if (rc) {
        b->failed = 1;
        return;
    }
    mcp__strbuf_printf(
        b, "<div class=\"display\" data-lo=\"%g\" data-hi=\"%g\" data-ramp=\"", FALSE_LO,
        FALSE_HI);
    for (int i = 0; i < 256 * 3; i++)
        mcp__strbuf_printf(b, "%s%d", i ? "," : "", rgb[i]);
    mcp__strbuf_printf(
        b,
        "\"><b>renders</b><label>exposure <input class=\"dsp-exp\" type=\"range\" "
        "min=\"-10\" max=\"10\" step=\"0.25\" value=\"%g\" aria-label=\"exposure\">"
        "</label><output class=\"dsp-ev\">%+.2f EV</output><label>display "
        "<select class=\"dsp-mode\">",
        ev, ev);
    for (size_t i = 0; i < sizeof modes / sizeof *modes; i++)
        mcp__strbuf_printf(b, "<option value=\"%s\"%s>%s</option>", modes[i][0],
                           strcmp(mode, modes[i][0]) ? "" : " selected", modes[i][1]);
    sb_str(b, "</select></label><span class=\"dim\">for the renders marked &#9788;</span>"
              "<div class=\"dsp-legend\" hidden>");
    cJSON *scale = cJSON_CreateObject();
    if (!scale || !cJSON_AddStringToObject(scale, "colormap", "viridis") ||
        !cJSON_AddNumberToObject(scale, "min", pow(10.0, FALSE_LO)) ||
        !cJSON_AddNumberToObject(scale, "max", pow(10.0, FALSE_HI)) ||
        !cJSON_AddStringToObject(scale, "axis", "log") ||
        !cJSON_AddStringToObject(scale, "unit", "luminance x 2^exposure")) {
        cJSON_Delete(scale);
        b->failed = 1;
        return;
    }
    render_colour_bar(b, scale);
    cJSON_Delete(scale);
    sb_str(b, "</div></div>\n");
}

/* ---- the page ---- */

static const char css[] =
    "*{box-sizing:border-box}\n"
    "body{font-family:-apple-system,'Segoe UI',Helvetica,Arial,sans-serif;margin:0;"
    "color:#222;background:#fafafa}\n"
    "header{background:#263238;color:#fff;padding:16px 28px}\n"
    "header h1{margin:0;font-size:22px}"
    "header p{margin:4px 0 0;color:#b0bec5;font-size:13px}\n"
    "nav{padding:10px 28px;font-size:13px;border-bottom:1px solid #ddd;background:#fff}\n"
    "nav a{margin-right:14px;color:#1565c0;text-decoration:none;display:inline-block}\n"
    "section{background:#fff;margin:18px 28px;padding:8px 20px 18px;"
    "border:1px solid #ddd;border-radius:6px;overflow-wrap:anywhere}\n"
    "h2{font-size:18px;margin:12px 0}"
    "h2 small{color:#888;font-weight:normal;font-size:12px;margin-left:8px}\n"
    ".verdict{margin:8px 0 12px;padding:8px 12px;border-left:5px solid #1565c0;"
    "background:#e3f2fd;font-weight:600;font-size:15px}\n"
    ".verdict.good{border-color:#2e7d32;background:#e8f5e9}\n"
    ".verdict.bad{border-color:#c62828;background:#ffebee}\n"
    "table{border-collapse:collapse;margin:10px 0;font-size:13px}\n"
    "th,td{border:1px solid #e0e0e0;padding:4px "
    "10px;text-align:left;vertical-align:top}\n"
    "table.figures>tbody>tr>th{background:#f5f5f5;font-weight:600;white-space:nowrap}\n"
    "table.figures>tbody>tr>td.num{text-align:left}\n"
    "table.kv,table.nested{margin:0;font-size:12px}"
    "table.kv th{background:#fafafa;font-weight:500}\n"
    "table.data th{background:#eceff1}"
    "td.num{text-align:right;font-variant-numeric:tabular-nums}\n"
    "caption{text-align:left;font-weight:600;padding:4px 0}\n"
    "ul.list{margin:0;padding-left:18px}.dim{color:#888}\n"
    ".scroll{max-width:100%;overflow-x:auto}\n"
    ".images{display:flex;flex-wrap:wrap;gap:18px;align-items:flex-start}\n"
    "figure{margin:0;max-width:100%}\n"
    "img.px{image-rendering:pixelated;max-width:100%;height:auto;display:block}\n"
    "figure img{border:1px solid #ccc}\n"
    "figcaption{font-size:12px;color:#555;margin-top:3px}\n"
    ".cbar{margin-top:4px;font-size:11px;color:#444}\n"
    ".cbar .ramp{position:relative;height:12px;border:1px solid #999}\n"
    ".cbar .mark{position:absolute;top:-3px;bottom:-3px;width:2px;margin-left:-1px;"
    "background:#0bf;border:1px solid #fff}\n"
    ".cbar .ticks{position:relative;height:17px}.cbar sup{font-size:8px}"
    ".cbar .ticks span{position:absolute;top:1px;white-space:nowrap}\n"
    ".cbar .ticks .mid{transform:translateX(-50%)}"
    ".cbar .ticks .last{transform:translateX(-100%)}\n"
    ".cbar .marklabel{color:#0277bd}.cbar .unit{font-style:italic}\n"
    ".compare{margin:6px 0 18px}.cmp-bar{font-size:13px;margin-bottom:6px}\n"
    ".cmp-bar select{margin:0 10px 0 4px;max-width:260px}\n"
    ".cmp-view{position:relative;max-width:100%;overflow:hidden;cursor:ew-resize;"
    "border:1px solid #999;touch-action:none;user-select:none}\n"
    ".cmp-view .cmp-clip,.cmp-view .cmp-in{position:absolute;inset:0}\n"
    ".cmp-view img{position:absolute;inset:0;width:100%;height:100%;max-width:none}\n"
    ".cmp-line{position:absolute;top:0;bottom:0;width:2px;margin-left:-1px;"
    "background:#fff;box-shadow:0 0 3px #000}\n"
    ".cmp-pos{display:block;max-width:100%;margin:6px 0 0}\n"
    ".hint{font-size:12px;color:#666;margin:4px 0}\n"
    ".plot{display:inline-block;margin:8px 12px 8px 0;max-width:100%}"
    ".plot svg{max-width:100%;height:auto}\n"
    ".noimg{padding:20px;border:1px dashed #bbb;color:#777;font-size:13px}\n"
    ".flat{position:relative}\n"
    ".onevalue{position:absolute;left:8%;right:8%;top:38%;padding:4px;text-align:center;"
    "background:rgba(255,255,255,.9);border:1px solid #999;font-size:12px}\n"
    ".display{position:sticky;top:0;z-index:5;display:flex;flex-wrap:wrap;gap:6px 16px;"
    "align-items:center;padding:8px 28px;font-size:13px;background:#eceff1;"
    "border-bottom:1px solid #ccc}\n"
    ".display input{vertical-align:middle;width:180px;max-width:40vw}"
    ".display output{font-variant-numeric:tabular-nums;min-width:64px}\n"
    ".dsp-legend{width:260px;max-width:100%}.dsp-legend[hidden]{display:none}\n";

/* The wipe comparisons: pick the two images, move the split, magnify both at the
 * pointer. Plain DOM, no libraries. */
static const char script[] =
    "document.querySelectorAll('.compare').forEach(function(c){\n"
    "var q=function(s){return c.querySelector(s)},v=q('.cmp-view'),"
    "ia=q('img.cmp-a'),ib=q('img.cmp-b'),clip=q('.cmp-clip'),line=q('.cmp-line'),"
    "sa=q('select.cmp-a'),sb=q('select.cmp-b'),sz=q('select.cmp-z'),r=q('.cmp-pos'),"
    "ins=v.querySelectorAll('.cmp-in'),down=false;\n"
    "function pick(){ia.src=document.getElementById(sa.value).src;"
    "ib.src=document.getElementById(sb.value).src}\n"
    "function split(p){p=Math.max(0,Math.min(100,p));"
    "clip.style.clipPath='inset(0 '+(100-p)+'% 0 0)';line.style.left=p+'%';r.value=p}\n"
    "function zoom(e){var b=v.getBoundingClientRect();ins.forEach(function(i){"
    "i.style.transform='scale('+sz.value+')';if(e)i.style.transformOrigin="
    "(e.clientX-b.left)+'px '+(e.clientY-b.top)+'px'})}\n"
    "function move(e){var b=v.getBoundingClientRect();"
    "if(down)split(100*(e.clientX-b.left)/b.width);zoom(e)}\n"
    "sa.onchange=sb.onchange=pick;sz.onchange=function(){zoom(null)};"
    "r.oninput=function(){split(+r.value)};\n"
    "v.onpointerdown=function(e){down=true;v.setPointerCapture(e.pointerId);move(e)};"
    "v.onpointerup=function(){down=false};v.onpointermove=move;\n"
    "pick();split(50);c.hidden=false});\n"
    /* The display controls: the linear values of every img[data-hdr] (RGBE, decoded
     * once) times 2^exposure, through the tone map -- the curves of tonemap.h, clamped
     * and sRGB-encoded as the PNG writer does -- or false colour (log10 luminance,
     * data-lo to data-hi, on the bar's ramp); the comparison picks the new pictures. */
    "(function(){var bar=document.querySelector('.display');if(!bar)return;\n"
    "var q=function(s){return bar.querySelector(s)},ex=q('.dsp-exp'),md=q('.dsp-mode'),"
    "ev=q('.dsp-ev'),lg=q('.dsp-legend'),lo=+bar.dataset.lo,hi=+bar.dataset.hi,"
    "ramp=bar.dataset.ramp.split(',').map(Number),items=[];\n"
    "function R(k,x){return(k[0]*x*x+k[1]*x+k[2])/(k[3]*x*x+k[4]*x+k[5])}\n"
    "var TM={clamp:function(x){return x},"
    "aces:function(x){return R([2.51,0.03,0,2.43,0.59,0.14],x)},"
    "hable:function(x){return R([0.231683,0.013791,0,0.18,0.3,0.018],x)},"
    "reinhard:function(x){return x/(1+x)}};\n"
    "function enc(v){v=v>0?(v<1?v:1):0;return Math.round(255*(v<=0.0031308?12.92*v:"
    "1.055*Math.pow(v,1/2.4)-0.055))}\n"
    "document.querySelectorAll('img[data-hdr]').forEach(function(img){"
    "var a=img.dataset.hdr.split(','),w=+a[0],h=+a[1],s=atob(a[2]),n=w*h,"
    "f=new Float32Array(3*n);\n"
    "for(var p=0;p<n;p++){var e=s.charCodeAt(4*p+3);if(!e)continue;var "
    "k=Math.pow(2,e-136);"
    "for(var c=0;c<3;c++)f[3*p+c]=(s.charCodeAt(4*p+c)+0.5)*k}\n"
    "items.push({img:img,f:f,w:w,h:h})});\n"
    "function draw(){var k=Math.pow(2,+ex.value),m=md.value,t=TM[m]||TM.clamp,"
    "fc=m==='false-colour';ev.textContent=(ex.value<0?'':'+')+(+ex.value).toFixed(2)+' "
    "EV';"
    "lg.hidden=!fc;\n"
    "items.forEach(function(it){var cv=document.createElement('canvas');cv.width=it.w;"
    "cv.height=it.h;var x=cv.getContext('2d'),d=x.createImageData(it.w,it.h),o=d.data,"
    "f=it.f;\n"
    "for(var p=0,i=0;i<o.length;p+=3,i+=4){if(fc){var L=k*(0.2126*f[p]+0.7152*f[p+1]+"
    "0.0722*f[p+2]),u=L>0?(Math.log10(L)-lo)/"
    "(hi-lo):0,j=3*Math.round(255*(u>0?(u<1?u:1):0));"
    "o[i]=ramp[j];o[i+1]=ramp[j+1];o[i+2]=ramp[j+2]}\n"
    "else{o[i]=enc(t(k*f[p]));o[i+1]=enc(t(k*f[p+1]));o[i+2]=enc(t(k*f[p+2]))}o[i+3]=255}"
    "\n"
    "x.putImageData(d,0,0);it.img.src=cv.toDataURL()});\n"
    "document.querySelectorAll('.compare select.cmp-a').forEach(function(s){"
    "if(s.onchange)s.onchange()})}\n"
    "ex.oninput=md.onchange=draw;if(+ex.value!==0||md.value!=='clamp')draw()})();\n";

int
mcp_report_html(mcp_report *r, const char *dir, char **html)
{
    *html = NULL;
    const cJSON *root = mcp_report_json(r);
    const char *t = json_string(root, "title");
    const cJSON *sections = cJSON_GetObjectItem(root, "sections"), *s;
    int n_sections = cJSON_GetArraySize(sections);
    if (!t) t = "mcpost report";
    sbuf b = {0};
    sb_str(&b, "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n"
               "<meta name=\"viewport\" content=\"width=device-width,initial-scale=1\">\n"
               "<title>");
    mcp__strbuf_markup_text(&b, t);
    mcp__strbuf_printf(&b, "</title>\n<style>\n%s</style>\n</head><body>\n<header><h1>",
                       css);
    mcp__strbuf_markup_text(&b, t);
    mcp__strbuf_printf(
        &b,
        "</h1><p>mcpost %s &middot; %d section%s &middot; every figure is also in "
        "report.json &middot; docs/report.md explains the page</p></header>\n",
        MCP_VERSION, n_sections, n_sections == 1 ? "" : "s");
    if (n_sections > 1) {
        int i = 0;
        sb_str(&b, "<nav>");
        cJSON_ArrayForEach(s, sections)
        {
            const char *st = json_string(s, "title");
            mcp__strbuf_printf(&b, "<a href=\"#s%d\">", i++);
            mcp__strbuf_markup_text(&b, st ? st : "section");
            sb_str(&b, "</a>");
        }
        sb_str(&b, "</nav>\n");
    }
    if (page_has_hdr(sections)) render_display_bar(&b, root);
    int i = 0;
    cJSON_ArrayForEach(s, sections)
    {
        const char *st = json_string(s, "title"), *sg = json_string(s, "stage");
        mcp__strbuf_printf(&b, "<section id=\"s%d\"><h2>", i);
        mcp__strbuf_markup_text(&b, st ? st : "");
        if (sg) {
            sb_str(&b, "<small>");
            mcp__strbuf_markup_text(&b, sg);
            sb_str(&b, "</small>");
        }
        sb_str(&b, "</h2>\n");
        render_verdict(&b, s);
        render_figures(&b, s);
        render_images(&b, s, dir, i);
        render_tables(&b, s);
        render_plots(&b, s);
        sb_str(&b, "</section>\n");
        i++;
    }
    mcp__strbuf_printf(&b, "<script>\n%s</script>\n</body></html>\n", script);
    if (b.failed) {
        free(b.s);
        return mcp_error("out of memory for the report");
    }
    *html = b.s;
    return 0;
}
