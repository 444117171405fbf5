/* cmd_adaptive.c: `mcpost adaptive` -- the adaptive-sampling loop of Firmino 2023
 * (estimate/adaptive.c) driving any renderer through a command template: {counts} (an
 * EXR of per-pixel sample counts, channel SampleCount), {output} (the dump the command
 * must write), {pass}, {seed}. Writes, per pass, the sampling map and the counts as
 * images, and at the end the accumulated dump, the denoised image, adaptive.json /
 * adaptive.csv (relMSE with a reference, and the estimated error, against the total
 * samples) and adaptive.svg. The loop is the library's, shared with the `adaptive` job
 * stage (jobs/adaptive_loop.c). Flags and job keys are the same words. */
#include "cli.h"

#include <mcpost/estimate.h>
#include <mcpost/progress.h>

#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- the subcommand ---- */

static const char usage[] =
    "usage: mcpost adaptive --render CMD -o DIR (--size WxH | --reference REF)\n"
    "                       (--budget SPP | --stop) [options]\n"
    "  The adaptive-sampling loop of Firmino 2023: render -> merge -> denoise ->\n"
    "  variance of the denoised image -> sampling map -> integer counts -> render more.\n"
    "  --render CMD             the render command, run by /bin/sh once per pass; it "
    "must\n"
    "                           render {counts}(p) new samples in pixel p (an EXR with\n"
    "                           channel SampleCount) from samples no earlier pass used,\n"
    "                           and write a dump with those counts to {output}. {pass}\n"
    "                           (0, 1, ...) and {seed} are numbers for it to use\n"
    "  -o, --output DIR         the outputs: accumulated.exr, denoised.exr,\n"
    "                           adaptive.json, adaptive.csv, adaptive.svg, maps/*.png\n"
    "  --size WxH               the image size [the reference's]\n"
    "  --map KIND               variance, tonemapped, mc-sure or uniform [variance]\n"
    "  --spp-per-iteration N    new samples per pixel per pass, on average [32]\n"
    "  --initial-spp N          the first pass, uniform [--spp-per-iteration]\n"
    "  --budget SPP             stop at this many samples per pixel in all (on average)\n"
    "  --stop                   stop when the estimate says F(tau) >= p (as estimate)\n"
    "  --tau T, --percentile P  the stopping criterion [0.01, 0.999]\n"
    "  --max-iterations N       passes at most [1000]\n"
    "  --quantum Q              counts in multiples of Q: K*K for a renderer that draws\n"
    "                           stratified passes of K*K samples [1]\n"
    "  --uniform-mix F          share of every pass spread evenly, the rest by the map:\n"
    "                           a floor for rare paths no pixel has drawn yet [0]\n"
    "  --probes N               probes of the estimate [4]\n"
    "  --seed S                 the {seed} of the command, and the probes' [1]\n"
    "  --reference REF          the converged image: relMSE per pass\n"
    "  --keep-passes            keep every pass's counts and dump in DIR\n"
    "  --json                   the figures as JSON on stdout\n"
    "  --quiet                  no line per pass on stderr\n"
    "  --denoiser NAME          " MCP_CLI_DEFAULT_DENOISER "\n" MCP_CLI_DENOISER_USAGE(
        " ") "\n"
             "examples (mcpost-procedural is built and installed beside mcpost, and mcpost\n"
             "finds the programs beside it after those on the PATH):\n"
             "  mcpost adaptive --size 64x64 --budget 64 --denoiser nlm -o out/adaptive \\\n"
             "    --render 'mcpost-procedural --sample-counts {counts} --pass {pass} --seed {seed} -o {output}'\n"
             "  mcpost adaptive --size 64x64 --budget 96 --map tonemapped --spp-per-iteration 16 \\\n"
             "    --denoiser gauss -o out/adaptive_tonemapped \\\n"
             "    --render 'mcpost-procedural --sample-counts {counts} --pass {pass} --seed {seed} -o {output}'\n";

enum {
    OPT_RENDER = 1,
    OPT_SIZE,
    OPT_MAP,
    OPT_SPP_IT,
    OPT_INITIAL,
    OPT_BUDGET,
    OPT_STOP,
    OPT_TAU,
    OPT_P,
    OPT_MAXIT,
    OPT_QUANTUM,
    OPT_UNIFORM_MIX,
    OPT_PROBES,
    OPT_SEED,
    OPT_REF,
    OPT_KEEP,
    OPT_JSON,
    OPT_QUIET
};

static int
cmd_adaptive(int argc, char **argv)
{
    static const struct option longs[] = {
        {"render", required_argument, 0, OPT_RENDER},
        {"output", required_argument, 0, 'o'},
        {"size", required_argument, 0, OPT_SIZE},
        {"map", required_argument, 0, OPT_MAP},
        {"spp-per-iteration", required_argument, 0, OPT_SPP_IT},
        {"initial-spp", required_argument, 0, OPT_INITIAL},
        {"budget", required_argument, 0, OPT_BUDGET},
        {"stop", no_argument, 0, OPT_STOP},
        {"tau", required_argument, 0, OPT_TAU},
        {"percentile", required_argument, 0, OPT_P},
        {"max-iterations", required_argument, 0, OPT_MAXIT},
        {"quantum", required_argument, 0, OPT_QUANTUM},
        {"uniform-mix", required_argument, 0, OPT_UNIFORM_MIX},
        {"probes", required_argument, 0, OPT_PROBES},
        {"seed", required_argument, 0, OPT_SEED},
        {"reference", required_argument, 0, OPT_REF},
        {"keep-passes", no_argument, 0, OPT_KEEP},
        {"json", no_argument, 0, OPT_JSON},
        {"quiet", no_argument, 0, OPT_QUIET},
        {"help", no_argument, 0, 'h'},
        MCP_CLI_DENOISER_LONGOPTS,
        {0, 0, 0, 0}};
    mcp__adaptive_loop c;
    memset(&c, 0, sizeof c);
    c.ao = mcp_adaptive_defaults();
    c.seed = 1;
    mcp_cli_denoiser_flags df = {0};
    const char *out = NULL, *size = NULL, *ref_path = NULL;
    int json = 0, opt;
    double seed = 1;
    optind = 1;
    while ((opt = getopt_long(argc, argv, "ho:", longs, NULL)) != -1) {
        int taken = mcp_cli_denoiser_flag(&df, opt, optarg), rc = 0;
        if (taken < 0) goto fail;
        if (taken) continue;
        switch (opt) {
        case OPT_RENDER:
            c.render = optarg;
            break;
        case 'o':
            out = optarg;
            break;
        case OPT_SIZE:
            size = optarg;
            break;
        case OPT_MAP:
            rc = mcp_adaptive_map_from_name(optarg, &c.ao.map);
            break;
        case OPT_SPP_IT:
            rc =
                mcp__parse_double("--spp-per-iteration", optarg, &c.ao.spp_per_iteration);
            break;
        case OPT_INITIAL:
            rc = mcp__parse_double("--initial-spp", optarg, &c.ao.initial_spp);
            break;
        case OPT_BUDGET:
            rc = mcp__parse_double("--budget", optarg, &c.ao.budget_spp);
            break;
        case OPT_STOP:
            c.ao.stop_on_estimate = 1;
            break;
        case OPT_TAU:
            rc = mcp__parse_double("--tau", optarg, &c.ao.est.tau);
            break;
        case OPT_P:
            rc = mcp__parse_double("--percentile", optarg, &c.ao.est.p);
            break;
        case OPT_MAXIT:
            rc = mcp__parse_int("--max-iterations", optarg, &c.ao.max_iterations);
            break;
        case OPT_QUANTUM:
            rc = mcp__parse_int("--quantum", optarg, &c.ao.quantum);
            break;
        case OPT_UNIFORM_MIX:
            rc = mcp__parse_double("--uniform-mix", optarg, &c.ao.uniform_mix);
            break;
        case OPT_PROBES:
            rc = mcp__parse_int("--probes", optarg, &c.ao.est.sure.n_probes);
            break;
        case OPT_SEED:
            rc = mcp__parse_double("--seed", optarg, &seed);
            if (!rc && (seed < 0 || seed != floor(seed) || seed > 9007199254740992.0))
                rc = mcp_error("--seed must be a whole number >= 0 (got %s)", optarg);
            break;
        case OPT_REF:
            ref_path = optarg;
            break;
        case OPT_KEEP:
            c.keep_passes = 1;
            break;
        case OPT_JSON:
            json = 1;
            break;
        case OPT_QUIET:
            mcp_progress_set_quiet(1);
            break;
        case 'h':
            fputs(usage, stdout);
            mcp_cli_denoiser_flags_free(&df);
            return 0;
        default:
            mcp_cli_denoiser_flags_free(&df);
            return mcp_cli_usage("adaptive", "bad option");
        }
        if (rc) goto fail;
    }
    if (optind < argc) {
        mcp_cli_denoiser_flags_free(&df);
        return mcp_cli_usage("adaptive", "unexpected argument '%s'", argv[optind]);
    }
    if (!c.render || !out) {
        mcp_cli_denoiser_flags_free(&df);
        return mcp_cli_usage("adaptive", "needs --render CMD and -o DIR");
    }
    c.seed = (uint64_t)seed;
    c.ao.est.sure.seed = c.seed;
    snprintf(c.dir, sizeof c.dir, "%s", out);
    mcp_image *ref = NULL;
    mcp_denoiser *den = NULL;
    cJSON *j = NULL;
    int status = 1;
    if (ref_path && mcp_image_read(ref_path, NULL, &ref)) goto done;
    c.reference = ref;
    if (size ? mcp__parse_size(size, &c.width, &c.height) : 0) goto done;
    if (!size && !ref) {
        mcp_error("give the image size (--size WxH) or a --reference");
        goto done;
    }
    if (!size) c.width = ref->width, c.height = ref->height;
    if (mcp_adaptive_check(&c.ao) || mcp_cli_denoiser_create(&df, &den)) goto done;
    c.den = den;
    if (mcp__adaptive_run_loop(&c, json ? &j : NULL)) goto done;
    if (j) mcp_cli_print_json(j);
    j = NULL;
    status = 0;
done:
    if (status) status = mcp_cli_fail();
    mcp_image_free(ref);
    mcp_denoiser_free(den);
    mcp_cli_denoiser_flags_free(&df);
    return status;
fail:
    mcp_cli_denoiser_flags_free(&df);
    return mcp_cli_fail();
}

const mcp_command mcp_command_adaptive = {
    "adaptive", "the adaptive-sampling loop: render, denoise, map, render more",
    cmd_adaptive, 1};
