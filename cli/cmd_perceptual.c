/* cmd_perceptual.c: `mcpost perceptual` -- perceptual error optimisation of M candidate
 * renders (docs/mathematics.md §4; perceptual.h). Writes the optimised image (for
 * horizontal methods the prediction and the permutation map, and the re-rendered image
 * when a re-render command is given), the surrogate, the scores against a reference
 * (pMSE, MSE, the blue-noise spectrum), and with --compare the table of every method on
 * the same input (Chizhov et al. 2022 Table 1). The settings and the run are the
 * library's, shared with the `perceptual` job stage (jobs/perceptual_run.c); the flags
 * are the perceptual table's (ops/op_perceptual.c), as the job's keys. */
#include "cli.h"

#include <mcpost/perceptual.h>

#include <getopt.h> /* optind */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void
print_summary(const cJSON *s)
{
    const cJSON *pm = cJSON_GetObjectItem(s, "pmse");
#define STR(k) cJSON_GetObjectItem(s, k)->valuestring
#define NUM(k) cJSON_GetObjectItem(s, k)->valuedouble
    printf("method:      %s on %d candidates of %dx%d\n", STR("method"),
           (int)NUM("candidates"), (int)NUM("width"), (int)NUM("height"));
    printf("surrogate:   %s\n", STR("surrogate"));
    printf("passes:      %d (%.0f changes, %.3f s)\n", (int)NUM("passes"), NUM("changes"),
           cJSON_IsNumber(cJSON_GetObjectItem(s, "seconds")) ? NUM("seconds") : 0.0);
    if (cJSON_IsNumber(pm)) {
        printf("pMSE:        %.6g (candidates' mean %.6g; ratio %.3f)%s\n", NUM("pmse"),
               NUM("mean_pmse"), NUM("pmse_ratio"),
               !cJSON_GetObjectItem(s, "rerendered")                ? ""
               : cJSON_IsTrue(cJSON_GetObjectItem(s, "rerendered")) ? ", re-rendered"
                                                                    : ", the prediction");
        printf("MSE:         %.6g (mean %.6g)\n", NUM("mse"), NUM("mean_mse"));
        if (cJSON_IsNumber(cJSON_GetObjectItem(s, "low_freq_fraction")))
            printf(
                "low-freq:    %.4f of the error spectrum (mean %.4f, white noise %.4f)\n",
                NUM("low_freq_fraction"), NUM("mean_low_freq_fraction"),
                NUM("white_fraction"));
    }
    const cJSON *t = cJSON_GetObjectItem(s, "comparison"), *row;
    if (t) {
        printf("\n%-20s %12s %12s %12s %10s %9s\n", "method", "pMSE", "MSE", "energy",
               "low-freq", "seconds");
        cJSON_ArrayForEach(row, t)
        {
#define RN(k)                                                                            \
    (cJSON_IsNumber(cJSON_GetObjectItem(row, k))                                         \
         ? cJSON_GetObjectItem(row, k)->valuedouble                                      \
         : NAN)
            const cJSON *again = cJSON_GetObjectItem(row, "rerendered");
            char secs[32] = "-";
            if (isfinite(RN("seconds")))
                snprintf(secs, sizeof secs, "%.4f", RN("seconds"));
            printf("%-20s %12.6g %12.6g %12.6g %10.4f %9s%s\n",
                   cJSON_GetObjectItem(row, "method")->valuestring, RN("pmse"), RN("mse"),
                   RN("energy"), RN("low_freq_fraction"), secs,
                   !again                ? ""
                   : cJSON_IsTrue(again) ? "  (re-rendered)"
                                         : "  (prediction)");
#undef RN
        }
    }
    const cJSON *o;
    printf("\nwrote:\n");
    cJSON_ArrayForEach(o, cJSON_GetObjectItem(s, "outputs"))
        printf("  %s\n", o->valuestring);
#undef STR
#undef NUM
}

/* ---- the subcommand ---- */

static const char head[] =
    "usage: mcpost perceptual [options] CANDIDATES...\n"
    "  Perceptual error optimisation (Chizhov et al. 2022): picks, per pixel, one of "
    "the\n"
    "  candidate renders (vertical methods) or permutes pixels' seeds (horizontal) so\n"
    "  that the error is least visible. Candidates are images or render dumps of few\n"
    "  samples each, e.g. 4 single-sample renders.\n";

static const char examples[] =
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost perceptual samples/fixtures/cornell/singles/cornell_single0[0-3].exr \\\n"
    "                    --ref samples/fixtures/cornell/cornell_reference.exr -o "
    "out/perceptual\n"
    "  mcpost perceptual --compare --surrogate reference --ref "
    "samples/fixtures/cornell/cornell_reference.exr \\\n"
    "                    samples/fixtures/cornell/singles/cornell_single0[0-3].exr -o "
    "out/compare\n"
    "  mcpost perceptual --group 4 --method error-diffusion \\\n"
    "                    samples/fixtures/texture/singles/texture_single*.exr -o "
    "out/perceptual_texture\n";

static int
read_rgb(const char *path, mcp_image **out)
{
    mcp_image *img = NULL;
    mcp__perc_run tmp = {0};
    *out = NULL;
    if (mcp_image_read(path, NULL, &img)) return -1;
    int rc = mcp__perc_add_file(&tmp, img);
    mcp_image_free(img);
    if (!rc) {
        *out = tmp.files[0];
        tmp.files[0] = NULL;
    }
    mcp__perc_run_free(&tmp);
    return rc;
}

static int
cmd_perceptual(int argc, char **argv)
{
    mcp_perceptual_settings st;
    mcp_shared_settings sh;
    mcp__perc_args a;
    mcp__perc_run r;
    mcp__perc_args_init(&a);
    memset(&r, 0, sizeof r);
    mcp_cli_denoiser_flags df = {0}; /* no --denoiser: the default */
    int first = 0, status = 1;
    mcp_image *ref = NULL, *surr = NULL, *conf = NULL, *kern = NULL;
    mcp_report *report = NULL;
    cJSON *summary = NULL;
    mcp__outdir od = {0}; /* the folder appears whole, or not at all */
    int parsed = mcp_cli_parse(mcp_operation_perceptual(), head, examples, argc, argv,
                               &st, &sh, &df, &first);
    if (parsed >= 0) {
        status = parsed;
        goto done;
    }
    mcp__perc_args_free(&a);
    if (mcp__perc_args_from_settings(&st, &a)) goto fail;
    const char *out_dir = sh.output ? sh.output : "perceptual", *ref_path = st.reference;
    int json = sh.json;
    optind = first;
    if (optind >= argc) {
        status = mcp_cli_usage("perceptual", "no candidate files given");
        goto done;
    }
    for (int i = optind; i < argc; i++) {
        mcp_image *img = NULL;
        if (mcp_image_read(argv[i], NULL, &img) || mcp__perc_add_file(&r, img)) {
            mcp_image_free(img);
            goto fail;
        }
        mcp_image_free(img);
    }
    if (mcp__perc_finish_features(&r)) goto fail;
    if (ref_path && read_rgb(ref_path, &ref)) goto fail;
    r.reference = ref;
    if (strcmp(a.surrogate, "denoise") && strcmp(a.surrogate, "reference")) {
        if (read_rgb(a.surrogate, &surr)) goto fail;
        r.surrogate_img = surr;
    }
    if (a.confidence) {
        if (mcp_image_read(a.confidence, NULL, &conf)) goto fail;
        r.confidence_map = conf;
    }
    if (a.kernel_file) {
        if (mcp_image_read(a.kernel_file, NULL, &kern)) goto fail;
        r.kernel_img = kern;
    }
    if (!strcmp(a.surrogate, "denoise") && mcp_cli_denoiser_create(&df, &r.den))
        goto fail;
    const char *named[] = {ref_path, surr ? a.surrogate : NULL, a.confidence,
                           a.kernel_file};
    if (mcp__outdir_begin(&od, out_dir) ||
        mcp__outdir_check_inputs(&od, (const char *const *)argv + optind,
                                 argc - optind) ||
        mcp__outdir_check_inputs(&od, named, 4) ||
        mcp_report_new("mcpost perceptual", &report))
        goto fail;
    snprintf(r.out_dir, sizeof r.out_dir, "%s", od.tmp);
    if (!(r.section = mcp_report_section(report, "perceptual",
                                         mcp_perc_method_name(a.opt.method))))
        goto fail;
    if (mcp__perceptual_run(&a, &r, &summary, NULL)) goto fail;
    if (mcp__outdir_fix_paths(&od, summary)) goto fail; /* the files where they will be */
    mcp__perc_fill_section(r.section, summary);
    if (mcp_report_write(report, od.tmp) || mcp__outdir_commit(&od)) goto fail;
    if (json)
        mcp_cli_print_json(summary);
    else {
        print_summary(summary);
        cJSON_Delete(summary);
    }
    summary = NULL;
    status = 0;
    goto done;
fail:
    status = mcp_cli_fail();
done:
    mcp__outdir_abort(&od);
    cJSON_Delete(summary);
    mcp_report_free(report);
    mcp_image_free(ref), mcp_image_free(surr), mcp_image_free(conf), mcp_image_free(kern);
    mcp__perc_run_free(&r);
    mcp__perc_args_free(&a);
    mcp_cli_denoiser_flags_free(&df);
    return status;
}

const mcp_command mcp_command_perceptual = {
    "perceptual", "perceptual error optimisation of few-sample renders (Chizhov 2022)",
    cmd_perceptual, 1};
