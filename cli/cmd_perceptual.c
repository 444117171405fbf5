/* cmd_perceptual.c: `mcpost perceptual` -- perceptual error optimisation of M candidate
 * renders (docs/mathematics.md §4; perceptual.h). Writes the optimised image (for
 * horizontal methods the prediction and the permutation map, and the re-rendered image
 * when a re-render command is given), the surrogate, the scores against a reference
 * (pMSE, MSE, the blue-noise spectrum), and with --compare the table of every method on
 * the same input (Chizhov et al. 2022 Table 1). The settings and the run are the
 * library's, shared with the `perceptual` job stage (jobs/perceptual_run.c). Flags and
 * job keys are the same words ('-' in flags, '_' in keys). */
#include "cli.h"

#include <mcpost/perceptual.h>

#include <getopt.h>
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

static const char usage[] =
    "usage: mcpost perceptual [options] CANDIDATES...\n"
    "  Perceptual error optimisation (Chizhov et al. 2022): picks, per pixel, one of "
    "the\n"
    "  candidate renders (vertical methods) or permutes pixels' seeds (horizontal) so\n"
    "  that the error is least visible. Candidates are images or render dumps of few\n"
    "  samples each, e.g. 4 single-sample renders.\n"
    "  --method M          vertical-iterative [default], power-set, error-diffusion,\n"
    "                      dither, horizontal, histogram, permutation\n"
    "  --surrogate S       denoise [default: the denoiser on the candidates' mean],\n"
    "                      reference (the ground truth: best case), or an image FILE\n"
    "  --denoiser NAME     the surrogate's denoiser [default: unet with the shipped\n"
    "                      weights; nlm when the candidates have no albedo and normal];\n"
    "                      its settings:\n"
    MCP_CLI_DENOISER_USAGE("")
    "  --ref FILE          ground truth: pMSE, MSE and the error spectrum\n"
    "  --confidence C      trust in the surrogate, in [0, 1] [1], or a per-pixel FILE\n"
    "  --group N           average N consecutive files into one candidate [1]\n"
    "  --compare           also run every method on the input: the comparison table\n"
    "  --rerender CMD      for horizontal methods: a shell command that re-renders with\n"
    "                      the permutation map {permutation} into the image {output}\n"
    "                      ({method} names the method); the result is then measured\n"
    "  -o, --output DIR    output folder [perceptual]\n"
    "  --json              print the figures as JSON\n"
    "  model: --tone-map clamp|aces|none [clamp]; --kernel tap3|gaussian|a,b,c "
    "(separable\n"
    "         taps)|FILE (a 2D kernel image) [tap3]; --dpi R [300], --distance INCHES "
    "[16]\n"
    "         (gaussian); --filter-surrogate (h = g instead of delta)\n"
    "  search: --passes T [100 vertical, 10 horizontal]; --init random|mean [random];\n"
    "         --seed S [1]; --max-subsets N [64]; --radius R [1]; --travel r [1];\n"
    "         --tile N [8] (permutation baseline)\n"
    "  mask:  --mask-size N [128]; --mask-sigma S [1.5]; --mask-seed S [1]; --no-cache\n"
    "         (the mask is cached in $XDG_CACHE_HOME/mcpost or ~/.cache/mcpost)\n"
    "  --spectra-tile N    tiles of the error spectrum [32]\n"
    "\n"
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost perceptual samples/fixtures/cornell/singles/cornell_single0[0-3].exr \\\n"
    "                    --ref samples/fixtures/cornell/cornell_reference.exr -o out/perceptual\n"
    "  mcpost perceptual --compare --surrogate reference --ref samples/fixtures/cornell/cornell_reference.exr \\\n"
    "                    samples/fixtures/cornell/singles/cornell_single0[0-3].exr -o out/compare\n"
    "  mcpost perceptual --group 4 --method error-diffusion \\\n"
    "                    samples/fixtures/texture/singles/texture_single*.exr -o out/perceptual_texture\n";

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
    enum { O_JSON = 1000, O_FILTER, O_NOCACHE, O_COMPARE };
    static const struct option longs[] = {
        {"method", required_argument, 0, 'm'},
        {"surrogate", required_argument, 0, 's'},
        {"ref", required_argument, 0, 'r'},
        {"reference", required_argument, 0, 'r'},
        {"output", required_argument, 0, 'o'},
        {"json", no_argument, 0, O_JSON},
        MCP_CLI_DENOISER_LONGOPTS,
        {"filter-surrogate", no_argument, 0, O_FILTER},
        {"no-cache", no_argument, 0, O_NOCACHE},
        {"compare", no_argument, 0, O_COMPARE},
        {"confidence", required_argument, 0, 'W'},
        {"group", required_argument, 0, 'W'},
        {"tone-map", required_argument, 0, 'W'},
        {"kernel", required_argument, 0, 'W'},
        {"dpi", required_argument, 0, 'W'},
        {"distance", required_argument, 0, 'W'},
        {"passes", required_argument, 0, 'W'},
        {"init", required_argument, 0, 'W'},
        {"seed", required_argument, 0, 'W'},
        {"max-subsets", required_argument, 0, 'W'},
        {"radius", required_argument, 0, 'W'},
        {"travel", required_argument, 0, 'W'},
        {"tile", required_argument, 0, 'W'},
        {"mask-size", required_argument, 0, 'W'},
        {"mask-sigma", required_argument, 0, 'W'},
        {"mask-seed", required_argument, 0, 'W'},
        {"rerender", required_argument, 0, 'W'},
        {"spectra-tile", required_argument, 0, 'W'},
        {"help", no_argument, 0, 'h'},
        {0, 0, 0, 0}};
    mcp__perc_args a;
    mcp__perc_run r;
    mcp__perc_args_init(&a);
    memset(&r, 0, sizeof r);
    const char *out_dir = "perceptual", *ref_path = NULL;
    mcp_cli_denoiser_flags df = {0}; /* no --denoiser: the default */
    int json = 0, opt, idx = 0, status = 1;
    mcp_image *ref = NULL, *surr = NULL, *conf = NULL, *kern = NULL;
    mcp_report *report = NULL;
    cJSON *summary = NULL;
    mcp__outdir od = {0}; /* the folder appears whole, or not at all */
    optind = 1;
    while ((opt = getopt_long(argc, argv, "m:s:r:o:h", longs, &idx)) != -1) {
        int rc = mcp_cli_denoiser_flag(&df, opt, optarg);
        if (rc < 0) goto fail;
        if (rc) continue;
        switch (opt) {
        case 'm':
            rc = mcp__perc_set_word(&a, "method", optarg);
            break;
        case 's':
            rc = mcp__perc_set_word(&a, "surrogate", optarg);
            break;
        case 'r':
            ref_path = optarg;
            break;
        case 'o':
            out_dir = optarg;
            break;
        case O_JSON:
            json = 1;
            break;
        case O_FILTER:
            a.opt.model.filter_surrogate = 1;
            break;
        case O_NOCACHE:
            a.opt.mask.use_cache = 0;
            break;
        case O_COMPARE:
            a.compare = 1;
            break;
        case 'W': {
            char key[64];
            snprintf(key, sizeof key, "%s", longs[idx].name);
            for (char *p = key; *p; p++)
                *p = *p == '-' ? '_' : *p;
            rc = mcp__perc_set_word(&a, key, optarg);
            break;
        }
        case 'h':
            fputs(usage, stdout);
            status = 0;
            goto done;
        default:
            status = mcp_cli_usage("perceptual", "bad option");
            goto done;
        }
        if (rc) {
            status = mcp_cli_fail();
            goto done;
        }
    }
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
    if (!strcmp(a.surrogate, "denoise") &&
        mcp_cli_denoiser_create(&df, &r.den))
        goto fail;
    if (mcp__outdir_begin(&od, out_dir) || mcp_report_new("mcpost perceptual", &report))
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
    cmd_perceptual, 0};
