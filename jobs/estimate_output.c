/* estimate_output.c: what an estimate writes, for `mcpost estimate` and the `estimate`
 * job stage alike (estimate/estimate.h; docs/mathematics.md §2): one dump's images, block
 * pictures, estimate.json and report section; a series' first spp per tau (Firmino 2024
 * Table 1), its estimate.json and report section. */
#include "internal.h"
#include "../common/filter/internal.h" /* colour maps on fewer levels */
#include "../common/report/internal.h" /* maps of one value */
#include "../estimate/internal.h"      /* λ as an image */

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int
mcp__estimate_path(const mcp__estimate_dir *o, const char *name, char *buf, size_t cap)
{
    if (snprintf(buf, cap, "%s/%s", o->dir, name) >= (int)cap)
        return mcp_error("output path too long: %s/%s", o->dir, name);
    return 0;
}

/* ---- one dump ---- */

cJSON *
mcp__estimate_json(const mcp_estimate *e, const char *input, const char *denoiser,
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
    mcp__add_variance_source(j, e->variance_source, e->variance_dof);
    cJSON_AddNumberToObject(j, "s2_pool", e->s2_pool);
    cJSON_AddNumberToObject(j, "probe_floor", e->probe_floor);
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
    cJSON_AddStringToObject(dist, "file", "distribution.exr (lambda.R/G/B)");
    cJSON_AddStringToObject(dist, "s2_file", "variance_rel.exr (R, G, B)");
    cJSON_AddNumberToObject(j, "probes", e->probes);
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

/* Each block's λ (R, G, B) as the distribution's image holds it (float), blocks->count
 * x 3 values (the caller frees them). */
static float *
block_lambdas(const mcp_estimate *e)
{
    float *l = mcp_malloc((size_t)e->blocks->count * 3 * sizeof *l);
    for (int i = 0; l && i < e->blocks->count; i++)
        for (int c = 0; c < 3; c++)
            l[3 * i + c] = (float)mcp_error_dist_lambda(e->dist, i, c);
    return l;
}

/* The report's block picture: the error each pixel is expected to have under the
 * model that F(tau) comes from, s²(λ + 1) (mean of R, G, B; log10 from -5 to 0 in
 * inferno, like the metrics' RelSE map), with the block edges in white. Unlike
 * blocks.png, whose colours only tell blocks apart, its colour bar reads as a value,
 * and a single block still shows where the error is: s² varies per pixel. s2 is the
 * distribution's (Var^r, variance_rel.exr), lambda each block's (block_lambdas).
 * *log_error: the log10 values it shows (the caller frees them). */
static int
blocks_error_picture(const mcp_blocks *blocks, const float *lambda, const mcp_image *s2,
                     unsigned char *rgb8, mcp_image **log_error)
{
    int w = blocks->width, h = blocks->height;
    int32_t *label = NULL;
    mcp_image *lg = NULL;
    if (mcp_blocks_label(blocks, &label) ||
        mcp_image_new(w, h, 1, (const char *[]){"log10_error"}, &lg)) {
        free(label);
        return -1;
    }
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *l = lambda + 3 * (size_t)label[(size_t)y * w + x],
                        *v = mcp_image_px(s2, x, y);
            double mean = 0;
            for (int c = 0; c < 3; c++)
                mean += v[c] * (l[c] + 1.0) / 3.0;
            mcp_image_px(lg, x, y)[0] = (float)(mean > 1e-30 ? log10(mean) : -30.0);
        }
    /* 255 levels and white: 256 colours, a palette PNG of a byte a pixel (png_encode.c;
       a third of the bytes to compress) */
    int rc =
        mcp__colormap_apply_levels(lg, 0, -5.0, 0.0, MCP_COLORMAP_INFERNO, 255, rgb8);
#pragma omp parallel for schedule(static) if (!rc)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            if ((x + 1 < w && label[i] != label[i + 1]) ||
                (y + 1 < h && label[i] != label[i + w]))
                memset(rgb8 + 3 * i, 255, 3);
        }
    free(label);
    if (rc) {
        mcp_image_free(lg);
        return -1;
    }
    *log_error = lg;
    return 0;
}

/* The denoised image as a screen shows it: R, G, B clamped to [0, 1], sRGB-encoded
 * bytes (the bytes a PNG of its clamp tone map holds, without that image's copies). */
static int
screen_picture(const mcp_image *img, unsigned char *rgb8)
{
    int rgb[3];
    if (mcp_rgb_channels(img, rgb)) return -1;
    mcp__srgb8_bytes(img, rgb, 3, 1, rgb8);
    return 0;
}

/* The sampling map as inferno from 0 to its 99th percentile (a few pixels far above
 * the rest would leave the picture black), in multiples of the mean weight (the map
 * sums to 1); *top the value at the scale's top, in the same unit. */
static int
sampling_map_picture(const mcp_image *map, unsigned char *rgb8, double *top)
{
    const size_t n = (size_t)map->width * map->height;
    /* by selection: a sort of a 1080p map took 8% of a whole gauss estimate */
    float sel[3];
    if (mcp__image_channel_spread(map, 0, 0.99, sel)) return -1;
    double hi = sel[1];
    if (!(hi > 0)) hi = sel[2] > 0 ? sel[2] : 1.0 / (double)n;
    *top = hi * (double)n;
    return mcp_colormap_apply(map, 0, 0.0, hi, MCP_COLORMAP_INFERNO, rgb8);
}

/* Every image of one estimate, the block pictures, and their place in the report.
 * The pictures are made first and every file is then written at once, a file per
 * thread (mcp_write_files), the costliest first: the error picture's PNG, the
 * denoised one, then the maps, which are stored raw. distribution.exr holds λ only:
 * the distribution's s² is Var[F]^r, which variance_rel.exr already holds (its six
 * channels took 0.23 s of deflate at 1080p, for three that repeated a file). */
int
mcp__estimate_write_single(const mcp_estimate *e, const mcp__estimate_dir *o,
                           cJSON *section, const cJSON *summary,
                           const unsigned char *denoised_rgb)
{
    enum { MAX_FILES = 14 };
    mcp_image *block_mean = NULL, *lambda = NULL, *log_error = NULL;
    float *block_lambda = NULL;
    unsigned char *blocks_rgb = NULL, *error_rgb = NULL, *map_rgb = NULL,
                  *screen_rgb = NULL;
    char(*paths)[4352] = NULL;
    double map_top = 0;
    int rc = -1, n = 0, w = e->blocks->width, h = e->blocks->height;
    /* a streamed estimate (its F(X) written band by band) writes its images of the
       blocks' values a band at a time too (estimate_stream.c) */
    const int streamed = !e->maps.denoised;
    if (mcp_make_dirs(o->dir) || !(block_lambda = block_lambdas(e)) ||
        (streamed ? mcp__estimate_block_files(e, block_lambda, o)
                  : mcp_blocks_mean_image(e->blocks, e->maps.sure_rel, &block_mean) ||
                        mcp__error_dist_image(e->dist, 0, &lambda)) ||
        !(paths = mcp_malloc(MAX_FILES * sizeof *paths)))
        goto done;
    /* one block is one colour: a flat square that shows nothing, so no blocks.png
     * (the error picture's caption says why there is one block) */
    if (e->blocks->count > 1 && (!(blocks_rgb = mcp_malloc((size_t)w * h * 3)) ||
                                 mcp_blocks_picture(e->blocks, blocks_rgb)))
        goto done;
    if (section && (!(error_rgb = mcp_malloc((size_t)w * h * 3)) ||
                    blocks_error_picture(e->blocks, block_lambda, e->maps.var_rel,
                                         error_rgb, &log_error)))
        goto done;
    /* what the report shows beside the error: the denoised image (its PNG as a screen
     * shows it, the page re-exposes denoised.exr) and where the next samples go */
    if (section && !denoised_rgb &&
        (!(screen_rgb = mcp_malloc((size_t)w * h * 3)) ||
         screen_picture(e->maps.denoised, screen_rgb)))
        goto done;
    if (section && !denoised_rgb) denoised_rgb = screen_rgb;
    if (section && e->sampling_map &&
        (!(map_rgb = mcp_malloc((size_t)w * h * 3)) ||
         sampling_map_picture(e->sampling_map, map_rgb, &map_top)))
        goto done;
    const struct {
        const char *name;
        const mcp_image *image;
        const unsigned char *rgb8;
    } outputs[MAX_FILES] = {
        {"blocks_error.png", NULL, error_rgb},
        {"denoised.png", NULL, denoised_rgb},
        {"sampling_map.png", NULL, map_rgb},
        {"distribution.exr", lambda, NULL},
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
        if (mcp__estimate_path(o, outputs[i].name, paths[n], sizeof *paths)) goto done;
        files[n] = (mcp_file_write){.path = paths[n],
                                    .image = outputs[i].image,
                                    .rgb8 = outputs[i].rgb8,
                                    .width = w,
                                    .height = h};
        n++;
    }
    if (mcp_write_files(files, n)) goto done;
    if (section) {
        char caption[256], unit[256], rel[512];
        const cJSON *mj = cJSON_GetObjectItem(summary, "metric");
        const char *metric = cJSON_IsString(mj) ? mj->valuestring : "error";
        if (e->blocks->count == 1 && e->no_variance)
            snprintf(caption, sizeof caption,
                     "expected %s per pixel; 1 block: the dump has no variance, so "
                     "there is no error to model and Alg. 1 does not cut it",
                     metric);
        else if (e->blocks->count == 1)
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
        char rel_exr[512];
        snprintf(rel, sizeof rel, "%sdenoised.png", o->rel);
        snprintf(rel_exr, sizeof rel_exr, "%sdenoised.exr", o->rel);
        if (!mcp_report_add_hdr_image(section, rel, rel_exr, "the denoised image"))
            goto done;
        snprintf(rel, sizeof rel, "%sblocks_error.png", o->rel);
        cJSON *map = mcp_report_add_map(section, rel, caption, MCP_COLORMAP_INFERNO, 1e-5,
                                        1.0, MCP_AXIS_LOG, unit);
        /* one value in every pixel (a render without variance; a uniform sampling
           map): the page says the value instead of a flat square */
        if (!map || mcp_report_map_add_mark(map, e->tau, "tau") ||
            mcp__report_map_one_value(map, log_error, 0, 1, 1.0))
            goto done;
        if (map_rgb) {
            snprintf(rel, sizeof rel, "%ssampling_map.png", o->rel);
            cJSON *sm = mcp_report_add_map(
                section, rel, "the sampling map: where the next pass puts its samples",
                MCP_COLORMAP_INFERNO, 0.0, map_top, MCP_AXIS_LINEAR,
                "sample density, times the image's mean (brightest: the 99th percentile "
                "and above)");
            if (!sm || mcp__report_map_one_value(sm, e->sampling_map, 0, 0,
                                                 (double)e->sampling_map->width *
                                                     e->sampling_map->height))
                goto done;
        }
    }
    rc = 0;
done:
    free(map_rgb);
    mcp_image_free(log_error);
    free(screen_rgb);
    free(error_rgb);
    free(blocks_rgb);
    free(paths);
    mcp_image_free(block_mean);
    mcp_image_free(lambda);
    free(block_lambda);
    return rc;
}

/* The report section of one estimate: key figures, the percentile table and curve. */
int
mcp__estimate_report_single(cJSON *section, const cJSON *summary, const mcp_estimate *e)
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
    /* with a reference, the true percentiles beside the estimated ones */
    const cJSON *tp = cJSON_GetObjectItem(summary, "true_percentiles");
    double truth[MCP_ESTIMATE_MAX_PERCENTILES];
    int has_truth = cJSON_IsArray(tp) && cJSON_GetArraySize(tp) == e->n_percentiles;
    for (int k = 0; has_truth && k < e->n_percentiles; k++)
        truth[k] = cJSON_GetArrayItem(tp, k)->valuedouble;
    const char *cols[] = {"percentile", "estimated error", "true error"};
    cJSON *t = mcp_report_add_table(section, "estimated error percentiles", cols,
                                    has_truth ? 3 : 2);
    if (!t) return -1;
    for (int k = 0; k < e->n_percentiles; k++)
        if (has_truth ? mcp_report_table_add_row(t, "ddd", e->percentiles[k],
                                                 e->percentile_tau[k], truth[k])
                      : mcp_report_table_add_row(t, "dd", e->percentiles[k],
                                                 e->percentile_tau[k]))
            return -1;
    cJSON *plot =
        mcp_report_add_plot(section, "estimated error percentiles", "percentile",
                            MCP_AXIS_LOGIT, "error", MCP_AXIS_LOG);
    if (!plot ||
        !mcp_report_plot_add_series(plot, "estimated", MCP_SERIES_LINE_POINTS,
                                    e->percentiles, e->percentile_tau,
                                    e->n_percentiles) ||
        (has_truth &&
         !mcp_report_plot_add_series(plot, "true", MCP_SERIES_LINE_POINTS, e->percentiles,
                                     truth, e->n_percentiles)))
        return -1;
    return 0;
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
    mcp__add_variance_source(j, s->variance_source, 0);
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
    cJSON_AddStringToObject(j, "sure", mcp__sure_source_words(s));
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
        /* what SURE's covariance term came from: the member's own groups (their
           number) or the probes' divergence (0) */
        cJSON_AddNumberToObject(m, "sure_groups", pt->sure_groups);
        /* the probes from the groups' variance: a per-sample variance off from it */
        cJSON_AddBoolToObject(m, "probes_from_groups", pt->probes_from_groups);
        /* F(tau) >= p here for some tau, but before the third checkpoint: no stop */
        cJSON_AddBoolToObject(m, "held", pt->held);
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
    char text[1400];
    int len = snprintf(text, sizeof text, "stop points (F(tau) >= %.4g%%):", 100 * s->p);
    for (int j = 0; j < s->n_taus && len < (int)sizeof text - 200; j++) {
        len += s->first_spp[j] > 0
                   ? snprintf(text + len, sizeof text - len, "%s tau = %g at %g spp",
                              j ? "," : "", s->taus[j], (double)s->first_spp[j])
                   : snprintf(text + len, sizeof text - len,
                              "%s tau = %g not reached by %g spp", j ? "," : "",
                              s->taus[j], (double)s->points[s->count - 1].spp);
        /* F(τ) >= p at a member before the third checkpoint, which may not stop */
        double held = 0;
        for (int i = 0; i < s->count && !held; i++)
            if (s->points[i].held && s->points[i].cdf[j] >= s->p) held = s->points[i].spp;
        if (held > 0)
            len += snprintf(text + len, sizeof text - len,
                            " (F(tau) >= p at %g spp, held: no stop before the third "
                            "checkpoint)",
                            held);
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
                               !s->has_reference    ? MCP_VERDICT_INFO
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
progress_cb(int done, int total, void *ctx)
{
    mcp_progress *p = ctx;
    if (done == 1) mcp_progress_begin(p, "estimate", total);
    mcp_progress_update(p, done);
    if (done == total) mcp_progress_end(p);
}

/* Runs a series and writes estimate.json and the section. *stop_all: the last member
 * reached every τ. */
int
mcp__estimate_run_series(const mcp_series *series, const mcp_denoiser *den,
                         const mcp_series_estimate_options *so, const mcp_image *ref,
                         const mcp__estimate_dir *o, cJSON *section, cJSON **json_out,
                         mcp_series_estimate **out)
{
    mcp_progress p;
    memset(&p, 0, sizeof p);
    mcp_series_estimate *s = NULL;
    if (mcp_estimate_series(series, den, so, ref, progress_cb, &p, &s)) {
        mcp__progress_stop(&p); /* where it got: no "100%" for a run that failed */
        return -1;
    }
    cJSON *j = series_json(s, den->name, so->est.sure.metric);
    int using_increments = s->variance_source == MCP_VARSRC_INCREMENTS;
    mcp__report_variance_ratio(s->variance_ratio, using_increments,
                               series->variance_from == MCP_SERIES_VARIANCE_INCREMENTS,
                               j);
    if (section) {
        cJSON_AddStringToObject(section, "variance_source",
                                mcp_variance_source_name(s->variance_source));
        cJSON_AddStringToObject(section, "sure", mcp__sure_source_words(s));
        static const char *const lines[2] = {"variance_warning", "variance_choice"};
        for (int k = 0; k < 2; k++) {
            const cJSON *w = cJSON_GetObjectItem(j, lines[k]);
            if (w) cJSON_AddStringToObject(section, lines[k], w->valuestring);
        }
    }
    char path[4352];
    char *text = cJSON_Print(j);
    int rc = !text || (o && (mcp_make_dirs(o->dir) ||
                             mcp__estimate_path(o, "estimate.json", path, sizeof path) ||
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

int
mcp__estimate_add_truth(const mcp_estimate *e, const mcp_image *ref,
                        const mcp_estimate_options *eo, cJSON *summary)
{
    mcp_image *err = NULL;
    double truth[MCP_ESTIMATE_MAX_PERCENTILES];
    int rc = mcp_true_error(e->maps.denoised, ref, eo->sure.metric, eo->sure.ppd, &err) ||
             mcp_true_percentiles(err, e->percentiles, e->n_percentiles, truth);
    mcp_image_free(err);
    if (rc) return -1;
    cJSON *tp = cJSON_AddArrayToObject(summary, "true_percentiles");
    for (int k = 0; k < e->n_percentiles; k++)
        cJSON_AddItemToArray(tp, cJSON_CreateNumber(truth[k]));
    return 0;
}
