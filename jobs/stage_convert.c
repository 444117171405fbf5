/* stage_convert.c: the `convert` job stage -- an input written in another format, with
 * chosen channels, pixel type and compression -- and the channel pick it shares with
 * `mcpost convert`. The keys are the convert table's (ops/op_convert.c). */
#include "internal.h"

#include <mcpost/tonemap.h>

#include <stdlib.h>
#include <string.h>

/* The keys: the options of the convert table that a job takes (ops/op_convert.c),
 * filled in by stages.c before the table is first handed out. */
const char *mcp__convert_keys[MCP__OPTION_KEYS_MAX];

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): through the convert table, the input checked against
 * the job's, the output's format known, and the channels to keep (free `names` with
 * mcp__free_words). */
typedef struct convert_plan {
    mcp_convert_settings s;
    char **names;
    int count;
} convert_plan;

static int
parse_convert(mcp_job *job, const mcp_node *settings, convert_plan *pl)
{
    const mcp_node *out_node = NULL;
    memset(pl, 0, sizeof *pl);
    if (mcp__job_settings(mcp_operation_convert(), settings, NULL, &pl->s) ||
        mcp_job_check_input(job, settings, "input", MCP_JOB_IMAGE) ||
        mcp_node_require(settings, "output", "stage 'convert'", &out_node))
        return -1;
    if (mcp_format_from_path(pl->s.output) == MCP_FORMAT_UNKNOWN)
        return mcp_node_error(out_node, "output: unknown image format '%s'",
                              pl->s.output);
    if (mcp__convert_channel_names(&pl->s, &pl->names, &pl->count))
        return mcp__at_line(settings, "channels");
    return 0;
}

static int
check_convert(mcp_job *job, const mcp_node *settings)
{
    convert_plan pl;
    int rc = parse_convert(job, settings, &pl);
    mcp__free_words(pl.names, pl.count);
    return rc;
}

static int
stage_convert(mcp_job *job, const mcp_node *settings)
{
    const mcp_image *img = NULL;
    const mcp_node *chan = mcp_node_get(settings, "channels");
    convert_plan pl;
    if (parse_convert(job, settings, &pl)) return -1;
    if (mcp_job_image(job, settings, "input", &img)) {
        mcp__free_words(pl.names, pl.count);
        return -1;
    }
    const char *out = pl.s.output;
    char path[4096];
    mcp_image *picked = NULL;
    int rc = mcp_job_output_path(job, out, path, sizeof path) ||
             mcp__convert_pick_channels(img, pl.names, pl.count, path, &picked) ||
             mcp_image_write(picked, path, &pl.s.wo);
    mcp__free_words(pl.names, pl.count);
    mcp_image_free(picked);
    if (rc) return chan ? mcp_node_error(chan, "%s", mcp_error_message()) : -1;
    cJSON *section = mcp_report_section(mcp_job_report(job), "convert", out);
    const char *input = pl.s.input, *dot = strrchr(out, '.');
    int png = dot && !strcmp(dot, ".png");
    if (!section || mcp_report_add_image(section, out, out) ||
        mcp_report_set_verdict(
            section, MCP_VERDICT_INFO, "wrote %s from %s, %dx%d%s", out,
            input ? input : "the input", img->width, img->height,
            png && pl.s.wo.srgb_encode
                ? ": linear values clamped to [0, 1] and sRGB-encoded, "
                  "as a screen shows them"
                : ""))
        return -1;
    /* by its name in the output folder: the path is the hidden folder's until the job
       ends (common/io/outdir.c) */
    mcp_note("wrote %s into the output folder", out);
    return 0;
}

const mcp_stage mcp_stage_convert = {"convert",
                                     "write an input in another format, with "
                                     "chosen channels",
                                     mcp__convert_keys, stage_convert, check_convert};

int
mcp__convert_channel_names(const mcp_convert_settings *s, char ***names, int *count)
{
    char **all = NULL;
    int n = 0;
    *names = NULL;
    *count = 0;
    for (int i = 0; i < s->n_channels; i++) {
        char **words = NULL;
        int k = 0;
        if (mcp__split_words(s->channels[i], &words, &k)) {
            mcp__free_words(all, n);
            return -1;
        }
        char **grown = realloc(all, (size_t)(n + k ? n + k : 1) * sizeof *grown);
        if (!grown) {
            mcp__free_words(words, k);
            mcp__free_words(all, n);
            return mcp_error("convert: out of memory");
        }
        all = grown;
        for (int j = 0; j < k; j++)
            all[n++] = words[j];
        free(words); /* the words themselves moved into all */
    }
    *names = all;
    *count = n;
    return 0;
}

/* The channels of img named in `names`, as a new image. With no names, a format that
 * stores colour by place gets the colour, found by name (docs/conventions.md, "Channel
 * order"): R, G, B, and A where PNG or JPEG can keep it. Other channels (a render
 * dump's, a depth Z) would otherwise land in the alpha slot or fail the write, and
 * colour is what a person converting to PNG means. */
int
mcp__convert_pick_channels(const mcp_image *img, char **names, int count,
                           const char *out_path, mcp_image **out)
{
    mcp_format f = mcp_format_from_path(out_path);
    int alpha_ok = f == MCP_FORMAT_PNG || f == MCP_FORMAT_JPEG;
    int rgb_only = f == MCP_FORMAT_HDR || f == MCP_FORMAT_PFM;
    int rgba[4];
    /* without colour names, every channel goes (by place), as before */
    if (count == 0 && (alpha_ok || rgb_only) && mcp_image_rgb_by_name(img, rgba) == 3) {
        int n = 3, a = alpha_ok ? mcp_image_channel(img, "A") : -1;
        if (a >= 0) rgba[n++] = a;
        return mcp_image_copy_channels(img, rgba, n, out);
    }
    if (count == 0) return mcp_image_copy(img, out);
    int *idx = mcp_calloc((size_t)count, sizeof *idx);
    if (!idx) return -1;
    int rc = mcp_image_channels(img, (const char *const *)names, count, idx) ||
             mcp_image_copy_channels(img, idx, count, out);
    free(idx);
    return rc ? -1 : 0;
}
