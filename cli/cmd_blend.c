/* cmd_blend.c: `mcpost blend SERIES --denoiser NAME` -- converging blends of a
 * progressive render with its denoised images (blend/blend.h; Denisova & Bocchi 2024).
 * Per member: the blended image and the weight map; with a reference: MSE, relMSE and
 * HDR-FLIP per spp of the noisy, denoised, easy, curve, ideal and James-Stein images
 * (the paper's Fig. 4) as tables and plots, in JSON and the report. The run and its
 * outputs are the library's, shared with the `blend` job stage (jobs/blend_run.c).
 * Flags and job keys are the same words ('-' for '_'). */
#include "cli.h"

#include <mcpost/blend.h>
#include <mcpost/progress.h>

#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- the subcommand ---- */

static const char usage[] =
    "usage: mcpost blend SERIES... [--denoiser NAME] [options]\n"
    "  Blends every member of a progressive render with its denoised image so that the\n"
    "  result converges to the noisy (unbiased) one (Denisova & Bocchi 2024). SERIES is\n"
    "  a printf pattern with --spp (e.g. 'cornell_spp%04d.exr' --spp 1,2,4,8), or a "
    "list\n"
    "  of dumps in increasing spp. Each member needs its variance and sample count.\n"
    "  Writes NAME.blend.exr and NAME.weights.exr per member, blend.json and a report\n"
    "  (report.json, report.html) into the output folder.\n"
    "\n"
    "  --denoiser NAME           the denoiser (see 'mcpost denoise --list')\n"
    "                            " MCP_CLI_DEFAULT_DENOISER "\n"
    MCP_CLI_DENOISER_USAGE("  ")
    "  --spp LIST                the pattern's sample counts, e.g. 1,2,4,8\n"
    "  --stop-denoising-at SPP   denoise up to this spp; later members reuse d and SURE\n"
    "  --ref, --reference REF    reference: errors of every method, ideal blending,\n"
    "                            tables and plots of MSE, relMSE, HDR-FLIP per spp\n"
    "  -o, --output DIR          output folder [blend-out]\n"
    "  --all-images              also write the denoised, easy, James-Stein and ideal\n"
    "                            images\n"
    "  --json                    print the result JSON on stdout\n"
    "  --quiet                   no progress\n"
    "  Curves and weights:\n"
    "  --weights NAME            james-stein (the weight of d from how far it is from n,\n"
    "                            against n's noise; needs no error estimate) or curves\n"
    "                            (Denisova & Bocchi's convergence curves from SURE)\n"
    "                            [james-stein]\n"
    "  --fit NAME                on_the_fly (newest point + Eq. 11 point, SPEC),\n"
    "                            last_two (the paper's: the last two kept points) or\n"
    "                            retrospective (least squares over every member) "
    "[on_the_fly]\n"
    "  --curve NAME              log (log v = a log I + b) or powerlaw (the authors'\n"
    "                            code: ln v + 100 = a I^b, W capped at 65536) [log]\n"
    "  --far-spp N               N of Eq. 11 [1e6]\n"
    "  --max-weight W            cap on W in spp [none; powerlaw 65536]\n"
    "  --denoiser-keeps-zeros    all-black pixels take d (else n) [off]\n"
    "  Estimates:\n"
    "  --filter NAME             gauss, denoiser or none [gauss]\n"
    "  --filter-window N         Gaussian window [11]\n"
    "  --filter-sigma-scale X    sigma = min(sqrt(mean v), 1) x X [100]\n"
    "  --no-stop-filtering       keep filtering after mean v < mean SURE\n"
    "  --negative-sure NAME      switch (zero, then magnitude once mean v < mean SURE),\n"
    "                            zero or magnitude [switch]\n"
    "  --n-probes K              SURE probes [1]\n"
    "  --seed S                  SURE probe seed [0]\n"
    "  --js-window N             James-Stein window (also the safeguard's) [7]\n"
    "  --no-safeguard            let the curve weights stand where the denoised image\n"
    "                            differs from the noisy one by more than its noise\n"
    "                            explains (docs/blend.md \"The safeguard\")\n"
    "  --no-flip                 skip HDR-FLIP\n"
    "  --variance-from KIND      auto (a member's own variance, or the spread between\n"
    "                            the series' increments where they show Variance/n\n"
    "                            off: stratified samplers), file (each member's own)\n"
    "                            or increments [auto]\n"
    "\n"
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost blend 'samples/fixtures/cornell/series/cornell_spp%04d.exr' --spp 16,32,64,128 --denoiser gauss \\\n"
    "               --fit last_two -o out/blend\n"
    "  mcpost blend samples/fixtures/texture/series/texture_spp0016.exr \\\n"
    "               samples/fixtures/texture/series/texture_spp0064.exr --denoiser nlm --no-flip \\\n"
    "               --ref samples/fixtures/texture/texture_reference.exr -o out/blend_texture\n";

enum {
    OPT_SPP = 256,
    OPT_STOP,
    OPT_REF,
    OPT_ALL,
    OPT_JSON,
    OPT_QUIET,
    OPT_FIT,
    OPT_CURVE,
    OPT_FAR,
    OPT_MAXW,
    OPT_ZEROS,
    OPT_FILTER,
    OPT_WINDOW,
    OPT_SIGMA,
    OPT_NO_STOP_FILTERING,
    OPT_NEG,
    OPT_PROBES,
    OPT_SEED,
    OPT_JS,
    OPT_NO_FLIP,
    OPT_NO_SAFEGUARD,
    OPT_WEIGHTS,
    OPT_VARIANCE_FROM
};

static int
parse_spp_list(const char *text, int **out, int *count)
{
    char **words = NULL;
    int n = 0;
    if (mcp__split_words(text, &words, &n)) return -1;
    int *v = mcp_calloc((size_t)(n > 0 ? n : 1), sizeof *v);
    int rc = v ? 0 : -1;
    for (int i = 0; rc == 0 && i < n; i++)
        rc = mcp__parse_int("--spp", words[i], &v[i]);
    mcp__free_words(words, n);
    if (rc || n == 0) {
        free(v);
        return rc ? -1 : mcp_error("--spp needs at least one value");
    }
    *out = v;
    *count = n;
    return 0;
}

static int
parse_seed(const char *text, uint64_t *out)
{
    char *end;
    errno = 0;
    unsigned long long v = strtoull(text, &end, 10);
    if (end == text || *end || errno || text[0] == '-')
        return mcp_error("--seed must be a non-negative integer (got '%s')", text);
    *out = (uint64_t)v;
    return 0;
}

static int
cmd_blend(int argc, char **argv)
{
    static const struct option longs[] = {
        MCP_CLI_DENOISER_LONGOPTS,
        {"spp", required_argument, 0, OPT_SPP},
        {"stop-denoising-at", required_argument, 0, OPT_STOP},
        {"ref", required_argument, 0, OPT_REF},
        {"reference", required_argument, 0, OPT_REF},
        {"output", required_argument, 0, 'o'},
        {"all-images", no_argument, 0, OPT_ALL},
        {"json", no_argument, 0, OPT_JSON},
        {"quiet", no_argument, 0, OPT_QUIET},
        {"fit", required_argument, 0, OPT_FIT},
        {"curve", required_argument, 0, OPT_CURVE},
        {"far-spp", required_argument, 0, OPT_FAR},
        {"max-weight", required_argument, 0, OPT_MAXW},
        {"denoiser-keeps-zeros", no_argument, 0, OPT_ZEROS},
        {"filter", required_argument, 0, OPT_FILTER},
        {"filter-window", required_argument, 0, OPT_WINDOW},
        {"filter-sigma-scale", required_argument, 0, OPT_SIGMA},
        {"no-stop-filtering", no_argument, 0, OPT_NO_STOP_FILTERING},
        {"negative-sure", required_argument, 0, OPT_NEG},
        {"n-probes", required_argument, 0, OPT_PROBES},
        {"seed", required_argument, 0, OPT_SEED},
        {"js-window", required_argument, 0, OPT_JS},
        {"no-flip", no_argument, 0, OPT_NO_FLIP},
        {"no-safeguard", no_argument, 0, OPT_NO_SAFEGUARD},
        {"weights", required_argument, 0, OPT_WEIGHTS},
        {"variance-from", required_argument, 0, OPT_VARIANCE_FROM},
        {"help", no_argument, 0, 'h'},
        {0, 0, 0, 0}};
    mcp_blend_series_options o = mcp_blend_series_defaults();
    mcp_blend_options *b = &o.blend;
    const char *ref_path = NULL, *out_dir = "blend-out";
    mcp_cli_denoiser_flags df = {0};
    int json = 0, all_images = 0, opt, status = 1;
    int *spps = NULL, n_spps = 0;
    mcp_series_variance variance_from = MCP_SERIES_VARIANCE_AUTO;
    mcp_series *series = NULL;
    mcp_denoiser *den = NULL;
    mcp_image *ref = NULL;
    mcp_report *report = NULL;
    mcp__outdir whole = {0}; /* -o DIR appears whole, or not at all */
    optind = 1;
    while ((opt = getopt_long(argc, argv, "ho:", longs, NULL)) != -1) {
        int rc = mcp_cli_denoiser_flag(&df, opt, optarg);
        if (rc < 0) goto fail;
        if (rc) continue;
        switch (opt) {
        case OPT_SPP:
            free(spps);
            spps = NULL;
            rc = parse_spp_list(optarg, &spps, &n_spps);
            break;
        case OPT_STOP:
            rc = mcp__parse_double("--stop-denoising-at", optarg, &o.stop_denoising_at);
            break;
        case OPT_REF:
            ref_path = optarg;
            break;
        case 'o':
            out_dir = optarg;
            break;
        case OPT_ALL:
            all_images = 1;
            break;
        case OPT_JSON:
            json = 1;
            break;
        case OPT_QUIET:
            mcp_progress_set_quiet(1);
            break;
        case OPT_FIT:
            rc = mcp_curve_fit_from_name(optarg, &b->fit);
            break;
        case OPT_CURVE:
            rc = mcp_curve_model_from_name(optarg, &b->curve);
            break;
        case OPT_FAR:
            rc = mcp__parse_double("--far-spp", optarg, &b->far_spp);
            break;
        case OPT_MAXW:
            rc = mcp__parse_double("--max-weight", optarg, &b->max_weight);
            break;
        case OPT_ZEROS:
            b->denoiser_keeps_zeros = 1;
            break;
        case OPT_FILTER:
            rc = mcp_blend_filter_from_name(optarg, &b->filter);
            break;
        case OPT_WINDOW:
            rc = mcp__parse_int("--filter-window", optarg, &b->filter_window);
            break;
        case OPT_SIGMA:
            rc =
                mcp__parse_double("--filter-sigma-scale", optarg, &b->filter_sigma_scale);
            break;
        case OPT_NO_STOP_FILTERING:
            b->stop_filtering = 0;
            break;
        case OPT_NEG:
            rc = mcp_neg_sure_from_name(optarg, &b->negative_sure);
            break;
        case OPT_PROBES:
            rc = mcp__parse_int("--n-probes", optarg, &o.sure.n_probes);
            break;
        case OPT_SEED:
            rc = parse_seed(optarg, &o.sure.seed);
            break;
        case OPT_JS:
            rc = mcp__parse_int("--js-window", optarg, &b->js_window);
            break;
        case OPT_NO_FLIP:
            o.flip = 0;
            break;
        case OPT_NO_SAFEGUARD: b->safeguard = 0; break;
        case OPT_WEIGHTS: rc = mcp_blend_weighting_from_name(optarg, &b->weights); break;
        case OPT_VARIANCE_FROM:
            rc = mcp__variance_from(optarg, &variance_from);
            break;
        case 'h':
            fputs(usage, stdout);
            status = 0;
            goto done;
        default:
            status = mcp_cli_usage("blend", "bad option");
            goto done;
        }
        if (rc) goto fail;
    }
    int n_files = argc - optind;
    if (n_files < 1) {
        status = mcp_cli_usage("blend", "no series given");
        goto done;
    }
    if (spps && n_files != 1) {
        status =
            mcp_cli_usage("blend", "--spp goes with one pattern (got %d files)", n_files);
        goto done;
    }
    if (mcp_blend_options_check(b) ||
        (spps ? mcp_series_from_pattern(argv[optind], spps, n_spps, &series)
              : mcp_series_from_paths((const char *const *)argv + optind, NULL, n_files,
                                      &series)) ||
        mcp_cli_denoiser_create(&df, &den) ||
        (ref_path && mcp_image_read(ref_path, NULL, &ref)) ||
        mcp__outdir_begin(&whole, out_dir) || mcp_report_new("mcpost blend", &report))
        goto fail;
    series->variance_from = variance_from;
    mcp__blend_sink sink;
    memset(&sink, 0, sizeof sink);
    snprintf(sink.dir, sizeof sink.dir, "%s", whole.tmp);
    sink.rel = "";
    sink.all_images = all_images;
    char title[600];
    snprintf(title, sizeof title, "blend: %s with %s", argv[optind], den->name);
    cJSON *section = mcp_report_section(report, "blend", title);
    if (!section || mcp__blend_run(series, den, ref, &o, den->name, &sink, section))
        goto fail;
    if (mcp__outdir_fix_paths(&whole, mcp_report_json(report))) goto fail;
    char *text = cJSON_Print(section), path[4400];
    snprintf(path, sizeof path, "%s/blend.json", whole.tmp);
    int wrc = !text || mcp_write_file_atomic(path, text, strlen(text));
    if (!wrc && json) puts(text);
    free(text);
    if (wrc || mcp_report_write(report, whole.tmp) || mcp__outdir_commit(&whole)) goto fail;
    mcp_note("blend: %d members into %s", series->count, out_dir);
    status = 0;
    goto done;
fail:
    status = mcp_cli_fail();
done:
    mcp__outdir_abort(&whole);
    mcp_report_free(report);
    mcp_image_free(ref);
    mcp_denoiser_free(den);
    mcp_series_free(series);
    free(spps);
    mcp_cli_denoiser_flags_free(&df);
    return status;
}

const mcp_command mcp_command_blend = {"blend",
                                       "blend a progressive render with its denoised "
                                       "images so that it converges (Denisova & Bocchi)",
                                       cmd_blend, 1};
