/* stage_adaptive.c: the `adaptive` job stage -- the adaptive-sampling loop against a
 * render command (adaptive_loop.c; docs/adaptive.md). The keys are the options of
 * the adaptive table (ops/op_adaptive.c), as `mcpost adaptive` reads them. */
#include "internal.h"

#include <stdio.h>
#include <string.h>

/* The keys: the options of the adaptive table that a job takes (ops/op_adaptive.c),
 * filled in by stages.c before the table is first handed out. */
const char *mcp__adaptive_keys[MCP__OPTION_KEYS_MAX];

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): the loop's options through the adaptive table, the
 * size, the reference by name (checked against the job's inputs) and the denoiser,
 * created from its settings. */
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
    mcp_adaptive_settings st;
    mcp_shared_settings sh;
    const mcp_node *render = NULL;
    if (mcp_node_require(s, "render", "adaptive", &render) ||
        mcp__job_settings(mcp_operation_adaptive(), s, &sh, &st))
        return -1;
    c->ao = st.ao;
    c->render = st.render;
    c->seed = st.seed;
    c->keep_passes = st.keep_passes;
    pl->sub = sh.output ? sh.output : "adaptive";
    pl->ref_name = st.reference;
    if (st.size && mcp__parse_size(st.size, &c->width, &c->height))
        return mcp_node_error(mcp_node_get(s, "size"), "%s", mcp_error_message());
    pl->have_size = st.size != NULL;
    if (pl->ref_name && mcp_job_check_input(job, s, "reference", MCP_JOB_IMAGE))
        return -1;
    if (!st.size && !pl->ref_name)
        return mcp_node_error(s, "adaptive: give the image size (size: WxH) or a "
                                 "reference");
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
    mcp__adaptive_keys, stage_adaptive, check_adaptive};
