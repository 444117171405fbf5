/* cmd_metrics.c: `mcpost metrics TEST REF` -- MSE, RMSE, relMSE, PSNR, pMSE, RelSE
 * percentiles, LDR-FLIP, HDR-FLIP and the blue-noise fraction of a test image against
 * a reference (common/metrics/metrics.h), as a table, JSON, and maps. The job stage is in
 * stage_metrics.c; the flags are the metrics table's (ops/op_metrics.c), as the job's
 * keys and Python's keywords. -o DIR appears whole (common/io/outdir.c): the maps go into
 * a hidden folder, renamed to DIR at the end. */
#include "cli.h"

#include <mcpost/metrics.h>

#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char head[] =
    "usage: mcpost metrics TEST [TEST...] REF [options]\n"
    "  Compares each TEST (e.g. a denoised render) with REF (the reference, the last\n"
    "  file). All are EXR, PFM, PNG, ... with R, G, B channels; 8-bit files are\n"
    "  sRGB-decoded to linear. Prints MSE, RMSE, relMSE (eps 1e-2), PSNR (displayed:\n"
    "  clamped, sRGB), pMSE, RelSE percentiles, LDR-FLIP and HDR-FLIP with FLIP's\n"
    "  statistics (weighted median and quartiles, min, max) and the blue-noise\n"
    "  low-frequency fraction; several TESTs give one row per test. A gate (--fail,\n"
    "  --warn, --fail-percent, --warn-percent) prints PASS, WARNING: ... or FAILURE: "
    "...\n"
    "  last (--json: a \"gate\" object) and exits 0 pass, 3 warning, 4 failure (1 "
    "error,\n"
    "  2 usage error, as always); several TESTs: the worst verdict of all, each test's\n"
    "  in its row.\n";

static const char examples[] =
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost metrics samples/fixtures/cornell/series/cornell_spp0016.exr "
    "samples/fixtures/cornell/cornell_reference.exr\n"
    "  mcpost metrics --json --flip ldr "
    "samples/fixtures/cornell/series/cornell_spp0064.exr \\\n"
    "                 samples/fixtures/cornell/cornell_reference.exr \\\n"
    "                 --fail 'flip_ldr.mean > 0.2' --warn 'relmse > 0.5'\n"
    "  mcpost metrics samples/fixtures/cornell/series/cornell_spp0016.exr \\\n"
    "                 samples/fixtures/cornell/series/cornell_spp0064.exr \\\n"
    "                 samples/fixtures/cornell/cornell_reference.exr -o out/metrics_maps "
    "\\\n"
    "                 --csv out/metrics.csv --fail-percent 'flip_ldr 0.5 1%'\n";

static void
print_flip_stats(const mcp_flip_stats *st)
{
    printf("  %-12s %.6f\n", "w. median", st->weighted_median);
    printf("  %-12s %.6f .. %.6f   (1st, 3rd weighted quartile)\n", "w. quartiles",
           st->weighted_q1, st->weighted_q3);
    printf("  %-12s %.6f .. %.6f\n", "min, max", st->min, st->max);
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
    if (m->has_flip_ldr) {
        printf("%-14s %.6f   (ppd %.2f)\n", "LDR-FLIP", m->flip_ldr.mean,
               m->flip_ldr.ppd);
        print_flip_stats(&m->flip_ldr.stats);
    }
    if (m->has_flip_hdr) {
        printf("%-14s %.6f   (%s, exposures %.4f to %.4f in %d steps)\n", "HDR-FLIP",
               m->flip_hdr.mean, mcp_tonemap_name(o->flip.tone_mapper),
               m->flip_hdr.start_exposure, m->flip_hdr.stop_exposure,
               m->flip_hdr.num_exposures);
        print_flip_stats(&m->flip_hdr.stats);
    }
    if (m->has_spectra)
        printf("%-14s %.4f   (low-frequency energy fraction; white noise %.4f)\n",
               "blue noise", m->spectra.low_fraction, m->spectra.white_fraction);
    for (int k = 0; k < m->n_above; k++)
        printf("%s > %g: %.4g%% of the pixels\n", mcp_above_map_name(m->above[k].map),
               m->above[k].threshold, m->above_percent[k]);
}

/* ---- several tests: a row each (text and CSV) ---- */

#define MAX_COLUMNS (16 + MCP_METRICS_MAX_PERCENTILES + MCP_METRICS_MAX_ABOVE)

typedef struct column {
    char text[48]; /* the text table's header */
    char csv[64];  /* the CSV header: the JSON's names joined by '_' */
} column;

static void
put_column(column *cols, double *vals, int *n, const char *text, const char *csv,
           double v)
{
    snprintf(cols[*n].text, sizeof cols[*n].text, "%s", text);
    snprintf(cols[*n].csv, sizeof cols[*n].csv, "%s", csv);
    vals[(*n)++] = v;
}

static void
put_flip_columns(column *cols, double *vals, int *n, const char *text, const char *csv,
                 const mcp_flip_result *f)
{
    const char *what[6][2] = {{"", "mean"},           {" median", "weighted_median"},
                              {" q1", "weighted_q1"}, {" q3", "weighted_q3"},
                              {" min", "min"},        {" max", "max"}};
    const double v[6] = {f->mean,
                         f->stats.weighted_median,
                         f->stats.weighted_q1,
                         f->stats.weighted_q3,
                         f->stats.min,
                         f->stats.max};
    for (int k = 0; k < 6; k++) {
        char t[48], c[64];
        snprintf(t, sizeof t, "%s%s", text, what[k][0]);
        snprintf(c, sizeof c, "%s_%s", csv, what[k][1]);
        put_column(cols, vals, n, t, c, v[k]);
    }
}

/* The figures of one test as columns: the same names and order for every test of one
 * call (one set of options). */
static int
columns_of(const mcp_metrics *m, column *cols, double *vals)
{
    int n = 0;
    put_column(cols, vals, &n, "MSE", "mse", m->mse);
    put_column(cols, vals, &n, "RMSE", "rmse", m->rmse);
    put_column(cols, vals, &n, "relMSE", "relmse", m->relmse);
    put_column(cols, vals, &n, "PSNR", "psnr", m->psnr);
    put_column(cols, vals, &n, "pMSE", "pmse", m->pmse);
    for (int k = 0; k < m->n_percentiles; k++) {
        char t[48], c[64];
        snprintf(t, sizeof t, "RelSE p%g", 100.0 * m->percentiles[k]);
        snprintf(c, sizeof c, "relse_p%g", 100.0 * m->percentiles[k]);
        put_column(cols, vals, &n, t, c, m->relse[k]);
    }
    if (m->has_flip_ldr)
        put_flip_columns(cols, vals, &n, "LDR-FLIP", "flip_ldr", &m->flip_ldr);
    if (m->has_flip_hdr)
        put_flip_columns(cols, vals, &n, "HDR-FLIP", "flip_hdr", &m->flip_hdr);
    if (m->has_spectra)
        put_column(cols, vals, &n, "blue noise", "blue_noise_low_fraction",
                   m->spectra.low_fraction);
    for (int k = 0; k < m->n_above; k++) {
        char t[48], c[64];
        const char *map = mcp_above_map_name(m->above[k].map);
        snprintf(t, sizeof t, "%% %s>%g", map, m->above[k].threshold);
        snprintf(c, sizeof c, "percent_%s_above_%g", map, m->above[k].threshold);
        put_column(cols, vals, &n, t, c, m->above_percent[k]);
    }
    return n;
}

typedef struct test_result {
    const char *path;
    mcp_metrics m;
    cJSON *doc; /* the test's figures, as `mcpost metrics TEST REF --json` prints them */
    mcp__gate_verdict verdict;
    char gate_line[2200];
} test_result;

static const char *
verdict_word(mcp__gate_verdict v)
{
    return v == MCP__GATE_FAILURE   ? "FAILURE"
           : v == MCP__GATE_WARNING ? "WARNING"
                                    : "PASS";
}

/* A row per test: the test's name, its figures and, with a gate, its verdict. */
static void
print_rows(const test_result *r, int n, const char *ref, const mcp_image *img, int gated)
{
    column cols[MAX_COLUMNS];
    double vals[MAX_COLUMNS];
    int nc = columns_of(&r[0].m, cols, vals);
    int name_w = 4, width[MAX_COLUMNS];
    for (int i = 0; i < n; i++)
        name_w = (int)strlen(r[i].path) > name_w ? (int)strlen(r[i].path) : name_w;
    for (int c = 0; c < nc; c++)
        width[c] = (int)strlen(cols[c].text) > 10 ? (int)strlen(cols[c].text) : 10;
    printf("reference:   %s (%dx%d)\n\n%-*s", ref, img->width, img->height, name_w,
           "test");
    for (int c = 0; c < nc; c++)
        printf("  %*s", width[c], cols[c].text);
    printf(gated ? "  gate\n" : "\n");
    for (int i = 0; i < n; i++) {
        columns_of(&r[i].m, cols, vals);
        printf("%-*s", name_w, r[i].path);
        for (int c = 0; c < nc; c++)
            printf("  %*.6g", width[c], vals[c]);
        printf(gated ? "  %s\n" : "\n", verdict_word(r[i].verdict));
    }
}

/* Appends t to the CSV text; as a field (field 1) it is quoted when it holds a comma,
 * a quote or a line break, quotes doubled. */
static void
csv_put(mcp__strbuf *b, const char *t, int field)
{
    int quote = field && strpbrk(t, ",\"\n\r") != NULL;
    char *o = mcp__strbuf_reserve(b, 2 * strlen(t) + 2);
    if (!o) return;
    if (quote) *o++ = '"';
    for (; *t; t++) {
        if (quote && *t == '"') *o++ = '"';
        *o++ = *t;
    }
    if (quote) *o++ = '"';
    *o = '\0';
    b->len = (size_t)(o - b->s);
}

/* The CSV: a header and a row per test (test, reference, the figures, gate), written
 * whole or not at all. */
static int
write_csv(const char *path, const test_result *r, int n, const char *ref, int gated)
{
    column cols[MAX_COLUMNS];
    double vals[MAX_COLUMNS];
    char num[64];
    mcp__strbuf b = {0};
    int nc = columns_of(&r[0].m, cols, vals);
    csv_put(&b, "test,reference", 0);
    for (int c = 0; c < nc; c++) {
        csv_put(&b, ",", 0);
        csv_put(&b, cols[c].csv, 1);
    }
    csv_put(&b, gated ? ",gate\n" : "\n", 0);
    for (int i = 0; i < n; i++) {
        columns_of(&r[i].m, cols, vals);
        csv_put(&b, r[i].path, 1);
        csv_put(&b, ",", 0);
        csv_put(&b, ref, 1);
        for (int c = 0; c < nc; c++) {
            if (isnan(vals[c]))
                snprintf(num, sizeof num, ",");
            else if (isinf(vals[c]))
                snprintf(num, sizeof num, ",%sinf", vals[c] < 0 ? "-" : "");
            else
                snprintf(num, sizeof num, ",%.9g", vals[c]);
            csv_put(&b, num, 0);
        }
        if (gated) {
            csv_put(&b, ",", 0);
            csv_put(&b, verdict_word(r[i].verdict), 0);
        }
        csv_put(&b, "\n", 0);
    }
    int rc = b.failed ? mcp_error("--csv %s: out of memory", path)
                      : mcp_write_file_atomic(path, b.s, b.len);
    mcp__strbuf_free(&b);
    return rc;
}

/* FLIP's weighted histogram (the tool's plot: count x bucket centre per megapixel),
 * one translucent bar series per test, as DIR/<kind>_histogram.svg. */
static int
write_histogram_svg(const char *dir, const test_result *r, int n, int hdr)
{
    enum { B = MCP_FLIP_HISTOGRAM_BUCKETS };
    double x[B], *y = malloc((size_t)n * B * sizeof *y);
    mcp_plot_series *ps = calloc((size_t)n, sizeof *ps);
    char path[4096], *svg = NULL;
    int rc = -1;
    if (!y || !ps) {
        mcp_error("metrics: out of memory for the histogram");
        goto done;
    }
    for (int i = 0; i < B; i++)
        x[i] = (i + 0.5) / B;
    for (int t = 0; t < n; t++) {
        const mcp_flip_stats *st = hdr ? &r[t].m.flip_hdr.stats : &r[t].m.flip_ldr.stats;
        for (int i = 0; i < B; i++)
            y[t * B + i] = mcp_flip_weighted_bucket(st, i);
        ps[t] = (mcp_plot_series){
            .name = r[t].path, .style = MCP_SERIES_BARS, .x = x, .y = y + t * B, .n = B};
    }
    mcp_plot plot = {.title = hdr ? "weighted HDR-FLIP histogram"
                                  : "weighted LDR-FLIP histogram",
                     .x_label = "FLIP error",
                     .y_label = "weighted FLIP sum per megapixel",
                     .x_scale = MCP_AXIS_LINEAR,
                     .y_scale = MCP_AXIS_LINEAR,
                     .series = ps,
                     .n_series = n};
    snprintf(path, sizeof path, "%s/%s_histogram.svg", dir,
             hdr ? "flip_hdr" : "flip_ldr");
    if (mcp_plot_svg(&plot, &svg)) goto done;
    rc = mcp_write_file_atomic(path, svg, strlen(svg));
done:
    free(svg);
    free(ps);
    free(y);
    return rc;
}

/* The maps' name prefix of test i of n: none for one test, else its file name without
 * folder and extension and a dot ("cornell_spp0016."), numbered when two tests share
 * a name ("2.cornell.") */
static void
maps_prefix(const test_result *r, int n, int i, char *out, size_t cap)
{
    if (n == 1) {
        *out = '\0';
        return;
    }
    char stem[512];
    const char *base = strrchr(r[i].path, '/');
    snprintf(stem, sizeof stem, "%s", base ? base + 1 : r[i].path);
    char *dot = strrchr(stem, '.');
    if (dot && dot != stem) *dot = '\0';
    int shared = 0;
    for (int j = 0; j < n; j++) {
        const char *b = strrchr(r[j].path, '/');
        b = b ? b + 1 : r[j].path;
        shared += j != i && !strncmp(b, stem, strlen(stem)) &&
                  (b[strlen(stem)] == '.' || b[strlen(stem)] == '\0');
    }
    if (shared)
        snprintf(out, cap, "%d.%s.", i + 1, stem);
    else
        snprintf(out, cap, "%s.", stem);
}

/* The verdict over all tests and its final line: the worst, with every test that has
 * it ("FAILURE: a.exr: relmse > 0.1 (0.2); b.exr: ..."); one test's line as it is. */
static mcp__gate_verdict
overall_verdict(const test_result *r, int n, char *line, size_t cap, cJSON **gate_json)
{
    mcp__gate_verdict worst = MCP__GATE_PASS;
    for (int i = 0; i < n; i++)
        worst = r[i].verdict > worst ? r[i].verdict : worst;
    if (n == 1) {
        snprintf(line, cap, "%s", r[0].gate_line);
        return worst;
    }
    cJSON *g = cJSON_CreateObject();
    cJSON_AddStringToObject(g, "verdict",
                            worst == MCP__GATE_FAILURE   ? "failure"
                            : worst == MCP__GATE_WARNING ? "warning"
                                                         : "pass");
    cJSON *failed = cJSON_AddArrayToObject(g, "failed_tests"),
          *warned = cJSON_AddArrayToObject(g, "warned_tests");
    size_t len = (size_t)snprintf(line, cap, "%s", verdict_word(worst));
    int shown = 0;
    for (int i = 0; i < n; i++) {
        if (r[i].verdict == MCP__GATE_FAILURE)
            cJSON_AddItemToArray(failed, cJSON_CreateString(r[i].path));
        if (r[i].verdict == MCP__GATE_WARNING)
            cJSON_AddItemToArray(warned, cJSON_CreateString(r[i].path));
        if (worst == MCP__GATE_PASS || r[i].verdict != worst || len >= cap) continue;
        /* the test's own line without its "FAILURE: " / "WARNING: " */
        const char *why = strchr(r[i].gate_line, ':');
        len += (size_t)snprintf(line + len, cap - len, "%s %s:%s", shown++ ? ";" : ":",
                                r[i].path, why ? why + 1 : "");
    }
    *gate_json = g;
    return worst;
}

static int
cmd_metrics(int argc, char **argv)
{
    mcp_metrics_settings st;
    mcp_shared_settings sh;
    mcp_cli_denoiser_flags df = {0};
    mcp__gate gate = {0};
    int first = 0;
    int parsed = mcp_cli_parse(mcp_operation_metrics(), head, examples, argc, argv, &st,
                               &sh, &df, &first);
    if (parsed >= 0) return parsed;
    mcp_metrics_options o = st.o;
    const char *out_dir = sh.output, *csv_path = st.csv;
    int json = sh.json;
    optind = first;
    if (argc - optind < 2)
        return mcp_cli_usage("metrics", "give TEST... and REF (got %d files)",
                             argc - optind);
    /* Gates checked before the images are read: a typo costs no FLIP run, and it is a
     * usage error (2), never mistaken for a gate's verdict. */
    const char *bad_key;
    int bad_index;
    if (mcp__gate_from_settings(&st, &o, &gate, &bad_key, &bad_index))
        return mcp_cli_usage("metrics", "%s", mcp_error_message());
    int n_tests = argc - optind - 1;
    const char *ref_path = argv[argc - 1];
    mcp_image *ref = NULL;
    test_result *res = calloc((size_t)n_tests, sizeof *res);
    cJSON *doc = NULL, *all_gate = NULL;
    mcp__outdir whole = {0};     /* -o DIR appears whole, or not at all */
    const char *maps_dir = NULL; /* where the maps go: whole.tmp */
    int status = 1;
    if (!res) {
        mcp_error("metrics: out of memory");
        goto done;
    }
    for (int i = 0; i < n_tests; i++)
        res[i].path = argv[optind + i];
    if (out_dir) { /* after the cheap checks, before any work */
        if (mcp__outdir_begin(&whole, out_dir) ||
            mcp__outdir_check_inputs(&whole, (const char *const *)argv + optind,
                                     n_tests + 1)) /* the tests, then REF */
            goto done;
        maps_dir = whole.tmp;
    }
    if (mcp_image_read(ref_path, NULL, &ref)) goto done;
    for (int i = 0; i < n_tests; i++) {
        test_result *r = &res[i];
        mcp_image *test = NULL;
        mcp_metrics_maps maps = {0};
        int failed = mcp_image_read(r->path, NULL, &test) ||
                     mcp_metrics_compute(test, ref, &o, &r->m, out_dir ? &maps : NULL);
        mcp_image_free(test);
        if (!failed && out_dir) {
            char prefix[600];
            maps_prefix(res, n_tests, i, prefix, sizeof prefix);
            failed = mcp_metrics_write_maps(&maps, maps_dir, prefix, NULL);
        }
        mcp_metrics_maps_free(&maps);
        if (failed || !(r->doc = cJSON_CreateObject())) goto done;
        cJSON_AddStringToObject(r->doc, "test", r->path);
        cJSON_AddStringToObject(r->doc, "reference", ref_path);
        cJSON_AddNumberToObject(r->doc, "width", ref->width);
        cJSON_AddNumberToObject(r->doc, "height", ref->height);
        if (mcp_metrics_json(&r->m, &o, r->doc)) goto done;
        if (gate.n) {
            cJSON *gj = NULL;
            if (mcp__gate_eval(&gate, r->doc, &r->verdict, &gj, r->gate_line,
                               sizeof r->gate_line))
                goto done;
            cJSON_AddItemToObject(r->doc, "gate", gj);
        }
    }
    char gate_line[4096] = "";
    mcp__gate_verdict verdict =
        gate.n ? overall_verdict(res, n_tests, gate_line, sizeof gate_line, &all_gate)
               : MCP__GATE_PASS;
    /* One test: its object, as always; several: the reference and a list of tests */
    if (n_tests == 1) {
        doc = res[0].doc;
        res[0].doc = NULL;
    } else {
        doc = cJSON_CreateObject();
        cJSON_AddStringToObject(doc, "reference", ref_path);
        cJSON_AddNumberToObject(doc, "width", ref->width);
        cJSON_AddNumberToObject(doc, "height", ref->height);
        cJSON *list = cJSON_AddArrayToObject(doc, "tests");
        for (int i = 0; i < n_tests; i++) {
            cJSON_AddItemToArray(list, res[i].doc);
            res[i].doc = NULL;
        }
        if (all_gate) cJSON_AddItemToObject(doc, "gate", all_gate);
        all_gate = NULL;
    }
    if (out_dir) {
        char path[4096];
        char *text = NULL;
        if ((o.flip_ldr && write_histogram_svg(maps_dir, res, n_tests, 0)) ||
            (o.flip_hdr && write_histogram_svg(maps_dir, res, n_tests, 1)))
            goto done;
        snprintf(path, sizeof path, "%s/metrics.json", maps_dir);
        if (!(text = cJSON_Print(doc))) goto done;
        int rc = mcp_write_file_atomic(path, text, strlen(text));
        free(text);
        if (rc) goto done;
    }
    /* the CSV before the folder is renamed into place: a CSV that cannot be written
       leaves no folder either, and one asked for inside DIR goes into it */
    char csv_in_dir[8400];
    size_t dir_len = out_dir ? strlen(whole.final) : 0;
    if (csv_path && out_dir && !strncmp(csv_path, whole.final, dir_len) &&
        csv_path[dir_len] == '/') {
        snprintf(csv_in_dir, sizeof csv_in_dir, "%s%s", whole.tmp, csv_path + dir_len);
        csv_path = csv_in_dir;
    }
    if (csv_path && write_csv(csv_path, res, n_tests, ref_path, gate.n > 0)) goto done;
    if (out_dir && mcp__outdir_commit(&whole)) goto done;
    if (json) {
        mcp_cli_print_json(doc);
        doc = NULL;
    } else {
        if (n_tests == 1)
            print_table(res[0].path, ref_path, ref, &res[0].m, &o);
        else
            print_rows(res, n_tests, ref_path, ref, gate.n > 0);
        if (out_dir) printf("\nmaps written to %s/\n", out_dir);
        /* idiff's convention: the verdict is the last line, after the figures */
        if (gate.n) printf("\n%s\n", gate_line);
    }
    status = mcp__gate_exit_code(verdict);
    goto out;
done:
    if (status) status = mcp_cli_fail();
out:
    mcp__outdir_abort(&whole);
    for (int i = 0; res && i < n_tests; i++)
        cJSON_Delete(res[i].doc);
    free(res);
    cJSON_Delete(all_gate);
    cJSON_Delete(doc);
    mcp_image_free(ref);
    return status;
}

const mcp_command mcp_command_metrics = {"metrics",
                                         "compare test images with a reference "
                                         "(MSE, relMSE, PSNR, pMSE, FLIP, ...)",
                                         cmd_metrics, 1};
