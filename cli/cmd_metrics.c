/* cmd_metrics.c: `mcpost metrics TEST REF` -- MSE, RMSE, relMSE, PSNR, pMSE, RelSE
 * percentiles, LDR-FLIP, HDR-FLIP and the blue-noise fraction of a test image against
 * a reference (common/metrics.h), as a table, JSON, and maps. The job stage is in
 * stage_metrics.c; flags and job keys are the same words. */
#include "cli.h"

#include <mcpost/metrics.h>

#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char usage[] =
    "usage: mcpost metrics TEST REF [options]\n"
    "  Compares TEST (e.g. a denoised render) with REF (the reference). Both are EXR,\n"
    "  PFM, PNG, ... with R, G, B channels; 8-bit files are sRGB-decoded to linear.\n"
    "  Prints MSE, RMSE, relMSE (eps 1e-2), PSNR (displayed: clamped, sRGB), pMSE,\n"
    "  RelSE percentiles, LDR-FLIP, HDR-FLIP and the blue-noise low-frequency fraction.\n"
    "\n"
    "  -o, --output DIR          write maps: flip_ldr/flip_hdr (.exr and magma .png),\n"
    "                            flip_hdr_exposure, relse, sq_error, spectra, "
    "metrics.json\n"
    "  --json                    print JSON instead of the table\n"
    "  FLIP (NVIDIA FLIP v1.6):\n"
    "  --ppd X                   pixels per degree (default: from the viewing "
    "condition)\n"
    "  --distance-m X            viewing distance [0.7]\n"
    "  --display-width-m X       display width [0.7]\n"
    "  --display-width-px N      display width in pixels [3840] (defaults: ppd 67.02)\n"
    "  --tone-mapper NAME        HDR-FLIP: aces, hable or reinhard [aces]\n"
    "  --start-exposure X        HDR-FLIP, stops [automatic]\n"
    "  --stop-exposure X         HDR-FLIP, stops [automatic]\n"
    "  --num-exposures N         HDR-FLIP, >= 2 [max(2, ceil(stop - start))]\n"
    "  --flip LIST               which FLIPs: ldr,hdr or none [ldr,hdr]\n"
    "  Relative errors:\n"
    "  --percentiles LIST        RelSE percentiles in [0, 1] [0.5,0.9,0.99]\n"
    "  --eps-rel X               epsilon of relMSE and RelSE [0.01]\n"
    "  pMSE (Chizhov et al. 2022):\n"
    "  --pmse-kernel NAME        tap3 ([1/pi, 1-2/pi, 1/pi]) or gaussian [tap3]\n"
    "  --pmse-dpi X              gaussian: screen resolution [300]\n"
    "  --pmse-distance-in X      gaussian: viewing distance in inches [16]\n"
    "  --pmse-filter-reference   filter the reference with g too (h = g, not delta)\n"
    "  --pmse-tone-map NAME      clamp, aces, hable, reinhard or none [clamp]\n"
    "  Blue noise:\n"
    "  --no-spectra              skip the tiled error spectra\n"
    "  --spectra-tile-size N     tile size [32]\n"
    "  --spectra-cutoff X        fraction of Nyquist [0.25]\n"
    "  Gates (CI; docs/metrics.md, \"Gates\"):\n"
    "  --fail 'EXPR'             FAILURE when EXPR holds (repeatable)\n"
    "  --warn 'EXPR'             WARNING when EXPR holds (repeatable)\n"
    "                            EXPR: FIGURE OP NUMBER, OP one of > >= < <=, FIGURE a\n"
    "                            number of the --json output, dots for nesting\n"
    "                            (mse, relmse, psnr, flip_ldr.mean, ...). Prints PASS,\n"
    "                            WARNING: ... or FAILURE: ... last (--json: a \"gate\"\n"
    "                            object) and exits 0 pass, 3 warning, 4 failure\n"
    "                            (1 error, 2 usage error, as always)\n"
    "\n"
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost metrics samples/fixtures/cornell/series/cornell_spp0016.exr samples/fixtures/cornell/cornell_reference.exr\n"
    "  mcpost metrics --json --flip ldr samples/fixtures/cornell/series/cornell_spp0064.exr \\\n"
    "                 samples/fixtures/cornell/cornell_reference.exr \\\n"
    "                 --fail 'flip_ldr.mean > 0.2' --warn 'relmse > 0.5'\n"
    "  mcpost metrics samples/fixtures/cornell/series/cornell_spp0016.exr samples/fixtures/cornell/cornell_reference.exr \\\n"
    "                 -o out/metrics_maps --tone-mapper hable\n";

enum {
    OPT_JSON = 256,
    OPT_PPD,
    OPT_DISTANCE,
    OPT_WIDTH_M,
    OPT_WIDTH_PX,
    OPT_TONE_MAPPER,
    OPT_START,
    OPT_STOP,
    OPT_NUM,
    OPT_FLIP,
    OPT_PERCENTILES,
    OPT_EPS,
    OPT_PKERNEL,
    OPT_PDPI,
    OPT_PDIST,
    OPT_PFILTER,
    OPT_PTONE,
    OPT_NO_SPECTRA,
    OPT_TILE,
    OPT_CUTOFF,
    OPT_FAIL,
    OPT_WARN
};

/* "ldr,hdr" / "none" into the two switches. */
static int
parse_flip_list(const char *text, mcp_metrics_options *o)
{
    char **words = NULL;
    int n = 0;
    if (mcp__split_words(text, &words, &n)) return -1;
    o->flip_ldr = o->flip_hdr = 0;
    int rc = 0;
    for (int i = 0; i < n && !rc; i++) {
        if (!strcmp(words[i], "ldr"))
            o->flip_ldr = 1;
        else if (!strcmp(words[i], "hdr"))
            o->flip_hdr = 1;
        else if (strcmp(words[i], "none"))
            rc = mcp_error("--flip: unknown '%s' (use ldr, hdr or none)", words[i]);
    }
    mcp__free_words(words, n);
    return rc;
}

static int
parse_percentiles(const char *text, mcp_metrics_options *o)
{
    char **words = NULL;
    int n = 0, rc = 0;
    if (mcp__split_words(text, &words, &n)) return -1;
    double p[MCP_METRICS_MAX_PERCENTILES];
    if (n > MCP_METRICS_MAX_PERCENTILES)
        rc = mcp_error("--percentiles: at most %d values (got %d)",
                       MCP_METRICS_MAX_PERCENTILES, n);
    for (int i = 0; i < n && !rc; i++)
        rc = mcp__parse_double("--percentiles", words[i], &p[i]);
    if (!rc) rc = mcp_metrics_set_percentiles(o, p, n);
    mcp__free_words(words, n);
    return rc;
}

static void
print_table(const char *test, const char *ref, const mcp_image *img, const mcp_metrics *m,
            const mcp_metrics_options *o)
{
    printf("test:        %s\nreference:   %s (%dx%d)\n\n", test, ref, img->width,
           img->height);
    printf("%-14s %.6g\n", "MSE", m->mse);
    printf("%-14s %.6g\n", "RMSE", m->rmse);
    printf("%-14s %.6g   (eps %g)\n", "relMSE", m->relmse, o->eps_rel);
    if (isinf(m->psnr))
        printf("%-14s inf dB   (identical when displayed)\n", "PSNR");
    else
        printf("%-14s %.4f dB   (displayed: clamped to [0, 1], sRGB)\n", "PSNR", m->psnr);
    printf("%-14s %.6g   (g %s, h %s, T %s)\n", "pMSE", m->pmse,
           mcp_pkernel_kind_name(o->pmse.kernel.kind),
           o->pmse.filter_reference ? "g" : "delta", mcp_tonemap_name(o->pmse.tone_map));
    for (int k = 0; k < m->n_percentiles; k++) {
        char name[32];
        snprintf(name, sizeof name, "RelSE p%g", 100.0 * m->percentiles[k]);
        printf("%-14s %.6g\n", name, m->relse[k]);
    }
    if (m->has_flip_ldr)
        printf("%-14s %.6f   (ppd %.2f)\n", "LDR-FLIP", m->flip_ldr.mean,
               m->flip_ldr.ppd);
    if (m->has_flip_hdr)
        printf("%-14s %.6f   (%s, exposures %.4f to %.4f in %d steps)\n", "HDR-FLIP",
               m->flip_hdr.mean, mcp_tonemap_name(o->flip.tone_mapper),
               m->flip_hdr.start_exposure, m->flip_hdr.stop_exposure,
               m->flip_hdr.num_exposures);
    if (m->has_spectra)
        printf("%-14s %.4f   (low-frequency energy fraction; white noise %.4f)\n",
               "blue noise", m->spectra.low_fraction, m->spectra.white_fraction);
}

static int
cmd_metrics(int argc, char **argv)
{
    static const struct option longs[] = {
        {"output", required_argument, 0, 'o'},
        {"json", no_argument, 0, OPT_JSON},
        {"ppd", required_argument, 0, OPT_PPD},
        {"distance-m", required_argument, 0, OPT_DISTANCE},
        {"display-width-m", required_argument, 0, OPT_WIDTH_M},
        {"display-width-px", required_argument, 0, OPT_WIDTH_PX},
        {"tone-mapper", required_argument, 0, OPT_TONE_MAPPER},
        {"start-exposure", required_argument, 0, OPT_START},
        {"stop-exposure", required_argument, 0, OPT_STOP},
        {"num-exposures", required_argument, 0, OPT_NUM},
        {"flip", required_argument, 0, OPT_FLIP},
        {"percentiles", required_argument, 0, OPT_PERCENTILES},
        {"eps-rel", required_argument, 0, OPT_EPS},
        {"pmse-kernel", required_argument, 0, OPT_PKERNEL},
        {"pmse-dpi", required_argument, 0, OPT_PDPI},
        {"pmse-distance-in", required_argument, 0, OPT_PDIST},
        {"pmse-filter-reference", no_argument, 0, OPT_PFILTER},
        {"pmse-tone-map", required_argument, 0, OPT_PTONE},
        {"no-spectra", no_argument, 0, OPT_NO_SPECTRA},
        {"spectra-tile-size", required_argument, 0, OPT_TILE},
        {"spectra-cutoff", required_argument, 0, OPT_CUTOFF},
        {"fail", required_argument, 0, OPT_FAIL},
        {"warn", required_argument, 0, OPT_WARN},
        {"help", no_argument, 0, 'h'},
        {0, 0, 0, 0}};
    mcp__gate gate = {0};
    mcp_metrics_options o = mcp_metrics_defaults();
    const char *out_dir = NULL;
    int json = 0, opt;
    optind = 1;
    while ((opt = getopt_long(argc, argv, "ho:", longs, NULL)) != -1) {
        int rc = 0;
        switch (opt) {
        case 'o':
            out_dir = optarg;
            break;
        case OPT_JSON:
            json = 1;
            break;
        case OPT_PPD:
            rc = mcp__parse_double("--ppd", optarg, &o.flip.ppd);
            break;
        case OPT_DISTANCE:
            rc = mcp__parse_double("--distance-m", optarg, &o.flip.distance_m);
            break;
        case OPT_WIDTH_M:
            rc = mcp__parse_double("--display-width-m", optarg, &o.flip.display_width_m);
            break;
        case OPT_WIDTH_PX:
            rc =
                mcp__parse_double("--display-width-px", optarg, &o.flip.display_width_px);
            break;
        case OPT_TONE_MAPPER:
            rc = mcp_tonemap_from_name(optarg, &o.flip.tone_mapper);
            break;
        case OPT_START:
            rc = mcp__parse_double("--start-exposure", optarg, &o.flip.start_exposure);
            break;
        case OPT_STOP:
            rc = mcp__parse_double("--stop-exposure", optarg, &o.flip.stop_exposure);
            break;
        case OPT_NUM:
            rc = mcp__parse_int("--num-exposures", optarg, &o.flip.num_exposures);
            break;
        case OPT_FLIP:
            rc = parse_flip_list(optarg, &o);
            break;
        case OPT_PERCENTILES:
            rc = parse_percentiles(optarg, &o);
            break;
        case OPT_EPS:
            rc = mcp__parse_double("--eps-rel", optarg, &o.eps_rel);
            break;
        case OPT_PKERNEL:
            rc = mcp_pkernel_kind_from_name(optarg, &o.pmse.kernel.kind);
            break;
        case OPT_PDPI:
            rc = mcp__parse_double("--pmse-dpi", optarg, &o.pmse.kernel.dpi);
            break;
        case OPT_PDIST:
            rc = mcp__parse_double("--pmse-distance-in", optarg,
                                   &o.pmse.kernel.distance_in);
            break;
        case OPT_PFILTER:
            o.pmse.filter_reference = 1;
            break;
        case OPT_PTONE:
            rc = mcp_tonemap_from_name(optarg, &o.pmse.tone_map);
            break;
        case OPT_NO_SPECTRA:
            o.spectra = 0;
            break;
        case OPT_TILE:
            rc = mcp__parse_int("--spectra-tile-size", optarg, &o.spectra_opt.tile_size);
            break;
        case OPT_CUTOFF:
            rc = mcp__parse_double("--spectra-cutoff", optarg, &o.spectra_opt.cutoff);
            break;
        case OPT_FAIL:
        case OPT_WARN:
            /* a malformed condition is the caller's mistake: a usage error, not a gate */
            if (mcp__gate_add(&gate, optarg, opt == OPT_FAIL))
                return mcp_cli_usage("metrics", "%s", mcp_error_message());
            break;
        case 'h':
            fputs(usage, stdout);
            return 0;
        default:
            return mcp_cli_usage("metrics", "bad option");
        }
        if (rc) return mcp_cli_fail();
    }
    if (argc - optind != 2)
        return mcp_cli_usage("metrics", "give TEST and REF (got %d files)",
                             argc - optind);
    if (o.flip_hdr && mcp_tonemap_flip_coefficients(o.flip.tone_mapper, (float[6]){0}))
        return mcp_cli_fail();
    if (gate.n) {
        /* Names checked before the images are read: a typo costs no FLIP run, and it
         * is a usage error (2), never mistaken for a gate's verdict. */
        cJSON *names = mcp__gate_metrics_names(&o);
        int bad = !names || mcp__gate_check(&gate, names, NULL);
        cJSON_Delete(names);
        if (bad) return mcp_cli_usage("metrics", "%s", mcp_error_message());
    }
    const char *test_path = argv[optind], *ref_path = argv[optind + 1];
    mcp_image *test = NULL, *ref = NULL;
    mcp_metrics m;
    mcp_metrics_maps maps = {0};
    cJSON *doc = NULL;
    int status = 1;
    if (mcp_image_read(test_path, NULL, &test) || mcp_image_read(ref_path, NULL, &ref) ||
        mcp_metrics_compute(test, ref, &o, &m, out_dir ? &maps : NULL))
        goto done;
    doc = cJSON_CreateObject();
    cJSON_AddStringToObject(doc, "test", test_path);
    cJSON_AddStringToObject(doc, "reference", ref_path);
    cJSON_AddNumberToObject(doc, "width", ref->width);
    cJSON_AddNumberToObject(doc, "height", ref->height);
    if (mcp_metrics_json(&m, &o, doc)) goto done;
    mcp__gate_verdict verdict = MCP__GATE_PASS;
    char gate_line[2200] = "";
    if (gate.n) {
        cJSON *gj = NULL;
        if (mcp__gate_eval(&gate, doc, &verdict, &gj, gate_line, sizeof gate_line))
            goto done;
        cJSON_AddItemToObject(doc, "gate", gj);
    }
    if (out_dir) {
        char path[4096];
        char *text = NULL;
        if (mcp_metrics_write_maps(&maps, out_dir, "", NULL)) goto done;
        snprintf(path, sizeof path, "%s/metrics.json", out_dir);
        if (!(text = cJSON_Print(doc))) goto done;
        int rc = mcp_write_file_atomic(path, text, strlen(text));
        free(text);
        if (rc) goto done;
    }
    if (json) {
        mcp_cli_print_json(doc);
        doc = NULL;
    } else {
        print_table(test_path, ref_path, ref, &m, &o);
        if (out_dir) printf("\nmaps written to %s/\n", out_dir);
        /* idiff's convention: the verdict is the last line, after the figures */
        if (gate.n) printf("\n%s\n", gate_line);
    }
    status = mcp__gate_exit_code(verdict);
    goto out;
done:
    if (status) status = mcp_cli_fail();
out:
    cJSON_Delete(doc);
    mcp_metrics_maps_free(&maps);
    mcp_image_free(ref);
    mcp_image_free(test);
    return status;
}

const mcp_command mcp_command_metrics = {"metrics",
                                         "compare a test image with a reference "
                                         "(MSE, relMSE, PSNR, pMSE, FLIP, ...)",
                                         cmd_metrics, 0};
