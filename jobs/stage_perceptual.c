/* stage_perceptual.c: the `perceptual` job stage -- blue-noise error optimisation of a
 * few renders (perceptual_run.c; docs/perceptual.md), its result published for later
 * stages under its name. The keys are the perceptual table's (ops/op_perceptual.c). */
#include "internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The keys: the options of the perceptual table that a job takes
 * (ops/op_perceptual.c), filled in by stages.c before the table is first handed out. */
const char *mcp__perceptual_keys[MCP__OPTION_KEYS_MAX];

/* Loads the candidates: a series input (every member a dump or image) or a list of
 * input names (images or dumps; their colour only). */
static int
stage_candidates(mcp_job *job, const mcp_node *settings, mcp__perc_run *r)
{
    const mcp_node *n = NULL;
    if (mcp_node_require(settings, "candidates", "stage 'perceptual'", &n)) return -1;
    if (n->kind == MCP_NODE_SCALAR) {
        const mcp_series *s = NULL;
        if (mcp_job_series(job, settings, "candidates", &s)) return -1;
        for (int i = 0; i < s->count; i++) {
            mcp_image *img = NULL;
            if (mcp_image_read(s->paths[i], NULL, &img) || mcp__perc_add_file(r, img)) {
                mcp_image_free(img);
                return mcp_node_error(n, "%s", mcp_error_message());
            }
            mcp_image_free(img);
        }
    } else if (n->kind == MCP_NODE_SEQ) {
        for (int i = 0; i < n->count; i++) {
            const char *name;
            if (mcp_node_string(n->items[i], "candidates", &name)) return -1;
            const mcp_image *img = mcp_job_find_image(job, name);
            if (!img)
                return mcp_node_error(
                    n->items[i], "no image input or result called '%s'%s%s", name,
                    *mcp_error_message() ? ": " : "", mcp_error_message());
            if (mcp__perc_add_file(r, img))
                return mcp_node_error(n->items[i], "%s", mcp_error_message());
        }
    } else {
        return mcp_node_error(n,
                              "candidates must name a series input or list image inputs");
    }
    return mcp__perc_finish_features(r);
}

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): through the perceptual table into `a` (as the flags),
 * the result's name and folder, the inputs it names (candidates, reference, surrogate,
 * confidence: checked against the job's inputs and earlier results), the kernel file,
 * and the surrogate's denoiser (*den, the caller's to free). Declares the result for
 * later stages. */
static int
parse_perceptual(mcp_job *job, const mcp_node *settings, mcp__perc_args *a,
                 const char **name, const char **folder, mcp_denoiser **den)
{
    mcp_perceptual_settings st;
    mcp_shared_settings sh;
    *den = NULL;
    if (mcp__job_settings(mcp_operation_perceptual(), settings, &sh, &st)) return -1;
    mcp__perc_args_free(a);
    if (mcp__perc_args_from_settings(&st, a)) {
        /* the kernel's or the confidence's error at its line, else the stage's */
        const char *m = mcp_error_message();
        const char *key = !strncmp(m, "kernel", 6)                    ? "kernel"
                          : !strncmp(m, "perceptual: confidence", 22) ? "confidence"
                                                                      : NULL;
        return key && mcp_node_get(settings, key)
                   ? mcp__at_line(settings, key)
                   : mcp_node_error(settings, "%s", mcp_error_message());
    }
    *name = st.name;
    *folder = sh.output ? sh.output : st.name;
    const mcp_node *n = NULL;
    if (mcp_node_require(settings, "candidates", "stage 'perceptual'", &n)) return -1;
    if (n->kind == MCP_NODE_SCALAR) {
        if (mcp_job_check_name(job, n, MCP_JOB_SERIES)) return -1;
    } else if (n->kind == MCP_NODE_SEQ) {
        for (int i = 0; i < n->count; i++)
            if (mcp_job_check_name(job, n->items[i], MCP_JOB_IMAGE)) return -1;
    } else {
        return mcp_node_error(n,
                              "candidates must name a series input or list image inputs");
    }
    if ((st.reference &&
         mcp_job_check_input(job, settings, "reference", MCP_JOB_IMAGE)) ||
        (strcmp(a->surrogate, "denoise") && strcmp(a->surrogate, "reference") &&
         mcp_job_check_input(job, settings, "surrogate", MCP_JOB_IMAGE)) ||
        (a->confidence &&
         mcp_job_check_input(job, settings, "confidence", MCP_JOB_IMAGE)) ||
        (a->kernel_file &&
         mcp_job_check_file(job, mcp_node_get(settings, "kernel"), "kernel")))
        return -1;
    if (!strcmp(a->surrogate, "denoise") && mcp__stage_denoiser(job, settings, den))
        return -1;
    return mcp_job_declare(job, *name, MCP_JOB_IMAGE);
}

static int
check_perceptual(mcp_job *job, const mcp_node *settings)
{
    mcp__perc_args a;
    mcp__perc_args_init(&a);
    const char *name, *folder;
    mcp_denoiser *den = NULL;
    int rc = parse_perceptual(job, settings, &a, &name, &folder, &den);
    mcp_denoiser_free(den);
    mcp__perc_args_free(&a);
    return rc;
}

static int
stage_perceptual(mcp_job *job, const mcp_node *settings)
{
    mcp__perc_args a;
    mcp__perc_run r;
    mcp__perc_args_init(&a);
    memset(&r, 0, sizeof r);
    int rc = -1;
    const char *name = "perceptual", *folder = name;
    cJSON *summary = NULL;
    mcp_image *kern = NULL, *img = NULL;
    if (parse_perceptual(job, settings, &a, &name, &folder, &r.den) ||
        stage_candidates(job, settings, &r))
        goto done;
    if (mcp_node_get(settings, "reference") &&
        mcp_job_image(job, settings, "reference", &r.reference))
        goto done;
    if (strcmp(a.surrogate, "denoise") && strcmp(a.surrogate, "reference") &&
        mcp_job_image(job, settings, "surrogate", &r.surrogate_img))
        goto done;
    if (a.confidence && mcp_job_image(job, settings, "confidence", &r.confidence_map))
        goto done;
    if (a.kernel_file) {
        char path[4096];
        if (mcp_job_resolve(job, a.kernel_file, path, sizeof path) ||
            mcp_image_read(path, NULL, &kern)) {
            mcp_node_error(mcp_node_get(settings, "kernel"), "%s", mcp_error_message());
            goto done;
        }
        r.kernel_img = kern;
    }
    /* outputs in <job output>/<output, else name>/, images relative to the report */
    snprintf(r.rel, sizeof r.rel, "%s/", folder);
    if (mcp_job_output_subdir(job, folder, r.out_dir, sizeof r.out_dir)) goto done;
    char title[300];
    snprintf(title, sizeof title, "%s: %s", name, mcp_perc_method_name(a.opt.method));
    if (!(r.section = mcp_report_section(mcp_job_report(job), "perceptual", title)) ||
        mcp__perceptual_run(&a, &r, &summary, &img))
        goto done;
    mcp__perc_fill_section(r.section, summary);
    /* the result, for later stages: NAME (the job takes it) */
    const char *m = mcp_perc_method_name(a.opt.method);
    if (mcp_image_set_source(img, name) || mcp_job_put_image(job, name, img)) {
        img = NULL;
        goto done;
    }
    img = NULL;
    const cJSON *pm = cJSON_GetObjectItem(summary, "pmse");
    const cJSON *again = cJSON_GetObjectItem(summary, "rerendered");
    if (cJSON_IsNumber(pm))
        mcp_note("%s: %s %spMSE %.4g (%.3f of the mean's)", name, m,
                 again && !cJSON_IsTrue(again) ? "prediction " : "", pm->valuedouble,
                 cJSON_GetObjectItem(summary, "pmse_ratio")->valuedouble);
    else
        mcp_note("%s: %s done", name, m);
    rc = 0;
done:
    mcp_image_free(img);
    cJSON_Delete(summary);
    mcp_image_free(kern);
    mcp__perc_run_free(&r);
    mcp__perc_args_free(&a);
    return rc;
}

const mcp_stage mcp_stage_perceptual = {
    "perceptual",
    "perceptual error optimisation of few-sample renders, with scores and the comparison "
    "of every method",
    mcp__perceptual_keys, stage_perceptual, check_perceptual};
