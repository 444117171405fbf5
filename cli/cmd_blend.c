/* cmd_blend.c: `mcpost blend SERIES --denoiser NAME` and the `blend` job stage --
 * converging blends of a progressive render with its denoised images (blend/blend.h;
 * Denisova & Bocchi 2024). Per member: the blended image and the weight map; with a
 * reference: MSE, relMSE and HDR-FLIP per spp of the noisy, denoised, easy, curve,
 * ideal and James-Stein images (the paper's Fig. 4) as tables and plots, in JSON and
 * the report. Flags and job keys are the same words ('-' for '_'). */
#include "cli.h"

#include <mcpost/blend.h>
#include <mcpost/progress.h>
#include <mcpost/tonemap.h>

#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* ---- shared by the subcommand and the stage ---- */

/* Where a run writes, and what it reports. */
typedef struct {
    char dir[4096];  /* the output folder (exists) */
    const char *rel; /* the folder relative to the report's folder ("" or "x/") */
    int all_images;  /* also denoised, easy, james_stein, ideal */
    cJSON *members;  /* per-member file list for the JSON */
    mcp_progress prog;
    char last_base[512]; /* the last member's file name without extension */
} blend_sink;

/* The file name of path without folder and extension. */
static void
base_name(const char *path, char *out, size_t cap)
{
    const char *slash = strrchr(path, '/');
    snprintf(out, cap, "%s", slash ? slash + 1 : path);
    char *dot = strrchr(out, '.');
    if (dot && dot != out) *dot = '\0';
}

static int
write_member_image(blend_sink *s, const mcp_image *img, const char *base,
                   const char *what, cJSON *files)
{
    char name[700], path[4096 + 800];
    snprintf(name, sizeof name, "%s.%s.exr", base, what);
    snprintf(path, sizeof path, "%s/%s", s->dir, name);
    if (mcp_image_write(img, path, NULL)) return -1;
    cJSON_AddStringToObject(files, what, name);
    return 0;
}

static int
on_point(const mcp_blend_point *p, void *ctx)
{
    blend_sink *s = ctx;
    char base[512];
    base_name(p->source, base, sizeof base);
    snprintf(s->last_base, sizeof s->last_base, "%s", base);
    cJSON *m = cJSON_CreateObject();
    cJSON_AddItemToArray(s->members, m);
    cJSON_AddStringToObject(m, "source", p->source);
    cJSON_AddNumberToObject(m, "spp", p->row->spp);
    cJSON *files = cJSON_AddObjectToObject(m, "files");
    if (write_member_image(s, p->images[MCP_BLEND_CURVES], base, "blend", files) ||
        write_member_image(s, p->weights, base, "weights", files))
        return -1;
    if (s->all_images) {
        const mcp_blend_method more[] = {MCP_BLEND_DENOISED, MCP_BLEND_EASY,
                                         MCP_BLEND_JAMES_STEIN, MCP_BLEND_IDEAL};
        for (int i = 0; i < 4; i++)
            if (p->images[more[i]] &&
                write_member_image(s, p->images[more[i]], base,
                                   mcp_blend_method_name(more[i]), files))
                return -1;
    }
    /* the last member's pictures go into the report */
    if (p->index == p->count - 1) {
        const mcp_blend_method shown[] = {MCP_BLEND_NOISY, MCP_BLEND_DENOISED,
                                          MCP_BLEND_CURVES};
        for (int i = 0; i < 3; i++) {
            char name[700], path[4096 + 800];
            mcp_image *ldr = NULL;
            snprintf(name, sizeof name, "%s.%s.png", base,
                     mcp_blend_method_name(shown[i]));
            snprintf(path, sizeof path, "%s/%s", s->dir, name);
            /* clamped and sRGB-encoded, as the PNG writer shows linear values */
            int rc = mcp_tonemap_apply(p->images[shown[i]], MCP_TONEMAP_CLAMP, &ldr) ||
                     mcp_image_write(ldr, path, NULL);
            mcp_image_free(ldr);
            if (rc) return -1;
        }
    }
    mcp_progress_update(&s->prog, p->index + 1);
    return 0;
}

/* Adds a table and a plot of one error per spp for every method. */
static int
add_error_figures(cJSON *section, const mcp_blend_series_result *r, const char *metric,
                  int which, const char *y_label)
{
    const char *cols[1 + MCP_BLEND_N_METHODS];
    cols[0] = "spp";
    for (int m = 0; m < MCP_BLEND_N_METHODS; m++)
        cols[1 + m] = mcp_blend_method_name(m);
    char title[128];
    snprintf(title, sizeof title, "%s against the reference per spp", metric);
    cJSON *table = mcp_report_add_table(section, title, cols, 1 + MCP_BLEND_N_METHODS);
    if (!table) return -1;
    int n = r->count;
    double *x = mcp_calloc((size_t)n * (1 + MCP_BLEND_N_METHODS), sizeof *x);
    if (!x) return -1;
    double *y = x + n;
    for (int i = 0; i < n; i++) {
        const mcp_blend_row *row = &r->rows[i];
        x[i] = row->spp;
        for (int m = 0; m < MCP_BLEND_N_METHODS; m++) {
            const mcp_blend_errors *e = &row->err[m];
            y[m * n + i] = which == 0 ? e->mse : which == 1 ? e->relmse : e->flip_hdr;
        }
        const double *v = &y[i];
        if (mcp_report_table_add_row(table, "ddddddd", x[i], v[0], v[n], v[2 * n],
                                     v[3 * n], v[4 * n], v[5 * n])) {
            free(x);
            return -1;
        }
    }
    snprintf(title, sizeof title,
             "%s against samples per pixel (Denisova & Bocchi Fig. 4)", metric);
    cJSON *plot =
        mcp_report_add_plot(section, title, "spp", MCP_AXIS_LOG, y_label, MCP_AXIS_LOG);
    int rc = plot ? 0 : -1;
    for (int m = 0; rc == 0 && m < MCP_BLEND_N_METHODS; m++) {
        cJSON *s = mcp_report_plot_add_series(plot, mcp_blend_method_name(m),
                                              MCP_SERIES_LINE_POINTS, x, y + m * n, n);
        /* the evaluation-only method is drawn dashed */
        if (!s || (m == MCP_BLEND_IDEAL && mcp_report_series_set_dashed(s, 1))) rc = -1;
    }
    free(x);
    return rc;
}

/* The blend section's verdict: with a reference, the blend's MSE (method curves) as a
 * multiple of the noisy image's at the last member, where it must be at most 1 for
 * the blend to converge, and at the member where the blend helps most. */
static int
blend_verdict(cJSON *section, const mcp_blend_series_result *r)
{
    const mcp_blend_row *last = &r->rows[r->count - 1];
    if (!r->has_reference)
        return mcp_report_set_verdict(section, MCP_VERDICT_INFO,
                                      "blended %d members, %g to %g spp; without a "
                                      "reference there are no error figures to judge "
                                      "convergence by",
                                      r->count, r->rows[0].spp, last->spp);
    double fin = last->err[MCP_BLEND_CURVES].mse / last->err[MCP_BLEND_NOISY].mse,
           den = last->err[MCP_BLEND_DENOISED].mse / last->err[MCP_BLEND_NOISY].mse;
    int best = r->count - 1;
    for (int i = 0; i < r->count; i++)
        if (r->rows[i].err[MCP_BLEND_CURVES].mse / r->rows[i].err[MCP_BLEND_NOISY].mse <
            r->rows[best].err[MCP_BLEND_CURVES].mse / r->rows[best].err[MCP_BLEND_NOISY].mse)
            best = i;
    double best_ratio =
        r->rows[best].err[MCP_BLEND_CURVES].mse / r->rows[best].err[MCP_BLEND_NOISY].mse;
    int converges = fin <= 1.0;
    return mcp_report_set_verdict(
        section, converges ? MCP_VERDICT_GOOD : MCP_VERDICT_BAD,
        "blend %s: at %g spp %.3g\u00d7 the noisy MSE (denoised alone %.3g\u00d7); at "
        "best %.3g\u00d7 at %g spp",
        converges ? "converges" : "does not beat the noisy image", last->spp, fin, den,
        best_ratio, r->rows[best].spp);
}

/* Fills a report section with the run's settings, per-member figures and, with a
 * reference, the comparison. */
static int
fill_section(cJSON *section, const mcp_blend_series_result *r,
             const mcp_blend_series_options *o, const char *denoiser, blend_sink *s)
{
    const mcp_blend_options *b = &o->blend;
    cJSON_AddStringToObject(section, "denoiser", denoiser);
    mcp_cli_add_variance_source(section, r->variance_source, 0);
    cJSON_AddStringToObject(section, "fit", mcp_curve_fit_name(b->fit));
    cJSON_AddStringToObject(section, "curve", mcp_curve_model_name(b->curve));
    cJSON_AddStringToObject(section, "filter", mcp_blend_filter_name(b->filter));
    cJSON_AddStringToObject(section, "negative_sure",
                            mcp_neg_sure_name(b->negative_sure));
    cJSON_AddNumberToObject(section, "far_spp", b->far_spp);
    cJSON_AddNumberToObject(section, "stop_denoising_at", o->stop_denoising_at);
    cJSON_AddNumberToObject(section, "members", r->count);
    cJSON_AddItemToObject(section, "files", s->members);
    s->members = NULL;
    cJSON *table = mcp_report_add_table(
        section, "members",
        (const char *const[]){"spp", "denoised at spp", "mean v", "mean SURE", "filtered",
                              "negative SURE", "mean W/(I+W)"},
        7);
    if (!table) return -1;
    for (int i = 0; i < r->count; i++) {
        const mcp_blend_row *row = &r->rows[i];
        if (mcp_report_table_add_row(
                table, "ddddssd", row->spp, row->denoised_spp, row->mean_var,
                row->mean_sure, row->filtered ? "yes" : "no",
                row->magnitude ? "magnitude" : "zero", row->mean_rho))
            return -1;
    }
    if (r->has_reference) {
        const mcp_blend_row *last = &r->rows[r->count - 1];
        cJSON *fin = cJSON_AddObjectToObject(section, "final");
        cJSON_AddNumberToObject(fin, "spp", last->spp);
        for (int m = 0; m < MCP_BLEND_N_METHODS; m++) {
            cJSON *e = cJSON_AddObjectToObject(fin, mcp_blend_method_name(m));
            cJSON_AddNumberToObject(e, "mse", last->err[m].mse);
            cJSON_AddNumberToObject(e, "relmse", last->err[m].relmse);
            if (r->has_flip)
                cJSON_AddNumberToObject(e, "flip_hdr", last->err[m].flip_hdr);
        }
        if (add_error_figures(section, r, "MSE", 0, "MSE") ||
            add_error_figures(section, r, "relMSE", 1, "relMSE") ||
            (r->has_flip &&
             add_error_figures(section, r, "HDR-FLIP", 2, "mean HDR-FLIP")))
            return -1;
    }
    if (blend_verdict(section, r)) return -1;
    const char *shown[] = {"noisy", "denoised", "curves"};
    for (int i = 0; i < 3; i++) {
        char rel[1400], caption[700];
        snprintf(rel, sizeof rel, "%s%s.%s.png", s->rel, s->last_base, shown[i]);
        snprintf(caption, sizeof caption, "%s at %g spp: %s", s->last_base,
                 r->rows[r->count - 1].spp, shown[i]);
        if (mcp_report_add_image(section, rel, caption)) return -1;
    }
    return 0;
}

/* Runs the driver into the sink and fills section. */
static int
run_blend(const mcp_series *series, const mcp_denoiser *den, const mcp_image *ref,
          const mcp_blend_series_options *o, const char *denoiser_name, blend_sink *s,
          cJSON *section)
{
    mcp_blend_series_result *r = NULL;
    s->members = cJSON_CreateArray();
    mcp_progress_begin(&s->prog, "blend", series->count);
    int rc = mcp_blend_series(series, den, ref, o, on_point, s, &r);
    if (rc == 0)
        mcp_progress_end(&s->prog);
    else if (s->prog.tty && !mcp_progress_quiet())
        fputc('\n', stderr); /* no "100%" for a run that failed */
    if (!rc) rc = fill_section(section, r, o, denoiser_name, s);
    /* the curves are fitted to the variance: say when Variance/n does not track the
       series' own increments */
    double ratio = 0;
    if (!rc) rc = mcp_series_variance_ratio(series, &ratio);
    if (!rc)
        mcp_cli_report_variance_ratio(ratio, r->variance_source == MCP_VARSRC_INCREMENTS,
                                      section);
    cJSON_Delete(s->members);
    s->members = NULL;
    mcp_blend_series_result_free(r);
    return rc;
}

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
    "  --js-window N             James-Stein window [7]\n"
    "  --no-flip                 skip HDR-FLIP\n"
    "  --variance-from KIND      file (each member's own variance) or increments (the\n"
    "                            spread between the series' increments: right for\n"
    "                            stratified samplers) [file]\n"
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
    OPT_VARIANCE_FROM
};

static int
parse_spp_list(const char *text, int **out, int *count)
{
    char **words = NULL;
    int n = 0;
    if (mcp_cli_split(text, &words, &n)) return -1;
    int *v = mcp_calloc((size_t)(n > 0 ? n : 1), sizeof *v);
    int rc = v ? 0 : -1;
    for (int i = 0; rc == 0 && i < n; i++)
        rc = mcp_cli_int("--spp", words[i], &v[i]);
    mcp_cli_free_words(words, n);
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
        {"variance-from", required_argument, 0, OPT_VARIANCE_FROM},
        {"help", no_argument, 0, 'h'},
        {0, 0, 0, 0}};
    mcp_blend_series_options o = mcp_blend_series_defaults();
    mcp_blend_options *b = &o.blend;
    const char *ref_path = NULL, *out_dir = "blend-out";
    mcp_cli_denoiser_flags df = {0};
    int json = 0, all_images = 0, opt, status = 1;
    int *spps = NULL, n_spps = 0;
    mcp_variance_source variance_from = MCP_VARSRC_NONE;
    mcp_series *series = NULL;
    mcp_denoiser *den = NULL;
    mcp_image *ref = NULL;
    mcp_report *report = NULL;
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
            rc = mcp_cli_double("--stop-denoising-at", optarg, &o.stop_denoising_at);
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
            rc = mcp_cli_double("--far-spp", optarg, &b->far_spp);
            break;
        case OPT_MAXW:
            rc = mcp_cli_double("--max-weight", optarg, &b->max_weight);
            break;
        case OPT_ZEROS:
            b->denoiser_keeps_zeros = 1;
            break;
        case OPT_FILTER:
            rc = mcp_blend_filter_from_name(optarg, &b->filter);
            break;
        case OPT_WINDOW:
            rc = mcp_cli_int("--filter-window", optarg, &b->filter_window);
            break;
        case OPT_SIGMA:
            rc = mcp_cli_double("--filter-sigma-scale", optarg, &b->filter_sigma_scale);
            break;
        case OPT_NO_STOP_FILTERING:
            b->stop_filtering = 0;
            break;
        case OPT_NEG:
            rc = mcp_neg_sure_from_name(optarg, &b->negative_sure);
            break;
        case OPT_PROBES:
            rc = mcp_cli_int("--n-probes", optarg, &o.sure.n_probes);
            break;
        case OPT_SEED:
            rc = parse_seed(optarg, &o.sure.seed);
            break;
        case OPT_JS:
            rc = mcp_cli_int("--js-window", optarg, &b->js_window);
            break;
        case OPT_NO_FLIP:
            o.flip = 0;
            break;
        case OPT_VARIANCE_FROM:
            rc = mcp_cli_variance_from(optarg, &variance_from);
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
        (ref_path && mcp_image_read(ref_path, NULL, &ref)) || mcp_make_dirs(out_dir) ||
        mcp_report_new("mcpost blend", &report))
        goto fail;
    series->variance_from = variance_from;
    blend_sink sink;
    memset(&sink, 0, sizeof sink);
    snprintf(sink.dir, sizeof sink.dir, "%s", out_dir);
    sink.rel = "";
    sink.all_images = all_images;
    char title[600];
    snprintf(title, sizeof title, "blend: %s with %s", argv[optind], den->name);
    cJSON *section = mcp_report_section(report, "blend", title);
    if (!section || run_blend(series, den, ref, &o, den->name, &sink, section)) goto fail;
    char *text = cJSON_Print(section), path[4200];
    snprintf(path, sizeof path, "%s/blend.json", out_dir);
    int wrc = !text || mcp_write_file_atomic(path, text, strlen(text));
    if (!wrc && json) puts(text);
    free(text);
    if (wrc || mcp_report_write(report, out_dir)) goto fail;
    mcp_note("blend: %d members into %s", series->count, out_dir);
    status = 0;
    goto done;
fail:
    status = mcp_cli_fail();
done:
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
                                       cmd_blend};

/* ---- the job stage ---- */

static const char *const blend_keys[] = {"input",
                                         "denoiser",
                                         "stop_denoising_at",
                                         "reference",
                                         "output",
                                         "title",
                                         "all_images",
                                         "fit",
                                         "curve",
                                         "far_spp",
                                         "max_weight",
                                         "denoiser_keeps_zeros",
                                         "filter",
                                         "filter_window",
                                         "filter_sigma_scale",
                                         "stop_filtering",
                                         "negative_sure",
                                         "n_probes",
                                         "seed",
                                         "js_window",
                                         "flip",
                                         NULL};

/* An enum key read with its from_name function; errors at the key's line. */
static int
opt_name(const mcp_node *settings, const char *key, int (*parse)(const char *, void *),
         void *out)
{
    const char *s = NULL;
    if (mcp_node_opt_string(settings, key, &s)) return -1;
    if (s && parse(s, out))
        return mcp_node_error(mcp_node_get(settings, key), "%s", mcp_error_message());
    return 0;
}

static int
p_fit(const char *s, void *o)
{
    return mcp_curve_fit_from_name(s, o);
}
static int
p_curve(const char *s, void *o)
{
    return mcp_curve_model_from_name(s, o);
}
static int
p_filter(const char *s, void *o)
{
    return mcp_blend_filter_from_name(s, o);
}
static int
p_neg(const char *s, void *o)
{
    return mcp_neg_sure_from_name(s, o);
}

static int
read_stage_options(const mcp_node *s, mcp_blend_series_options *o)
{
    mcp_blend_options *b = &o->blend;
    double seed = 0;
    int flip = o->flip, stop_filtering = b->stop_filtering,
        keeps_zeros = b->denoiser_keeps_zeros;
    if (mcp_node_opt_double(s, "stop_denoising_at", &o->stop_denoising_at) ||
        opt_name(s, "fit", p_fit, &b->fit) || opt_name(s, "curve", p_curve, &b->curve) ||
        mcp_node_opt_double(s, "far_spp", &b->far_spp) ||
        mcp_node_opt_double(s, "max_weight", &b->max_weight) ||
        mcp_node_opt_bool(s, "denoiser_keeps_zeros", &keeps_zeros) ||
        opt_name(s, "filter", p_filter, &b->filter) ||
        mcp_node_opt_int(s, "filter_window", &b->filter_window) ||
        mcp_node_opt_double(s, "filter_sigma_scale", &b->filter_sigma_scale) ||
        mcp_node_opt_bool(s, "stop_filtering", &stop_filtering) ||
        opt_name(s, "negative_sure", p_neg, &b->negative_sure) ||
        mcp_node_opt_int(s, "n_probes", &o->sure.n_probes) ||
        mcp_node_opt_double(s, "seed", &seed) ||
        mcp_node_opt_int(s, "js_window", &b->js_window) ||
        mcp_node_opt_bool(s, "flip", &flip))
        return -1;
    if (!(seed >= 0) || seed != floor(seed) || seed > 9007199254740992.0)
        return mcp_node_error(mcp_node_get(s, "seed"),
                              "seed must be a non-negative integer (got %g)", seed);
    if (!(o->stop_denoising_at >= 0))
        return mcp_node_error(mcp_node_get(s, "stop_denoising_at"),
                              "stop_denoising_at must be >= 0 (got %g)",
                              o->stop_denoising_at);
    o->sure.seed = (uint64_t)seed;
    o->flip = flip;
    b->stop_filtering = stop_filtering;
    b->denoiser_keeps_zeros = keeps_zeros;
    if (mcp_blend_options_check(b)) return mcp_node_error(s, "%s", mcp_error_message());
    return 0;
}

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): the options, the series and reference by name (checked
 * against the job's inputs) and the denoiser, created from its settings. Strings are
 * borrowed from the settings; the denoiser is the plan's. */
typedef struct blend_plan {
    mcp_blend_series_options o;
    const char *input, *reference, *output, *title;
    int all_images;
    mcp_denoiser *den;
} blend_plan;

static int
parse_blend(mcp_job *job, const mcp_node *settings, blend_plan *pl)
{
    const mcp_node *input_node = NULL;
    memset(pl, 0, sizeof *pl);
    pl->o = mcp_blend_series_defaults();
    if (mcp_node_opt_string(settings, "input", &pl->input) ||
        mcp_node_opt_string(settings, "reference", &pl->reference) ||
        mcp_node_opt_string(settings, "output", &pl->output) ||
        mcp_node_opt_string(settings, "title", &pl->title) ||
        mcp_node_opt_bool(settings, "all_images", &pl->all_images) ||
        read_stage_options(settings, &pl->o) ||
        mcp_node_require(settings, "input", "stage 'blend'", &input_node) ||
        mcp_job_check_input(job, settings, "input", MCP_JOB_SERIES) ||
        (pl->reference && mcp_job_check_input(job, settings, "reference", MCP_JOB_IMAGE)) ||
        mcp_cli_stage_denoiser(job, settings, &pl->den))
        return -1;
    return 0;
}

static int
check_blend(mcp_job *job, const mcp_node *settings)
{
    blend_plan pl;
    int rc = parse_blend(job, settings, &pl);
    mcp_denoiser_free(pl.den);
    return rc;
}

static int
stage_blend(mcp_job *job, const mcp_node *settings)
{
    blend_plan pl;
    const mcp_series *series = NULL;
    const mcp_image *ref = NULL;
    if (parse_blend(job, settings, &pl) || mcp_job_series(job, settings, "input", &series) ||
        (pl.reference && mcp_job_image(job, settings, "reference", &ref))) {
        mcp_denoiser_free(pl.den);
        return -1;
    }
    mcp_blend_series_options o = pl.o;
    const char *input = pl.input, *output = pl.output, *title = pl.title;
    int all_images = pl.all_images;
    mcp_denoiser *den = pl.den;
    const char *den_name = den->name;
    blend_sink sink;
    memset(&sink, 0, sizeof sink);
    char rel[1024], probe[4096];
    snprintf(rel, sizeof rel, "%s/", output ? output : "blend");
    sink.rel = rel;
    sink.all_images = all_images;
    int rc = -1;
    /* mcp_job_output_path creates the folders of rel */
    char marker[1100];
    snprintf(marker, sizeof marker, "%sblend.json", rel);
    if (mcp_job_output_path(job, marker, probe, sizeof probe) == 0) {
        char *slash = strrchr(probe, '/');
        if (slash) *slash = '\0';
        snprintf(sink.dir, sizeof sink.dir, "%s", probe);
        char default_title[600];
        snprintf(default_title, sizeof default_title, "blend: %s with %s", input,
                 den_name);
        cJSON *section = mcp_report_section(mcp_job_report(job), "blend",
                                            title ? title : default_title);
        if (section && run_blend(series, den, ref, &o, den_name, &sink, section) == 0) {
            char *text = cJSON_Print(section);
            snprintf(probe + strlen(probe), sizeof probe - strlen(probe), "/blend.json");
            rc = text && mcp_write_file_atomic(probe, text, strlen(text)) == 0 ? 0 : -1;
            free(text);
            if (rc == 0) mcp_note("blend: %s: %d members", input, series->count);
        }
    }
    mcp_denoiser_free(den);
    return rc;
}

const mcp_stage mcp_stage_blend = {"blend",
                                   "blend a series with its denoised images so that it "
                                   "converges (Denisova & Bocchi 2024), comparing noisy, "
                                   "denoised, easy, curves, ideal and James-Stein",
                                   blend_keys, stage_blend, check_blend};
