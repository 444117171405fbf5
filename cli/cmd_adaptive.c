/* cmd_adaptive.c: `mcpost adaptive` -- the adaptive-sampling loop of Firmino 2023
 * (estimate/adaptive.c) driving any renderer through a command template: {counts} (an
 * EXR of per-pixel sample counts, channel SampleCount), {output} (the dump the command
 * must write), {pass}, {seed}. Writes, per pass, the sampling map and the counts as
 * images, and at the end the accumulated dump, the denoised image, adaptive.json /
 * adaptive.csv (relMSE with a reference, and the estimated error, against the total
 * samples) and adaptive.svg. The loop is the library's, shared with the `adaptive` job
 * stage (jobs/adaptive_loop.c). The flags are the adaptive table's (ops/op_adaptive.c),
 * read by cli/options.c; the job keys are the same words. -o DIR appears whole
 * (common/io/outdir.c): the passes run in a hidden folder beside it. */
#include "cli.h"

#include <mcpost/estimate.h>
#include <mcpost/progress.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- the subcommand ---- */

static const char head[] =
    "usage: mcpost adaptive --render CMD -o DIR (--size WxH | --reference REF)\n"
    "                       (--budget SPP | --stop) [options]\n"
    "  The adaptive-sampling loop of Firmino 2023: render -> merge -> denoise ->\n"
    "  variance of the denoised image -> sampling map -> integer counts -> render "
    "more.\n";

static const char examples[] =
    "examples (mcpost-procedural is built and installed beside mcpost, and mcpost\n"
    "finds the programs beside it after those on the PATH):\n"
    "  mcpost adaptive --size 64x64 --budget 64 --denoiser nlm -o out/adaptive \\\n"
    "    --render 'mcpost-procedural --sample-counts {counts} --pass {pass} --seed "
    "{seed} -o {output}'\n"
    "  mcpost adaptive --size 64x64 --budget 96 --map tonemapped --spp-per-iteration 16 "
    "\\\n"
    "    --denoiser gauss -o out/adaptive_tonemapped \\\n"
    "    --render 'mcpost-procedural --sample-counts {counts} --pass {pass} --seed "
    "{seed} -o {output}'\n";

static int
cmd_adaptive(int argc, char **argv)
{
    mcp_adaptive_settings st;
    mcp_shared_settings sh;
    mcp_cli_denoiser_flags df = {0};
    int first = 0;
    int parsed = mcp_cli_parse(mcp_operation_adaptive(), head, examples, argc, argv, &st,
                               &sh, &df, &first);
    if (parsed >= 0) {
        mcp_cli_denoiser_flags_free(&df);
        return parsed;
    }
    if (first < argc) {
        mcp_cli_denoiser_flags_free(&df);
        return mcp_cli_usage("adaptive", "unexpected argument '%s'", argv[first]);
    }
    if (!st.render || !sh.output) {
        mcp_cli_denoiser_flags_free(&df);
        return mcp_cli_usage("adaptive", "needs --render CMD and -o DIR");
    }
    mcp__adaptive_loop c;
    memset(&c, 0, sizeof c);
    c.ao = st.ao;
    c.render = st.render;
    c.seed = st.seed;
    c.keep_passes = st.keep_passes;
    const char *size = st.size, *ref_path = st.reference;
    mcp_image *ref = NULL;
    mcp_denoiser *den = NULL;
    cJSON *j = NULL;
    mcp__outdir whole = {0}; /* -o DIR appears whole, or not at all */
    int status = 1;
    if (ref_path && mcp_image_read(ref_path, NULL, &ref)) goto done;
    c.reference = ref;
    if (size ? mcp__parse_size(size, &c.width, &c.height) : 0) goto done;
    if (!size && !ref) {
        mcp_error("give the image size (--size WxH) or a --reference");
        goto done;
    }
    if (!size) c.width = ref->width, c.height = ref->height;
    if (mcp_cli_denoiser_create(&df, &den)) goto done;
    c.den = den;
    /* after the cheap checks, before the first pass */
    if (mcp__outdir_begin(&whole, sh.output) ||
        mcp__outdir_check_inputs(&whole, &ref_path, 1))
        goto done;
    snprintf(c.dir, sizeof c.dir, "%s", whole.tmp);
    if (mcp__adaptive_run_loop(&c, sh.json ? &j : NULL) || mcp__outdir_commit(&whole))
        goto done;
    if (j) mcp_cli_print_json(j);
    j = NULL;
    status = 0;
done:
    mcp__outdir_abort(&whole);
    cJSON_Delete(j);
    if (status) status = mcp_cli_fail();
    mcp_image_free(ref);
    mcp_denoiser_free(den);
    mcp_cli_denoiser_flags_free(&df);
    return status;
}

const mcp_command mcp_command_adaptive = {
    "adaptive", "the adaptive-sampling loop: render, denoise, map, render more",
    cmd_adaptive, 1};
