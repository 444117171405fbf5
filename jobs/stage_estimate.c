/* stage_estimate.c: the `estimate` job stage -- how wrong a denoised dump or series is
 * and whether to stop (estimate/estimate.h; docs/estimate.md). The keys are the options
 * of the estimate's table (ops/op_estimate.c), as `mcpost estimate` and Python read
 * them; the outputs are estimate_output.c's. */
#include "internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The keys: the options of the estimate's table that a job takes (ops/op_estimate.c),
 * filled in by stages.c before the table is first handed out. */
const char *mcp__estimate_keys[MCP__OPTION_KEYS_MAX];

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): the options through the estimate's table, the names
 * of the input (a dump or a series) and the reference, checked against the job's
 * inputs, and the denoiser, created from its settings (its files read). Strings are
 * borrowed from the settings; the denoiser is the plan's. */
typedef struct estimate_plan {
    mcp_estimate_settings s;
    mcp_shared_settings sh;
    mcp_denoiser *den;
} estimate_plan;

static int
parse_estimate(mcp_job *job, const mcp_node *settings, estimate_plan *pl)
{
    memset(pl, 0, sizeof *pl);
    if (mcp__job_settings(mcp_operation_estimate(), settings, &pl->sh, &pl->s) ||
        mcp_job_check_input(job, settings, "input", MCP_JOB_SERIES | MCP_JOB_DUMP) ||
        (pl->s.reference &&
         mcp_job_check_input(job, settings, "reference", MCP_JOB_IMAGE)))
        return -1;
    if (mcp__stage_denoiser(job, settings, &pl->den))
        return mcp_node_get(settings, "denoiser") ? mcp__at_line(settings, "denoiser")
                                                  : -1;
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
    mcp_series_estimate_options so = pl.s.so;
    const char *name = pl.s.input, *sub = pl.sh.output ? pl.sh.output : "estimate",
               *ref_name = pl.s.reference;
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
    mcp__estimate_dir od;
    memset(&od, 0, sizeof od);
    snprintf(od.rel, sizeof od.rel, "%s/", sub);
    if (mcp_job_output_subdir(job, sub, od.dir, sizeof od.dir)) goto done;
    cJSON *section = mcp_report_section(mcp_job_report(job), "estimate", name);
    if (!section) goto done;
    if (series) {
        cJSON *j = NULL;
        mcp_series_estimate *s = NULL;
        if (mcp__estimate_run_series(series, den, &so, ref, &od, section, &j, &s))
            goto done;
        mcp_note("%s: %d members, %d thresholds", name, s->count, s->n_taus);
        cJSON_Delete(j);
        mcp_series_estimate_free(s);
    } else {
        mcp_estimate *e = NULL;
        if (mcp_estimate_compute(dump, den, &so.est, &e)) goto done;
        cJSON *j = mcp__estimate_json(e, name, den->name, &so.est);
        /* reference: the truth beside the estimate, as `mcpost estimate --ref` */
        int bad = ref && mcp__estimate_add_truth(e, ref, &so.est, j);
        char path[4352];
        char *text = bad ? NULL : cJSON_Print(j);
        bad = bad || !text || mcp__estimate_write_single(e, &od, section, j, NULL) ||
              mcp__estimate_path(&od, "estimate.json", path, sizeof path) ||
              mcp_write_file_atomic(path, text, strlen(text)) ||
              mcp__estimate_report_single(section, j, e);
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
    mcp__estimate_keys, stage_estimate, check_estimate};
