/* adaptive_loop.c: the adaptive-sampling loop around a render command, for `mcpost
 * adaptive` and the `adaptive` job stage alike (estimate/estimate.h, mcp_adaptive_run;
 * Firmino 2023; docs/adaptive.md): each pass renders with a count map through /bin/sh,
 * and the loop writes the accumulated dump, the maps, adaptive.json and the curves. */
#define _POSIX_C_SOURCE 200809L /* access */

#include "internal.h"

#include <mcpost/filter.h>
#include <mcpost/plot.h>

#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static int
path_in(const mcp__adaptive_loop *c, char *buf, size_t cap, const char *fmt, int pass)
{
    char name[256];
    snprintf(name, sizeof name, fmt, pass);
    if (snprintf(buf, cap, "%s/%s", c->dir, name) >= (int)cap)
        return mcp_error("output path too long: %s/%s", c->dir, name);
    return 0;
}

/* The command line of one pass: {counts} and {output} become quoted paths, {pass} and
 * {seed} numbers; other text stays. *out is malloc'd. */
static int
command_line(const char *tmpl, const char *counts, const char *output, int pass,
             uint64_t seed, char **out)
{
    char pass_text[32], seed_text[32];
    snprintf(pass_text, sizeof pass_text, "%d", pass);
    snprintf(seed_text, sizeof seed_text, "%" PRIu64, seed);
    static const char *const names[4] = {"{counts}", "{output}", "{pass}", "{seed}"};
    const char *const values[4] = {counts, output, pass_text, seed_text};
    return mcp__shell_fill(tmpl, 4, names, values, 0x3, out);
}

/* The renderer: writes the counts, runs the command, reads what it wrote. */
static int
render_pass(int pass, const mcp_image *counts, mcp_dump **out, void *ctx)
{
    const mcp__adaptive_loop *c = ctx;
    char cpath[4352], opath[4352];
    char *line = NULL;
    *out = NULL;
    if (path_in(c, cpath, sizeof cpath, "pass_%04d_counts.exr", pass) ||
        path_in(c, opath, sizeof opath, "pass_%04d.exr", pass) ||
        mcp_image_write(counts, cpath, NULL) ||
        command_line(c->render, cpath, opath, pass, c->seed, &line))
        return -1;
    remove(opath); /* an old file must not pass for this pass's output */
    int rc = mcp__shell_check(mcp__shell(line), "the render command", c->render);
    if (rc == 0 && access(opath, F_OK))
        rc = mcp_error("the render command wrote no {output} file %s: %s", opath, line);
    if (rc == 0) rc = mcp_dump_read(opath, out);
    free(line);
    if (!c->keep_passes) {
        remove(cpath);
        if (!rc) remove(opath);
    }
    return rc;
}

/* A one-channel image as a false-colour PNG, scaled to its 99th percentile: a few
 * pixels far above the rest (a firefly's) would otherwise leave the picture black.
 * *top receives the value at the scale's top (the colour bar's end), *flat (may be
 * NULL) whether every pixel has one value (then *top is it). */
static int
write_png(const mcp__adaptive_loop *c, const mcp_image *img, const char *fmt, int pass,
          double *top, int *flat)
{
    char path[4352];
    const size_t n = (size_t)img->width * img->height;
    float sel[3]; /* the smallest, the 99th percentile and the largest */
    if (mcp__image_channel_spread(img, 0, 0.99, sel)) return -1;
    double hi = sel[1];
    if (!(hi > 0)) hi = sel[2];
    if (flat) *flat = sel[0] == sel[2];
    *top = flat && *flat ? sel[0] : hi > 0 ? hi : 1.0;
    unsigned char *rgb = mcp_malloc(n * 3);
    int rc =
        !rgb || path_in(c, path, sizeof path, fmt, pass) ||
        mcp_colormap_apply(img, 0, 0.0, hi > 0 ? hi : 1.0, MCP_COLORMAP_INFERNO, rgb) ||
        mcp_write_rgb8(rgb, img->width, img->height, path);
    free(rgb);
    return rc ? -1 : 0;
}

static int
on_iteration(const mcp_adaptive_state *st, void *ctx)
{
    mcp__adaptive_loop *c = ctx;
    const mcp_adaptive_iteration *it = st->it;
    c->prev_map_hi = c->map_hi;
    if (write_png(c, st->counts, "maps/counts_%04d.png", it->pass, &c->counts_hi,
                  &c->counts_flat) ||
        (c->ao.map != MCP_ADAPTIVE_UNIFORM &&
         write_png(c, st->est->sampling_map, "maps/sampling_map_%04d.png", it->pass,
                   &c->map_hi, NULL)))
        return -1;
    char rel[64] = "";
    if (c->reference) snprintf(rel, sizeof rel, ", relMSE %.4g", it->relmse);
    mcp_note("pass %d: %.1f spp in all%s, estimated error %.4g, F(tau) %.4f "
             "(render %.0f ms, denoise %.0f ms, mcpost %.0f ms)",
             it->pass, it->mean_spp, rel, it->est_error, it->cdf_at_tau, it->ms_render,
             it->ms_denoise, it->ms_merge + it->ms_estimate + it->ms_counts);
    return 0;
}

static const char *const stop_words[] = {"budget", "estimate", "max_iterations"};

static cJSON *
result_json(const mcp__adaptive_loop *c, const mcp_adaptive_result *r)
{
    cJSON *j = cJSON_CreateObject();
    cJSON_AddStringToObject(j, "map", mcp_adaptive_map_name(c->ao.map));
    cJSON_AddStringToObject(j, "denoiser", c->den->name);
    cJSON_AddStringToObject(j, "render", c->render);
    cJSON_AddNumberToObject(j, "width", c->width);
    cJSON_AddNumberToObject(j, "height", c->height);
    cJSON_AddNumberToObject(j, "spp_per_iteration", c->ao.spp_per_iteration);
    if (c->ao.budget_spp > 0) cJSON_AddNumberToObject(j, "budget", c->ao.budget_spp);
    cJSON_AddStringToObject(j, "stopped_by", stop_words[r->stopped_by]);
    cJSON *its = cJSON_AddArrayToObject(j, "iterations");
    for (int i = 0; i < r->count; i++) {
        const mcp_adaptive_iteration *it = &r->iterations[i];
        cJSON *o = cJSON_CreateObject();
        cJSON_AddNumberToObject(o, "pass", it->pass);
        cJSON_AddNumberToObject(o, "samples", (double)it->samples);
        cJSON_AddNumberToObject(o, "total_samples", (double)it->total_samples);
        cJSON_AddNumberToObject(o, "mean_spp", it->mean_spp);
        cJSON_AddNumberToObject(o, "estimated_error", it->est_error);
        cJSON_AddNumberToObject(o, "cdf_at_tau", it->cdf_at_tau);
        cJSON_AddBoolToObject(o, "stop", it->stop);
        if (!isnan(it->relmse)) {
            cJSON_AddNumberToObject(o, "relmse", it->relmse);
            cJSON_AddNumberToObject(o, "relmse_noisy", it->relmse_noisy);
        }
        cJSON *t = cJSON_AddObjectToObject(o, "ms");
        cJSON_AddNumberToObject(t, "render", it->ms_render);
        cJSON_AddNumberToObject(t, "merge", it->ms_merge);
        cJSON_AddNumberToObject(t, "denoise", it->ms_denoise);
        cJSON_AddNumberToObject(t, "estimate", it->ms_estimate);
        cJSON_AddNumberToObject(t, "counts", it->ms_counts);
        cJSON_AddItemToArray(its, o);
    }
    return j;
}

static int
write_text(const mcp__adaptive_loop *c, const char *name, const char *text)
{
    char path[4352];
    if (path_in(c, path, sizeof path, name, 0)) return -1;
    return mcp_write_file_atomic(path, text, strlen(text));
}

/* adaptive.csv, adaptive.svg, and the job report's table and plot. */
static int
write_curves(const mcp__adaptive_loop *c, const mcp_adaptive_result *r)
{
    int n = r->count, rc = -1;
    double *x = mcp_calloc((size_t)n, sizeof *x),
           *rel = mcp_calloc((size_t)n, sizeof *rel),
           *est = mcp_calloc((size_t)n, sizeof *est);
    char *csv = mcp_malloc((size_t)n * 160 + 160), *svg = NULL;
    if (!x || !rel || !est || !csv) goto done;
    size_t len =
        (size_t)sprintf(csv, "pass,mean_spp,total_samples,relmse,relmse_noisy,"
                             "estimated_error,cdf_at_tau,ms_denoise,ms_mcpost\n");
    for (int i = 0; i < n; i++) {
        const mcp_adaptive_iteration *it = &r->iterations[i];
        x[i] = it->mean_spp;
        rel[i] = it->relmse;
        est[i] = it->est_error;
        len += (size_t)sprintf(
            csv + len, "%d,%.6g,%" PRId64 ",%.6g,%.6g,%.6g,%.6g,%.1f,%.1f\n", it->pass,
            it->mean_spp, it->total_samples, it->relmse, it->relmse_noisy, it->est_error,
            it->cdf_at_tau, it->ms_denoise,
            it->ms_merge + it->ms_estimate + it->ms_counts);
    }
    mcp_plot_series s[2] = {
        {"relMSE (denoised vs reference)", MCP_SERIES_LINE_POINTS, x, rel, n, 0},
        {"estimated error (mean s^2 (lambda + 1))", MCP_SERIES_LINE_POINTS, x, est, n,
         1}};
    int has_ref = c->reference != NULL;
    mcp_plot plot = {"adaptive sampling: error against samples",
                     "samples per pixel",
                     "error",
                     MCP_AXIS_LOG,
                     MCP_AXIS_LOG,
                     has_ref ? s : s + 1,
                     has_ref ? 2 : 1,
                     0,
                     0};
    if (write_text(c, "adaptive.csv", csv) || mcp_plot_svg(&plot, &svg) ||
        write_text(c, "adaptive.svg", svg))
        goto done;
    if (c->section) {
        static const char *const cols[] = {
            "pass", "spp", "relMSE", "relMSE noisy", "estimated error", "F(tau)"};
        cJSON *t = mcp_report_add_table(c->section, "per pass", cols, 6);
        for (int i = 0; t && i < n; i++)
            if (mcp_report_table_add_row(t, "iddddd", r->iterations[i].pass, x[i], rel[i],
                                         r->iterations[i].relmse_noisy, est[i],
                                         r->iterations[i].cdf_at_tau))
                goto done;
        cJSON *p = mcp_report_add_plot(c->section, plot.title, plot.x_label, MCP_AXIS_LOG,
                                       plot.y_label, MCP_AXIS_LOG);
        cJSON *se = p ? mcp_report_plot_add_series(p, s[1].name, MCP_SERIES_LINE_POINTS,
                                                   x, est, n)
                      : NULL;
        if (!t || !p || !se || mcp_report_series_set_dashed(se, 1) ||
            (has_ref && !mcp_report_plot_add_series(p, s[0].name, MCP_SERIES_LINE_POINTS,
                                                    x, rel, n)))
            goto done;
        char relp[512];
        snprintf(relp, sizeof relp, "%smaps/counts_%04d.png", c->rel, n - 1);
        /* the colours run from 0 to the 99th percentile (write_png); one value for
           every pixel would be a flat square, so the section says the value instead */
        if (c->counts_flat) {
            char text[128];
            snprintf(text, sizeof text, "%g in every pixel (one value: no map to show)",
                     c->counts_hi);
            if (!cJSON_AddStringToObject(c->section, "last_pass_samples", text))
                goto done;
        } else if (!mcp_report_add_map(
                       c->section, relp, "the last pass's sample counts",
                       MCP_COLORMAP_INFERNO, 0.0, c->counts_hi, MCP_AXIS_LINEAR,
                       "samples per pixel in the pass (brightest: its 99th "
                       "percentile and above)"))
            goto done;
        if (n > 1 && c->ao.map != MCP_ADAPTIVE_UNIFORM) {
            /* the map's weights sum to 1: shown as multiples of the mean weight */
            double mean = 1.0 / ((double)c->width * c->height);
            snprintf(relp, sizeof relp, "%smaps/sampling_map_%04d.png", c->rel, n - 2);
            if (!mcp_report_add_map(c->section, relp, "the sampling map it came from",
                                    MCP_COLORMAP_INFERNO, 0.0, c->prev_map_hi / mean,
                                    MCP_AXIS_LINEAR,
                                    "sample density, times the image's mean (brightest: "
                                    "the 99th percentile and above)"))
                goto done;
        }
    }
    rc = 0;
done:
    free(x);
    free(rel);
    free(est);
    free(csv);
    free(svg);
    return rc;
}

/* The section's verdict: where the loop stopped and what the estimate says of the
 * result -- good when F(tau) >= p (the error is below tau for the share p of the
 * values asked for), information otherwise, with the true relMSE when there is a
 * reference. */
static int
adaptive_verdict(const mcp__adaptive_loop *c, const mcp_adaptive_result *r)
{
    const mcp_adaptive_iteration *last = &r->iterations[r->count - 1];
    double tau = c->ao.est.tau, p = c->ao.est.p;
    int reached = last->cdf_at_tau >= p;
    char truth[96] = "";
    if (c->reference)
        snprintf(truth, sizeof truth, "; relMSE %.3g against the reference",
                 last->relmse);
    return mcp_report_set_verdict(
        c->section, reached ? MCP_VERDICT_GOOD : MCP_VERDICT_INFO,
        "%.1f spp in %d passes, stopped by the %s: F(tau = %g) = %.3f %s p = %g, %s%s",
        last->mean_spp, r->count, stop_words[r->stopped_by], tau, last->cdf_at_tau,
        reached ? ">=" : "<", p,
        reached ? "the estimate says the image is done" : "more samples would still help",
        truth);
}

/* Runs the loop and writes every output; *json (may be NULL) receives the figures. */
int
mcp__adaptive_run_loop(mcp__adaptive_loop *c, cJSON **json)
{
    mcp_adaptive_result *r = NULL;
    char sub[4352], path[4352];
    int rc = -1;
    if (!strstr(c->render, "{counts}") || !strstr(c->render, "{output}"))
        return mcp_error("the render command '%s' must name {counts} and {output}",
                         c->render);
    if (snprintf(sub, sizeof sub, "%s/maps", c->dir) >= (int)sizeof sub)
        return mcp_error("output path too long: %s", c->dir);
    if (mcp_make_dirs(sub)) return -1;
    if (mcp_adaptive_run(c->width, c->height, c->den, &c->ao, render_pass, c,
                         c->reference, on_iteration, c, &r))
        return -1;
    cJSON *j = result_json(c, r);
    char *text = j ? cJSON_Print(j) : NULL;
    if (!text || path_in(c, path, sizeof path, "accumulated.exr", 0) ||
        mcp_dump_write(r->accumulated, path, MCP_CONV_MCPOST, NULL) ||
        path_in(c, path, sizeof path, "denoised.exr", 0) ||
        mcp_image_write(r->denoised, path, NULL) ||
        write_text(c, "adaptive.json", text) || write_curves(c, r) ||
        (c->section && adaptive_verdict(c, r)))
        goto done;
    if (c->section) {
        /* the page shows the settings and the per-pass table (write_curves); the
           whole result, timings included, is for report.json, which owns it now */
        if (!cJSON_AddStringToObject(c->section, "map",
                                     mcp_adaptive_map_name(c->ao.map)) ||
            !cJSON_AddStringToObject(c->section, "denoiser", c->den->name) ||
            !cJSON_AddStringToObject(c->section, "render", c->render) ||
            mcp_report_json_only(c->section, "adaptive")) {
            mcp_error("out of memory");
            goto done;
        }
        cJSON_AddItemToObject(c->section, "adaptive", j);
        j = NULL;
    }
    const mcp_adaptive_iteration *last = &r->iterations[r->count - 1];
    mcp_note("%d passes, %.1f spp in all, stopped by the %s%s", r->count, last->mean_spp,
             stop_words[r->stopped_by],
             r->stopped_by == MCP_ADAPTIVE_STOP_ESTIMATE ? " (F(tau) >= p)" : "");
    rc = 0;
done:
    free(text);
    if (!rc && json)
        *json = j;
    else
        cJSON_Delete(j);
    mcp_adaptive_result_free(r);
    return rc;
}

int
mcp__parse_size(const char *text, int *w, int *h)
{
    char tail;
    if (!text || sscanf(text, "%dx%d%c", w, h, &tail) != 2 || *w < 1 || *h < 1)
        return mcp_error("--size must be WIDTHxHEIGHT, e.g. 128x128 (got '%s')",
                         text ? text : "");
    return 0;
}
