/* blend_run.c: a converging blend over a series, for `mcpost blend` and the `blend` job
 * stage alike (blend/blend.h; Denisova & Bocchi 2024): per member the blended image and
 * the weight map; with a reference MSE, relMSE and HDR-FLIP per spp of the noisy,
 * denoised, easy, curve, ideal and James-Stein images (the paper's Fig. 4) as tables
 * and plots in the report section. */
#include "internal.h"

#include <mcpost/tonemap.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The file name of path without folder and extension. */
static void
base_name(const char *path, char *out, size_t cap)
{
    const char *slash = strrchr(path, '/');
    snprintf(out, cap, "%s", slash ? slash + 1 : path);
    char *dot = strrchr(out, '.');
    if (dot && dot != out) *dot = '\0';
}

static int
write_member_image(mcp__blend_sink *s, const mcp_image *img, const char *base,
                   const char *what, cJSON *files)
{
    char name[700], path[4096 + 800];
    snprintf(name, sizeof name, "%s.%s.exr", base, what);
    snprintf(path, sizeof path, "%s/%s", s->dir, name);
    if (mcp_image_write(img, path, NULL)) return -1;
    cJSON_AddStringToObject(files, what, name);
    return 0;
}

static int
on_point(const mcp_blend_point *p, void *ctx)
{
    mcp__blend_sink *s = ctx;
    char base[512];
    base_name(p->source, base, sizeof base);
    snprintf(s->last_base, sizeof s->last_base, "%s", base);
    cJSON *m = cJSON_CreateObject();
    cJSON_AddItemToArray(s->members, m);
    cJSON_AddStringToObject(m, "source", p->source);
    cJSON_AddNumberToObject(m, "spp", p->row->spp);
    cJSON *files = cJSON_AddObjectToObject(m, "files");
    if (write_member_image(s, p->images[p->method], base, "blend", files) ||
        write_member_image(s, p->weights, base, "weights", files))
        return -1;
    if (s->all_images) {
        const mcp_blend_method more[] = {MCP_BLEND_DENOISED, MCP_BLEND_EASY,
                                         MCP_BLEND_JAMES_STEIN, MCP_BLEND_CURVES,
                                         MCP_BLEND_IDEAL};
        for (int i = 0; i < 5; i++)
            if (p->images[more[i]] && more[i] != p->method &&
                write_member_image(s, p->images[more[i]], base,
                                   mcp_blend_method_name(more[i]), files))
                return -1;
    }
    /* the last member's pictures go into the report, each with its linear values for
       the page's display controls: the blend's own file, the others written here
       unless all_images wrote them */
    if (p->index == p->count - 1) {
        const mcp_blend_method shown[] = {MCP_BLEND_NOISY, MCP_BLEND_DENOISED, p->method};
        for (int i = 0; i < 3; i++) {
            char name[700], path[4096 + 800];
            mcp_image *ldr = NULL;
            snprintf(name, sizeof name, "%s.%s.png", base,
                     mcp_blend_method_name(shown[i]));
            snprintf(path, sizeof path, "%s/%s", s->dir, name);
            int written = shown[i] == p->method ||
                          (s->all_images && shown[i] == MCP_BLEND_DENOISED);
            /* clamped and sRGB-encoded, as the PNG writer shows linear values */
            int rc =
                mcp_tonemap_apply(p->images[shown[i]], MCP_TONEMAP_CLAMP, &ldr) ||
                mcp_image_write(ldr, path, NULL) ||
                (!written && write_member_image(s, p->images[shown[i]], base,
                                                mcp_blend_method_name(shown[i]), files));
            mcp_image_free(ldr);
            if (rc) return -1;
        }
    }
    mcp_progress_update(&s->prog, p->index + 1);
    return 0;
}

/* Adds a table and a plot of one error per spp for every method. */
static int
add_error_figures(cJSON *section, const mcp_blend_series_result *r, const char *metric,
                  int which, const char *y_label)
{
    const char *cols[1 + MCP_BLEND_N_METHODS];
    cols[0] = "spp";
    for (int m = 0; m < MCP_BLEND_N_METHODS; m++)
        cols[1 + m] = mcp_blend_method_name(m);
    char title[128];
    snprintf(title, sizeof title, "%s against the reference per spp", metric);
    cJSON *table = mcp_report_add_table(section, title, cols, 1 + MCP_BLEND_N_METHODS);
    if (!table) return -1;
    int n = r->count;
    double *x = mcp_calloc((size_t)n * (1 + MCP_BLEND_N_METHODS), sizeof *x);
    if (!x) return -1;
    double *y = x + n;
    for (int i = 0; i < n; i++) {
        const mcp_blend_row *row = &r->rows[i];
        x[i] = row->spp;
        for (int m = 0; m < MCP_BLEND_N_METHODS; m++) {
            const mcp_blend_errors *e = &row->err[m];
            y[m * n + i] = which == 0 ? e->mse : which == 1 ? e->relmse : e->flip_hdr;
        }
        const double *v = &y[i];
        if (mcp_report_table_add_row(table, "ddddddd", x[i], v[0], v[n], v[2 * n],
                                     v[3 * n], v[4 * n], v[5 * n])) {
            free(x);
            return -1;
        }
    }
    snprintf(title, sizeof title,
             "%s against samples per pixel (Denisova & Bocchi Fig. 4)", metric);
    cJSON *plot =
        mcp_report_add_plot(section, title, "spp", MCP_AXIS_LOG, y_label, MCP_AXIS_LOG);
    int rc = plot ? 0 : -1;
    for (int m = 0; rc == 0 && m < MCP_BLEND_N_METHODS; m++) {
        cJSON *s = mcp_report_plot_add_series(plot, mcp_blend_method_name(m),
                                              MCP_SERIES_LINE_POINTS, x, y + m * n, n);
        /* the evaluation-only method is drawn dashed */
        if (!s || (m == MCP_BLEND_IDEAL && mcp_report_series_set_dashed(s, 1))) rc = -1;
    }
    free(x);
    return rc;
}

/* The blend section's verdict: with a reference, the blend's MSE (its method's) as a
 * multiple of the noisy image's at the last member, where it must be at most 1 for
 * the blend to converge, and at the member where the blend helps most. */
static int
blend_verdict(cJSON *section, const mcp_blend_series_result *r)
{
    const mcp_blend_row *last = &r->rows[r->count - 1];
    const mcp_blend_method m = r->method;
    if (!r->has_reference)
        return mcp_report_set_verdict(section, MCP_VERDICT_INFO,
                                      "blended %d members, %g to %g spp; without a "
                                      "reference there are no error figures to judge "
                                      "convergence by",
                                      r->count, r->rows[0].spp, last->spp);
    double fin = last->err[m].mse / last->err[MCP_BLEND_NOISY].mse,
           den = last->err[MCP_BLEND_DENOISED].mse / last->err[MCP_BLEND_NOISY].mse;
    int best = r->count - 1;
    for (int i = 0; i < r->count; i++)
        if (r->rows[i].err[m].mse / r->rows[i].err[MCP_BLEND_NOISY].mse <
            r->rows[best].err[m].mse / r->rows[best].err[MCP_BLEND_NOISY].mse)
            best = i;
    double best_ratio = r->rows[best].err[m].mse / r->rows[best].err[MCP_BLEND_NOISY].mse;
    int converges = fin <= 1.0;
    /* another blend with a lower MSE at the last member: say which and why it is not
     * the one used (the ideal weights need the reference: a bound, not a method) */
    char other[300] = "";
    int win = -1;
    for (int k = 0; k < MCP_BLEND_N_METHODS; k++)
        if (k != (int)m && k != MCP_BLEND_NOISY && k != MCP_BLEND_DENOISED &&
            last->err[k].mse < last->err[win < 0 ? (int)m : win].mse)
            win = k;
    if (win == MCP_BLEND_IDEAL)
        snprintf(other, sizeof other,
                 "; the %s weights reach %.3g\u00d7 of it, but they need the reference "
                 "(a bound, not a method)",
                 mcp_blend_method_name(win), last->err[win].mse / last->err[m].mse);
    else if (win >= 0)
        snprintf(other, sizeof other,
                 "; %s does better here (%.3g\u00d7 of it; weights: %s)",
                 mcp_blend_method_name(win), last->err[win].mse / last->err[m].mse,
                 mcp_blend_method_name(win));
    return mcp_report_set_verdict(
        section, converges ? MCP_VERDICT_GOOD : MCP_VERDICT_BAD,
        "blend (%s) %s: at %g spp %.3g\u00d7 the noisy MSE (denoised alone %.3g\u00d7); "
        "at "
        "best %.3g\u00d7 at %g spp%s",
        mcp_blend_method_name(m),
        converges ? "converges" : "does not beat the noisy image", last->spp, fin, den,
        best_ratio, r->rows[best].spp, other);
}

/* Fills a report section with the run's settings, per-member figures and, with a
 * reference, the comparison. */
static int
fill_section(cJSON *section, const mcp_blend_series_result *r,
             const mcp_blend_series_options *o, const char *denoiser, mcp__blend_sink *s)
{
    const mcp_blend_options *b = &o->blend;
    cJSON_AddStringToObject(section, "denoiser", denoiser);
    mcp__add_variance_source(section, r->variance_source, 0);
    cJSON_AddStringToObject(section, "weights", mcp_blend_weighting_name(b->weights));
    cJSON_AddStringToObject(section, "fit", mcp_curve_fit_name(b->fit));
    cJSON_AddStringToObject(section, "curve", mcp_curve_model_name(b->curve));
    cJSON_AddStringToObject(section, "filter", mcp_blend_filter_name(b->filter));
    cJSON_AddStringToObject(section, "negative_sure",
                            mcp_neg_sure_name(b->negative_sure));
    cJSON_AddNumberToObject(section, "far_spp", b->far_spp);
    cJSON_AddNumberToObject(section, "stop_denoising_at", o->stop_denoising_at);
    cJSON_AddNumberToObject(section, "members", r->count);
    cJSON_AddItemToObject(section, "files", s->members);
    s->members = NULL;
    cJSON *table = mcp_report_add_table(
        section, "members",
        (const char *const[]){"spp", "denoised at spp", "mean v", "mean SURE", "filtered",
                              "negative SURE", "mean W/(I+W)", "safeguard pulled back",
                              "self-influence"},
        9);
    if (!table) return -1;
    for (int i = 0; i < r->count; i++) {
        const mcp_blend_row *row = &r->rows[i];
        if (mcp_report_table_add_row(table, "ddddssddd", row->spp, row->denoised_spp,
                                     row->mean_var, row->mean_sure,
                                     row->filtered ? "yes" : "no",
                                     row->magnitude ? "magnitude" : "zero", row->mean_rho,
                                     row->safeguard_pulled, row->self_influence))
            return -1;
    }
    if (r->has_reference) {
        const mcp_blend_row *last = &r->rows[r->count - 1];
        cJSON *fin = cJSON_AddObjectToObject(section, "final");
        cJSON_AddNumberToObject(fin, "spp", last->spp);
        for (int m = 0; m < MCP_BLEND_N_METHODS; m++) {
            cJSON *e = cJSON_AddObjectToObject(fin, mcp_blend_method_name(m));
            cJSON_AddNumberToObject(e, "mse", last->err[m].mse);
            cJSON_AddNumberToObject(e, "relmse", last->err[m].relmse);
            if (r->has_flip)
                cJSON_AddNumberToObject(e, "flip_hdr", last->err[m].flip_hdr);
        }
        if (add_error_figures(section, r, "MSE", 0, "MSE") ||
            add_error_figures(section, r, "relMSE", 1, "relMSE") ||
            (r->has_flip &&
             add_error_figures(section, r, "HDR-FLIP", 2, "mean HDR-FLIP")))
            return -1;
    }
    if (blend_verdict(section, r)) return -1;
    /* the pictures on_point wrote, and their linear values: the blend's in its own
       file, NAME.blend.exr */
    const mcp_blend_method shown[] = {MCP_BLEND_NOISY, MCP_BLEND_DENOISED, r->method};
    for (int i = 0; i < 3; i++) {
        const char *name = mcp_blend_method_name(shown[i]);
        char rel[1400], rel_exr[1400], caption[700];
        snprintf(rel, sizeof rel, "%s%s.%s.png", s->rel, s->last_base, name);
        snprintf(rel_exr, sizeof rel_exr, "%s%s.%s.exr", s->rel, s->last_base,
                 shown[i] == r->method ? "blend" : name);
        snprintf(caption, sizeof caption, "%s at %g spp: %s", s->last_base,
                 r->rows[r->count - 1].spp, name);
        if (!mcp_report_add_hdr_image(section, rel, rel_exr, caption)) return -1;
    }
    return 0;
}

/* Runs the driver into the sink and fills section. */
int
mcp__blend_run(const mcp_series *series, const mcp_denoiser *den, const mcp_image *ref,
               const mcp_blend_series_options *o, const char *denoiser_name,
               mcp__blend_sink *s, cJSON *section)
{
    mcp_blend_series_result *r = NULL;
    s->members = cJSON_CreateArray();
    mcp_progress_begin(&s->prog, "blend", series->count);
    int rc = mcp_blend_series(series, den, ref, o, on_point, s, &r);
    if (rc == 0)
        mcp_progress_end(&s->prog);
    else
        mcp__progress_stop(&s->prog); /* no "100%" for a run that failed */
    if (!rc) rc = fill_section(section, r, o, denoiser_name, s);
    /* the curves are fitted to the variance: say when Variance/n does not track the
       series' own increments */
    double ratio = 0;
    if (!rc) rc = mcp_series_variance_ratio(series, &ratio);
    if (!rc)
        mcp__report_variance_ratio(
            ratio, r->variance_source == MCP_VARSRC_INCREMENTS,
            series->variance_from == MCP_SERIES_VARIANCE_INCREMENTS, section);
    cJSON_Delete(s->members);
    s->members = NULL;
    mcp_blend_series_result_free(r);
    return rc;
}
