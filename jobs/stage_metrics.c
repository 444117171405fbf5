/* stage_metrics.c: the `metrics` job stage -- the figures of `mcpost metrics` for an
 * input against a reference, with maps, previews, FLIP's weighted histograms (another
 * test's overlapped with compare:) and the error-percentile plot (Firmino et al. 2024)
 * in the report, and error-vs-spp curves for a series.
 * Job keys are the flags of `mcpost metrics` with '_' for '-'. */
#include "internal.h"

#include <mcpost/metrics.h>
#include <mcpost/progress.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The keys: the options of the metrics table that a job takes (ops/op_metrics.c),
 * filled in by stages.c before the table is first handed out. */
const char *mcp__metrics_keys[MCP__OPTION_KEYS_MAX];

/* ---- report pieces ---- */

/* Firmino et al. 2024's error-percentile plot: the sorted per-value RelSE against the
 * percentile on a logit axis, log error; an estimate (a per-value estimated RelSE map,
 * e.g. SURE^r) beside it when given. */
static int
percentile_plot(cJSON *section, const mcp_image *relse, const mcp_image *estimate,
                const char *estimate_name)
{
    enum { N = 48 };
    double p[N], truth[N], est[N];
    double n = (double)relse->width * relse->height * relse->channels;
    double p_hi = 1.0 - 1.0 / n < 0.9999 ? 1.0 - 1.0 / n : 0.9999, p_lo = 0.5;
    if (!(p_hi > p_lo)) return 0; /* too few values for a curve */
    double z0 = mcp_logit(p_lo), z1 = mcp_logit(p_hi);
    for (int i = 0; i < N; i++)
        p[i] = mcp_logistic(z0 + (z1 - z0) * i / (N - 1));
    if (mcp_image_percentiles(relse, p, N, truth)) return -1;
    cJSON *plot = mcp_report_add_plot(section, "error percentiles (Firmino et al. 2024)",
                                      "percentile", MCP_AXIS_LOGIT,
                                      "relative squared error", MCP_AXIS_LOG);
    if (!plot ||
        !mcp_report_plot_add_series(plot, "true RelSE", MCP_SERIES_LINE, p, truth, N))
        return -1;
    if (estimate) {
        cJSON *s;
        if (mcp_image_percentiles(estimate, p, N, est) ||
            !(s = mcp_report_plot_add_series(plot, estimate_name, MCP_SERIES_LINE, p, est,
                                             N)) ||
            mcp_report_series_set_dashed(s, 1))
            return -1;
    }
    return 0;
}

/* FLIP's statistics of a second test (compare:) beside the input's. */
static void
add_flip_figures(cJSON *obj, const char *key, const mcp_flip_result *f)
{
    cJSON *o = cJSON_AddObjectToObject(obj, key);
    if (!o) return;
    cJSON_AddNumberToObject(o, "mean", f->mean);
    cJSON_AddNumberToObject(o, "weighted_median", f->stats.weighted_median);
    cJSON_AddNumberToObject(o, "weighted_q1", f->stats.weighted_q1);
    cJSON_AddNumberToObject(o, "weighted_q3", f->stats.weighted_q3);
    cJSON_AddNumberToObject(o, "min", f->stats.min);
    cJSON_AddNumberToObject(o, "max", f->stats.max);
}

/* FLIP's weighted histogram as its tool plots it (each bucket's count times its
 * centre, per megapixel; flip.h), a plot per FLIP; with a second test (compare:) its
 * bars overlap the input's, as the tool's overlapped histogram of two tests. The
 * counts stay in report.json (flip_histogram), not in the figures table. */
int
mcp__metrics_flip_histograms(cJSON *section, const mcp_metrics *m, const char *input,
                             const mcp_flip_result cmp[2], const char *compare_name)
{
    enum { B = MCP_FLIP_HISTOGRAM_BUCKETS };
    double x[B], y[B];
    for (int i = 0; i < B; i++)
        x[i] = (i + 0.5) / B;
    for (int hdr = 0; hdr < 2; hdr++) {
        if (!(hdr ? m->has_flip_hdr : m->has_flip_ldr)) continue;
        cJSON *plot = mcp_report_add_plot(
            section, hdr ? "weighted HDR-FLIP histogram" : "weighted LDR-FLIP histogram",
            "FLIP error", MCP_AXIS_LINEAR, "weighted FLIP sum per megapixel",
            MCP_AXIS_LINEAR);
        if (!plot) return -1;
        for (int t = 0; t < (compare_name ? 2 : 1); t++) {
            const mcp_flip_stats *st = t     ? &cmp[hdr].stats
                                       : hdr ? &m->flip_hdr.stats
                                             : &m->flip_ldr.stats;
            for (int i = 0; i < B; i++)
                y[i] = mcp_flip_weighted_bucket(st, i);
            if (!mcp_report_plot_add_series(plot, t ? compare_name : input,
                                            MCP_SERIES_BARS, x, y, B))
                return -1;
        }
    }
    return mcp_report_json_only(section, "flip_histogram");
}

/* A render's picture for the page: rel (a .png) as a screen shows it, and beside it the
 * same name in .exr with its linear RGB, which the page re-exposes and tone-maps with
 * its display controls (report.h; as the compare page's renders). */
static int
write_preview(mcp_job *job, const mcp_image *img, const char *rel, cJSON *section,
              const char *caption)
{
    char path[4096], rel_exr[1300], exr_path[4096];
    int rgb[3];
    mcp_image *view = NULL;
    snprintf(rel_exr, sizeof rel_exr, "%.*s.exr", (int)(strlen(rel) - strlen(".png")),
             rel);
    if (mcp_rgb_channels(img, rgb) || mcp_job_output_path(job, rel, path, sizeof path) ||
        mcp_job_output_path(job, rel_exr, exr_path, sizeof exr_path) ||
        mcp_image_copy_channels(img, rgb, 3, &view))
        return -1;
    /* Displayed as the PNG writer shows linear values: clamped and sRGB-encoded. */
    mcp_image *shown = NULL;
    int rc = mcp_tonemap_apply(view, MCP_TONEMAP_CLAMP, &shown) ||
             mcp_image_write(shown, path, NULL) ||
             mcp_image_write(view, exr_path, NULL) ||
             !mcp_report_add_hdr_image(section, rel, rel_exr, caption);
    mcp_image_free(shown);
    mcp_image_free(view);
    return rc ? -1 : 0;
}

/* Error-vs-spp curves: every member of a series against the reference. */
/* FLIP's 0..1 scale in words (a rough reading guide; docs/report.md). */
static const char *
flip_words(double flip)
{
    return flip < 0.01   ? "practically identical"
           : flip < 0.05 ? "differences only on close inspection"
           : flip < 0.1  ? "differences noticeable"
           : flip < 0.2  ? "differences visible at a glance"
                         : "strongly different";
}

static double
number_of(const cJSON *v)
{
    return cJSON_IsNumber(v) ? v->valuedouble : NAN;
}

static double
member_number(const cJSON *obj, const char *key)
{
    return number_of(cJSON_GetObjectItem(obj, key));
}

/* The metrics section's verdict, from its figures: the relative error in percent,
 * FLIP in words, and over a series how fast the MSE falls (1/spp when unbiased). */
int
mcp__metrics_verdict(cJSON *section, const mcp__gate *gate, mcp__gate_verdict gv,
                     const char *gate_line)
{
    char text[3000] = "";
    int len = 0;
    /* A gate decides the colour (pass good, warning info, failure bad) and its line
     * comes first: it is what the job was asked to check. */
    if (gate->n) len += snprintf(text, sizeof text, "gate %s", gate_line);
    double relmse = member_number(section, "relmse");
    double fh = member_number(cJSON_GetObjectItem(section, "flip_hdr"), "mean"),
           fl = member_number(cJSON_GetObjectItem(section, "flip_ldr"), "mean");
    if (!isnan(relmse))
        len += snprintf(text + len, sizeof text - len,
                        "%srelMSE %.3g (RMS relative error about %.2g%%)",
                        len ? "; " : "", relmse, 100 * sqrt(relmse));
    if (!isnan(fh) || !isnan(fl))
        len += snprintf(text + len, sizeof text - len, "%s%s mean %.3g on 0..1: %s",
                        len ? "; " : "", isnan(fh) ? "LDR-FLIP" : "HDR-FLIP",
                        isnan(fh) ? fl : fh, flip_words(isnan(fh) ? fl : fh));
    /* the series table: first and last rows' spp and MSE */
    const cJSON *t = cJSON_GetArrayItem(cJSON_GetObjectItem(section, "tables"), 0);
    const cJSON *rows = cJSON_GetObjectItem(t, "rows");
    int n = cJSON_GetArraySize(rows);
    if (n > 1) {
        const cJSON *a = cJSON_GetArrayItem(rows, 0),
                    *z = cJSON_GetArrayItem(rows, n - 1);
        double s0 = number_of(cJSON_GetArrayItem(a, 0)),
               s1 = number_of(cJSON_GetArrayItem(z, 0)),
               m0 = number_of(cJSON_GetArrayItem(a, 1)),
               m1 = number_of(cJSON_GetArrayItem(z, 1));
        double slope = log(m1 / m0) / log(s1 / s0);
        if (isfinite(slope))
            snprintf(text + len, sizeof text - len,
                     "%sMSE falls as spp^%.2f from %g to %g spp (an unbiased render: "
                     "spp^-1)",
                     len ? "; " : "", slope, s0, s1);
    }
    mcp_verdict level = !gate->n                  ? MCP_VERDICT_INFO
                        : gv == MCP__GATE_FAILURE ? MCP_VERDICT_BAD
                        : gv == MCP__GATE_WARNING ? MCP_VERDICT_INFO
                                                  : MCP_VERDICT_GOOD;
    return mcp_report_set_verdict(section, level, "%s",
                                  *text ? text : "no figure to judge by (see the table)");
}

static int
series_curves(mcp_job *job, const mcp_node *settings, const mcp_series *series,
              const mcp_image *ref, const mcp_metrics_options *opt, cJSON *section)
{
    int n = series->count, rc = -1;
    mcp_metrics_options o = *opt;
    o.n_percentiles = 0;
    o.spectra = 0;
    o.n_above = 0; /* the gates judge the input, not the series */
    double *v = mcp_calloc((size_t)n * 8, sizeof *v);
    if (!v) return -1;
    double *spp = v, *mse = v + n, *rmse = v + 2 * n, *rel = v + 3 * n, *psnr = v + 4 * n,
           *pmse = v + 5 * n, *fl = v + 6 * n, *fh = v + 7 * n;
    cJSON *table =
        mcp_report_add_table(section, "error against the reference per sample count",
                             (const char *const[]){"spp", "MSE", "RMSE", "relMSE", "PSNR",
                                                   "pMSE", "LDR-FLIP", "HDR-FLIP"},
                             8);
    if (!table) goto done;
    mcp_progress prog;
    mcp_progress_begin(&prog, "metrics: series", n);
    for (int i = 0; i < n; i++) {
        mcp_dump *d = NULL;
        mcp_metrics m;
        if (mcp_series_load(series, i, &d)) {
            mcp_progress_end(&prog);
            mcp__at_line(settings, "series");
            goto done;
        }
        spp[i] = series->spp && series->spp[i] > 0 ? series->spp[i] : d->spp;
        int failed = mcp_metrics_compute(d->color, ref, &o, &m, NULL);
        mcp_dump_free(d);
        if (failed) {
            mcp_progress_end(&prog);
            goto done;
        }
        mse[i] = m.mse;
        rmse[i] = m.rmse;
        rel[i] = m.relmse;
        psnr[i] = m.psnr;
        pmse[i] = m.pmse;
        fl[i] = m.has_flip_ldr ? m.flip_ldr.mean : NAN;
        fh[i] = m.has_flip_hdr ? m.flip_hdr.mean : NAN;
        if (mcp_report_table_add_row(table, "dddddddd", spp[i], mse[i], rmse[i], rel[i],
                                     psnr[i], pmse[i], fl[i], fh[i])) {
            mcp_progress_end(&prog);
            goto done;
        }
        mcp_progress_update(&prog, i + 1);
    }
    mcp_progress_end(&prog);
    cJSON *plot = mcp_report_add_plot(section, "error against samples per pixel", "spp",
                                      MCP_AXIS_LOG, "error", MCP_AXIS_LOG);
    if (!plot ||
        !mcp_report_plot_add_series(plot, "MSE", MCP_SERIES_LINE_POINTS, spp, mse, n) ||
        !mcp_report_plot_add_series(plot, "relMSE", MCP_SERIES_LINE_POINTS, spp, rel,
                                    n) ||
        !mcp_report_plot_add_series(plot, "pMSE", MCP_SERIES_LINE_POINTS, spp, pmse, n))
        goto done;
    /* An unbiased estimator's MSE falls as 1/spp: a guide through the first point. */
    if (n > 1 && spp[0] > 0 && mse[0] > 0) {
        double gx[2] = {spp[0], spp[n - 1]},
               gy[2] = {mse[0], mse[0] * spp[0] / spp[n - 1]};
        cJSON *g = mcp_report_plot_add_series(plot, "1/spp", MCP_SERIES_LINE, gx, gy, 2);
        if (!g || mcp_report_series_set_dashed(g, 1)) goto done;
    }
    if (o.flip_ldr || o.flip_hdr) {
        cJSON *fp = mcp_report_add_plot(section, "FLIP against samples per pixel", "spp",
                                        MCP_AXIS_LOG, "mean FLIP", MCP_AXIS_LOG);
        if (!fp ||
            (o.flip_ldr && !mcp_report_plot_add_series(
                               fp, "LDR-FLIP", MCP_SERIES_LINE_POINTS, spp, fl, n)) ||
            (o.flip_hdr && !mcp_report_plot_add_series(
                               fp, "HDR-FLIP", MCP_SERIES_LINE_POINTS, spp, fh, n)))
            goto done;
    }
    (void)job;
    rc = 0;
done:
    free(v);
    return rc;
}

/* ---- the stage ---- */

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): the options through the metrics table and the names of
 * what it compares, each checked against the job's inputs and earlier results. Strings
 * are borrowed from the settings. */
typedef struct metrics_plan {
    mcp_metrics_settings s;
    mcp_shared_settings sh;
    mcp_metrics_options o; /* s.o with the shares of pixels the gates judge */
    mcp__gate gate;
} metrics_plan;

/* The gate's error at the condition's line, without the flag's "--fail " (the key says
 * it); copied first, as mcp_node_error rewrites the error line that it would read. */
static int
gate_error(const mcp_node *settings, const char *key, int index)
{
    char msg[1024];
    const char *m = mcp_error_message();
    /* "--fail-percent 'x': ..." -> "'x': ..." */
    const char *after_flag =
        strncmp(m, "--", 2) || !strchr(m, ' ') ? m : strchr(m, ' ') + 1;
    snprintf(msg, sizeof msg, "%s", after_flag);
    const mcp_node *n = mcp_node_get(settings, key);
    const mcp_node *item =
        n && n->kind == MCP_NODE_SEQ && index < n->count ? n->items[index] : n;
    return mcp_node_error(item, "%s: %s", key, msg);
}

static int
parse_metrics(mcp_job *job, const mcp_node *settings, metrics_plan *pl)
{
    memset(pl, 0, sizeof *pl);
    const char *bad_key = NULL;
    int bad_index = -1;
    if (mcp__job_settings(mcp_operation_metrics(), settings, &pl->sh, &pl->s)) return -1;
    pl->o = pl->s.o;
    if (mcp__gate_from_settings(&pl->s, &pl->o, &pl->gate, &bad_key, &bad_index))
        return gate_error(settings, bad_key, bad_index);
    if (pl->gate.n && !pl->s.input) {
        static const char *const keys[] = {"fail", "warn", "fail_percent",
                                           "warn_percent"};
        const mcp_node *at = NULL;
        for (int k = 0; k < 4 && !at; k++)
            at = mcp_node_get(settings, keys[k]);
        return mcp_node_error(
            at, "a gate (fail:, warn:, fail_percent:, warn_percent:) judges "
                "'input' against the reference; give 'input'");
    }
    if (pl->s.compare && !pl->s.input)
        return mcp_node_error(mcp_node_get(settings, "compare"),
                              "'compare' needs 'input' (the image it is drawn beside)");
    if (pl->s.compare && !pl->o.flip_ldr && !pl->o.flip_hdr)
        return mcp_node_error(mcp_node_get(settings, "compare"),
                              "'compare' overlaps FLIP histograms, but flip is none");
    if (!pl->s.reference) {
        const mcp_node *n = NULL;
        return mcp_node_require(settings, "reference", "stage 'metrics'", &n);
    }
    if (!pl->s.input && !pl->s.series)
        return mcp_node_error(settings,
                              "stage 'metrics' needs 'input' or 'series' (or both)");
    if (pl->s.estimate && !pl->s.input)
        return mcp_node_error(mcp_node_get(settings, "estimate"),
                              "'estimate' needs 'input' (the image it estimates)");
    return mcp_job_check_input(job, settings, "reference", MCP_JOB_IMAGE) ||
                   (pl->s.input &&
                    mcp_job_check_input(job, settings, "input", MCP_JOB_IMAGE)) ||
                   (pl->s.estimate &&
                    mcp_job_check_input(job, settings, "estimate", MCP_JOB_IMAGE)) ||
                   (pl->s.compare &&
                    mcp_job_check_input(job, settings, "compare", MCP_JOB_IMAGE)) ||
                   (pl->s.series &&
                    mcp_job_check_input(job, settings, "series", MCP_JOB_SERIES))
               ? -1
               : 0;
}

static int
check_metrics(mcp_job *job, const mcp_node *settings)
{
    metrics_plan pl;
    return parse_metrics(job, settings, &pl);
}

static int
stage_metrics(mcp_job *job, const mcp_node *settings)
{
    metrics_plan pl;
    if (parse_metrics(job, settings, &pl)) return -1;
    mcp_metrics_options o = pl.o;
    const char *input = pl.s.input, *reference = pl.s.reference, *output = pl.sh.output,
               *series_name = pl.s.series, *estimate_name = pl.s.estimate;
    int want_maps = pl.s.maps;

    const mcp_image *ref = NULL, *test = NULL, *estimate = NULL, *compare = NULL;
    const mcp_series *series = NULL;
    if (mcp_job_image(job, settings, "reference", &ref) ||
        (input && mcp_job_image(job, settings, "input", &test)) ||
        (pl.s.compare && mcp_job_image(job, settings, "compare", &compare)) ||
        (estimate_name && mcp_job_image(job, settings, "estimate", &estimate)) ||
        (series_name && mcp_job_series(job, settings, "series", &series)))
        return -1;

    char default_title[512], prefix[1024];
    snprintf(default_title, sizeof default_title, "metrics: %s against %s",
             input ? input : series_name, reference);
    snprintf(prefix, sizeof prefix, "%s/", output ? output : input ? input : series_name);
    cJSON *section = mcp_report_section(mcp_job_report(job), "metrics", default_title);
    if (!section) return -1;
    cJSON_AddStringToObject(section, "reference", reference);
    cJSON_AddNumberToObject(section, "width", ref->width);
    cJSON_AddNumberToObject(section, "height", ref->height);

    int rc = -1;
    mcp_metrics_maps maps = {0};
    if (test) {
        mcp_metrics m;
        cJSON_AddStringToObject(section, "input", input);
        if (estimate && !mcp_image_same_size(estimate, test)) {
            mcp__at_line(settings, "estimate");
            goto done;
        }
        mcp_note("metrics: %s against %s", input, reference);
        if (mcp_metrics_compute(test, ref, &o, &m, &maps) ||
            mcp_metrics_json(&m, &o, section))
            goto done;
        mcp_flip_result cmp[2];
        memset(cmp, 0, sizeof cmp);
        if (compare) {
            /* the second test's FLIPs only: its histogram and statistics */
            cJSON *c = cJSON_AddObjectToObject(section, "compare");
            if (!c) goto done;
            cJSON_AddStringToObject(c, "input", pl.s.compare);
            mcp_note("metrics: FLIP of %s against %s", pl.s.compare, reference);
            if ((o.flip_ldr && mcp_flip_ldr(compare, ref, &o.flip, &cmp[0], NULL)) ||
                (o.flip_hdr &&
                 mcp_flip_hdr(compare, ref, &o.flip, &cmp[1], NULL, NULL))) {
                mcp__at_line(settings, "compare");
                goto done;
            }
            if (o.flip_ldr) add_flip_figures(c, "flip_ldr", &cmp[0]);
            if (o.flip_hdr) add_flip_figures(c, "flip_hdr", &cmp[1]);
        }
        if (percentile_plot(section, maps.relse, estimate, estimate_name) ||
            mcp__metrics_flip_histograms(section, &m, input, cmp,
                                         compare ? pl.s.compare : NULL))
            goto done;
        if (want_maps) {
            char rel_t[1200], rel_r[1200], path[4096];
            snprintf(rel_t, sizeof rel_t, "%stest.png", prefix);
            snprintf(rel_r, sizeof rel_r, "%sreference.png", prefix);
            /* mcp_job_output_path creates the folders of prefix */
            if (mcp_job_output_path(job, rel_t, path, sizeof path) ||
                write_preview(job, test, rel_t, section, input) ||
                write_preview(job, ref, rel_r, section, reference) ||
                mcp_metrics_write_maps(&maps, mcp_job_output_dir(job), prefix, section))
                goto done;
        }
    }
    if (series && series_curves(job, settings, series, ref, &o, section)) goto done;
    mcp__gate_verdict gv = MCP__GATE_PASS;
    char gate_line[2200] = "";
    if (pl.gate.n) {
        cJSON *gj = NULL;
        if (mcp__gate_eval(&pl.gate, section, &gv, &gj, gate_line, sizeof gate_line)) {
            mcp__at_line(settings, mcp_node_get(settings, "fail") ? "fail" : "warn");
            goto done;
        }
        cJSON_AddItemToObject(section, "gate", gj);
        mcp_note("metrics: gate %s", gate_line);
        /* `mcpost run` exits with the job's worst gate (cli/cmd_run.c) */
        mcp__gate_record(gv);
    }
    if (mcp__metrics_verdict(section, &pl.gate, gv, gate_line)) goto done;
    rc = 0;
done:
    mcp_metrics_maps_free(&maps);
    return rc;
}

const mcp_stage mcp_stage_metrics = {"metrics",
                                     "compare an input and/or a series with a "
                                     "reference (MSE, relMSE, PSNR, pMSE, FLIP, "
                                     "RelSE percentiles, blue noise) with maps and "
                                     "plots",
                                     mcp__metrics_keys, stage_metrics, check_metrics};
