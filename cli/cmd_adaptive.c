/* cmd_adaptive.c: `mcpost adaptive` and the `adaptive` job stage -- the adaptive-
 * sampling loop of Firmino 2023 (estimate/adaptive.c) driving any renderer through a
 * command template: {counts} (an EXR of per-pixel sample counts, channel SampleCount),
 * {output} (the dump the command must write), {pass}, {seed}. Writes, per pass, the
 * sampling map and the counts as images, and at the end the accumulated dump, the
 * denoised image, adaptive.json / adaptive.csv (relMSE with a reference, and the
 * estimated error, against the total samples) and adaptive.svg. Flags and job keys
 * are the same words. */
#include "cli.h"

#include <mcpost/estimate.h>
#include <mcpost/filter.h>
#include <mcpost/plot.h>
#include <mcpost/progress.h>

#include <errno.h>
#include <getopt.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

/* ---- the loop, shared by the subcommand and the stage ---- */

typedef struct loop_cfg {
    const char *render; /* the command template */
    char dir[4096];     /* output folder */
    char rel[256];      /* prefix of report paths ("" or "adaptive/") */
    int width, height;
    uint64_t seed;
    int keep_passes;
    mcp_adaptive_options ao;
    const mcp_image *reference;
    const mcp_denoiser *den;
    cJSON *section; /* the job report's section, or NULL */
} loop_cfg;

static int
path_in(const loop_cfg *c, char *buf, size_t cap, const char *fmt, int pass)
{
    char name[256];
    snprintf(name, sizeof name, fmt, pass);
    if (snprintf(buf, cap, "%s/%s", c->dir, name) >= (int)cap)
        return mcp_error("output path too long: %s/%s", c->dir, name);
    return 0;
}

/* Appends text to a growing string, single-quoted for /bin/sh when quote is set. */
static int
append(char **s, size_t *len, size_t *cap, const char *text, size_t n, int quote)
{
    size_t need = *len + (quote ? 4 * n + 2 : n) + 1;
    if (need > *cap) {
        size_t c = need * 2;
        char *p = realloc(*s, c);
        if (!p) return mcp_error("out of memory");
        *s = p;
        *cap = c;
    }
    if (quote) (*s)[(*len)++] = '\'';
    for (size_t i = 0; i < n; i++) {
        if (quote && text[i] == '\'') {
            memcpy(*s + *len, "'\\''", 4);
            *len += 4;
        } else
            (*s)[(*len)++] = text[i];
    }
    if (quote) (*s)[(*len)++] = '\'';
    (*s)[*len] = '\0';
    return 0;
}

/* The command line of one pass: {counts} and {output} become quoted paths, {pass} and
 * {seed} numbers; other text stays. *out is malloc'd. */
static int
command_line(const char *tmpl, const char *counts, const char *output, int pass,
             uint64_t seed, char **out)
{
    char pass_text[32], seed_text[32];
    snprintf(pass_text, sizeof pass_text, "%d", pass);
    snprintf(seed_text, sizeof seed_text, "%" PRIu64, seed);
    const char *names[4] = {"{counts}", "{output}", "{pass}", "{seed}"};
    const char *values[4] = {counts, output, pass_text, seed_text};
    char *s = NULL;
    size_t len = 0, cap = 0;
    if (append(&s, &len, &cap, "", 0, 0)) return -1;
    for (const char *p = tmpl; *p;) {
        int k = -1;
        for (int i = 0; i < 4 && k < 0; i++)
            if (!strncmp(p, names[i], strlen(names[i]))) k = i;
        int bad = k < 0 ? append(&s, &len, &cap, p, 1, 0)
                        : append(&s, &len, &cap, values[k], strlen(values[k]), k < 2);
        if (bad) {
            free(s);
            return -1;
        }
        p += k < 0 ? 1 : strlen(names[k]);
    }
    *out = s;
    return 0;
}

/* The renderer: writes the counts, runs the command, reads what it wrote. */
static int
render_pass(int pass, const mcp_image *counts, mcp_dump **out, void *ctx)
{
    const loop_cfg *c = ctx;
    char cpath[4352], opath[4352];
    char *line = NULL;
    *out = NULL;
    if (path_in(c, cpath, sizeof cpath, "pass_%04d_counts.exr", pass) ||
        path_in(c, opath, sizeof opath, "pass_%04d.exr", pass) ||
        mcp_image_write(counts, cpath, NULL) ||
        command_line(c->render, cpath, opath, pass, c->seed, &line))
        return -1;
    remove(opath); /* an old file must not pass for this pass's output */
    fflush(NULL);
    int status = system(line);
    int rc = -1;
    if (status == -1)
        mcp_error("cannot run the render command '%s' (%s)", line, strerror(errno));
    else if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
        mcp_error("the render command failed (exit status %d): %s",
                  WIFEXITED(status) ? WEXITSTATUS(status) : -1, line);
    else if (access(opath, F_OK))
        mcp_error("the render command wrote no {output} file %s: %s", opath, line);
    else
        rc = mcp_dump_read(opath, out);
    free(line);
    if (!c->keep_passes) {
        remove(cpath);
        if (!rc) remove(opath);
    }
    return rc;
}

static int
cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* A one-channel image as a false-colour PNG, scaled to its 99th percentile: a few
 * pixels far above the rest (a firefly's) would otherwise leave the picture black. */
static int
write_png(const loop_cfg *c, const mcp_image *img, const char *fmt, int pass)
{
    char path[4352];
    size_t n = (size_t)img->width * img->height;
    float *v = mcp_malloc(n * sizeof *v);
    if (!v) return -1;
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++)
            v[(size_t)y * img->width + x] = mcp_image_px(img, x, y)[0];
    qsort(v, n, sizeof *v, cmp_float);
    double hi = v[(size_t)(0.99 * (double)(n - 1))];
    if (!(hi > 0)) hi = v[n - 1];
    free(v);
    unsigned char *rgb = mcp_malloc(n * 3);
    int rc =
        !rgb || path_in(c, path, sizeof path, fmt, pass) ||
        mcp_colormap_apply(img, 0, 0.0, hi > 0 ? hi : 1.0, MCP_COLORMAP_INFERNO, rgb) ||
        mcp_write_rgb8(rgb, img->width, img->height, path);
    free(rgb);
    return rc ? -1 : 0;
}

static int
on_iteration(const mcp_adaptive_state *st, void *ctx)
{
    const loop_cfg *c = ctx;
    const mcp_adaptive_iteration *it = st->it;
    if (write_png(c, st->counts, "maps/counts_%04d.png", it->pass) ||
        (c->ao.map != MCP_ADAPTIVE_UNIFORM &&
         write_png(c, st->est->sampling_map, "maps/sampling_map_%04d.png", it->pass)))
        return -1;
    char rel[64] = "";
    if (c->reference) snprintf(rel, sizeof rel, ", relMSE %.4g", it->relmse);
    mcp_note("pass %d: %.1f spp in all%s, estimated error %.4g, F(tau) %.4f "
             "(render %.0f ms, denoise %.0f ms, mcpost %.0f ms)",
             it->pass, it->mean_spp, rel, it->est_error, it->cdf_at_tau, it->ms_render,
             it->ms_denoise, it->ms_merge + it->ms_estimate + it->ms_counts);
    return 0;
}

static const char *const stop_words[] = {"budget", "estimate", "max_iterations"};

static cJSON *
result_json(const loop_cfg *c, const mcp_adaptive_result *r)
{
    cJSON *j = cJSON_CreateObject();
    cJSON_AddStringToObject(j, "map", mcp_adaptive_map_name(c->ao.map));
    cJSON_AddStringToObject(j, "denoiser", c->den->name);
    cJSON_AddStringToObject(j, "render", c->render);
    cJSON_AddNumberToObject(j, "width", c->width);
    cJSON_AddNumberToObject(j, "height", c->height);
    cJSON_AddNumberToObject(j, "spp_per_iteration", c->ao.spp_per_iteration);
    if (c->ao.budget_spp > 0) cJSON_AddNumberToObject(j, "budget", c->ao.budget_spp);
    cJSON_AddStringToObject(j, "stopped_by", stop_words[r->stopped_by]);
    cJSON *its = cJSON_AddArrayToObject(j, "iterations");
    for (int i = 0; i < r->count; i++) {
        const mcp_adaptive_iteration *it = &r->iterations[i];
        cJSON *o = cJSON_CreateObject();
        cJSON_AddNumberToObject(o, "pass", it->pass);
        cJSON_AddNumberToObject(o, "samples", (double)it->samples);
        cJSON_AddNumberToObject(o, "total_samples", (double)it->total_samples);
        cJSON_AddNumberToObject(o, "mean_spp", it->mean_spp);
        cJSON_AddNumberToObject(o, "estimated_error", it->est_error);
        cJSON_AddNumberToObject(o, "cdf_at_tau", it->cdf_at_tau);
        cJSON_AddBoolToObject(o, "stop", it->stop);
        if (!isnan(it->relmse)) {
            cJSON_AddNumberToObject(o, "relmse", it->relmse);
            cJSON_AddNumberToObject(o, "relmse_noisy", it->relmse_noisy);
        }
        cJSON *t = cJSON_AddObjectToObject(o, "ms");
        cJSON_AddNumberToObject(t, "render", it->ms_render);
        cJSON_AddNumberToObject(t, "merge", it->ms_merge);
        cJSON_AddNumberToObject(t, "denoise", it->ms_denoise);
        cJSON_AddNumberToObject(t, "estimate", it->ms_estimate);
        cJSON_AddNumberToObject(t, "counts", it->ms_counts);
        cJSON_AddItemToArray(its, o);
    }
    return j;
}

static int
write_text(const loop_cfg *c, const char *name, const char *text)
{
    char path[4352];
    if (path_in(c, path, sizeof path, name, 0)) return -1;
    return mcp_write_file_atomic(path, text, strlen(text));
}

/* adaptive.csv, adaptive.svg, and the job report's table and plot. */
static int
write_curves(const loop_cfg *c, const mcp_adaptive_result *r)
{
    int n = r->count, rc = -1;
    double *x = mcp_calloc((size_t)n, sizeof *x),
           *rel = mcp_calloc((size_t)n, sizeof *rel),
           *est = mcp_calloc((size_t)n, sizeof *est);
    char *csv = mcp_malloc((size_t)n * 160 + 160), *svg = NULL;
    if (!x || !rel || !est || !csv) goto done;
    size_t len =
        (size_t)sprintf(csv, "pass,mean_spp,total_samples,relmse,relmse_noisy,"
                             "estimated_error,cdf_at_tau,ms_denoise,ms_mcpost\n");
    for (int i = 0; i < n; i++) {
        const mcp_adaptive_iteration *it = &r->iterations[i];
        x[i] = it->mean_spp;
        rel[i] = it->relmse;
        est[i] = it->est_error;
        len += (size_t)sprintf(
            csv + len, "%d,%.6g,%" PRId64 ",%.6g,%.6g,%.6g,%.6g,%.1f,%.1f\n", it->pass,
            it->mean_spp, it->total_samples, it->relmse, it->relmse_noisy, it->est_error,
            it->cdf_at_tau, it->ms_denoise,
            it->ms_merge + it->ms_estimate + it->ms_counts);
    }
    mcp_plot_series s[2] = {
        {"relMSE (denoised vs reference)", MCP_SERIES_LINE_POINTS, x, rel, n, 0},
        {"estimated error (mean s^2 (lambda + 1))", MCP_SERIES_LINE_POINTS, x, est, n,
         1}};
    int has_ref = c->reference != NULL;
    mcp_plot plot = {"adaptive sampling: error against samples",
                     "samples per pixel",
                     "error",
                     MCP_AXIS_LOG,
                     MCP_AXIS_LOG,
                     has_ref ? s : s + 1,
                     has_ref ? 2 : 1,
                     0,
                     0};
    if (write_text(c, "adaptive.csv", csv) || mcp_plot_svg(&plot, &svg) ||
        write_text(c, "adaptive.svg", svg))
        goto done;
    if (c->section) {
        static const char *const cols[] = {"pass", "spp", "relMSE", "estimated error",
                                           "F(tau)"};
        cJSON *t = mcp_report_add_table(c->section, "per pass", cols, 5);
        for (int i = 0; t && i < n; i++)
            if (mcp_report_table_add_row(t, "idddd", r->iterations[i].pass, x[i], rel[i],
                                         est[i], r->iterations[i].cdf_at_tau))
                goto done;
        cJSON *p = mcp_report_add_plot(c->section, plot.title, plot.x_label, MCP_AXIS_LOG,
                                       plot.y_label, MCP_AXIS_LOG);
        cJSON *se = p ? mcp_report_plot_add_series(p, s[1].name, MCP_SERIES_LINE_POINTS,
                                                   x, est, n)
                      : NULL;
        if (!t || !p || !se || mcp_report_series_set_dashed(se, 1) ||
            (has_ref && !mcp_report_plot_add_series(p, s[0].name, MCP_SERIES_LINE_POINTS,
                                                    x, rel, n)))
            goto done;
        char relp[512];
        snprintf(relp, sizeof relp, "%smaps/counts_%04d.png", c->rel, n - 1);
        if (mcp_report_add_image(c->section, relp, "the last pass's sample counts"))
            goto done;
        if (n > 1 && c->ao.map != MCP_ADAPTIVE_UNIFORM) {
            snprintf(relp, sizeof relp, "%smaps/sampling_map_%04d.png", c->rel, n - 2);
            if (mcp_report_add_image(c->section, relp, "the sampling map it came from"))
                goto done;
        }
    }
    rc = 0;
done:
    free(x);
    free(rel);
    free(est);
    free(csv);
    free(svg);
    return rc;
}

/* Runs the loop and writes every output; *json (may be NULL) receives the figures. */
static int
run_loop(loop_cfg *c, cJSON **json)
{
    mcp_adaptive_result *r = NULL;
    char sub[4352], path[4352];
    int rc = -1;
    if (!strstr(c->render, "{counts}") || !strstr(c->render, "{output}"))
        return mcp_error("the render command '%s' must name {counts} and {output}",
                         c->render);
    if (snprintf(sub, sizeof sub, "%s/maps", c->dir) >= (int)sizeof sub)
        return mcp_error("output path too long: %s", c->dir);
    if (mcp_make_dirs(sub)) return -1;
    if (mcp_adaptive_run(c->width, c->height, c->den, &c->ao, render_pass, c,
                         c->reference, on_iteration, c, &r))
        return -1;
    cJSON *j = result_json(c, r);
    char *text = j ? cJSON_Print(j) : NULL;
    if (!text || path_in(c, path, sizeof path, "accumulated.exr", 0) ||
        mcp_dump_write(r->accumulated, path, MCP_CONV_MCPOST, NULL) ||
        path_in(c, path, sizeof path, "denoised.exr", 0) ||
        mcp_image_write(r->denoised, path, NULL) ||
        write_text(c, "adaptive.json", text) || write_curves(c, r))
        goto done;
    if (c->section) { /* the section owns the figures now */
        cJSON_AddItemToObject(c->section, "adaptive", j);
        j = NULL;
    }
    const mcp_adaptive_iteration *last = &r->iterations[r->count - 1];
    mcp_note("%d passes, %.1f spp in all, stopped by the %s%s", r->count, last->mean_spp,
             stop_words[r->stopped_by],
             r->stopped_by == MCP_ADAPTIVE_STOP_ESTIMATE ? " (F(tau) >= p)" : "");
    rc = 0;
done:
    free(text);
    if (!rc && json)
        *json = j;
    else
        cJSON_Delete(j);
    mcp_adaptive_result_free(r);
    return rc;
}

static int
parse_size(const char *text, int *w, int *h)
{
    char tail;
    if (!text || sscanf(text, "%dx%d%c", w, h, &tail) != 2 || *w < 1 || *h < 1)
        return mcp_error("--size must be WIDTHxHEIGHT, e.g. 128x128 (got '%s')",
                         text ? text : "");
    return 0;
}

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
    "  --probes N               probes of the estimate [1]\n"
    "  --seed S                 the {seed} of the command, and the probes' [1]\n"
    "  --reference REF          the converged image: relMSE per pass\n"
    "  --keep-passes            keep every pass's counts and dump in DIR\n"
    "  --json                   the figures as JSON on stdout\n"
    "  --quiet                  no line per pass on stderr\n"
    "  --denoiser NAME          " MCP_CLI_DEFAULT_DENOISER "\n" MCP_CLI_DENOISER_USAGE(
        " ") "\n"
             "examples (from the source folder; mcpost-procedural is built beside mcpost,\n"
             "in build/samples/procedural/, and must be on the PATH):\n"
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
        {"probes", required_argument, 0, OPT_PROBES},
        {"seed", required_argument, 0, OPT_SEED},
        {"reference", required_argument, 0, OPT_REF},
        {"keep-passes", no_argument, 0, OPT_KEEP},
        {"json", no_argument, 0, OPT_JSON},
        {"quiet", no_argument, 0, OPT_QUIET},
        {"help", no_argument, 0, 'h'},
        MCP_CLI_DENOISER_LONGOPTS,
        {0, 0, 0, 0}};
    loop_cfg c;
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
            rc = mcp_cli_double("--spp-per-iteration", optarg, &c.ao.spp_per_iteration);
            break;
        case OPT_INITIAL:
            rc = mcp_cli_double("--initial-spp", optarg, &c.ao.initial_spp);
            break;
        case OPT_BUDGET:
            rc = mcp_cli_double("--budget", optarg, &c.ao.budget_spp);
            break;
        case OPT_STOP:
            c.ao.stop_on_estimate = 1;
            break;
        case OPT_TAU:
            rc = mcp_cli_double("--tau", optarg, &c.ao.est.tau);
            break;
        case OPT_P:
            rc = mcp_cli_double("--percentile", optarg, &c.ao.est.p);
            break;
        case OPT_MAXIT:
            rc = mcp_cli_int("--max-iterations", optarg, &c.ao.max_iterations);
            break;
        case OPT_QUANTUM:
            rc = mcp_cli_int("--quantum", optarg, &c.ao.quantum);
            break;
        case OPT_PROBES:
            rc = mcp_cli_int("--probes", optarg, &c.ao.est.sure.n_probes);
            break;
        case OPT_SEED:
            rc = mcp_cli_double("--seed", optarg, &seed);
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
    if (size ? parse_size(size, &c.width, &c.height) : 0) goto done;
    if (!size && !ref) {
        mcp_error("give the image size (--size WxH) or a --reference");
        goto done;
    }
    if (!size) c.width = ref->width, c.height = ref->height;
    if (mcp_adaptive_check(&c.ao) || mcp_cli_denoiser_create(&df, &den)) goto done;
    c.den = den;
    if (run_loop(&c, json ? &j : NULL)) goto done;
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
    cmd_adaptive};

/* ---- the job stage ---- */

static const char *const adaptive_keys[] = {
    "render",         "output",   "size",   "map",  "spp_per_iteration",
    "initial_spp",    "budget",   "stop",   "tau",  "p",
    "max_iterations", "quantum",  "probes", "seed", "reference",
    "keep_passes",    "denoiser", "title",  NULL};

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): the loop's options, the size, the reference by name
 * (checked against the job's inputs) and the denoiser, created from its settings. */
typedef struct adaptive_plan {
    loop_cfg c;
    const char *sub, *ref_name, *title;
    int have_size;
    mcp_denoiser *den;
} adaptive_plan;

static int
parse_adaptive(mcp_job *job, const mcp_node *s, adaptive_plan *pl)
{
    memset(pl, 0, sizeof *pl);
    loop_cfg *c = &pl->c;
    c->ao = mcp_adaptive_defaults();
    pl->sub = "adaptive";
    const char *map = NULL, *size = NULL;
    double seed = 1;
    const mcp_node *render = NULL;
    if (mcp_node_require(s, "render", "adaptive", &render) ||
        mcp_node_string(render, "render", &c->render) ||
        mcp_node_opt_string(s, "output", &pl->sub) || mcp_node_opt_string(s, "map", &map) ||
        mcp_node_opt_string(s, "size", &size) ||
        mcp_node_opt_string(s, "reference", &pl->ref_name) ||
        mcp_node_opt_string(s, "title", &pl->title) ||
        mcp_node_opt_double(s, "spp_per_iteration", &c->ao.spp_per_iteration) ||
        mcp_node_opt_double(s, "initial_spp", &c->ao.initial_spp) ||
        mcp_node_opt_double(s, "budget", &c->ao.budget_spp) ||
        mcp_node_opt_bool(s, "stop", &c->ao.stop_on_estimate) ||
        mcp_node_opt_double(s, "tau", &c->ao.est.tau) ||
        mcp_node_opt_double(s, "p", &c->ao.est.p) ||
        mcp_node_opt_int(s, "max_iterations", &c->ao.max_iterations) ||
        mcp_node_opt_int(s, "quantum", &c->ao.quantum) ||
        mcp_node_opt_int(s, "probes", &c->ao.est.sure.n_probes) ||
        mcp_node_opt_double(s, "seed", &seed) ||
        mcp_node_opt_bool(s, "keep_passes", &c->keep_passes))
        return -1;
    if (map && mcp_adaptive_map_from_name(map, &c->ao.map))
        return mcp_node_error(mcp_node_get(s, "map"), "%s", mcp_error_message());
    if (seed < 0 || seed != floor(seed) || seed > 9007199254740992.0)
        return mcp_node_error(mcp_node_get(s, "seed"),
                              "seed must be a whole number >= 0 (got %g)", seed);
    c->seed = (uint64_t)seed;
    c->ao.est.sure.seed = c->seed;
    if (size && parse_size(size, &c->width, &c->height))
        return mcp_node_error(mcp_node_get(s, "size"), "%s", mcp_error_message());
    pl->have_size = size != NULL;
    if (pl->ref_name && mcp_job_check_input(job, s, "reference", MCP_JOB_IMAGE)) return -1;
    if (!size && !pl->ref_name)
        return mcp_node_error(s, "adaptive: give the image size (size: WxH) or a "
                                 "reference");
    if (mcp_adaptive_check(&c->ao)) return mcp_node_error(s, "%s", mcp_error_message());
    return mcp_cli_stage_denoiser(job, s, &pl->den);
}

static int
check_adaptive(mcp_job *job, const mcp_node *s)
{
    adaptive_plan pl;
    int rc = parse_adaptive(job, s, &pl);
    mcp_denoiser_free(pl.den);
    return rc;
}

static int
stage_adaptive(mcp_job *job, const mcp_node *s)
{
    adaptive_plan pl;
    loop_cfg *c = &pl.c;
    int rc = -1;
    if (parse_adaptive(job, s, &pl) ||
        (pl.ref_name && mcp_job_image(job, s, "reference", &c->reference)))
        goto done;
    if (!pl.have_size) c->width = c->reference->width, c->height = c->reference->height;
    char probe[4352], rel_json[300];
    snprintf(c->rel, sizeof c->rel, "%s/", pl.sub);
    snprintf(rel_json, sizeof rel_json, "%sadaptive.json", c->rel);
    if (mcp_job_output_path(job, rel_json, probe, sizeof probe)) goto done;
    *strrchr(probe, '/') = '\0';
    snprintf(c->dir, sizeof c->dir, "%s", probe);
    c->den = pl.den;
    c->section = mcp_report_section(mcp_job_report(job), "adaptive",
                                    pl.title ? pl.title : "adaptive sampling");
    rc = c->section ? run_loop(c, NULL) : -1;
done:
    mcp_denoiser_free(pl.den);
    return rc;
}

const mcp_stage mcp_stage_adaptive = {
    "adaptive", "the adaptive-sampling loop against a render command (Firmino 2023)",
    adaptive_keys, stage_adaptive, check_adaptive};
