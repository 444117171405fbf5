/* variance_source.c: what a variance rests on, said the same way by every command
 * (estimate, blend, info): a per-sample variance / n is an assumption that the samples
 * are independent, which stratified samplers break. And what a series estimate's SURE
 * rests on (docs/mathematics.md §2.10). */
#include "internal.h"

#include <stdio.h>
#include <string.h>

static const char per_sample_note[] =
    "the renderer's per-sample variance / n assumes independent samples; a stratified "
    "sampler (Cycles, pbrt-v4) makes it an overstatement: give replicates (mcpost "
    "merge) or a series with --variance-from increments";

static const char xyz_moments_note[] =
    "Mitsuba 3's moment integrator stores XYZ second moments without their "
    "covariances: the RGB variance takes X, Y, Z as perfectly correlated (exact when a "
    "pixel's samples share one chromaticity, as grey ones do; at most (sum_j "
    "|M_rj| sd_j)^2 otherwise), and / n assumes independent samples";

void
mcp__add_variance_source(cJSON *j, mcp_variance_source src, double dof)
{
    cJSON_AddStringToObject(j, "variance_source", mcp_variance_source_name(src));
    if (dof > 0) cJSON_AddNumberToObject(j, "variance_dof", dof);
    if (src == MCP_VARSRC_PER_SAMPLE)
        cJSON_AddStringToObject(j, "variance_note", per_sample_note);
    if (src == MCP_VARSRC_XYZ_MOMENTS)
        cJSON_AddStringToObject(j, "variance_note", xyz_moments_note);
}

const char *
mcp__variance_source_words(mcp_variance_source src)
{
    switch (src) {
    case MCP_VARSRC_NONE:
        return "none";
    case MCP_VARSRC_PER_SAMPLE:
        return "per-sample / n (assumes independent samples; see mcpost merge, "
               "--variance-from increments)";
    case MCP_VARSRC_OF_MEAN:
        return "of the mean, as the file stores it";
    case MCP_VARSRC_REPLICATES:
        return "the spread between replicates";
    case MCP_VARSRC_INCREMENTS:
        return "the spread between the series' increments";
    case MCP_VARSRC_XYZ_MOMENTS:
        return "per-sample / n from Mitsuba's XYZ moments (no XYZ covariances: X, Y, Z "
               "taken as perfectly correlated; assumes independent samples)";
    }
    return "?";
}

void
mcp__report_variance_ratio(double ratio, int using_increments, int asked, cJSON *j)
{
    if (!(ratio > 0)) return;
    if (j) cJSON_AddNumberToObject(j, "variance_ratio", ratio);
    if (!mcp_variance_ratio_off(ratio)) return;
    const char *w = mcp__variance_ratio_warning(ratio, using_increments);
    /* taken care of (the increments are used) is news, not a warning; and no news when
     * the job or command asked for the increments itself */
    if (!using_increments || !asked)
        fprintf(stderr, "mcpost: %s%s\n", using_increments ? "" : "warning: ", w);
    if (j)
        cJSON_AddStringToObject(
            j, using_increments ? "variance_choice" : "variance_warning", w);
}

const char *
mcp__variance_ratio_warning(double ratio, int using_increments)
{
    static _Thread_local char text[400];
    snprintf(text, sizeof text,
             "Variance/n is %.2fx the spread between this series' increments: the "
             "per-sample variance %s the error (%s)%s",
             ratio, ratio > 1 ? "overstates" : "understates",
             ratio > 1 ? "stratified samples"
                       : "correlated samples, or members that are not checkpoints of one "
                         "render?",
             using_increments ? "; the estimates use the increments (--variance-from "
                                "file keeps Variance/n)"
             : ratio > 1      ? "; use --variance-from increments (job: variance_from: "
                                "increments)"
                              : "");
    return text;
}

const char *
mcp__sure_source_words(const mcp_series_estimate *s)
{
    /* the last member says for the series: the earlier ones have fewer groups */
    const mcp_series_point *last = s->count ? &s->points[s->count - 1] : NULL;
    if (!last || last->sure_groups <= 0)
        return "the probes' divergence (Stein's lemma; assumes Gaussian noise)";
    return last->probes_from_groups
               ? "covariance and variance from groups of each member's own checkpoints, "
                 "from the third member on (--sure-groups); the probes too, since "
                 "Variance/n is off from what the groups measure"
               : "covariance and variance from groups of each member's own checkpoints, "
                 "from the third member on (--sure-groups)";
}
