/* cmd_compare.c: `mcpost compare REF TEST... -o DIR` -- the quickest way to look at
 * renders beside a reference, without a job file: one page (docs/report.md, "The
 * compare page") with, for each TEST, the wipe comparison of TEST and REF, the error
 * maps with their colour bars, the figures of `mcpost metrics` and the gate's verdict;
 * display controls (exposure, tone map or false colour) re-expose the renders. The
 * figures, maps and gates are metrics' own (common/metrics/metrics.h, jobs/gate.c), and
 * each section's verdict is the metrics stage's (mcp__metrics_verdict). */
#include "cli.h"

#include <mcpost/metrics.h>
#include <mcpost/report.h>
#include <mcpost/tonemap.h>

#include <getopt.h> /* optind */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char head[] =
    "usage: mcpost compare REF TEST... [-o DIR] [options]\n"
    "  A page to look at renders against a reference: for each TEST, a wipe comparison\n"
    "  of TEST and REF (drag the split, zoom), the error maps (LDR/HDR-FLIP, relative\n"
    "  squared error, error spectra) with colour bars, the figures of `mcpost metrics`\n"
    "  (its options, below) and, with a gate (--fail, --warn, ...), the verdict, judged\n"
    "  on every TEST: the last line is the worst; exit 0 pass, 3 warning, 4 failure (1\n"
    "  error, 2 usage error). The page re-exposes the renders: an exposure slider and\n"
    "  clamp, ACES, Hable, Reinhard or false colour. Note the order: the reference\n"
    "  first (metrics takes TEST REF).\n";

static const char examples[] =
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost compare samples/fixtures/cornell/cornell_reference.exr \\\n"
    "                 samples/fixtures/cornell/series/cornell_spp0064.exr -o "
    "out/compare\n"
    "  mcpost compare samples/fixtures/cornell/cornell_reference.exr \\\n"
    "                 samples/fixtures/cornell/series/cornell_spp0016.exr \\\n"
    "                 samples/fixtures/cornell/series/cornell_spp0256.exr \\\n"
    "                 -o out/compare_spp --flip ldr --exposure 1 \\\n"
    "                 --fail 'flip_ldr.mean > 0.5' --warn 'relmse > 1'\n";

/* The render's RGB as a screen shows it (PNG: clamped, sRGB) and its linear values
 * (EXR), for the page's display controls; both into the section. */
static int
write_render(const mcp_image *img, const char *dir, const char *prefix, const char *stem,
             const char *caption, cJSON *section)
{
    int rgb[3];
    char png[4400], exr[4400], rel_png[600], rel_exr[600];
    mcp_image *view = NULL, *shown = NULL;
    snprintf(rel_png, sizeof rel_png, "%s%s.png", prefix, stem);
    snprintf(rel_exr, sizeof rel_exr, "%s%s.exr", prefix, stem);
    snprintf(png, sizeof png, "%s/%s", dir, rel_png);
    snprintf(exr, sizeof exr, "%s/%s", dir, rel_exr);
    int rc = mcp_rgb_channels(img, rgb) || mcp_image_copy_channels(img, rgb, 3, &view) ||
             mcp_tonemap_apply(view, MCP_TONEMAP_CLAMP, &shown) ||
             mcp_image_write(shown, png, NULL) || mcp_image_write(view, exr, NULL) ||
             !mcp_report_add_hdr_image(section, rel_png, rel_exr, caption);
    mcp_image_free(shown);
    mcp_image_free(view);
    return rc ? -1 : 0;
}

/* The file's name without its folders, for captions and titles. */
static const char *
base_name(const char *path)
{
    const char *slash = strrchr(path, '/');
    return slash && slash[1] ? slash + 1 : path;
}

static double
figure(const cJSON *section, const char *key, const char *sub)
{
    const cJSON *v = cJSON_GetObjectItem(section, key);
    if (sub) v = cJSON_GetObjectItem(v, sub);
    return cJSON_IsNumber(v) ? v->valuedouble : NAN;
}

/* One TEST against the reference: its section, maps and verdict; *verdict the gate's. */
static int
compare_one(const char *test_path, const char *ref_path, const mcp_image *ref, int index,
            int n_tests, const mcp_metrics_options *o, const mcp__gate *gate,
            const char *dir, mcp_report *report, mcp__gate_verdict *verdict,
            char *gate_line, size_t line_cap)
{
    char prefix[64] = "", title[4400], cap_test[4400], cap_ref[4400];
    if (n_tests > 1) snprintf(prefix, sizeof prefix, "test%d/", index + 1);
    snprintf(title, sizeof title, "%s against %s", base_name(test_path),
             base_name(ref_path));
    snprintf(cap_test, sizeof cap_test, "test: %s", base_name(test_path));
    snprintf(cap_ref, sizeof cap_ref, "reference: %s", base_name(ref_path));
    cJSON *section = mcp_report_section(report, "compare", title);
    if (!section) return -1;
    mcp_image *test = NULL;
    mcp_metrics m;
    mcp_metrics_maps maps = {0};
    int rc = -1;
    if (mcp_image_read(test_path, NULL, &test)) goto done;
    if (!mcp_image_same_size(test, ref)) goto done;
    mcp_note("compare: %s against %s", test_path, ref_path);
    cJSON_AddStringToObject(section, "test", test_path);
    cJSON_AddStringToObject(section, "reference", ref_path);
    cJSON_AddNumberToObject(section, "width", ref->width);
    cJSON_AddNumberToObject(section, "height", ref->height);
    /* FLIP's weighted histograms drawn, their counts in report.json only */
    if (mcp_metrics_compute(test, ref, o, &m, &maps) ||
        mcp_metrics_json(&m, o, section) ||
        mcp__metrics_flip_histograms(section, &m, base_name(test_path), NULL, NULL))
        goto done;
    if (n_tests > 1) {
        char sub[4400];
        snprintf(sub, sizeof sub, "%s/%.*s", dir, (int)strlen(prefix) - 1, prefix);
        if (mcp_make_dirs(sub)) goto done;
    }
    /* the test first, then the reference: the wipe shows them left and right (a bar
       on a terminal for a megapixel: two 4K renders take 2 to 3 s) */
    mcp_progress bar;
    int shown = (double)ref->width * ref->height >= 1048576.0;
    if (shown) mcp_progress_begin(&bar, "writing the renders", 2);
    int failed = write_render(test, dir, prefix, "test", cap_test, section);
    if (shown && !failed) mcp_progress_update(&bar, 1);
    failed = failed || write_render(ref, dir, prefix, "reference", cap_ref, section);
    if (shown) {
        if (failed)
            mcp__progress_stop(&bar);
        else
            mcp_progress_end(&bar);
    }
    if (failed || mcp_metrics_write_maps(&maps, dir, prefix, section)) goto done;
    *verdict = MCP__GATE_PASS;
    *gate_line = 0;
    if (gate->n) {
        cJSON *gj = NULL;
        if (mcp__gate_eval(gate, section, verdict, &gj, gate_line, line_cap)) goto done;
        cJSON_AddItemToObject(section, "gate", gj);
    }
    rc = mcp__metrics_verdict(section, gate, *verdict, gate_line);
done:
    mcp_metrics_maps_free(&maps);
    mcp_image_free(test);
    return rc;
}

/* With several tests, the first section: one row a test (the FLIP columns that were
 * computed, the gate's verdict when there is a gate), and the worst gate. */
static int
summary_section(cJSON *sections, int n_tests, const mcp_metrics_options *o,
                const mcp__gate *gate, mcp__gate_verdict worst, const char *worst_test,
                cJSON **out)
{
    const char *cols[6] = {"test", "relMSE", "PSNR (dB)"};
    int n_cols = 3;
    if (o->flip_ldr) cols[n_cols++] = "LDR-FLIP";
    if (o->flip_hdr) cols[n_cols++] = "HDR-FLIP";
    if (gate->n) cols[n_cols++] = "gate";
    cJSON *s = cJSON_CreateObject();
    cJSON *t =
        s ? mcp_report_add_table(s, "every test against the reference", cols, n_cols)
          : NULL;
    cJSON *rows = cJSON_GetObjectItem(t, "rows");
    if (!rows) {
        cJSON_Delete(s);
        return mcp_error("out of memory for the report");
    }
    cJSON_AddStringToObject(s, "stage", "compare");
    cJSON_AddStringToObject(s, "title", "summary");
    int best = -1;
    double best_relmse = INFINITY;
    for (int i = 0; i < n_tests; i++) {
        const cJSON *sec = cJSON_GetArrayItem(sections, i);
        const cJSON *g = cJSON_GetObjectItem(cJSON_GetObjectItem(sec, "gate"), "verdict");
        double relmse = figure(sec, "relmse", NULL);
        if (relmse < best_relmse) best_relmse = relmse, best = i;
        /* a row as report.h has it: numbers (NaN as null) and strings */
        cJSON *row = cJSON_CreateArray();
        double v[4] = {relmse, figure(sec, "psnr", NULL), figure(sec, "flip_ldr", "mean"),
                       figure(sec, "flip_hdr", "mean")};
        int on[4] = {1, 1, o->flip_ldr, o->flip_hdr};
        if (!row || !cJSON_AddItemToArray(row, cJSON_CreateString(cJSON_GetStringValue(
                                                   cJSON_GetObjectItem(sec, "test"))))) {
            cJSON_Delete(row);
            cJSON_Delete(s);
            return mcp_error("out of memory for the report");
        }
        for (int k = 0; k < 4; k++)
            if (on[k])
                cJSON_AddItemToArray(row, isfinite(v[k]) ? cJSON_CreateNumber(v[k])
                                                         : cJSON_CreateNull());
        if (gate->n)
            cJSON_AddItemToArray(row, cJSON_IsString(g)
                                          ? cJSON_CreateString(g->valuestring)
                                          : cJSON_CreateNull());
        cJSON_AddItemToArray(rows, row);
        if (cJSON_GetArraySize(row) != n_cols) { /* an item ran out of memory */
            cJSON_Delete(s);
            return mcp_error("out of memory for the report");
        }
    }
    const char *best_name = best >= 0 ? cJSON_GetStringValue(cJSON_GetObjectItem(
                                            cJSON_GetArrayItem(sections, best), "test"))
                                      : NULL;
    char best_text[4400] = "";
    if (best_name)
        snprintf(best_text, sizeof best_text, "lowest relMSE: %s (%.3g)", best_name,
                 best_relmse);
    int rc;
    if (!gate->n)
        rc = mcp_report_set_verdict(s, MCP_VERDICT_INFO, "%d tests; %s", n_tests,
                                    *best_text ? best_text : "no relMSE to rank by");
    else if (worst == MCP__GATE_PASS)
        rc = mcp_report_set_verdict(s, MCP_VERDICT_GOOD, "gate PASS on all %d tests; %s",
                                    n_tests, best_text);
    else
        rc = mcp_report_set_verdict(
            s, worst == MCP__GATE_FAILURE ? MCP_VERDICT_BAD : MCP_VERDICT_INFO,
            "gate %s, first in %s; %s",
            worst == MCP__GATE_FAILURE ? "FAILURE" : "WARNING", worst_test, best_text);
    if (rc) {
        cJSON_Delete(s);
        return -1;
    }
    *out = s;
    return 0;
}

static int
cmd_compare(int argc, char **argv)
{
    mcp_compare_settings st;
    mcp_shared_settings sh;
    mcp_cli_denoiser_flags df = {0};
    mcp__gate gate = {0};
    int first = 0;
    int parsed = mcp_cli_parse(mcp_operation_compare(), head, examples, argc, argv, &st,
                               &sh, &df, &first);
    /* a bad value is a usage error here, as it always was for compare */
    if (parsed >= 0) return parsed == 1 ? 2 : parsed;
    mcp_metrics_options o = st.m.o;
    const char *out_dir = sh.output ? sh.output : "compare",
               *display = mcp_wordlist_name(&mcp_report_display_words, st.display);
    double exposure = st.exposure;
    int json = sh.json;
    optind = first;
    int n_tests = argc - optind - 1;
    if (n_tests < 1)
        return mcp_cli_usage("compare", "give REF and at least one TEST (got %d files)",
                             argc - optind);
    /* gates checked before any image is read: a usage error */
    const char *bad_key;
    int bad_index;
    if (mcp__gate_from_settings(&st.m, &o, &gate, &bad_key, &bad_index))
        return mcp_cli_usage("compare", "%s", mcp_error_message());
    const char *ref_path = argv[optind];
    char *const *tests = argv + optind + 1;
    mcp_image *ref = NULL;
    mcp_report *report = NULL;
    mcp__outdir od = {0};
    cJSON *out = NULL;
    mcp__gate_verdict worst = MCP__GATE_PASS;
    const char *worst_test = NULL;
    char worst_line[2200] = "", title[4400];
    int status = 1;
    if (n_tests == 1)
        snprintf(title, sizeof title, "mcpost compare: %s against %s",
                 base_name(tests[0]), base_name(ref_path));
    else
        snprintf(title, sizeof title, "mcpost compare: %d renders against %s", n_tests,
                 base_name(ref_path));
    if (mcp_image_read(ref_path, NULL, &ref) || mcp_report_new(title, &report) ||
        mcp_report_set_display(report, exposure, display) ||
        mcp__outdir_begin(&od, out_dir) ||
        mcp__outdir_check_inputs(&od, (const char *const *)argv + optind, n_tests + 1))
        goto done;
    for (int i = 0; i < n_tests; i++) {
        mcp__gate_verdict v;
        char line[2200];
        if (compare_one(tests[i], ref_path, ref, i, n_tests, &o, &gate, od.tmp, report,
                        &v, line, sizeof line))
            goto done;
        if (v > worst) {
            worst = v;
            worst_test = tests[i];
            snprintf(worst_line, sizeof worst_line, "%s", line);
        }
    }
    cJSON *sections = cJSON_GetObjectItem(mcp_report_json(report), "sections");
    if (n_tests > 1) { /* the summary goes first */
        cJSON *sum = NULL;
        if (summary_section(sections, n_tests, &o, &gate, worst, worst_test, &sum))
            goto done;
        cJSON_InsertItemInArray(sections, 0, sum);
    }
    if (mcp_report_write(report, od.tmp) || mcp__outdir_commit(&od)) goto done;
    /* what was printed: each test's figures, then the worst gate last (idiff's way) */
    if (json) {
        out = cJSON_CreateObject();
        cJSON_AddStringToObject(out, "reference", ref_path);
        cJSON_AddStringToObject(out, "page", out_dir);
        cJSON *list = cJSON_AddArrayToObject(out, "tests");
        const cJSON *s;
        cJSON_ArrayForEach(s, sections) if (cJSON_GetObjectItem(s, "test"))
        {
            cJSON *copy = cJSON_Duplicate(s, 1);
            if (!copy) break;
            static const char *const page_only[] = {"images", "tables", "plots", "stage",
                                                    "title"};
            for (size_t k = 0; k < sizeof page_only / sizeof *page_only; k++)
                cJSON_DeleteItemFromObject(copy, page_only[k]);
            cJSON_AddItemToArray(list, copy);
        }
        if (gate.n)
            cJSON_AddStringToObject(out, "gate",
                                    worst == MCP__GATE_PASS      ? "pass"
                                    : worst == MCP__GATE_WARNING ? "warning"
                                                                 : "failure");
        mcp_cli_print_json(out);
        out = NULL;
    } else {
        const cJSON *s;
        cJSON_ArrayForEach(s, sections) if (cJSON_GetObjectItem(s, "test"))
        {
            const cJSON *v = cJSON_GetObjectItem(s, "verdict");
            printf("%s: %s\n", cJSON_GetStringValue(cJSON_GetObjectItem(s, "test")),
                   cJSON_GetStringValue(cJSON_GetObjectItem(v, "text")));
        }
        printf("page: %s/report.html\n", od.final);
        if (gate.n) printf("\n%s\n", worst == MCP__GATE_PASS ? "PASS" : worst_line);
    }
    status = mcp__gate_exit_code(worst);
done:
    if (status == 1) mcp_cli_fail();
    mcp__outdir_abort(&od);
    cJSON_Delete(out);
    mcp_report_free(report);
    mcp_image_free(ref);
    return status;
}

const mcp_command mcp_command_compare = {"compare",
                                         "a page to look at renders against a reference "
                                         "(wipe, error maps, figures, gates)",
                                         cmd_compare, 1};
