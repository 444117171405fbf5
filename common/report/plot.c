/* plot.c: line/scatter plots as SVG text with linear, log and logit axes (see plot.h;
 * used by report.c for the error-percentile plot of Firmino et al. 2024 and the
 * error-vs-spp curves). */
#define _POSIX_C_SOURCE 200809L /* strcasecmp */
#include <mcpost/plot.h>

#include "internal.h"
#include "../core/internal.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

/* ---- names ---- */

static const char *const scale_names[] = {"linear", "log", "logit"};
static const char *const style_names[] = {"line", "scatter", "line+points", "bars"};

const mcp_wordlist mcp_axis_scale_words = {"axis scale", scale_names, 3};
const mcp_wordlist mcp_series_style_words = {"series style", style_names, 4};

int
mcp_axis_scale_from_name(const char *name, mcp_axis_scale *out)
{
    return mcp_wordlist_find(&mcp_axis_scale_words, name, (int *)out);
}

const char *
mcp_axis_scale_name(mcp_axis_scale s)
{
    return (unsigned)s < 3 ? scale_names[s] : "?";
}

int
mcp_series_style_from_name(const char *name, mcp_series_style *out)
{
    return mcp_wordlist_find(&mcp_series_style_words, name, (int *)out);
}

const char *
mcp_series_style_name(mcp_series_style s)
{
    return (unsigned)s < 4 ? style_names[s] : "?";
}

/* A bar series' bar width: the smallest gap between neighbouring valid x (1 when it
 * has one point). */
static double
bar_width(const mcp_plot_series *ps)
{
    double w = INFINITY;
    for (int i = 1; i < ps->n; i++) {
        double d = fabs(ps->x[i] - ps->x[i - 1]);
        if (isfinite(d) && d > 0 && d < w) w = d;
    }
    return isfinite(w) ? w : 1.0;
}

double
mcp_logit(double p)
{
    return log(p / (1.0 - p));
}

double
mcp_logistic(double z)
{
    return 1.0 / (1.0 + exp(-z));
}

/* ---- a growing text buffer (core/strbuf.c; a failure sticks in b->failed) ---- */

typedef mcp__strbuf sbuf;

/* ---- axes ---- */

typedef struct {
    mcp_axis_scale scale;
    double lo, hi; /* range in transformed units */
    double a0, a1; /* pixel positions of lo and hi */
} axis;

static int
valid(mcp_axis_scale s, double v)
{
    if (!isfinite(v)) return 0;
    if (s == MCP_AXIS_LOG) return v > 0.0;
    if (s == MCP_AXIS_LOGIT) return v > 0.0 && v < 1.0;
    return 1;
}

static double
forward(mcp_axis_scale s, double v)
{
    return s == MCP_AXIS_LOG ? log10(v) : s == MCP_AXIS_LOGIT ? mcp_logit(v) : v;
}

static double
to_px(const axis *a, double v)
{
    return a->a0 + (forward(a->scale, v) - a->lo) / (a->hi - a->lo) * (a->a1 - a->a0);
}

/* The transformed data range, padded so that points do not sit on the frame. */
static void
set_range(axis *a, double lo, double hi)
{
    if (a->scale == MCP_AXIS_LOG) {
        if (hi - lo < 1e-9) {
            lo -= 0.5;
            hi += 0.5;
        } else {
            double pad = 0.04 * (hi - lo);
            lo -= pad;
            hi += pad;
        }
    } else {
        if (hi - lo < 1e-12 * (fabs(lo) + fabs(hi)) || hi == lo) {
            double d =
                a->scale == MCP_AXIS_LOGIT ? 1.0 : (fabs(lo) > 0 ? 0.1 * fabs(lo) : 1.0);
            lo -= d;
            hi += d;
        } else {
            double pad = 0.04 * (hi - lo);
            lo -= pad;
            hi += pad;
        }
    }
    a->lo = lo;
    a->hi = hi;
}

typedef struct {
    double value; /* data units */
    int major;
} tick;

#define MAX_TICKS 64

static int
linear_ticks(const axis *a, tick *t)
{
    double span = a->hi - a->lo, raw = span / 5.0;
    double mag = pow(10.0, floor(log10(raw))), step = mag;
    const double mult[4] = {1, 2, 5, 10};
    for (int i = 0; i < 4; i++)
        if (mult[i] * mag >= raw) {
            step = mult[i] * mag;
            break;
        }
    int n = 0;
    for (double v = ceil(a->lo / step) * step; v <= a->hi + 1e-9 * step && n < MAX_TICKS;
         v += step) {
        t[n].value = fabs(v) < 1e-9 * step ? 0.0 : v;
        t[n++].major = 1;
    }
    return n;
}

static int
log_ticks(const axis *a, tick *t)
{
    int k0 = (int)ceil(a->lo - 1e-9), k1 = (int)floor(a->hi + 1e-9), n = 0;
    int decades = k1 - k0 + 1, every = decades > 8 ? (decades + 7) / 8 : 1;
    for (int k = (int)floor(a->lo); k <= (int)ceil(a->hi) && n < MAX_TICKS - 9; k++)
        for (int m = 1; m <= 9; m++) {
            double e = k + log10((double)m);
            if (e < a->lo - 1e-9 || e > a->hi + 1e-9) continue;
            int major = m == 1 && (k - k0) % every == 0;
            /* Few decades: label 2 and 5 as well (and 3 within one decade). */
            if ((decades <= 2 && (m == 2 || m == 5)) || (a->hi - a->lo < 1.0 && m == 3))
                major = 1;
            if (!major && decades > 6) continue; /* no minor lines when crowded */
            t[n].value = pow(10.0, e);
            t[n++].major = major;
        }
    return n;
}

static int
logit_ticks(const axis *a, tick *t)
{
    static const double cand[] = {1e-6,   1e-5,    1e-4,     0.001,     0.01,
                                  0.1,    0.5,     0.9,      0.99,      0.999,
                                  0.9999, 0.99999, 0.999999, 0.9999999, 0.99999999};
    int n = 0;
    for (size_t i = 0; i < sizeof cand / sizeof cand[0]; i++) {
        double z = mcp_logit(cand[i]);
        if (z >= a->lo - 1e-9 && z <= a->hi + 1e-9) {
            t[n].value = cand[i];
            t[n++].major = 1;
        }
    }
    if (n < 2) /* a narrow range: fall back to evenly spaced probabilities */
        for (int i = 0; i <= 4 && n < MAX_TICKS; i++) {
            double z = a->lo + (a->hi - a->lo) * i / 4.0;
            t[n].value = mcp_logistic(z);
            t[n++].major = 1;
        }
    return n;
}

static int
ticks(const axis *a, tick *t)
{
    return a->scale == MCP_AXIS_LOG     ? log_ticks(a, t)
           : a->scale == MCP_AXIS_LOGIT ? logit_ticks(a, t)
                                        : linear_ticks(a, t);
}

static void
tick_label(const axis *a, double v, char *buf, size_t cap)
{
    if (a->scale == MCP_AXIS_LOGIT)
        snprintf(buf, cap, "%.10g", v);
    else
        snprintf(buf, cap, "%g", v);
}

/* ---- the plot ---- */

static const char *const palette[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e",
                                      "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
                                      "#bcbd22", "#17becf"};

int
mcp_plot_svg(const mcp_plot *p, char **svg)
{
    *svg = NULL;
    const char *title = p->title ? p->title : "";
    int W = p->width > 0 ? p->width : 640, H = p->height > 0 ? p->height : 400;
    if (W < 200 || H < 150 || W > 10000 || H > 10000)
        return mcp_error("plot '%s': size %dx%d outside 200x150 .. 10000x10000", title, W,
                         H);
    if ((unsigned)p->x_scale > MCP_AXIS_LOGIT || (unsigned)p->y_scale > MCP_AXIS_LOGIT)
        return mcp_error("plot '%s': unknown axis scale", title);
    double xlo = INFINITY, xhi = -INFINITY, ylo = INFINITY, yhi = -INFINITY;
    long shown = 0;
    for (int s = 0; s < p->n_series; s++)
        for (int i = 0; i < p->series[s].n; i++) {
            double x = p->series[s].x[i], y = p->series[s].y[i];
            if (!valid(p->x_scale, x) || !valid(p->y_scale, y)) continue;
            double fx = forward(p->x_scale, x), fy = forward(p->y_scale, y);
            xlo = fx < xlo ? fx : xlo;
            xhi = fx > xhi ? fx : xhi;
            ylo = fy < ylo ? fy : ylo;
            yhi = fy > yhi ? fy : yhi;
            shown++;
            if (p->series[s].style == MCP_SERIES_BARS && p->x_scale == MCP_AXIS_LINEAR) {
                /* the bars' full width, and on a linear y axis their foot at 0 */
                double half = 0.5 * bar_width(&p->series[s]);
                xlo = x - half < xlo ? x - half : xlo;
                xhi = x + half > xhi ? x + half : xhi;
                if (p->y_scale == MCP_AXIS_LINEAR) ylo = ylo > 0 ? 0 : ylo;
            }
        }
    if (!shown)
        return mcp_error("plot '%s': no points to show on %s/%s axes", title,
                         mcp_axis_scale_name(p->x_scale),
                         mcp_axis_scale_name(p->y_scale));

    const double right = 16, top = p->title ? 34 : 14, bottom = 48;
    axis ay = {p->y_scale, 0, 0, H - bottom, top};
    set_range(&ay, ylo, yhi);
    /* The left margin holds the y label and the widest y tick label (~7 px a
     * character at 12 px; logit ticks such as 0.99999999 are long). */
    tick t[MAX_TICKS];
    char label[64];
    size_t widest = 0;
    int nt = ticks(&ay, t);
    for (int i = 0; i < nt; i++) {
        if (!t[i].major) continue;
        tick_label(&ay, t[i].value, label, sizeof label);
        widest = strlen(label) > widest ? strlen(label) : widest;
    }
    const double left = 30 + 7.0 * (double)widest > 72 ? 30 + 7.0 * (double)widest : 72;
    axis ax = {p->x_scale, 0, 0, left, W - right};
    set_range(&ax, xlo, xhi);

    sbuf b = {0};
    mcp__strbuf_printf(
        &b,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 %d %d\" width=\"%d\" "
        "height=\"%d\" font-family=\"Helvetica, Arial, sans-serif\" font-size=\"12\">\n",
        W, H, W, H);
    mcp__strbuf_printf(&b, "<title>");
    mcp__strbuf_markup_text(&b, title);
    mcp__strbuf_printf(
        &b, "</title>\n<rect width=\"%d\" height=\"%d\" fill=\"white\"/>\n", W, H);
    if (p->title) {
        mcp__strbuf_printf(
            &b,
            "<text x=\"%.1f\" y=\"20\" text-anchor=\"middle\" font-size=\"14\" "
            "font-weight=\"bold\">",
            (left + W - right) / 2);
        mcp__strbuf_markup_text(&b, p->title);
        mcp__strbuf_printf(&b, "</text>\n");
    }
    /* Grid and tick labels. */
    nt = ticks(&ax, t);
    for (int i = 0; i < nt; i++) {
        double x = to_px(&ax, t[i].value);
        mcp__strbuf_printf(
            &b, "<line x1=\"%.2f\" y1=\"%.2f\" x2=\"%.2f\" y2=\"%.2f\" stroke=\"%s\"/>\n",
            x, ay.a1, x, ay.a0, t[i].major ? "#d0d0d0" : "#eeeeee");
        if (!t[i].major) continue;
        tick_label(&ax, t[i].value, label, sizeof label);
        mcp__strbuf_printf(
            &b, "<text x=\"%.2f\" y=\"%.2f\" text-anchor=\"middle\">%s</text>\n", x,
            ay.a0 + 16, label);
    }
    nt = ticks(&ay, t);
    for (int i = 0; i < nt; i++) {
        double y = to_px(&ay, t[i].value);
        mcp__strbuf_printf(
            &b, "<line x1=\"%.2f\" y1=\"%.2f\" x2=\"%.2f\" y2=\"%.2f\" stroke=\"%s\"/>\n",
            ax.a0, y, ax.a1, y, t[i].major ? "#d0d0d0" : "#eeeeee");
        if (!t[i].major) continue;
        tick_label(&ay, t[i].value, label, sizeof label);
        mcp__strbuf_printf(&b,
                           "<text x=\"%.2f\" y=\"%.2f\" text-anchor=\"end\">%s</text>\n",
                           ax.a0 - 6, y + 4, label);
    }
    mcp__strbuf_printf(
        &b,
        "<rect x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" height=\"%.2f\" fill=\"none\" "
        "stroke=\"#333\"/>\n",
        ax.a0, ay.a1, ax.a1 - ax.a0, ay.a0 - ay.a1);
    /* Axis labels. */
    if (p->x_label) {
        mcp__strbuf_printf(&b, "<text x=\"%.2f\" y=\"%d\" text-anchor=\"middle\">",
                           (ax.a0 + ax.a1) / 2, H - 10);
        mcp__strbuf_markup_text(&b, p->x_label);
        mcp__strbuf_printf(&b, "</text>\n");
    }
    if (p->y_label) {
        mcp__strbuf_printf(&b,
                           "<text transform=\"translate(16 %.2f) rotate(-90)\" "
                           "text-anchor=\"middle\">",
                           (ay.a0 + ay.a1) / 2);
        mcp__strbuf_markup_text(&b, p->y_label);
        mcp__strbuf_printf(&b, "</text>\n");
    }
    /* Series, clipped to the frame. Several plots share one HTML page and so one id
     * namespace: name the clip path by a hash of its geometry (plots with equal
     * names have equal frames), which keeps the output deterministic. */
    char clip_id[32];
    {
        double geo[6] = {ax.a0, ax.a1, ay.a0, ay.a1, (double)W, (double)H};
        uint64_t hsh = 1469598103934665603ull;
        const unsigned char *g = (const unsigned char *)geo;
        for (size_t i = 0; i < sizeof geo; i++)
            hsh = (hsh ^ g[i]) * 1099511628211ull;
        snprintf(clip_id, sizeof clip_id, "mcpclip%016llx", (unsigned long long)hsh);
    }
    mcp__strbuf_printf(&b,
                       "<clipPath id=\"%s\"><rect x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" "
                       "height=\"%.2f\"/></clipPath>\n<g clip-path=\"url(#%s)\">\n",
                       clip_id, ax.a0, ay.a1, ax.a1 - ax.a0, ay.a0 - ay.a1, clip_id);
    for (int s = 0; s < p->n_series; s++) {
        const mcp_plot_series *ps = &p->series[s];
        const char *colour = palette[s % 10];
        if (ps->style == MCP_SERIES_BARS) {
            double half = 0.5 * bar_width(ps);
            double foot = p->y_scale == MCP_AXIS_LINEAR ? to_px(&ay, 0.0) : ay.a0;
            mcp__strbuf_printf(&b,
                               "<g fill=\"%s\" fill-opacity=\"0.45\" stroke=\"%s\" "
                               "stroke-width=\"0.6\">\n",
                               colour, colour);
            for (int i = 0; i < ps->n; i++) {
                if (!valid(p->x_scale, ps->x[i]) || !valid(p->y_scale, ps->y[i]) ||
                    (p->y_scale == MCP_AXIS_LINEAR && ps->y[i] == 0))
                    continue;
                double x0 = to_px(&ax, ps->x[i] - half), x1 = to_px(&ax, ps->x[i] + half);
                double y = to_px(&ay, ps->y[i]);
                mcp__strbuf_printf(
                    &b, "<rect x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" height=\"%.2f\"/>\n",
                    x0, y < foot ? y : foot, x1 - x0, fabs(foot - y));
            }
            mcp__strbuf_printf(&b, "</g>\n");
            continue;
        }
        if (ps->style != MCP_SERIES_SCATTER) {
            mcp__strbuf_printf(
                &b, "<path fill=\"none\" stroke=\"%s\" stroke-width=\"1.8\"%s d=\"",
                colour, ps->dashed ? " stroke-dasharray=\"6 4\"" : "");
            int pen = 0;
            for (int i = 0; i < ps->n; i++) {
                if (!valid(p->x_scale, ps->x[i]) || !valid(p->y_scale, ps->y[i])) {
                    pen = 0;
                    continue;
                }
                mcp__strbuf_printf(&b, "%c%.2f %.2f ", pen ? 'L' : 'M',
                                   to_px(&ax, ps->x[i]), to_px(&ay, ps->y[i]));
                pen = 1;
            }
            mcp__strbuf_printf(&b, "\"/>\n");
        }
        if (ps->style != MCP_SERIES_LINE)
            for (int i = 0; i < ps->n; i++)
                if (valid(p->x_scale, ps->x[i]) && valid(p->y_scale, ps->y[i]))
                    mcp__strbuf_printf(
                        &b, "<circle cx=\"%.2f\" cy=\"%.2f\" r=\"3\" fill=\"%s\"/>\n",
                        to_px(&ax, ps->x[i]), to_px(&ay, ps->y[i]), colour);
    }
    mcp__strbuf_printf(&b, "</g>\n");
    /* Legend, inside the frame. */
    int named = 0;
    size_t longest = 0;
    for (int s = 0; s < p->n_series; s++)
        if (p->series[s].name && *p->series[s].name) {
            named++;
            size_t l = strlen(p->series[s].name);
            longest = l > longest ? l : longest;
        }
    if (named) {
        /* The corner whose legend box hides the fewest points (line segments are
         * sampled at their ends and midpoints). */
        double lw = 36 + 7.0 * (double)longest, lh = 8 + 16 * named;
        double cx[4] = {ax.a0 + 8, ax.a1 - 8 - lw, ax.a0 + 8, ax.a1 - 8 - lw};
        double cy[4] = {ay.a1 + 8, ay.a1 + 8, ay.a0 - 8 - lh, ay.a0 - 8 - lh};
        long hidden[4] = {0, 0, 0, 0};
        for (int s = 0; s < p->n_series; s++) {
            const mcp_plot_series *ps = &p->series[s];
            double px0 = NAN, py0 = NAN;
            for (int i = 0; i < ps->n; i++) {
                if (!valid(p->x_scale, ps->x[i]) || !valid(p->y_scale, ps->y[i])) {
                    px0 = NAN;
                    continue;
                }
                double px = to_px(&ax, ps->x[i]), py = to_px(&ay, ps->y[i]);
                for (int k = 0; k < 3; k++) {
                    double qx = px, qy = py;
                    if (k) { /* points along the segment from the previous point */
                        if (isnan(px0) || ps->style == MCP_SERIES_SCATTER) break;
                        qx = px0 + (px - px0) * k / 3.0;
                        qy = py0 + (py - py0) * k / 3.0;
                    }
                    for (int c = 0; c < 4; c++)
                        hidden[c] += qx >= cx[c] - 4 && qx <= cx[c] + lw + 4 &&
                                     qy >= cy[c] - 4 && qy <= cy[c] + lh + 4;
                }
                px0 = px;
                py0 = py;
            }
        }
        int best = 0;
        for (int c = 1; c < 4; c++)
            if (hidden[c] < hidden[best]) best = c;
        double lx = cx[best], ly = cy[best];
        mcp__strbuf_printf(
            &b,
            "<rect x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" height=\"%.0f\" fill=\"white\" "
            "fill-opacity=\"0.85\" stroke=\"#bbb\"/>\n",
            lx, ly, lw, lh);
        int row = 0;
        for (int s = 0; s < p->n_series; s++) {
            const mcp_plot_series *ps = &p->series[s];
            if (!ps->name || !*ps->name) continue;
            double y = ly + 14 + 16 * row++;
            const char *colour = palette[s % 10];
            if (ps->style == MCP_SERIES_BARS)
                mcp__strbuf_printf(
                    &b,
                    "<rect x=\"%.2f\" y=\"%.2f\" width=\"12\" height=\"9\" "
                    "fill=\"%s\" fill-opacity=\"0.45\" stroke=\"%s\"/>\n",
                    lx + 10, y - 9, colour, colour);
            else if (ps->style != MCP_SERIES_SCATTER)
                mcp__strbuf_printf(
                    &b,
                    "<line x1=\"%.2f\" y1=\"%.2f\" x2=\"%.2f\" y2=\"%.2f\" "
                    "stroke=\"%s\" stroke-width=\"1.8\"%s/>\n",
                    lx + 6, y - 4, lx + 26, y - 4, colour,
                    ps->dashed ? " stroke-dasharray=\"6 4\"" : "");
            if (ps->style != MCP_SERIES_LINE && ps->style != MCP_SERIES_BARS)
                mcp__strbuf_printf(
                    &b, "<circle cx=\"%.2f\" cy=\"%.2f\" r=\"3\" fill=\"%s\"/>\n",
                    lx + 16, y - 4, colour);
            mcp__strbuf_printf(&b, "<text x=\"%.2f\" y=\"%.2f\">", lx + 32, y);
            mcp__strbuf_markup_text(&b, ps->name);
            mcp__strbuf_printf(&b, "</text>\n");
        }
    }
    mcp__strbuf_printf(&b, "</svg>\n");
    if (b.failed) {
        free(b.s);
        return mcp_error("plot '%s': out of memory", title);
    }
    *svg = b.s;
    return 0;
}
