/* cmd_blend.c: `mcpost blend SERIES --denoiser NAME` -- converging blends of a
 * progressive render with its denoised images (blend/blend.h; Denisova & Bocchi 2024).
 * Per member: the blended image and the weight map; with a reference: MSE, relMSE and
 * HDR-FLIP per spp of the noisy, denoised, easy, curve, ideal and James-Stein images
 * (the paper's Fig. 4) as tables and plots, in JSON and the report. The run and its
 * outputs are the library's, shared with the `blend` job stage (jobs/blend_run.c).
 * The flags are the blend's table (ops/op_blend.c), read by cli/options.c: the job
 * keys and Python keywords are the same words ('-' for '_'). */
#include "cli.h"

#include <mcpost/blend.h>
#include <mcpost/progress.h>

#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- the subcommand ---- */

static const char head[] =
    "usage: mcpost blend SERIES... [--denoiser NAME] [options]\n"
    "  Blends every member of a progressive render with its denoised image so that the\n"
    "  result converges to the noisy (unbiased) one (Denisova & Bocchi 2024). SERIES is\n"
    "  a printf pattern with --spp (e.g. 'cornell_spp%04d.exr' --spp 1,2,4,8), or a "
    "list\n"
    "  of dumps in increasing spp. Each member needs its variance and sample count.\n"
    "  Writes NAME.blend.exr and NAME.weights.exr per member, blend.json and a report\n"
    "  (report.json, report.html) into the output folder.\n";

static const char examples[] =
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost blend 'samples/fixtures/cornell/series/cornell_spp%04d.exr' --spp "
    "16,32,64,128 --denoiser gauss \\\n"
    "               --fit last_two -o out/blend\n"
    "  mcpost blend samples/fixtures/texture/series/texture_spp0016.exr \\\n"
    "               samples/fixtures/texture/series/texture_spp0064.exr --denoiser nlm "
    "--no-flip \\\n"
    "               --ref samples/fixtures/texture/texture_reference.exr -o "
    "out/blend_texture\n";

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
cmd_blend(int argc, char **argv)
{
    mcp_blend_settings st;
    mcp_shared_settings sh;
    mcp_cli_denoiser_flags df = {0};
    int first = 0, status = 1;
    int *spps = NULL, n_spps = 0;
    mcp_series *series = NULL;
    mcp_denoiser *den = NULL;
    mcp_image *ref = NULL;
    mcp_report *report = NULL;
    mcp__outdir whole = {0}; /* -o DIR appears whole, or not at all */
    int parsed = mcp_cli_parse(mcp_operation_blend(), head, examples, argc, argv, &st,
                               &sh, &df, &first);
    if (parsed >= 0) {
        status = parsed;
        goto done;
    }
    mcp_blend_series_options o = st.o;
    const char *ref_path = st.reference, *out_dir = sh.output ? sh.output : "blend-out";
    int json = sh.json, all_images = st.all_images;
    mcp_series_variance variance_from = st.variance_from;
    if (st.spp && parse_spp_list(st.spp, &spps, &n_spps)) goto fail;
    optind = first;
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
    if ((spps ? mcp_series_from_pattern(argv[optind], spps, n_spps, &series)
              : mcp_series_from_paths((const char *const *)argv + optind, NULL, n_files,
                                      &series)) ||
        mcp_cli_denoiser_create(&df, &den) ||
        (ref_path && mcp_image_read(ref_path, NULL, &ref)) ||
        mcp__outdir_begin(&whole, out_dir) ||
        mcp__outdir_check_inputs(&whole, (const char *const *)argv + optind, n_files) ||
        mcp__outdir_check_inputs(&whole, &ref_path, 1) ||
        mcp_report_new("mcpost blend", &report))
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
    if (wrc || mcp_report_write(report, whole.tmp) || mcp__outdir_commit(&whole))
        goto fail;
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
