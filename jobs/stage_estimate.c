/* stage_estimate.c: the `estimate` job stage -- how wrong a denoised dump or series is
 * and whether to stop (estimate/estimate.h; docs/estimate.md). The keys are the flags
 * of `mcpost estimate` with '_' for '-'; the outputs are estimate_output.c's. */
#include "internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const estimate_keys[] = {
    "input",           "denoiser", "metric", "tau",      "percentile",
    "percentiles",     "probes",   "seed",   "mc_sure",  "delta",
    "variance_probes", "ppd",      "tile",   "sampling", "budget",
    "reference",       "taus",     "output", "s2_pool",  "title", NULL};

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
    return mcp__variance_probes_from_name(s, out);
}

/* s2_pool: a radius, or auto (mcp_estimate_auto_s2_pool), as --s2-pool and Python take */
static int
read_s2_pool(const mcp_node *s, int *out)
{
    const mcp_node *n = mcp_node_get(s, "s2_pool");
    if (n && n->kind == MCP_NODE_SCALAR && n->value && !strcmp(n->value, "auto")) {
        *out = -1;
        return 0;
    }
    return mcp_node_opt_int(s, "s2_pool", out);
}

static int
read_settings(const mcp_node *s, mcp_series_estimate_options *so)
{
    mcp_estimate_options *o = &so->est;
    double *p = NULL, *taus = NULL, seed = 0, budget = 0;
    int np = 0, nt = 0, rc = -1;
    if (mcp__opt_enum(s, "metric", parse_metric, &o->sure.metric) ||
        mcp_node_opt_double(s, "tau", &o->tau) ||
        mcp_node_opt_double(s, "percentile", &o->p) ||
        mcp_node_opt_doubles(s, "percentiles", &p, &np) ||
        mcp_node_opt_int(s, "probes", &o->sure.n_probes) ||
        mcp_node_opt_double(s, "seed", &seed) ||
        mcp_node_opt_bool(s, "mc_sure", &o->sure.mc_sure) ||
        mcp_node_opt_double(s, "delta", &o->sure.fd_delta) ||
        mcp__opt_enum(s, "variance_probes", parse_vprobes, &o->variance_rademacher) ||
        mcp_node_opt_double(s, "ppd", &o->sure.ppd) ||
        mcp_node_opt_int(s, "tile", &o->blocks.tile_size) ||
        mcp__opt_enum(s, "sampling", parse_sampling, &o->sampling.kind) ||
        mcp_node_opt_double(s, "budget", &budget) ||
        read_s2_pool(s, &o->s2_pool) ||
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
    if (mcp__stage_denoiser(job, settings, &pl->den))
        return mcp_node_get(settings, "denoiser") ? mcp__at_line(settings, "denoiser") : -1;
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
        bad = bad || !text || mcp__estimate_write_single(e, &od, section, j) ||
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
    estimate_keys, stage_estimate, check_estimate};
