/* cmd_estimate.c: `mcpost estimate` -- how wrong a denoised render is and whether to
 * stop (estimate/estimate.h; SPEC "estimate"). The flags parsed here; the outputs
 * (images, estimate.json, the report section) are the library's, shared with the
 * `estimate` job stage (jobs/estimate_output.c, jobs/stage_estimate.c).
 *
 * One dump: the denoised image, SURE, variance, sampling map and counts, the blocks,
 * the error distribution, and the decision F(τ) >= p with the estimated percentiles,
 * written to a folder with estimate.json and a report. A series (several dumps, or a
 * pattern with --spp): the first spp at which each τ is reached and, with a reference,
 * the true one beside it (Firmino 2024 Table 1) with the estimated and true percentile
 * curves. Flags and job keys are the same words (--denoiser-opt is the denoiser map in
 * a job). */
#include "cli.h"

#include <mcpost/estimate.h>

#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define EXIT_CONTINUE 10 /* --exit-status: keep rendering */

/* ---- flag values ---- */

static int
parse_list(const char *flag, const char *text, double *out, int max, int *n)
{
    char **words = NULL;
    int count = 0, rc = 0;
    if (mcp__split_words(text, &words, &count)) return -1;
    if (count < 1 || count > max)
        rc = mcp_error("%s: needs 1 to %d values (got %d)", flag, max, count);
    for (int i = 0; i < count && !rc; i++)
        rc = mcp__parse_double(flag, words[i], &out[i]);
    mcp__free_words(words, count);
    if (!rc) *n = count;
    return rc;
}

static int
parse_int_list(const char *flag, const char *text, int **out, int *n)
{
    char **words = NULL;
    int count = 0, rc = 0;
    if (mcp__split_words(text, &words, &count)) return -1;
    int *v = mcp_calloc((size_t)(count ? count : 1), sizeof *v);
    rc = v ? 0 : -1;
    for (int i = 0; i < count && !rc; i++) {
        rc = mcp__parse_int(flag, words[i], &v[i]);
        if (!rc && v[i] < 1)
            rc = mcp_error("%s: sample counts must be >= 1 (got %d)", flag, v[i]);
    }
    mcp__free_words(words, count);
    if (rc) {
        free(v);
        return -1;
    }
    *out = v;
    *n = count;
    return 0;
}
static void
print_single(const mcp_estimate *e, const char *input, const char *denoiser,
             const mcp_estimate_options *o)
{
    printf("input:       %s\n", input);
    printf("denoiser:    %s\n", denoiser);
    printf("metric:      %s, tau %g, p %g\n", mcp_error_metric_name(o->sure.metric),
           e->tau, e->p);
    printf("F(tau):      %.6f -> %s%s\n", e->cdf_at_tau, e->stop ? "stop" : "continue",
           e->no_variance ? " (the dump has no variance: no estimate)" : "");
    printf("blocks:      %d\n", e->blocks->count);
    printf("variance:    %s\n", mcp__variance_source_words(e->variance_source));
    printf("estimated error at percentile:\n");
    for (int k = 0; k < e->n_percentiles; k++)
        printf("  %-10g %.6g\n", e->percentiles[k], e->percentile_tau[k]);
    printf(
        "time (ms):   denoise+jvp %.1f, SURE+variance %.1f, blocks %.1f, stopping %.1f, "
        "percentiles %.1f, sampling map %.1f\n",
        e->ms_denoise, e->ms_error_terms, e->ms_blocks, e->ms_stopping, e->ms_percentiles,
        e->ms_sampling);
}

static void
print_series(const mcp_series_estimate *s)
{
    printf("%-10s", "spp");
    for (int j = 0; j < s->n_taus; j++)
        printf("  F(%-8g)%s", s->taus[j], s->has_reference ? "  true     " : "");
    printf("\n");
    for (int i = 0; i < s->count; i++) {
        const mcp_series_point *pt = &s->points[i];
        printf("%-10g", pt->spp);
        for (int j = 0; j < s->n_taus; j++) {
            printf("  %.6f%s", pt->cdf[j], pt->stop[j] ? "*" : " ");
            if (s->has_reference)
                printf("  %.6f%s", pt->true_cdf[j], pt->true_stop[j] ? "*" : " ");
        }
        printf("\n");
    }
    printf("\n%-10s  %-12s%s\n", "tau", "stop at spp",
           s->has_reference ? "  true spp      agree" : "");
    int agree = 0;
    for (int j = 0; j < s->n_taus; j++) {
        printf("%-10g  %-12g", s->taus[j], s->first_spp[j]);
        if (s->has_reference)
            printf("  %-12g  %s", s->true_first_spp[j], s->agree[j] ? "yes" : "no");
        printf("\n");
        agree += s->agree[j];
    }
    if (s->has_reference) printf("agreement: %d of %d\n", agree, s->n_taus);
    printf("(0: not reached within the series; * F(tau) >= p)\n");
    printf("variance: %s\n", mcp__variance_source_words(s->variance_source));
}

/* ---- the subcommand ---- */

static const char usage[] =
    "usage: mcpost estimate DUMP... [--denoiser NAME] [options]\n"
    "  Estimates the error of the denoised DUMP (SURE, Firmino et al. 2024) and decides\n"
    "  whether rendering can stop: F(tau) >= p, F the estimated CDF of the per-value\n"
    "  error. Several DUMPs, or --series, make a progressive series: then it reports\n"
    "  the first spp at which each tau is reached (and the true one with --ref).\n"
    "\n"
    "  --denoiser NAME          the denoiser (see `mcpost denoise --list`)\n"
    "                           " MCP_CLI_DEFAULT_DENOISER "\n"
    MCP_CLI_DENOISER_USAGE(" ")
    "  --metric NAME            relse, relse-perceptual or se [relse]\n"
    "  --tau T                  error threshold [0.01]\n"
    "  --percentile P           fraction of values that must be below tau [0.999]\n"
    "  --percentiles LIST       the estimated percentile curve "
    "[0.5,0.9,0.99,0.999,0.9999]\n"
    "  --probes K               random probes for SURE and the variance [4]\n"
    "  --seed S                 seed of the probes [0]\n"
    "  --mc-sure                J.eps by finite differences (MC-SURE)\n"
    "  --delta D                finite-difference step, unitless [0.1]\n"
    "  --variance-probes KIND   sure (reuse the SURE probes) or rademacher [sure]\n"
    "  --ppd X                  relse-perceptual: pixels per degree [67.02]\n"
    "  --tile N                 pre-split into NxN tiles before block averaging [none]\n"
    "  --sampling KIND          sampling map: variance, tonemapped or mc-sure "
    "[variance]\n"
    "  --budget N               samples for the next iteration: write integer counts\n"
    "  --s2-pool R|auto         pool s^2 = (J eps)^2 over (2R+1)^2 pixels; auto: 1, or 0\n"
    "                           for bilateral on a per-sample variance [auto]\n"
    "  -o, --output DIR         write images, blocks.png, estimate.json and a report\n"
    "  --json                   print estimate.json on stdout\n"
    "  --exit-status            exit 0 to stop, 10 to continue rendering (a series: the\n"
    "                           last member and every tau)\n"
    "  Series:\n"
    "  --series PATTERN         dump files from a printf pattern, with --spp LIST\n"
    "  --spp LIST               sample counts for --series (e.g. 1,2,4,8)\n"
    "  --taus LIST              thresholds to report [0.05,0.02,0.01; or --tau]\n"
    "  --ref FILE               the reference image: true error and agreement\n"
    "  --variance-from KIND     auto (a member's own variance, or the spread between\n"
    "                           the series' increments where they show Variance/n\n"
    "                           off: stratified samplers), file (each member's own)\n"
    "                           or increments [auto]\n"
    "  Reading dumps:\n"
    "  --convention NAME        pbrt, mitsuba, blender, mcpost, plain [auto]\n"
    "  --variance KIND          per-sample or of-mean [per convention]\n"
    "\n"
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost estimate samples/fixtures/cornell/series/cornell_spp0064.exr --denoiser nlm -o out/estimate\n"
    "  mcpost estimate --series 'samples/fixtures/cornell/series/cornell_spp%04d.exr' --spp 16,32,64,128 \\\n"
    "                  --denoiser bilateral --ref samples/fixtures/cornell/cornell_reference.exr\n";

enum {
    OPT_METRIC = 256,
    OPT_TAU,
    OPT_PERCENTILE,
    OPT_PERCENTILES,
    OPT_PROBES,
    OPT_SEED,
    OPT_MC,
    OPT_DELTA,
    OPT_VPROBES,
    OPT_PPD,
    OPT_TILE,
    OPT_SAMPLING,
    OPT_BUDGET,
    OPT_JSON,
    OPT_EXIT,
    OPT_SERIES,
    OPT_SPP,
    OPT_TAUS,
    OPT_REF,
    OPT_CONVENTION,
    OPT_VARIANCE,
    OPT_VARIANCE_FROM,
    OPT_S2_POOL
};

static int
parse_seed(const char *flag, const char *text, uint64_t *out)
{
    char *end;
    errno = 0;
    unsigned long long v = strtoull(text, &end, 10);
    if (end == text || *end || errno || text[0] == '-')
        return mcp_error("%s must be a non-negative integer (got '%s')", flag, text);
    *out = v;
    return 0;
}

static int
cmd_estimate(int argc, char **argv)
{
    static const struct option longs[] = {
        MCP_CLI_DENOISER_LONGOPTS,
        {"metric", required_argument, 0, OPT_METRIC},
        {"tau", required_argument, 0, OPT_TAU},
        {"percentile", required_argument, 0, OPT_PERCENTILE},
        {"percentiles", required_argument, 0, OPT_PERCENTILES},
        {"probes", required_argument, 0, OPT_PROBES},
        {"seed", required_argument, 0, OPT_SEED},
        {"mc-sure", no_argument, 0, OPT_MC},
        {"delta", required_argument, 0, OPT_DELTA},
        {"variance-probes", required_argument, 0, OPT_VPROBES},
        {"ppd", required_argument, 0, OPT_PPD},
        {"tile", required_argument, 0, OPT_TILE},
        {"sampling", required_argument, 0, OPT_SAMPLING},
        {"budget", required_argument, 0, OPT_BUDGET},
        {"output", required_argument, 0, 'o'},
        {"json", no_argument, 0, OPT_JSON},
        {"exit-status", no_argument, 0, OPT_EXIT},
        {"series", required_argument, 0, OPT_SERIES},
        {"spp", required_argument, 0, OPT_SPP},
        {"taus", required_argument, 0, OPT_TAUS},
        {"ref", required_argument, 0, OPT_REF},
        {"convention", required_argument, 0, OPT_CONVENTION},
        {"variance", required_argument, 0, OPT_VARIANCE},
        {"variance-from", required_argument, 0, OPT_VARIANCE_FROM},
        {"s2-pool", required_argument, 0, OPT_S2_POOL},
        {"help", no_argument, 0, 'h'},
        {0, 0, 0, 0}};
    mcp_series_estimate_options so = mcp_series_estimate_defaults();
    mcp_estimate_options *eo = &so.est;
    const char *outdir = NULL, *pattern = NULL, *spp_text = NULL,
               *ref_path = NULL, *convention = NULL, *variance = NULL;
    mcp_cli_denoiser_flags df = {0};
    int json = 0, exit_status = 0, have_taus = 0, have_tau = 0, opt;
    mcp_series_variance variance_from = MCP_SERIES_VARIANCE_AUTO;
    optind = 1;
    while ((opt = getopt_long(argc, argv, "ho:", longs, NULL)) != -1) {
        int rc = 0;
        double b = 0;
        int taken = mcp_cli_denoiser_flag(&df, opt, optarg);
        if (taken < 0) {
            mcp_cli_denoiser_flags_free(&df);
            return mcp_cli_fail();
        }
        if (taken) continue;
        switch (opt) {
        case OPT_METRIC:
            rc = mcp_error_metric_from_name(optarg, &eo->sure.metric);
            break;
        case OPT_TAU:
            rc = mcp__parse_double("--tau", optarg, &eo->tau);
            have_tau = 1;
            break;
        case OPT_PERCENTILE:
            rc = mcp__parse_double("--percentile", optarg, &eo->p);
            break;
        case OPT_PERCENTILES:
            rc = parse_list("--percentiles", optarg, eo->percentiles,
                            MCP_ESTIMATE_MAX_PERCENTILES, &eo->n_percentiles);
            break;
        case OPT_PROBES:
            rc = mcp__parse_int("--probes", optarg, &eo->sure.n_probes);
            break;
        case OPT_SEED:
            rc = parse_seed("--seed", optarg, &eo->sure.seed);
            break;
        case OPT_MC:
            eo->sure.mc_sure = 1;
            break;
        case OPT_DELTA:
            rc = mcp__parse_double("--delta", optarg, &eo->sure.fd_delta);
            break;
        case OPT_VPROBES:
            rc = mcp__variance_probes_from_name(optarg, &eo->variance_rademacher);
            break;
        case OPT_PPD:
            rc = mcp__parse_double("--ppd", optarg, &eo->sure.ppd);
            break;
        case OPT_TILE:
            rc = mcp__parse_int("--tile", optarg, &eo->blocks.tile_size);
            break;
        case OPT_SAMPLING:
            rc = mcp_sampling_kind_from_name(optarg, &eo->sampling.kind);
            break;
        case OPT_BUDGET:
            rc = mcp__parse_double("--budget", optarg, &b);
            if (!rc && (b < 0 || b != floor(b) || b > 4503599627370496.0))
                rc = mcp_error("--budget must be a whole number of samples (got %s)",
                               optarg);
            eo->budget = (int64_t)b;
            break;
        case 'o':
            outdir = optarg;
            break;
        case OPT_JSON:
            json = 1;
            break;
        case OPT_EXIT:
            exit_status = 1;
            break;
        case OPT_SERIES:
            pattern = optarg;
            break;
        case OPT_SPP:
            spp_text = optarg;
            break;
        case OPT_TAUS:
            rc = parse_list("--taus", optarg, so.taus, MCP_ESTIMATE_MAX_TAUS, &so.n_taus);
            have_taus = 1;
            break;
        case OPT_REF:
            ref_path = optarg;
            break;
        case OPT_CONVENTION:
            convention = optarg;
            break;
        case OPT_VARIANCE:
            variance = optarg;
            break;
        case OPT_VARIANCE_FROM:
            rc = mcp__variance_from(optarg, &variance_from);
            break;
        case OPT_S2_POOL:
            if (!strcmp(optarg, "auto"))
                eo->s2_pool = -1;
            else
                rc = mcp__parse_int("--s2-pool", optarg, &eo->s2_pool);
            break;
        case 'h':
            fputs(usage, stdout);
            mcp_cli_denoiser_flags_free(&df);
            return 0;
        default:
            mcp_cli_denoiser_flags_free(&df);
            return mcp_cli_usage("estimate", "bad option");
        }
        if (rc) {
            mcp_cli_denoiser_flags_free(&df);
            return mcp_cli_fail();
        }
    }
    int n_files = argc - optind;
    if (!n_files && !pattern) {
        mcp_cli_denoiser_flags_free(&df);
        return mcp_cli_usage("estimate", "no dump given");
    }
    if (pattern && (n_files || !spp_text)) {
        mcp_cli_denoiser_flags_free(&df);
        return mcp_cli_usage("estimate", "--series needs --spp and no other dumps");
    }
    if (have_tau && !have_taus) { /* a series checks the one --tau */
        so.n_taus = 1;
        so.taus[0] = eo->tau;
    }
    int status = 1, is_series = pattern || n_files > 1;
    mcp_denoiser *den = NULL;
    mcp_dump *dump = NULL;
    mcp_series *series = NULL;
    mcp_image *ref = NULL;
    mcp_estimate *e = NULL;
    mcp_series_estimate *s = NULL;
    mcp_report *report = NULL;
    cJSON *summary = NULL, *section = NULL;
    mcp__estimate_dir od;
    mcp__outdir whole = {0}; /* -o DIR appears whole, or not at all */
    memset(&od, 0, sizeof od);
    if (mcp_estimate_check(eo) ||
        mcp_cli_denoiser_create(&df, &den) ||
        (ref_path && mcp_image_read(ref_path, NULL, &ref)))
        goto done;
    if (outdir) { /* after the cheap checks, before any work */
        if (mcp__outdir_begin(&whole, outdir)) goto done;
        snprintf(od.dir, sizeof od.dir, "%s", whole.tmp);
    }
    if (outdir && (mcp_report_new("mcpost estimate", &report) ||
                   !(section = mcp_report_section(
                         report, "estimate",
                         is_series ? "error estimate over a series" : "error estimate"))))
        goto done;
    if (is_series) {
        if (pattern) {
            int *spps = NULL, n = 0;
            int rc = parse_int_list("--spp", spp_text, &spps, &n) ||
                     mcp_series_from_pattern(pattern, spps, n, &series);
            free(spps);
            if (rc) goto done;
        } else if (mcp_series_from_paths((const char *const *)argv + optind, NULL,
                                         n_files, &series)) {
            goto done;
        }
        if ((convention &&
             mcp_convention_from_name(convention, &series->spec.convention)) ||
            (variance && mcp_variance_kind_from_name(variance, &series->spec.variance)))
            goto done;
        series->variance_from = variance_from;
        if (mcp__estimate_run_series(series, den, &so, ref, outdir ? &od : NULL, section,
                                     &summary, &s))
            goto done;
        if (!json) print_series(s);
        status = 0;
        if (exit_status) {
            const mcp_series_point *last = &s->points[s->count - 1];
            for (int j = 0; j < s->n_taus; j++)
                if (!last->stop[j]) status = EXIT_CONTINUE;
        }
    } else {
        const char *path = argv[optind];
        if (mcp_cli_read_dump(path, NULL, convention, variance, &dump) ||
            mcp_estimate_compute(dump, den, eo, &e))
            goto done;
        summary = mcp__estimate_json(e, path, den->name, eo);
        if (ref && mcp__estimate_add_truth(e, ref, eo, summary)) /* the truth beside it */
            goto done;
        if (outdir) {
            char path_json[4352];
            char *text = cJSON_Print(summary);
            int rc =
                !text || mcp__estimate_write_single(e, &od, section, summary) ||
                mcp__estimate_path(&od, "estimate.json", path_json, sizeof path_json) ||
                mcp_write_file_atomic(path_json, text, strlen(text)) ||
                mcp__estimate_report_single(section, summary, e);
            free(text);
            if (rc) goto done;
        }
        if (!json) print_single(e, path, den->name, eo);
        status = exit_status && !e->stop ? EXIT_CONTINUE : 0;
    }
    if ((report && mcp__outdir_fix_paths(&whole, mcp_report_json(report))) ||
        mcp__outdir_fix_paths(&whole, summary) ||
        (report && (mcp_report_write(report, od.dir) || mcp__outdir_commit(&whole)))) {
        status = 1;
        goto done;
    }
    if (json) {
        mcp_cli_print_json(summary);
        summary = NULL;
    }
done:
    mcp__outdir_abort(&whole);
    if (status == 1) mcp_cli_fail();
    cJSON_Delete(summary);
    mcp_report_free(report);
    mcp_series_estimate_free(s);
    mcp_estimate_free(e);
    mcp_image_free(ref);
    mcp_series_free(series);
    mcp_dump_free(dump);
    mcp_denoiser_free(den);
    mcp_cli_denoiser_flags_free(&df);
    return status;
}

const mcp_command mcp_command_estimate = {
    "estimate", "estimate the error of a denoised render and decide when to stop",
    cmd_estimate, 0};
