/* stage_info.c: the `info` job stage -- an input described in the report: size,
 * channels with statistics, the render-dump convention and sample count -- and the
 * descriptions it shares with `mcpost info`. */
#include "internal.h"

#include <mcpost/stats.h>

#include <stdio.h>
#include <string.h>

/* The keys: the options of the info table that a job takes (ops/op_info.c), filled
 * in by stages.c before the table is first handed out. */
const char *mcp__info_keys[MCP__OPTION_KEYS_MAX];

/* The stage's settings: one input, an image or a dump (read by the run, before it
 * loads anything, and by the job's check before any stage runs). */
static int
check_info(mcp_job *job, const mcp_node *settings)
{
    mcp_info_settings st;
    return mcp__job_settings(mcp_operation_info(), settings, NULL, &st) ||
           mcp_job_check_input(job, settings, "input", MCP_JOB_IMAGE);
}

/* The info section's verdict: whether any value would break the later stages (NaN,
 * Inf, or a negative radiance or variance; normals and covariances may be negative). */
static int
info_verdict(cJSON *section, const cJSON *channels)
{
    char worst[600] = "";
    int n_channels = 0, len = 0;
    const cJSON *ch;
    cJSON_ArrayForEach(ch, channels)
    {
        const cJSON *name = cJSON_GetObjectItem(ch, "name");
        const char *nm = cJSON_IsString(name) ? name->valuestring : "?";
        int signed_ok =
            !strncmp(nm, "normal.", 7) || !strncmp(nm, "covariance_of_mean.", 19);
        static const char *const bad[] = {"nan", "inf", "negative"};
        n_channels++;
        for (int k = 0; k < 3; k++) {
            const cJSON *v = cJSON_GetObjectItem(ch, bad[k]);
            if (!cJSON_IsNumber(v) || v->valuedouble <= 0 || (k == 2 && signed_ok) ||
                len >= (int)sizeof worst - 80)
                continue;
            len += snprintf(worst + len, sizeof worst - len, "%s%.0f %s in %s",
                            len ? ", " : "", v->valuedouble, bad[k], nm);
        }
    }
    const cJSON *spp = cJSON_GetObjectItem(section, "spp"),
                *conv = cJSON_GetObjectItem(section, "convention");
    char what[200] = "";
    if (cJSON_IsString(conv) && cJSON_IsNumber(spp))
        snprintf(what, sizeof what, "; %s convention, %g spp", conv->valuestring,
                 spp->valuedouble);
    else if (cJSON_IsString(conv))
        snprintf(what, sizeof what, "; %s convention", conv->valuestring);
    if (*worst)
        return mcp_report_set_verdict(section, MCP_VERDICT_BAD,
                                      "check the input: %s (such values spoil means, "
                                      "variances and metrics)%s",
                                      worst, what);
    return mcp_report_set_verdict(section, MCP_VERDICT_GOOD,
                                  "clean: %d channels, no NaN, Inf or negative values%s",
                                  n_channels, what);
}

static int
stage_info(mcp_job *job, const mcp_node *settings)
{
    const char *name = NULL;
    const mcp_image *img = NULL;
    if (check_info(job, settings) || mcp_node_opt_string(settings, "input", &name) ||
        mcp_job_image(job, settings, "input", &img))
        return -1;
    cJSON *section = mcp_report_section(mcp_job_report(job), "info", name);
    if (!section) return -1;
    cJSON_AddNumberToObject(section, "width", img->width);
    cJSON_AddNumberToObject(section, "height", img->height);
    cJSON *channels = cJSON_AddArrayToObject(section, "channels");
    const mcp_dump *d = NULL;
    /* a dump input: describe every part that it holds */
    if (mcp_node_get(settings, "input") &&
        mcp_job_dump(job, settings, "input", &d) == 0) {
        mcp__info_add_dump(section, d);
        const mcp_image *parts[] = {d->color,  d->var_of_mean, d->cov_of_mean,
                                    d->albedo, d->normal,      d->spp_map};
        const char *prefixes[] = {"",        "variance_of_mean.", "covariance_of_mean.",
                                  "albedo.", "normal.",           "spp."};
        for (int i = 0; i < 6; i++)
            if (parts[i] && mcp__info_add_channels(channels, parts[i], prefixes[i]))
                return -1;
    } else if (mcp__info_add_channels(channels, img, "")) {
        return -1;
    }
    mcp_error_clear();
    if (info_verdict(section, channels)) return -1;
    mcp_note("%s: %dx%d", name, img->width, img->height);
    return 0;
}

const mcp_stage mcp_stage_info = {"info",
                                  "describe an input (channels, statistics, "
                                  "convention, sample count) in the report",
                                  mcp__info_keys, stage_info, check_info};

void
mcp__info_add_channel(cJSON *array, const char *name, const mcp_channel_stats *s)
{
    cJSON *ch = cJSON_CreateObject();
    cJSON_AddStringToObject(ch, "name", name);
    cJSON_AddNumberToObject(ch, "min", s->min);
    cJSON_AddNumberToObject(ch, "mean", s->mean);
    cJSON_AddNumberToObject(ch, "max", s->max);
    cJSON_AddNumberToObject(ch, "nan", (double)s->n_nan);
    cJSON_AddNumberToObject(ch, "inf", (double)s->n_inf);
    cJSON_AddNumberToObject(ch, "negative", (double)s->n_negative);
    cJSON_AddItemToArray(array, ch);
}

/* Appends statistics of every channel of img to the array, names prefixed. */
int
mcp__info_add_channels(cJSON *array, const mcp_image *img, const char *prefix)
{
    for (int c = 0; c < img->channels; c++) {
        mcp_channel_stats s;
        if (mcp_channel_stats_compute(img, c, &s)) return -1;
        char name[600];
        snprintf(name, sizeof name, "%s%s", prefix, img->names[c]);
        mcp__info_add_channel(array, name, &s);
    }
    return 0;
}

void
mcp__info_add_dump(cJSON *o, const mcp_dump *d)
{
    cJSON_AddStringToObject(o, "convention", mcp_convention_name(d->convention));
    if (d->spp_map)
        cJSON_AddStringToObject(o, "spp", "per-pixel map");
    else if (d->spp > 0)
        cJSON_AddNumberToObject(o, "spp", d->spp);
    else
        cJSON_AddNullToObject(o, "spp");
    cJSON_AddStringToObject(o, "variance",
                            !d->var_of_mean ? "none"
                            : d->variance_in_file == MCP_VAR_PER_SAMPLE
                                ? "per-sample in the file (divided by spp)"
                                : "of the mean in the file");
    cJSON_AddStringToObject(o, "variance_source",
                            mcp_variance_source_name(d->variance_source));
    if (d->variance_dof > 0) cJSON_AddNumberToObject(o, "variance_dof", d->variance_dof);
    if (d->replicates > 0) cJSON_AddNumberToObject(o, "replicates", d->replicates);
    if (d->variance_pool > 0)
        cJSON_AddNumberToObject(o, "variance_pool", d->variance_pool);
    cJSON_AddBoolToObject(o, "covariance", d->cov_of_mean != NULL);
    cJSON_AddBoolToObject(o, "albedo", d->albedo != NULL);
    cJSON_AddBoolToObject(o, "normal", d->normal != NULL);
}
