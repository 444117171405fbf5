/* stage_convert.c: the `convert` job stage -- an input written in another format, with
 * chosen channels, pixel type and compression -- and the channel pick it shares with
 * `mcpost convert`. */
#include "internal.h"

#include <mcpost/tonemap.h>

#include <stdlib.h>
#include <string.h>

static const char *const convert_keys[] = {"input",       "output", "channels", "pixel",
                                           "compression", "title",  NULL};

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): the output file's name and how to write it, and the
 * channels to keep (names borrowed from the settings; free `names`). */
typedef struct convert_plan {
    const char *out;
    mcp_write_options wo;
    const char **names;
    int count;
} convert_plan;

static int
parse_convert(mcp_job *job, const mcp_node *settings, convert_plan *pl)
{
    const mcp_node *out_node = NULL, *chan = mcp_node_get(settings, "channels");
    const char *pixel = NULL, *comp = NULL;
    memset(pl, 0, sizeof *pl);
    pl->wo = mcp_write_defaults();
    if (mcp_job_check_input(job, settings, "input", MCP_JOB_IMAGE) ||
        mcp_node_require(settings, "output", "stage 'convert'", &out_node) ||
        mcp_node_string(out_node, "output", &pl->out) ||
        mcp_node_opt_string(settings, "pixel", &pixel) ||
        mcp_node_opt_string(settings, "compression", &comp))
        return -1;
    if (mcp_format_from_path(pl->out) == MCP_FORMAT_UNKNOWN)
        return mcp_node_error(out_node, "output: unknown image format '%s'", pl->out);
    if (pixel && strcmp(pixel, "half") && strcmp(pixel, "float"))
        return mcp_node_error(mcp_node_get(settings, "pixel"),
                              "pixel must be half or float (got '%s')", pixel);
    if (pixel && !strcmp(pixel, "half"))
        pl->wo.exr_pixel = MCP_EXR_HALF;
    if (comp && mcp_exr_compression_from_name(comp, &pl->wo.compression))
        return mcp_node_error(mcp_node_get(settings, "compression"), "%s",
                              mcp_error_message());
    if (chan) {
        if (chan->kind != MCP_NODE_SEQ || chan->count == 0)
            return mcp_node_error(chan, "channels must be a list of channel names");
        if (!(pl->names = mcp_calloc((size_t)chan->count, sizeof *pl->names)))
            return -1;
        pl->count = chan->count;
        for (int i = 0; i < pl->count; i++)
            if (mcp_node_string(chan->items[i], "channels", &pl->names[i])) {
                free(pl->names);
                pl->names = NULL;
                return -1;
            }
    }
    return 0;
}

static int
check_convert(mcp_job *job, const mcp_node *settings)
{
    convert_plan pl;
    int rc = parse_convert(job, settings, &pl);
    free(pl.names);
    return rc;
}

static int
stage_convert(mcp_job *job, const mcp_node *settings)
{
    const mcp_image *img = NULL;
    const mcp_node *chan = mcp_node_get(settings, "channels");
    convert_plan pl;
    if (parse_convert(job, settings, &pl))
        return -1;
    if (mcp_job_image(job, settings, "input", &img)) {
        free(pl.names);
        return -1;
    }
    const char *out = pl.out;
    const char **names = pl.names;
    int count = pl.count;
    mcp_write_options wo = pl.wo;
    char path[4096];
    mcp_image *picked = NULL;
    int rc = mcp_job_output_path(job, out, path, sizeof path) ||
             mcp__convert_pick_channels(img, (char **)names, count, path, &picked) ||
             mcp_image_write(picked, path, &wo);
    free(names);
    mcp_image_free(picked);
    if (rc)
        return chan ? mcp_node_error(chan, "%s", mcp_error_message()) : -1;
    cJSON *section = mcp_report_section(mcp_job_report(job), "convert", out);
    const char *input = NULL, *dot = strrchr(out, '.');
    mcp_node_opt_string(settings, "input", &input);
    int png = dot && !strcmp(dot, ".png");
    if (!section || mcp_report_add_image(section, out, out) ||
        mcp_report_set_verdict(section, MCP_VERDICT_INFO, "wrote %s from %s, %dx%d%s", out,
                               input ? input : "the input", img->width, img->height,
                               png ? ": linear values clamped to [0, 1] and sRGB-encoded, "
                                     "as a screen shows them"
                                   : ""))
        return -1;
    /* by its name in the output folder: the path is the hidden folder's until the job
       ends (common/outdir.c) */
    mcp_note("wrote %s into the output folder", out);
    return 0;
}

const mcp_stage mcp_stage_convert = {"convert", "write an input in another format, with "
                                                "chosen channels",
                                     convert_keys, stage_convert, check_convert};

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
    if (count == 0)
        return mcp_image_copy(img, out);
    int *idx = mcp_calloc((size_t)count, sizeof *idx);
    if (!idx)
        return -1;
    int rc = mcp_image_channels(img, (const char *const *)names, count, idx) ||
             mcp_image_copy_channels(img, idx, count, out);
    free(idx);
    return rc ? -1 : 0;
}
