/* stage_blend.c: the `blend` job stage -- a series blended with its denoised images so
 * that it converges (blend_run.c; docs/blend.md). Keys are the flags of `mcpost blend`
 * with '_' for '-'. */
#include "internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const blend_keys[] = {"input",
                                         "denoiser",
                                         "stop_denoising_at",
                                         "reference",
                                         "output",
                                         "title",
                                         "all_images",
                                         "fit",
                                         "curve",
                                         "far_spp",
                                         "max_weight",
                                         "denoiser_keeps_zeros",
                                         "filter",
                                         "filter_window",
                                         "filter_sigma_scale",
                                         "stop_filtering",
                                         "negative_sure",
                                         "n_probes",
                                         "seed",
                                         "js_window",
                                         "safeguard",
                                         "weights",
                                         "flip",
                                         NULL};

/* The enum keys' from_name functions, for mcp__opt_enum. */
static int
p_fit(const char *s, void *o)
{
    return mcp_curve_fit_from_name(s, o);
}
static int
p_curve(const char *s, void *o)
{
    return mcp_curve_model_from_name(s, o);
}
static int
p_filter(const char *s, void *o)
{
    return mcp_blend_filter_from_name(s, o);
}
static int
p_neg(const char *s, void *o)
{
    return mcp_neg_sure_from_name(s, o);
}
static int
p_weights(const char *s, void *o)
{
    return mcp_blend_weighting_from_name(s, o);
}

static int
read_stage_options(const mcp_node *s, mcp_blend_series_options *o)
{
    mcp_blend_options *b = &o->blend;
    double seed = 0;
    int flip = o->flip, stop_filtering = b->stop_filtering,
        keeps_zeros = b->denoiser_keeps_zeros, safeguard = b->safeguard;
    if (mcp_node_opt_double(s, "stop_denoising_at", &o->stop_denoising_at) ||
        mcp__opt_enum(s, "fit", p_fit, &b->fit) ||
        mcp__opt_enum(s, "curve", p_curve, &b->curve) ||
        mcp_node_opt_double(s, "far_spp", &b->far_spp) ||
        mcp_node_opt_double(s, "max_weight", &b->max_weight) ||
        mcp_node_opt_bool(s, "denoiser_keeps_zeros", &keeps_zeros) ||
        mcp__opt_enum(s, "filter", p_filter, &b->filter) ||
        mcp_node_opt_int(s, "filter_window", &b->filter_window) ||
        mcp_node_opt_double(s, "filter_sigma_scale", &b->filter_sigma_scale) ||
        mcp_node_opt_bool(s, "stop_filtering", &stop_filtering) ||
        mcp__opt_enum(s, "negative_sure", p_neg, &b->negative_sure) ||
        mcp_node_opt_int(s, "n_probes", &o->sure.n_probes) ||
        mcp_node_opt_double(s, "seed", &seed) ||
        mcp_node_opt_int(s, "js_window", &b->js_window) ||
        mcp_node_opt_bool(s, "safeguard", &safeguard) ||
        mcp__opt_enum(s, "weights", p_weights, &b->weights) ||
        mcp_node_opt_bool(s, "flip", &flip))
        return -1;
    if (!(seed >= 0) || seed != floor(seed) || seed > 9007199254740992.0)
        return mcp_node_error(mcp_node_get(s, "seed"),
                              "seed must be a non-negative integer (got %g)", seed);
    if (!(o->stop_denoising_at >= 0))
        return mcp_node_error(mcp_node_get(s, "stop_denoising_at"),
                              "stop_denoising_at must be >= 0 (got %g)",
                              o->stop_denoising_at);
    o->sure.seed = (uint64_t)seed;
    o->flip = flip;
    b->stop_filtering = stop_filtering;
    b->denoiser_keeps_zeros = keeps_zeros;
    b->safeguard = safeguard;
    if (mcp_blend_options_check(b)) return mcp_node_error(s, "%s", mcp_error_message());
    return 0;
}

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): the options, the series and reference by name (checked
 * against the job's inputs) and the denoiser, created from its settings. Strings are
 * borrowed from the settings; the denoiser is the plan's. */
typedef struct blend_plan {
    mcp_blend_series_options o;
    const char *input, *reference, *output;
    int all_images;
    mcp_denoiser *den;
} blend_plan;

static int
parse_blend(mcp_job *job, const mcp_node *settings, blend_plan *pl)
{
    const mcp_node *input_node = NULL;
    memset(pl, 0, sizeof *pl);
    pl->o = mcp_blend_series_defaults();
    if (mcp_node_opt_string(settings, "input", &pl->input) ||
        mcp_node_opt_string(settings, "reference", &pl->reference) ||
        mcp_node_opt_string(settings, "output", &pl->output) ||
        mcp_node_opt_bool(settings, "all_images", &pl->all_images) ||
        read_stage_options(settings, &pl->o) ||
        mcp_node_require(settings, "input", "stage 'blend'", &input_node) ||
        mcp_job_check_input(job, settings, "input", MCP_JOB_SERIES) ||
        (pl->reference && mcp_job_check_input(job, settings, "reference", MCP_JOB_IMAGE)) ||
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
    if (parse_blend(job, settings, &pl) || mcp_job_series(job, settings, "input", &series) ||
        (pl.reference && mcp_job_image(job, settings, "reference", &ref))) {
        mcp_denoiser_free(pl.den);
        return -1;
    }
    mcp_blend_series_options o = pl.o;
    const char *input = pl.input, *output = pl.output;
    int all_images = pl.all_images;
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
                                   blend_keys, stage_blend, check_blend};
