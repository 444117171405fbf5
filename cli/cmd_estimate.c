/* cmd_estimate.c: `mcpost estimate` and the `estimate` job stage -- how wrong a denoised
 * render is and whether to stop (estimate/estimate.h; SPEC "estimate").
 *
 * One dump: the denoised image, SURE, variance, sampling map and counts, the blocks,
 * the error distribution, and the decision F(τ) >= p with the estimated percentiles,
 * written to a folder with estimate.json and a report. A series (several dumps, or a
 * pattern with --spp): the first spp at which each τ is reached and, with a reference,
 * the true one beside it (Firmino 2024 Table 1) with the estimated and true percentile
 * curves. Flags and job keys are the same words (--denoiser-opt is the denoiser map in
 * a job). */
#include "cli.h"

#include <mcpost/estimate.h>
#include <mcpost/progress.h>

#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define EXIT_CONTINUE 10 /* --exit-status: keep rendering */

/* ---- helpers shared by the subcommand and the stage ---- */

static int
parse_list(const char *flag, const char *text, double *out, int max, int *n)
{
    char **words = NULL;
    int count = 0, rc = 0;
    if (mcp_cli_split(text, &words, &count)) return -1;
    if (count < 1 || count > max)
        rc = mcp_error("%s: needs 1 to %d values (got %d)", flag, max, count);
    for (int i = 0; i < count && !rc; i++)
        rc = mcp_cli_double(flag, words[i], &out[i]);
    mcp_cli_free_words(words, count);
    if (!rc) *n = count;
    return rc;
}

static int
parse_int_list(const char *flag, const char *text, int **out, int *n)
{
    char **words = NULL;
    int count = 0, rc = 0;
    if (mcp_cli_split(text, &words, &count)) return -1;
    int *v = mcp_calloc((size_t)(count ? count : 1), sizeof *v);
    rc = v ? 0 : -1;
    for (int i = 0; i < count && !rc; i++) {
        rc = mcp_cli_int(flag, words[i], &v[i]);
        if (!rc && v[i] < 1)
            rc = mcp_error("%s: sample counts must be >= 1 (got %d)", flag, v[i]);
    }
    mcp_cli_free_words(words, count);
    if (rc) {
        free(v);
        return -1;
    }
    *out = v;
    *n = count;
    return 0;
}

/* Where outputs go: a folder and a prefix for report paths ("" or "estimate/"). */
typedef struct out_dir {
    char dir[4096];
    char rel[256];
} out_dir;

static int
out_path(const out_dir *o, const char *name, char *buf, size_t cap)
{
    if (snprintf(buf, cap, "%s/%s", o->dir, name) >= (int)cap)
        return mcp_error("output path too long: %s/%s", o->dir, name);
    return 0;
}

/* ---- one dump ---- */

static cJSON *
estimate_json(const mcp_estimate *e, const char *input, const char *denoiser,
              const mcp_estimate_options *o)
{
    cJSON *j = cJSON_CreateObject();
    cJSON_AddStringToObject(j, "input", input);
    cJSON_AddStringToObject(j, "denoiser", denoiser);
    cJSON_AddStringToObject(j, "metric", mcp_error_metric_name(o->sure.metric));
    cJSON_AddNumberToObject(j, "tau", e->tau);
    cJSON_AddNumberToObject(j, "p", e->p);
    cJSON_AddNumberToObject(j, "cdf_at_tau", e->cdf_at_tau);
    cJSON_AddBoolToObject(j, "stop", e->stop);
    if (e->no_variance)
        cJSON_AddStringToObject(j, "warning",
                                "the dump has no variance (1 spp?): no estimate, "
                                "stop forced to false");
    mcp_cli_add_variance_source(j, e->variance_source, e->variance_dof);
    cJSON_AddNumberToObject(j, "s2_pool", e->s2_pool);
    cJSON *pct = cJSON_AddArrayToObject(j, "percentiles");
    for (int k = 0; k < e->n_percentiles; k++) {
        cJSON *item = cJSON_CreateObject();
        cJSON_AddNumberToObject(item, "p", e->percentiles[k]);
        if (isfinite(e->percentile_tau[k]))
            cJSON_AddNumberToObject(item, "error", e->percentile_tau[k]);
        else
            cJSON_AddStringToObject(item, "error", "inf");
        cJSON_AddItemToArray(pct, item);
    }
    cJSON_AddNumberToObject(j, "blocks", e->blocks->count);
    cJSON_AddNumberToObject(j, "expected_mean_error", mcp_error_dist_mean(e->dist));
    /* the distribution parameters in brief (every value: distribution.exr) */
    double lambda = 0.0, s2 = 0.0, n = (double)e->blocks->width * e->blocks->height * 3;
    for (int i = 0; i < e->blocks->count; i++) {
        const mcp_block *k = &e->blocks->items[i];
        for (int c = 0; c < 3; c++) {
            lambda += mcp_error_dist_lambda(e->dist, i, c) * k->w * k->h;
            s2 += k->var_sum[c];
        }
    }
    cJSON *dist = cJSON_AddObjectToObject(j, "distribution");
    cJSON_AddNumberToObject(dist, "mean_lambda", lambda / n);
    cJSON_AddNumberToObject(dist, "mean_s2", s2 / n);
    cJSON_AddStringToObject(dist, "file", "distribution.exr (lambda.R/G/B, s2.R/G/B)");
    cJSON_AddNumberToObject(j, "probes", o->sure.n_probes);
    cJSON_AddNumberToObject(j, "seed", (double)o->sure.seed);
    cJSON_AddBoolToObject(j, "mc_sure", o->sure.mc_sure);
    cJSON_AddStringToObject(j, "sampling", mcp_sampling_kind_name(o->sampling.kind));
    if (o->budget > 0) cJSON_AddNumberToObject(j, "budget", (double)o->budget);
    cJSON *t = cJSON_AddObjectToObject(j, "time_ms");
    cJSON_AddNumberToObject(t, "denoise_and_jvp", e->ms_denoise);
    cJSON_AddNumberToObject(t, "sure_and_variance", e->ms_error_terms);
    cJSON_AddNumberToObject(t, "block_averaging", e->ms_blocks);
    cJSON_AddNumberToObject(t, "stopping", e->ms_stopping);
    cJSON_AddNumberToObject(t, "percentiles", e->ms_percentiles);
    cJSON_AddNumberToObject(t, "sampling_map", e->ms_sampling);
    return j;
}

/* The report's block picture: the error each pixel is expected to have under the
 * model that F(tau) comes from, s²(λ + 1) (mean of R, G, B; log10 from -5 to 0 in
 * inferno, like the metrics' RelSE map), with the block edges in white. Unlike
 * blocks.png, whose colours only tell blocks apart, its colour bar reads as a value,
 * and a single block still shows where the error is: s² varies per pixel. */
static int
blocks_error_picture(const mcp_blocks *blocks, const mcp_image *dist,
                     unsigned char *rgb8)
{
    int w = blocks->width, h = blocks->height, ch[6];
    int32_t *label = NULL;
    mcp_image *lg = NULL;
    if (mcp_image_channels(dist,
                           (const char *[]){"lambda.R", "lambda.G", "lambda.B", "s2.R",
                                            "s2.G", "s2.B"},
                           6, ch) ||
        mcp_blocks_label(blocks, &label) ||
        mcp_image_new(w, h, 1, (const char *const[]){"log10_error"}, &lg)) {
        free(label);
        return -1;
    }
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *p = mcp_image_px(dist, x, y);
            double mean = 0;
            for (int c = 0; c < 3; c++)
                mean += p[ch[3 + c]] * (p[ch[c]] + 1.0) / 3.0;
            mcp_image_px(lg, x, y)[0] = (float)(mean > 1e-30 ? log10(mean) : -30.0);
        }
    int rc = mcp_colormap_apply(lg, 0, -5.0, 0.0, MCP_COLORMAP_INFERNO, rgb8);
#pragma omp parallel for schedule(static) if (!rc)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            if ((x + 1 < w && label[i] != label[i + 1]) ||
                (y + 1 < h && label[i] != label[i + w]))
                memset(rgb8 + 3 * i, 255, 3);
        }
    mcp_image_free(lg);
    free(label);
    return rc;
}

/* Every image of one estimate, the block pictures, and their place in the report.
 * The pictures are made first and every file is then written at once, a file per
 * thread (mcp_write_files), the costliest first: distribution.exr (its six channels
 * halve under zip), the error picture's PNG, then the maps, which are stored raw. */
static int
write_single(const mcp_estimate *e, const out_dir *o, cJSON *section,
             const cJSON *summary)
{
    enum { MAX_FILES = 12 };
    mcp_image *block_mean = NULL, *dist = NULL;
    unsigned char *blocks_rgb = NULL, *error_rgb = NULL;
    char (*paths)[4352] = NULL;
    int rc = -1, n = 0, w = e->blocks->width, h = e->blocks->height;
    if (mcp_make_dirs(o->dir) ||
        mcp_blocks_mean_image(e->blocks, e->maps.sure_rel, &block_mean) ||
        mcp_error_dist_image(e->dist, &dist) ||
        !(paths = mcp_malloc(MAX_FILES * sizeof *paths)) ||
        !(blocks_rgb = mcp_malloc((size_t)w * h * 3)) ||
        mcp_blocks_picture(e->blocks, blocks_rgb))
        goto done;
    if (section && (!(error_rgb = mcp_malloc((size_t)w * h * 3)) ||
                    blocks_error_picture(e->blocks, dist, error_rgb)))
        goto done;
    const struct {
        const char *name;
        const mcp_image *image;
        const unsigned char *rgb8;
    } outputs[MAX_FILES] = {
        {"distribution.exr", dist, NULL},
        {"blocks_error.png", NULL, error_rgb},
        {"denoised.exr", e->maps.denoised, NULL},
        {"sure.exr", e->maps.sure, NULL},
        {"sure_rel.exr", e->maps.sure_rel, NULL},
        {"variance.exr", e->maps.var, NULL},
        {"variance_rel.exr", e->maps.var_rel, NULL},
        {"sampling_map.exr", e->sampling_map, NULL},
        {"sample_counts.exr", e->sample_counts, NULL},
        {"blocks_sure_rel.exr", block_mean, NULL},
        {"blocks.png", NULL, blocks_rgb},
    };
    mcp_file_write files[MAX_FILES];
    for (int i = 0; i < MAX_FILES; i++) {
        if (!outputs[i].image && !outputs[i].rgb8) continue; /* none, or not asked for */
        if (out_path(o, outputs[i].name, paths[n], sizeof *paths)) goto done;
        files[n] = (mcp_file_write){.path = paths[n], .image = outputs[i].image,
                                    .rgb8 = outputs[i].rgb8, .width = w, .height = h};
        n++;
    }
    if (mcp_write_files(files, n)) goto done;
    if (section) {
        char caption[256], unit[256], rel[512];
        const cJSON *mj = cJSON_GetObjectItem(summary, "metric");
        const char *metric = cJSON_IsString(mj) ? mj->valuestring : "error";
        if (e->blocks->count == 1)
            snprintf(caption, sizeof caption,
                     "expected %s per pixel; 1 block: Firmino 2024 Alg. 1 found no "
                     "split that passes its test, so one SURE mean covers the image",
                     metric);
        else
            snprintf(caption, sizeof caption,
                     "expected %s per pixel; %d blocks (Firmino 2024 Alg. 1), edges in "
                     "white",
                     metric, e->blocks->count);
        snprintf(unit, sizeof unit,
                 "the model's expected error s\u00b2(\u03bb + 1), mean of R, G, B, log "
                 "scale; F(tau) averages each pixel's chance to be below tau");
        snprintf(rel, sizeof rel, "%sblocks_error.png", o->rel);
        cJSON *map = mcp_report_add_map(section, rel, caption, MCP_COLORMAP_INFERNO, 1e-5,
                                        1.0, MCP_AXIS_LOG, unit);
        if (!map || mcp_report_map_add_mark(map, e->tau, "tau")) goto done;
    }
    rc = 0;
done:
    free(error_rgb);
    free(blocks_rgb);
    free(paths);
    mcp_image_free(block_mean);
    mcp_image_free(dist);
    return rc;
}

/* The report section of one estimate: key figures, the percentile table and curve. */
static int
report_single(cJSON *section, const cJSON *summary, const mcp_estimate *e)
{
    const char *keys[] = {"input", "denoiser", "metric",
                          "tau",   "p",        "cdf_at_tau",
                          "stop",  "blocks",   "expected_mean_error"};
    for (size_t i = 0; i < sizeof keys / sizeof *keys; i++) {
        const cJSON *v = cJSON_GetObjectItem(summary, keys[i]);
        if (v) cJSON_AddItemToObject(section, keys[i], cJSON_Duplicate(v, 1));
    }
    const cJSON *mj = cJSON_GetObjectItem(summary, "metric");
    const char *metric = cJSON_IsString(mj) ? mj->valuestring : "error";
    int rc;
    if (e->no_variance)
        rc = mcp_report_set_verdict(section, MCP_VERDICT_BAD,
                                    "no estimate: the dump's variance is 0 everywhere "
                                    "(e.g. 1 spp), so the model cannot see any error");
    else
        rc = mcp_report_set_verdict(
            section, e->stop ? MCP_VERDICT_GOOD : MCP_VERDICT_INFO,
            "stop: %s, %.4g%% of the estimated %s values below tau = %g (%.4g%% "
            "needed)%s; expected mean error %.3g",
            e->stop ? "yes" : "no", 100 * e->cdf_at_tau, metric, e->tau, 100 * e->p,
            e->stop ? "" : ": render more samples", mcp_error_dist_mean(e->dist));
    if (rc) return -1;
    const char *cols[] = {"percentile", "estimated error"};
    cJSON *t = mcp_report_add_table(section, "estimated error percentiles", cols, 2);
    if (!t) return -1;
    for (int k = 0; k < e->n_percentiles; k++)
        if (mcp_report_table_add_row(t, "dd", e->percentiles[k], e->percentile_tau[k]))
            return -1;
    cJSON *plot =
        mcp_report_add_plot(section, "estimated error percentiles", "percentile",
                            MCP_AXIS_LOGIT, "error", MCP_AXIS_LOG);
    if (!plot ||
        !mcp_report_plot_add_series(plot, "estimated", MCP_SERIES_LINE_POINTS,
                                    e->percentiles, e->percentile_tau, e->n_percentiles))
        return -1;
    return 0;
}

static void
print_single(const mcp_estimate *e, const char *input, const char *denoiser,
             const mcp_estimate_options *o)
{
    printf("input:       %s\n", input);
    printf("denoiser:    %s\n", denoiser);
    printf("metric:      %s, tau %g, p %g\n", mcp_error_metric_name(o->sure.metric),
           e->tau, e->p);
    printf("F(tau):      %.6f -> %s%s\n", e->cdf_at_tau, e->stop ? "stop" : "continue",
           e->no_variance ? " (the dump has no variance: no estimate)" : "");
    printf("blocks:      %d\n", e->blocks->count);
    printf("variance:    %s\n", mcp_cli_variance_source_words(e->variance_source));
    printf("estimated error at percentile:\n");
    for (int k = 0; k < e->n_percentiles; k++)
        printf("  %-10g %.6g\n", e->percentiles[k], e->percentile_tau[k]);
    printf(
        "time (ms):   denoise+jvp %.1f, SURE+variance %.1f, blocks %.1f, stopping %.1f, "
        "percentiles %.1f, sampling map %.1f\n",
        e->ms_denoise, e->ms_error_terms, e->ms_blocks, e->ms_stopping, e->ms_percentiles,
        e->ms_sampling);
}

/* ---- a series ---- */

static cJSON *
series_json(const mcp_series_estimate *s, const char *denoiser, mcp_error_metric metric)
{
    cJSON *j = cJSON_CreateObject();
    cJSON_AddStringToObject(j, "denoiser", denoiser);
    cJSON_AddStringToObject(j, "metric", mcp_error_metric_name(metric));
    cJSON_AddNumberToObject(j, "p", s->p);
    cJSON_AddBoolToObject(j, "reference", s->has_reference);
    mcp_cli_add_variance_source(j, s->variance_source, 0);
    cJSON *taus = cJSON_AddArrayToObject(j, "taus");
    int agree = 0;
    for (int t = 0; t < s->n_taus; t++) {
        cJSON *o = cJSON_CreateObject();
        cJSON_AddNumberToObject(o, "tau", s->taus[t]);
        if (s->first_spp[t] > 0)
            cJSON_AddNumberToObject(o, "first_spp", s->first_spp[t]);
        else
            cJSON_AddNullToObject(o, "first_spp");
        if (s->has_reference) {
            if (s->true_first_spp[t] > 0)
                cJSON_AddNumberToObject(o, "true_first_spp", s->true_first_spp[t]);
            else
                cJSON_AddNullToObject(o, "true_first_spp");
            cJSON_AddBoolToObject(o, "agree", s->agree[t]);
            agree += s->agree[t];
        }
        cJSON_AddItemToArray(taus, o);
    }
    if (s->has_reference)
        cJSON_AddNumberToObject(j, "agreement_rate", (double)agree / s->n_taus);
    cJSON *members = cJSON_AddArrayToObject(j, "members");
    for (int i = 0; i < s->count; i++) {
        const mcp_series_point *pt = &s->points[i];
        cJSON *m = cJSON_CreateObject();
        cJSON_AddNumberToObject(m, "spp", pt->spp);
        cJSON *cdf = cJSON_AddArrayToObject(m, "cdf"),
              *stop = cJSON_AddArrayToObject(m, "stop");
        for (int t = 0; t < s->n_taus; t++) {
            cJSON_AddItemToArray(cdf, cJSON_CreateNumber(pt->cdf[t]));
            cJSON_AddItemToArray(stop, cJSON_CreateBool(pt->stop[t]));
        }
        cJSON *ep = cJSON_AddArrayToObject(m, "estimated_percentiles");
        for (int k = 0; k < s->n_percentiles; k++)
            cJSON_AddItemToArray(ep, cJSON_CreateNumber(isfinite(pt->est_percentile[k])
                                                            ? pt->est_percentile[k]
                                                            : -1));
        cJSON_AddNumberToObject(m, "expected_mean_error", pt->est_mean_error);
        if (s->has_reference) {
            cJSON *tc = cJSON_AddArrayToObject(m, "true_cdf");
            for (int t = 0; t < s->n_taus; t++)
                cJSON_AddItemToArray(tc, cJSON_CreateNumber(pt->true_cdf[t]));
            cJSON *tp = cJSON_AddArrayToObject(m, "true_percentiles");
            for (int k = 0; k < s->n_percentiles; k++)
                cJSON_AddItemToArray(tp, cJSON_CreateNumber(pt->true_percentile[k]));
            cJSON_AddNumberToObject(m, "true_mean_error", pt->true_mean_error);
        }
        cJSON_AddItemToArray(members, m);
    }
    cJSON *pct = cJSON_AddArrayToObject(j, "percentiles");
    for (int k = 0; k < s->n_percentiles; k++)
        cJSON_AddItemToArray(pct, cJSON_CreateNumber(s->percentiles[k]));
    return j;
}

static int
report_series(cJSON *section, const mcp_series_estimate *s)
{
    const char *cols[] = {"tau", "estimated first spp", "true first spp", "agree"};
    cJSON *t = mcp_report_add_table(section,
                                    "first spp at which F(tau) >= p "
                                    "(Firmino 2024 Table 1; 0: not within the series)",
                                    cols, s->has_reference ? 4 : 2);
    if (!t) return -1;
    int agree = 0;
    for (int j = 0; j < s->n_taus; j++) {
        int rc = s->has_reference
                     ? mcp_report_table_add_row(t, "ddds", s->taus[j], s->first_spp[j],
                                                s->true_first_spp[j],
                                                s->agree[j] ? "yes" : "no")
                     : mcp_report_table_add_row(t, "dd", s->taus[j], s->first_spp[j]);
        if (rc) return -1;
        agree += s->agree[j];
    }
    if (s->has_reference)
        cJSON_AddNumberToObject(section, "agreement_rate", (double)agree / s->n_taus);
    /* the verdict: where each tau is reached, and whether the truth agrees */
    char text[900];
    int len = snprintf(text, sizeof text, "stop points (F(tau) >= %.4g%%):", 100 * s->p);
    for (int j = 0; j < s->n_taus && len < (int)sizeof text - 120; j++) {
        len += s->first_spp[j] > 0
                   ? snprintf(text + len, sizeof text - len, "%s tau = %g at %g spp",
                              j ? "," : "", s->taus[j], (double)s->first_spp[j])
                   : snprintf(text + len, sizeof text - len,
                              "%s tau = %g not reached by %g spp", j ? "," : "",
                              s->taus[j], (double)s->points[s->count - 1].spp);
        if (s->has_reference)
            len += s->true_first_spp[j] > 0
                       ? snprintf(text + len, sizeof text - len, " (true: %g)",
                                  (double)s->true_first_spp[j])
                       : snprintf(text + len, sizeof text - len, " (true: not reached)");
    }
    if (s->has_reference)
        snprintf(text + len, sizeof text - len, "; estimate and truth agree on %d of %d",
                 agree, s->n_taus);
    if (mcp_report_set_verdict(section,
                               !s->has_reference     ? MCP_VERDICT_INFO
                               : agree == s->n_taus ? MCP_VERDICT_GOOD
                                                    : MCP_VERDICT_BAD,
                               "%s", text))
        return -1;
    /* F(τ) against spp, one line per τ */
    cJSON *plot = mcp_report_add_plot(section, "estimated F(tau) against spp", "spp",
                                      MCP_AXIS_LOG, "F(tau)", MCP_AXIS_LOGIT);
    double *x = mcp_calloc((size_t)s->count, sizeof *x),
           *y = mcp_calloc((size_t)s->count, sizeof *y);
    int rc = plot && x && y ? 0 : -1;
    for (int j = 0; j < s->n_taus && !rc; j++) {
        char name[64];
        for (int i = 0; i < s->count; i++) {
            x[i] = s->points[i].spp;
            y[i] = s->points[i].cdf[j];
        }
        snprintf(name, sizeof name, "tau %g", s->taus[j]);
        cJSON *ser = mcp_report_plot_add_series(plot, name, MCP_SERIES_LINE_POINTS, x, y,
                                                s->count);
        rc = ser ? 0 : -1;
        if (!rc && s->has_reference) {
            for (int i = 0; i < s->count; i++)
                y[i] = s->points[i].true_cdf[j];
            snprintf(name, sizeof name, "tau %g, true", s->taus[j]);
            ser = mcp_report_plot_add_series(plot, name, MCP_SERIES_LINE, x, y, s->count);
            rc = ser && !mcp_report_series_set_dashed(ser, 1) ? 0 : -1;
        }
    }
    free(x);
    free(y);
    if (rc) return -1;
    /* the estimated (dashed) and true percentile curves of up to 4 members, evenly
     * spaced and ending with the last */
    plot = mcp_report_add_plot(section, "estimated (dashed) and true error percentiles",
                               "percentile", MCP_AXIS_LOGIT, "error", MCP_AXIS_LOG);
    if (!plot) return -1;
    int step = (s->count + 3) / 4;
    for (int i = 0; i < s->count; i++) {
        if ((s->count - 1 - i) % step) continue;
        const mcp_series_point *pt = &s->points[i];
        char name[64];
        snprintf(name, sizeof name, "%g spp", pt->spp);
        cJSON *ser =
            mcp_report_plot_add_series(plot, name, MCP_SERIES_LINE, s->percentiles,
                                       pt->est_percentile, s->n_percentiles);
        if (!ser || mcp_report_series_set_dashed(ser, 1)) return -1;
        if (s->has_reference) {
            snprintf(name, sizeof name, "%g spp, true", pt->spp);
            if (!mcp_report_plot_add_series(plot, name, MCP_SERIES_LINE, s->percentiles,
                                            pt->true_percentile, s->n_percentiles))
                return -1;
        }
    }
    return 0;
}

static void
print_series(const mcp_series_estimate *s)
{
    printf("%-10s", "spp");
    for (int j = 0; j < s->n_taus; j++)
        printf("  F(%-8g)%s", s->taus[j], s->has_reference ? "  true     " : "");
    printf("\n");
    for (int i = 0; i < s->count; i++) {
        const mcp_series_point *pt = &s->points[i];
        printf("%-10g", pt->spp);
        for (int j = 0; j < s->n_taus; j++) {
            printf("  %.6f%s", pt->cdf[j], pt->stop[j] ? "*" : " ");
            if (s->has_reference)
                printf("  %.6f%s", pt->true_cdf[j], pt->true_stop[j] ? "*" : " ");
        }
        printf("\n");
    }
    printf("\n%-10s  %-12s%s\n", "tau", "stop at spp",
           s->has_reference ? "  true spp      agree" : "");
    int agree = 0;
    for (int j = 0; j < s->n_taus; j++) {
        printf("%-10g  %-12g", s->taus[j], s->first_spp[j]);
        if (s->has_reference)
            printf("  %-12g  %s", s->true_first_spp[j], s->agree[j] ? "yes" : "no");
        printf("\n");
        agree += s->agree[j];
    }
    if (s->has_reference) printf("agreement: %d of %d\n", agree, s->n_taus);
    printf("(0: not reached within the series; * F(tau) >= p)\n");
    printf("variance: %s\n", mcp_cli_variance_source_words(s->variance_source));
}

static void
progress_cb(int done, int total, void *ctx)
{
    mcp_progress *p = ctx;
    if (done == 1) mcp_progress_begin(p, "estimate", total);
    mcp_progress_update(p, done);
    if (done == total) mcp_progress_end(p);
}

/* Runs a series and writes estimate.json and the section. *stop_all: the last member
 * reached every τ. */
static int
run_series(const mcp_series *series, const mcp_denoiser *den,
           const mcp_series_estimate_options *so, const mcp_image *ref, const out_dir *o,
           cJSON *section, cJSON **json_out, mcp_series_estimate **out)
{
    mcp_progress p;
    memset(&p, 0, sizeof p);
    mcp_series_estimate *s = NULL;
    if (mcp_estimate_series(series, den, so, ref, progress_cb, &p, &s)) return -1;
    cJSON *j = series_json(s, den->name, so->est.sure.metric);
    int using_increments = s->variance_source == MCP_VARSRC_INCREMENTS;
    mcp_cli_report_variance_ratio(s->variance_ratio, using_increments, j);
    if (section) {
        cJSON_AddStringToObject(section, "variance_source",
                                mcp_variance_source_name(s->variance_source));
        const cJSON *w = cJSON_GetObjectItem(j, "variance_warning");
        if (w)
            cJSON_AddStringToObject(section, "variance_warning", w->valuestring);
    }
    char path[4352];
    char *text = cJSON_Print(j);
    int rc = !text || (o && (mcp_make_dirs(o->dir) ||
                             out_path(o, "estimate.json", path, sizeof path) ||
                             mcp_write_file_atomic(path, text, strlen(text))));
    free(text);
    if (!rc && section) rc = report_series(section, s);
    if (rc) {
        cJSON_Delete(j);
        mcp_series_estimate_free(s);
        return -1;
    }
    *json_out = j;
    *out = s;
    return 0;
}

/* ---- the subcommand ---- */

static const char usage[] =
    "usage: mcpost estimate DUMP... [--denoiser NAME] [options]\n"
    "  Estimates the error of the denoised DUMP (SURE, Firmino et al. 2024) and decides\n"
    "  whether rendering can stop: F(tau) >= p, F the estimated CDF of the per-value\n"
    "  error. Several DUMPs, or --series, make a progressive series: then it reports\n"
    "  the first spp at which each tau is reached (and the true one with --ref).\n"
    "\n"
    "  --denoiser NAME          the denoiser (see `mcpost denoise --list`)\n"
    "                           " MCP_CLI_DEFAULT_DENOISER "\n"
    MCP_CLI_DENOISER_USAGE(" ")
    "  --metric NAME            relse, relse-perceptual or se [relse]\n"
    "  --tau T                  error threshold [0.01]\n"
    "  --percentile P           fraction of values that must be below tau [0.999]\n"
    "  --percentiles LIST       the estimated percentile curve "
    "[0.5,0.9,0.99,0.999,0.9999]\n"
    "  --probes K               random probes for SURE and the variance [1]\n"
    "  --seed S                 seed of the probes [0]\n"
    "  --mc-sure                J.eps by finite differences (MC-SURE)\n"
    "  --delta D                finite-difference step, unitless [0.1]\n"
    "  --variance-probes KIND   sure (reuse the SURE probes) or rademacher [sure]\n"
    "  --ppd X                  relse-perceptual: pixels per degree [67.02]\n"
    "  --tile N                 pre-split into NxN tiles before block averaging [none]\n"
    "  --sampling KIND          sampling map: variance, tonemapped or mc-sure "
    "[variance]\n"
    "  --budget N               samples for the next iteration: write integer counts\n"
    "  --s2-pool R|auto         pool s^2 = (J eps)^2 over (2R+1)^2 pixels; auto: 1 below\n"
    "                           8 probes, else 0 [0]\n"
    "  -o, --output DIR         write images, blocks.png, estimate.json and a report\n"
    "  --json                   print estimate.json on stdout\n"
    "  --exit-status            exit 0 to stop, 10 to continue rendering (a series: the\n"
    "                           last member and every tau)\n"
    "  Series:\n"
    "  --series PATTERN         dump files from a printf pattern, with --spp LIST\n"
    "  --spp LIST               sample counts for --series (e.g. 1,2,4,8)\n"
    "  --taus LIST              thresholds to report [0.05,0.02,0.01; or --tau]\n"
    "  --ref FILE               the reference image: true error and agreement\n"
    "  --variance-from KIND     file (each member's own variance) or increments (the\n"
    "                           spread between the series' increments: right for\n"
    "                           stratified samplers) [file]\n"
    "  Reading dumps:\n"
    "  --convention NAME        pbrt, mitsuba, blender, mcpost, plain [auto]\n"
    "  --variance KIND          per-sample or of-mean [per convention]\n"
    "\n"
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost estimate samples/fixtures/cornell/series/cornell_spp0064.exr --denoiser nlm -o out/estimate\n"
    "  mcpost estimate --series 'samples/fixtures/cornell/series/cornell_spp%04d.exr' --spp 16,32,64,128 \\\n"
    "                  --denoiser bilateral --ref samples/fixtures/cornell/cornell_reference.exr\n";

enum {
    OPT_METRIC = 256,
    OPT_TAU,
    OPT_PERCENTILE,
    OPT_PERCENTILES,
    OPT_PROBES,
    OPT_SEED,
    OPT_MC,
    OPT_DELTA,
    OPT_VPROBES,
    OPT_PPD,
    OPT_TILE,
    OPT_SAMPLING,
    OPT_BUDGET,
    OPT_JSON,
    OPT_EXIT,
    OPT_SERIES,
    OPT_SPP,
    OPT_TAUS,
    OPT_REF,
    OPT_CONVENTION,
    OPT_VARIANCE,
    OPT_VARIANCE_FROM,
    OPT_S2_POOL
};

static int
parse_seed(const char *flag, const char *text, uint64_t *out)
{
    char *end;
    errno = 0;
    unsigned long long v = strtoull(text, &end, 10);
    if (end == text || *end || errno || text[0] == '-')
        return mcp_error("%s must be a non-negative integer (got '%s')", flag, text);
    *out = v;
    return 0;
}

static int
parse_variance_probes(const char *text, int *out)
{
    if (!strcmp(text, "sure"))
        *out = 0;
    else if (!strcmp(text, "rademacher"))
        *out = 1;
    else
        return mcp_error("variance probes must be sure or rademacher (got '%s')", text);
    return 0;
}

static int
cmd_estimate(int argc, char **argv)
{
    static const struct option longs[] = {
        MCP_CLI_DENOISER_LONGOPTS,
        {"metric", required_argument, 0, OPT_METRIC},
        {"tau", required_argument, 0, OPT_TAU},
        {"percentile", required_argument, 0, OPT_PERCENTILE},
        {"percentiles", required_argument, 0, OPT_PERCENTILES},
        {"probes", required_argument, 0, OPT_PROBES},
        {"seed", required_argument, 0, OPT_SEED},
        {"mc-sure", no_argument, 0, OPT_MC},
        {"delta", required_argument, 0, OPT_DELTA},
        {"variance-probes", required_argument, 0, OPT_VPROBES},
        {"ppd", required_argument, 0, OPT_PPD},
        {"tile", required_argument, 0, OPT_TILE},
        {"sampling", required_argument, 0, OPT_SAMPLING},
        {"budget", required_argument, 0, OPT_BUDGET},
        {"output", required_argument, 0, 'o'},
        {"json", no_argument, 0, OPT_JSON},
        {"exit-status", no_argument, 0, OPT_EXIT},
        {"series", required_argument, 0, OPT_SERIES},
        {"spp", required_argument, 0, OPT_SPP},
        {"taus", required_argument, 0, OPT_TAUS},
        {"ref", required_argument, 0, OPT_REF},
        {"convention", required_argument, 0, OPT_CONVENTION},
        {"variance", required_argument, 0, OPT_VARIANCE},
        {"variance-from", required_argument, 0, OPT_VARIANCE_FROM},
        {"s2-pool", required_argument, 0, OPT_S2_POOL},
        {"help", no_argument, 0, 'h'},
        {0, 0, 0, 0}};
    mcp_series_estimate_options so = mcp_series_estimate_defaults();
    mcp_estimate_options *eo = &so.est;
    const char *outdir = NULL, *pattern = NULL, *spp_text = NULL,
               *ref_path = NULL, *convention = NULL, *variance = NULL;
    mcp_cli_denoiser_flags df = {0};
    int json = 0, exit_status = 0, have_taus = 0, have_tau = 0, opt;
    mcp_variance_source variance_from = MCP_VARSRC_NONE;
    optind = 1;
    while ((opt = getopt_long(argc, argv, "ho:", longs, NULL)) != -1) {
        int rc = 0;
        double b = 0;
        int taken = mcp_cli_denoiser_flag(&df, opt, optarg);
        if (taken < 0) {
            mcp_cli_denoiser_flags_free(&df);
            return mcp_cli_fail();
        }
        if (taken) continue;
        switch (opt) {
        case OPT_METRIC:
            rc = mcp_error_metric_from_name(optarg, &eo->sure.metric);
            break;
        case OPT_TAU:
            rc = mcp_cli_double("--tau", optarg, &eo->tau);
            have_tau = 1;
            break;
        case OPT_PERCENTILE:
            rc = mcp_cli_double("--percentile", optarg, &eo->p);
            break;
        case OPT_PERCENTILES:
            rc = parse_list("--percentiles", optarg, eo->percentiles,
                            MCP_ESTIMATE_MAX_PERCENTILES, &eo->n_percentiles);
            break;
        case OPT_PROBES:
            rc = mcp_cli_int("--probes", optarg, &eo->sure.n_probes);
            break;
        case OPT_SEED:
            rc = parse_seed("--seed", optarg, &eo->sure.seed);
            break;
        case OPT_MC:
            eo->sure.mc_sure = 1;
            break;
        case OPT_DELTA:
            rc = mcp_cli_double("--delta", optarg, &eo->sure.fd_delta);
            break;
        case OPT_VPROBES:
            rc = parse_variance_probes(optarg, &eo->variance_rademacher);
            break;
        case OPT_PPD:
            rc = mcp_cli_double("--ppd", optarg, &eo->sure.ppd);
            break;
        case OPT_TILE:
            rc = mcp_cli_int("--tile", optarg, &eo->blocks.tile_size);
            break;
        case OPT_SAMPLING:
            rc = mcp_sampling_kind_from_name(optarg, &eo->sampling.kind);
            break;
        case OPT_BUDGET:
            rc = mcp_cli_double("--budget", optarg, &b);
            if (!rc && (b < 0 || b != floor(b) || b > 4503599627370496.0))
                rc = mcp_error("--budget must be a whole number of samples (got %s)",
                               optarg);
            eo->budget = (int64_t)b;
            break;
        case 'o':
            outdir = optarg;
            break;
        case OPT_JSON:
            json = 1;
            break;
        case OPT_EXIT:
            exit_status = 1;
            break;
        case OPT_SERIES:
            pattern = optarg;
            break;
        case OPT_SPP:
            spp_text = optarg;
            break;
        case OPT_TAUS:
            rc = parse_list("--taus", optarg, so.taus, MCP_ESTIMATE_MAX_TAUS, &so.n_taus);
            have_taus = 1;
            break;
        case OPT_REF:
            ref_path = optarg;
            break;
        case OPT_CONVENTION:
            convention = optarg;
            break;
        case OPT_VARIANCE:
            variance = optarg;
            break;
        case OPT_VARIANCE_FROM:
            rc = mcp_cli_variance_from(optarg, &variance_from);
            break;
        case OPT_S2_POOL:
            if (!strcmp(optarg, "auto"))
                eo->s2_pool = -1;
            else
                rc = mcp_cli_int("--s2-pool", optarg, &eo->s2_pool);
            break;
        case 'h':
            fputs(usage, stdout);
            mcp_cli_denoiser_flags_free(&df);
            return 0;
        default:
            mcp_cli_denoiser_flags_free(&df);
            return mcp_cli_usage("estimate", "bad option");
        }
        if (rc) {
            mcp_cli_denoiser_flags_free(&df);
            return mcp_cli_fail();
        }
    }
    int n_files = argc - optind;
    if (!n_files && !pattern) {
        mcp_cli_denoiser_flags_free(&df);
        return mcp_cli_usage("estimate", "no dump given");
    }
    if (pattern && (n_files || !spp_text)) {
        mcp_cli_denoiser_flags_free(&df);
        return mcp_cli_usage("estimate", "--series needs --spp and no other dumps");
    }
    if (have_tau && !have_taus) { /* a series checks the one --tau */
        so.n_taus = 1;
        so.taus[0] = eo->tau;
    }
    int status = 1, is_series = pattern || n_files > 1;
    mcp_denoiser *den = NULL;
    mcp_dump *dump = NULL;
    mcp_series *series = NULL;
    mcp_image *ref = NULL;
    mcp_estimate *e = NULL;
    mcp_series_estimate *s = NULL;
    mcp_report *report = NULL;
    cJSON *summary = NULL, *section = NULL;
    out_dir od;
    memset(&od, 0, sizeof od);
    if (outdir) snprintf(od.dir, sizeof od.dir, "%s", outdir);
    if (mcp_estimate_check(eo) ||
        mcp_cli_denoiser_create(&df, &den) ||
        (ref_path && mcp_image_read(ref_path, NULL, &ref)))
        goto done;
    if (outdir && (mcp_report_new("mcpost estimate", &report) ||
                   !(section = mcp_report_section(
                         report, "estimate",
                         is_series ? "error estimate over a series" : "error estimate"))))
        goto done;
    if (is_series) {
        if (pattern) {
            int *spps = NULL, n = 0;
            int rc = parse_int_list("--spp", spp_text, &spps, &n) ||
                     mcp_series_from_pattern(pattern, spps, n, &series);
            free(spps);
            if (rc) goto done;
        } else if (mcp_series_from_paths((const char *const *)argv + optind, NULL,
                                         n_files, &series)) {
            goto done;
        }
        if ((convention &&
             mcp_convention_from_name(convention, &series->spec.convention)) ||
            (variance && mcp_variance_kind_from_name(variance, &series->spec.variance)))
            goto done;
        series->variance_from = variance_from;
        if (run_series(series, den, &so, ref, outdir ? &od : NULL, section, &summary, &s))
            goto done;
        if (!json) print_series(s);
        status = 0;
        if (exit_status) {
            const mcp_series_point *last = &s->points[s->count - 1];
            for (int j = 0; j < s->n_taus; j++)
                if (!last->stop[j]) status = EXIT_CONTINUE;
        }
    } else {
        const char *path = argv[optind];
        if (mcp_cli_read_dump(path, NULL, convention, variance, &dump) ||
            mcp_estimate_compute(dump, den, eo, &e))
            goto done;
        summary = estimate_json(e, path, den->name, eo);
        if (ref) { /* the truth beside the estimate */
            mcp_image *err = NULL;
            double truth[MCP_ESTIMATE_MAX_PERCENTILES];
            if (mcp_true_error(e->maps.denoised, ref, eo->sure.metric, eo->sure.ppd,
                               &err) ||
                mcp_true_percentiles(err, e->percentiles, e->n_percentiles, truth)) {
                mcp_image_free(err);
                goto done;
            }
            mcp_image_free(err);
            cJSON *tp = cJSON_AddArrayToObject(summary, "true_percentiles");
            for (int k = 0; k < e->n_percentiles; k++)
                cJSON_AddItemToArray(tp, cJSON_CreateNumber(truth[k]));
        }
        if (outdir) {
            char path_json[4352];
            char *text = cJSON_Print(summary);
            int rc = !text || write_single(e, &od, section, summary) ||
                     out_path(&od, "estimate.json", path_json, sizeof path_json) ||
                     mcp_write_file_atomic(path_json, text, strlen(text)) ||
                     report_single(section, summary, e);
            free(text);
            if (rc) goto done;
        }
        if (!json) print_single(e, path, den->name, eo);
        status = exit_status && !e->stop ? EXIT_CONTINUE : 0;
    }
    if (report && mcp_report_write(report, od.dir)) {
        status = 1;
        goto done;
    }
    if (json) {
        mcp_cli_print_json(summary);
        summary = NULL;
    }
done:
    if (status == 1) mcp_cli_fail();
    cJSON_Delete(summary);
    mcp_report_free(report);
    mcp_series_estimate_free(s);
    mcp_estimate_free(e);
    mcp_image_free(ref);
    mcp_series_free(series);
    mcp_dump_free(dump);
    mcp_denoiser_free(den);
    mcp_cli_denoiser_flags_free(&df);
    return status;
}

const mcp_command mcp_command_estimate = {
    "estimate", "estimate the error of a denoised render and decide when to stop",
    cmd_estimate};

/* ---- the job stage ---- */

static const char *const estimate_keys[] = {
    "input",           "denoiser", "metric", "tau",      "percentile",
    "percentiles",     "probes",   "seed",   "mc_sure",  "delta",
    "variance_probes", "ppd",      "tile",   "sampling", "budget",
    "reference",       "taus",     "output", "s2_pool",  NULL};

static int
at_line(const mcp_node *settings, const char *key)
{
    const mcp_node *n = mcp_node_get(settings, key);
    return n ? mcp_node_error(n, "%s", mcp_error_message()) : -1;
}

static int
opt_enum(const mcp_node *settings, const char *key, int (*parse)(const char *, void *),
         void *out)
{
    const char *s = NULL;
    if (mcp_node_opt_string(settings, key, &s)) return -1;
    if (s && parse(s, out)) return at_line(settings, key);
    return 0;
}

static int
parse_metric(const char *s, void *out)
{
    return mcp_error_metric_from_name(s, out);
}

static int
parse_sampling(const char *s, void *out)
{
    return mcp_sampling_kind_from_name(s, out);
}

static int
parse_vprobes(const char *s, void *out)
{
    return parse_variance_probes(s, out);
}

static int
read_settings(const mcp_node *s, mcp_series_estimate_options *so)
{
    mcp_estimate_options *o = &so->est;
    double *p = NULL, *taus = NULL, seed = 0, budget = 0;
    int np = 0, nt = 0, rc = -1;
    if (opt_enum(s, "metric", parse_metric, &o->sure.metric) ||
        mcp_node_opt_double(s, "tau", &o->tau) ||
        mcp_node_opt_double(s, "percentile", &o->p) ||
        mcp_node_opt_doubles(s, "percentiles", &p, &np) ||
        mcp_node_opt_int(s, "probes", &o->sure.n_probes) ||
        mcp_node_opt_double(s, "seed", &seed) ||
        mcp_node_opt_bool(s, "mc_sure", &o->sure.mc_sure) ||
        mcp_node_opt_double(s, "delta", &o->sure.fd_delta) ||
        opt_enum(s, "variance_probes", parse_vprobes, &o->variance_rademacher) ||
        mcp_node_opt_double(s, "ppd", &o->sure.ppd) ||
        mcp_node_opt_int(s, "tile", &o->blocks.tile_size) ||
        opt_enum(s, "sampling", parse_sampling, &o->sampling.kind) ||
        mcp_node_opt_double(s, "budget", &budget) ||
        mcp_node_opt_int(s, "s2_pool", &o->s2_pool) ||
        mcp_node_opt_doubles(s, "taus", &taus, &nt))
        goto done;
    if (seed < 0 || seed != floor(seed) || seed > 9007199254740992.0) {
        mcp_node_error(mcp_node_get(s, "seed"),
                       "seed must be a non-negative integer (got %g)", seed);
        goto done;
    }
    o->sure.seed = (uint64_t)seed;
    if (budget < 0 || budget != floor(budget) || budget > 4503599627370496.0) {
        mcp_node_error(mcp_node_get(s, "budget"),
                       "budget must be a whole number of samples "
                       "(got %g)",
                       budget);
        goto done;
    }
    o->budget = (int64_t)budget;
    if (p) {
        if (np > MCP_ESTIMATE_MAX_PERCENTILES) {
            mcp_node_error(mcp_node_get(s, "percentiles"), "at most %d percentiles",
                           MCP_ESTIMATE_MAX_PERCENTILES);
            goto done;
        }
        o->n_percentiles = np;
        memcpy(o->percentiles, p, (size_t)np * sizeof *p);
    }
    if (taus) {
        if (nt < 1 || nt > MCP_ESTIMATE_MAX_TAUS) {
            mcp_node_error(mcp_node_get(s, "taus"), "taus needs 1 to %d values",
                           MCP_ESTIMATE_MAX_TAUS);
            goto done;
        }
        so->n_taus = nt;
        memcpy(so->taus, taus, (size_t)nt * sizeof *taus);
    } else if (mcp_node_get(s, "tau")) {
        so->n_taus = 1;
        so->taus[0] = o->tau;
    }
    if (mcp_estimate_check(o)) {
        mcp_node_error(s, "%s", mcp_error_message());
        goto done;
    }
    rc = 0;
done:
    free(p);
    free(taus);
    return rc;
}

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): the options, the names of the input (a dump or a
 * series) and the reference, checked against the job's inputs, and the denoiser,
 * created from its settings (its files read). Strings are borrowed from the settings;
 * the denoiser is the plan's. */
typedef struct estimate_plan {
    mcp_series_estimate_options so;
    const char *name, *sub, *ref_name;
    mcp_denoiser *den;
} estimate_plan;

static int
parse_estimate(mcp_job *job, const mcp_node *settings, estimate_plan *pl)
{
    memset(pl, 0, sizeof *pl);
    pl->so = mcp_series_estimate_defaults();
    pl->sub = "estimate";
    if (mcp_node_opt_string(settings, "input", &pl->name) ||
        mcp_node_opt_string(settings, "output", &pl->sub) ||
        mcp_node_opt_string(settings, "reference", &pl->ref_name) ||
        read_settings(settings, &pl->so) ||
        mcp_job_check_input(job, settings, "input", MCP_JOB_SERIES | MCP_JOB_DUMP) ||
        (pl->ref_name && mcp_job_check_input(job, settings, "reference", MCP_JOB_IMAGE)))
        return -1;
    if (mcp_cli_stage_denoiser(job, settings, &pl->den))
        return mcp_node_get(settings, "denoiser") ? at_line(settings, "denoiser") : -1;
    return 0;
}

static int
check_estimate(mcp_job *job, const mcp_node *settings)
{
    estimate_plan pl;
    int rc = parse_estimate(job, settings, &pl);
    mcp_denoiser_free(pl.den);
    return rc;
}

static int
stage_estimate(mcp_job *job, const mcp_node *settings)
{
    estimate_plan pl;
    if (parse_estimate(job, settings, &pl)) {
        mcp_denoiser_free(pl.den);
        return -1;
    }
    mcp_series_estimate_options so = pl.so;
    const char *name = pl.name, *sub = pl.sub, *ref_name = pl.ref_name;
    char probe[4352];
    mcp_denoiser *den = pl.den;
    const mcp_image *ref = NULL;
    const mcp_series *series = NULL;
    const mcp_dump *dump = NULL;
    int rc = -1;
    if (ref_name && mcp_job_image(job, settings, "reference", &ref)) goto done;
    /* the input is a series or a dump */
    if (mcp_job_series(job, settings, "input", &series)) {
        if (!strstr(mcp_error_message(), "is not a series")) goto done;
        mcp_error_clear();
        series = NULL;
        if (mcp_job_dump(job, settings, "input", &dump)) goto done;
    }
    out_dir od;
    memset(&od, 0, sizeof od);
    snprintf(od.rel, sizeof od.rel, "%s/", sub);
    char rel_json[300];
    snprintf(rel_json, sizeof rel_json, "%sestimate.json", od.rel);
    if (mcp_job_output_path(job, rel_json, probe, sizeof probe)) /* creates the folder */
        goto done;
    *strrchr(probe, '/') = '\0';
    snprintf(od.dir, sizeof od.dir, "%s", probe);
    cJSON *section = mcp_report_section(mcp_job_report(job), "estimate", name);
    if (!section) goto done;
    if (series) {
        cJSON *j = NULL;
        mcp_series_estimate *s = NULL;
        if (run_series(series, den, &so, ref, &od, section, &j, &s)) goto done;
        mcp_note("%s: %d members, %d thresholds", name, s->count, s->n_taus);
        cJSON_Delete(j);
        mcp_series_estimate_free(s);
    } else {
        mcp_estimate *e = NULL;
        if (mcp_estimate_compute(dump, den, &so.est, &e)) goto done;
        cJSON *j = estimate_json(e, name, den->name, &so.est);
        char path[4352];
        char *text = cJSON_Print(j);
        int bad = !text || write_single(e, &od, section, j) ||
                  out_path(&od, "estimate.json", path, sizeof path) ||
                  mcp_write_file_atomic(path, text, strlen(text)) ||
                  report_single(section, j, e);
        if (!bad)
            mcp_note("%s: F(%g) = %.6f, %s", name, e->tau, e->cdf_at_tau,
                     e->stop ? "stop" : "continue");
        free(text);
        cJSON_Delete(j);
        mcp_estimate_free(e);
        if (bad) goto done;
    }
    rc = 0;
done:
    mcp_denoiser_free(den);
    return rc;
}

const mcp_stage mcp_stage_estimate = {
    "estimate",
    "error estimate of a denoised dump or series: SURE, blocks, stopping (Firmino 2024)",
    estimate_keys, stage_estimate, check_estimate};
