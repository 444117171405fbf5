/* cmd_merge.c: `mcpost merge` -- K renders of one frame (replicates with other seeds,
 * or passes of one render) combined into one dump whose variance of the mean rests on
 * what the renders show (common/replicates.c). */
#include "cli.h"

#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>

static const char usage[] =
    "usage: mcpost merge IN1 IN2 ... -o OUT [options]\n"
    "  Combines render dumps of one frame into one dump: the mean (weighted by sample\n"
    "  counts, per pixel when a dump has a count map), albedo and normal averaged, the\n"
    "  total sample count, and a variance of the mean:\n"
    "  --variance replicates  (default) the INs are independent renders (other seeds):\n"
    "                         the variance comes from their spread, with K-1 degrees of\n"
    "                         freedom; right for stratified samplers, whose per-sample\n"
    "                         variance overstates it\n"
    "  --variance pooled      the INs are passes of one render: their per-sample\n"
    "                         variances combined exactly, as one render of all the\n"
    "                         samples would report them\n"
    "  --pool R               pool the variance over (2R+1)^2 pixels (its pattern from\n"
    "                         the INs' own per-sample variance where they have one)\n"
    "  -o, --output OUT       the merged dump (mcpost convention, EXR); the header\n"
    "                         records the source: mcpost:varianceSource, :varianceDof,\n"
    "                         :replicates\n"
    "  --spp N, --convention NAME  how to read INs that hold no sample count\n"
    "  --half                 store half floats\n"
    "\n"
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost merge samples/fixtures/strat/texture/blocks/texture_r[0-3]_b00.exr -o /tmp/texture_merged.exr\n"
    "  mcpost merge --variance pooled samples/fixtures/strat/texture/blocks/texture_r0_b0[0-3].exr \\\n"
    "                 -o /tmp/texture_pooled.exr\n";

static int
cmd_merge(int argc, char **argv)
{
    static const struct option longs[] = {
        {"variance", required_argument, 0, 'v'}, {"pool", required_argument, 0, 'p'},
        {"output", required_argument, 0, 'o'},   {"spp", required_argument, 0, 's'},
        {"convention", required_argument, 0, 'c'}, {"half", no_argument, 0, 'H'},
        {"help", no_argument, 0, 'h'},           {0, 0, 0, 0}};
    mcp_merge_options mo = mcp_merge_defaults();
    mcp_write_options wo = mcp_write_defaults();
    const char *out_path = NULL, *spp = NULL, *convention = NULL;
    int opt;
    optind = 1;
    while ((opt = getopt_long(argc, argv, "ho:", longs, NULL)) != -1) {
        int rc = 0;
        switch (opt) {
        case 'v': rc = mcp_merge_variance_from_name(optarg, &mo.variance); break;
        case 'p':
            rc = mcp__parse_int("--pool", optarg, &mo.pool_radius);
            if (!rc && mo.pool_radius < 0)
                rc = mcp_error("--pool must be >= 0 (got %s)", optarg);
            break;
        case 'o': out_path = optarg; break;
        case 's': spp = optarg; break;
        case 'c': convention = optarg; break;
        case 'H': wo.exr_pixel = MCP_EXR_HALF; break;
        case 'h': fputs(usage, stdout); return 0;
        default: return mcp_cli_usage("merge", "bad option");
        }
        if (rc)
            return mcp_cli_fail();
    }
    int count = argc - optind;
    if (count < 1)
        return mcp_cli_usage("merge", "no dumps given");
    if (!out_path)
        return mcp_cli_usage("merge", "no output given (-o OUT)");
    if (mcp_cli_output_is_not_input("merge", out_path, (const char *const *)argv + optind,
                                    count))
        return mcp_cli_fail();
    mcp_dump **parts = mcp_calloc((size_t)count, sizeof *parts);
    mcp_dump *merged = NULL;
    int status = 1;
    if (!parts)
        return mcp_cli_fail();
    for (int i = 0; i < count; i++)
        if (mcp_cli_read_dump(argv[optind + i], spp, convention, NULL, &parts[i]))
            goto done;
    if (mcp_dump_merge((const mcp_dump *const *)parts, count, &mo, &merged) ||
        mcp_dump_write(merged, out_path, MCP_CONV_MCPOST, &wo))
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
    if (status)
        status = mcp_cli_fail();
    for (int i = 0; i < count; i++)
        mcp_dump_free(parts[i]);
    free(parts);
    mcp_dump_free(merged);
    return status;
}

const mcp_command mcp_command_merge = {"merge", "combine renders of one frame into a dump "
                                                "(variance from replicates)",
                                       cmd_merge, 0};
