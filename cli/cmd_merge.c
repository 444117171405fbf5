/* cmd_merge.c: `mcpost merge` -- K renders of one frame (replicates with other seeds,
 * or passes of one render) combined into one dump whose variance of the mean rests on
 * what the renders show (common/dump/replicates.c). The flags are the merge table's
 * (ops/op_merge.c), read by cli/options.c. */
#include "cli.h"
#include "../common/dump/internal.h" /* the merge in bands */

#include <stdio.h>
#include <stdlib.h>

static const char head[] =
    "usage: mcpost merge IN1 IN2 ... -o OUT [options]\n"
    "  Combines render dumps of one frame into one dump: the mean (weighted by sample\n"
    "  counts, per pixel when a dump has a count map), albedo and normal averaged, the\n"
    "  total sample count, and a variance of the mean.\n";

static const char examples[] =
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost merge samples/fixtures/strat/texture/blocks/texture_r[0-3]_b00.exr -o "
    "/tmp/texture_merged.exr\n"
    "  mcpost merge --variance pooled "
    "samples/fixtures/strat/texture/blocks/texture_r0_b0[0-3].exr \\\n"
    "                 -o /tmp/texture_pooled.exr\n";

static int
cmd_merge(int argc, char **argv)
{
    mcp_merge_settings st;
    mcp_shared_settings sh;
    mcp_cli_denoiser_flags df = {0}; /* merge takes no denoiser */
    int first = 0;
    int parsed = mcp_cli_parse(mcp_operation_merge(), head, examples, argc, argv, &st,
                               &sh, &df, &first);
    mcp_cli_denoiser_flags_free(&df);
    if (parsed >= 0) return parsed;
    mcp_merge_options mo = st.mo;
    mcp_write_options wo = mcp_write_defaults();
    if (st.half) wo.exr_pixel = MCP_EXR_HALF;
    const char *out_path = sh.output;
    int count = argc - first;
    if (count < 1) return mcp_cli_usage("merge", "no dumps given");
    if (!out_path) return mcp_cli_usage("merge", "no output given (-o OUT)");
    if (mcp_cli_output_is_not_input("merge", out_path, (const char *const *)argv + first,
                                    count))
        return mcp_cli_fail();
    mcp_dump **parts = mcp_calloc((size_t)count, sizeof *parts);
    mcp_dump_spec *specs = mcp_calloc((size_t)count, sizeof *specs);
    mcp_dump *merged = NULL;
    int status = 1, streamed = 0;
    if (!parts || !specs) goto done;
    for (int i = 0; i < count; i++) {
        specs[i] = st.spec;
        specs[i].path = argv[first + i];
    }
    /* EXR dumps a band of rows at a time (common/dump/merge_stream.c), the others
       whole */
    if (mcp__dump_merge_streamed(specs, count, &mo, out_path, &wo, &merged, &streamed))
        goto done;
    for (int i = 0; !streamed && i < count; i++)
        if (mcp_dump_load(&specs[i], &parts[i])) goto done;
    if (!streamed &&
        (mcp_dump_merge((const mcp_dump *const *)parts, count, &mo, &merged) ||
         mcp_dump_write(merged, out_path, MCP_CONV_MCPOST, &wo)))
        goto done;
    if (merged->spp_map)
        printf("%s: %d dumps, per-pixel sample counts", out_path, count);
    else
        printf("%s: %d dumps, %g spp", out_path, count, merged->spp);
    if (mo.variance == MCP_MERGE_REPLICATES)
        printf("; variance of the mean from their spread (%d degrees of freedom)",
               count - 1);
    else
        printf("; per-sample variances pooled");
    if (merged->variance_pool > 0)
        printf(", pooled over %g pixels", merged->variance_pool);
    printf("\n");
    status = 0;
done:
    if (status) status = mcp_cli_fail();
    for (int i = 0; parts && i < count; i++)
        mcp_dump_free(parts[i]);
    free(parts);
    free(specs);
    mcp_dump_free(merged);
    return status;
}

const mcp_command mcp_command_merge = {"merge",
                                       "combine renders of one frame into a dump "
                                       "(variance from replicates)",
                                       cmd_merge, 1};
