/* stage_adaptive.c: the `adaptive` job stage -- the adaptive-sampling loop against a
 * render command (adaptive_loop.c; docs/adaptive.md). */
#include "internal.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

static const char *const adaptive_keys[] = {
    "render",         "output",   "size",   "map",         "spp_per_iteration",
    "initial_spp",    "budget",   "stop",   "tau",         "p",
    "max_iterations", "quantum",  "probes", "seed",        "reference",
    "keep_passes",    "denoiser", "title",  "uniform_mix", NULL};

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): the loop's options, the size, the reference by name
 * (checked against the job's inputs) and the denoiser, created from its settings. */
typedef struct adaptive_plan {
    mcp__adaptive_loop c;
    const char *sub, *ref_name;
    int have_size;
    mcp_denoiser *den;
} adaptive_plan;

static int
parse_adaptive(mcp_job *job, const mcp_node *s, adaptive_plan *pl)
{
    memset(pl, 0, sizeof *pl);
    mcp__adaptive_loop *c = &pl->c;
    c->ao = mcp_adaptive_defaults();
    pl->sub = "adaptive";
    const char *map = NULL, *size = NULL;
    double seed = 1;
    const mcp_node *render = NULL;
    if (mcp_node_require(s, "render", "adaptive", &render) ||
        mcp_node_string(render, "render", &c->render) ||
        mcp_node_opt_string(s, "output", &pl->sub) ||
        mcp_node_opt_string(s, "map", &map) || mcp_node_opt_string(s, "size", &size) ||
        mcp_node_opt_string(s, "reference", &pl->ref_name) ||
        mcp_node_opt_double(s, "spp_per_iteration", &c->ao.spp_per_iteration) ||
        mcp_node_opt_double(s, "initial_spp", &c->ao.initial_spp) ||
        mcp_node_opt_double(s, "budget", &c->ao.budget_spp) ||
        mcp_node_opt_bool(s, "stop", &c->ao.stop_on_estimate) ||
        mcp_node_opt_double(s, "tau", &c->ao.est.tau) ||
        mcp_node_opt_double(s, "p", &c->ao.est.p) ||
        mcp_node_opt_int(s, "max_iterations", &c->ao.max_iterations) ||
        mcp_node_opt_int(s, "quantum", &c->ao.quantum) ||
        mcp_node_opt_double(s, "uniform_mix", &c->ao.uniform_mix) ||
        mcp_node_opt_int(s, "probes", &c->ao.est.sure.n_probes) ||
        mcp_node_opt_double(s, "seed", &seed) ||
        mcp_node_opt_bool(s, "keep_passes", &c->keep_passes))
        return -1;
    if (map && mcp_adaptive_map_from_name(map, &c->ao.map))
        return mcp_node_error(mcp_node_get(s, "map"), "%s", mcp_error_message());
    if (seed < 0 || seed != floor(seed) || seed > 9007199254740992.0)
        return mcp_node_error(mcp_node_get(s, "seed"),
                              "seed must be a whole number >= 0 (got %g)", seed);
    c->seed = (uint64_t)seed;
    c->ao.est.sure.seed = c->seed;
    if (size && mcp__parse_size(size, &c->width, &c->height))
        return mcp_node_error(mcp_node_get(s, "size"), "%s", mcp_error_message());
    pl->have_size = size != NULL;
    if (pl->ref_name && mcp_job_check_input(job, s, "reference", MCP_JOB_IMAGE)) return -1;
    if (!size && !pl->ref_name)
        return mcp_node_error(s, "adaptive: give the image size (size: WxH) or a "
                                 "reference");
    if (mcp_adaptive_check(&c->ao)) return mcp_node_error(s, "%s", mcp_error_message());
    return mcp__stage_denoiser(job, s, &pl->den);
}

static int
check_adaptive(mcp_job *job, const mcp_node *s)
{
    adaptive_plan pl;
    int rc = parse_adaptive(job, s, &pl);
    mcp_denoiser_free(pl.den);
    return rc;
}

static int
stage_adaptive(mcp_job *job, const mcp_node *s)
{
    adaptive_plan pl;
    mcp__adaptive_loop *c = &pl.c;
    int rc = -1;
    if (parse_adaptive(job, s, &pl) ||
        (pl.ref_name && mcp_job_image(job, s, "reference", &c->reference)))
        goto done;
    if (!pl.have_size) c->width = c->reference->width, c->height = c->reference->height;
    snprintf(c->rel, sizeof c->rel, "%s/", pl.sub);
    if (mcp_job_output_subdir(job, pl.sub, c->dir, sizeof c->dir)) goto done;
    c->den = pl.den;
    c->section = mcp_report_section(mcp_job_report(job), "adaptive", "adaptive sampling");
    rc = c->section ? mcp__adaptive_run_loop(c, NULL) : -1;
done:
    mcp_denoiser_free(pl.den);
    return rc;
}

const mcp_stage mcp_stage_adaptive = {
    "adaptive", "the adaptive-sampling loop against a render command (Firmino 2023)",
    adaptive_keys, stage_adaptive, check_adaptive};
