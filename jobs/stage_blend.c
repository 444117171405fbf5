/* stage_blend.c: the `blend` job stage -- a series blended with its denoised images so
 * that it converges (blend_run.c; docs/blend.md). The keys are the options of the
 * blend's table (ops/op_blend.c), as `mcpost blend` and Python read them. */
#include "internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The keys: the options of the blend's table that a job takes (ops/op_blend.c),
 * filled in by stages.c before the table is first handed out. */
const char *mcp__blend_keys[MCP__OPTION_KEYS_MAX];

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): the options through the blend's table, the series and
 * reference by name (checked against the job's inputs) and the denoiser, created from
 * its settings. Strings are borrowed from the settings; the denoiser is the plan's. */
typedef struct blend_plan {
    mcp_blend_settings s;
    mcp_shared_settings sh;
    mcp_denoiser *den;
} blend_plan;

static int
parse_blend(mcp_job *job, const mcp_node *settings, blend_plan *pl)
{
    const mcp_node *input_node = NULL;
    memset(pl, 0, sizeof *pl);
    if (mcp__job_settings(mcp_operation_blend(), settings, &pl->sh, &pl->s) ||
        mcp_node_require(settings, "input", "stage 'blend'", &input_node) ||
        mcp_job_check_input(job, settings, "input", MCP_JOB_SERIES) ||
        (pl->s.reference &&
         mcp_job_check_input(job, settings, "reference", MCP_JOB_IMAGE)) ||
        mcp__stage_denoiser(job, settings, &pl->den))
        return -1;
    return 0;
}

static int
check_blend(mcp_job *job, const mcp_node *settings)
{
    blend_plan pl;
    int rc = parse_blend(job, settings, &pl);
    mcp_denoiser_free(pl.den);
    return rc;
}

static int
stage_blend(mcp_job *job, const mcp_node *settings)
{
    blend_plan pl;
    const mcp_series *series = NULL;
    const mcp_image *ref = NULL;
    if (parse_blend(job, settings, &pl) ||
        mcp_job_series(job, settings, "input", &series) ||
        (pl.s.reference && mcp_job_image(job, settings, "reference", &ref))) {
        mcp_denoiser_free(pl.den);
        return -1;
    }
    mcp_blend_series_options o = pl.s.o;
    const char *input = pl.s.input, *output = pl.sh.output;
    int all_images = pl.s.all_images;
    mcp_denoiser *den = pl.den;
    const char *den_name = den->name;
    mcp__blend_sink sink;
    memset(&sink, 0, sizeof sink);
    char rel[1024], path[4200];
    const char *sub = output ? output : "blend";
    snprintf(rel, sizeof rel, "%s/", sub);
    sink.rel = rel;
    sink.all_images = all_images;
    int rc = -1;
    if (mcp_job_output_subdir(job, sub, sink.dir, sizeof sink.dir) == 0) {
        char default_title[600];
        snprintf(default_title, sizeof default_title, "blend: %s with %s", input,
                 den_name);
        cJSON *section = mcp_report_section(mcp_job_report(job), "blend", default_title);
        if (section &&
            mcp__blend_run(series, den, ref, &o, den_name, &sink, section) == 0) {
            char *text = cJSON_Print(section);
            snprintf(path, sizeof path, "%s/blend.json", sink.dir);
            rc = text && mcp_write_file_atomic(path, text, strlen(text)) == 0 ? 0 : -1;
            free(text);
            if (rc == 0) mcp_note("blend: %s: %d members", input, series->count);
        }
    }
    mcp_denoiser_free(den);
    return rc;
}

const mcp_stage mcp_stage_blend = {"blend",
                                   "blend a series with its denoised images so that it "
                                   "converges (Denisova & Bocchi 2024), comparing noisy, "
                                   "denoised, easy, curves, ideal and James-Stein",
                                   mcp__blend_keys, stage_blend, check_blend};
