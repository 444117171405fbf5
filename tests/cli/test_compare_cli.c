/* test_compare_cli.c: `mcpost compare REF TEST... -o DIR` -- figures against closed
 * forms, the gates' exit statuses and last line, the files and the report, the linear
 * values the page embeds for its display controls (decoded back within RGBE's 2^-8),
 * and the usage and input errors (one line, no folder left). The page in a browser is
 * tests/report/compare_page.sh. */
#include "testing.h"

#include <cjson/cJSON.h>
#include <mcpost/imageio.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static char out[1 << 16], err[1 << 16];

#define run(...) mcp_test_run_mcpostf(out, sizeof out, err, sizeof err, __VA_ARGS__)

static const char *const RGB[] = {"R", "G", "B"};

/* mcp_test_path's buffer rotates (and run() takes some): a copy of our own */
static char paths[16][4096];
static int n_paths;

static const char *
scratch(const char *name)
{
    char *p = paths[n_paths++ % 16];
    snprintf(p, sizeof paths[0], "%s", mcp_test_path(name));
    return p;
}

static int
exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

/* ref: a constant 0.5; test: 0.5 + d. MSE = d^2, relMSE = d^2 / (0.25 + 0.01). */
static void
write_pair(const char *ref, const char *test, float d)
{
    mcp_image *r = mcp_test_constant(24, 16, 3, 0.5f, RGB);
    mcp_image *t = mcp_test_constant(24, 16, 3, 0.5f + d, RGB);
    assert_int_equal(mcp_image_write(r, ref, NULL), 0);
    assert_int_equal(mcp_image_write(t, test, NULL), 0);
    mcp_image_free(r);
    mcp_image_free(t);
}

static void
test_figures_and_gates(void **state)
{
    (void)state;
    const char *ref = scratch("ref.exr"), *a = scratch("a.exr"), *b = scratch("b.exr"),
               *dir = scratch("page");
    char path[4400];
    write_pair(ref, a, 0.1f);
    write_pair(ref, b, 0.3f);
    /* no gate: exit 0, the figures in JSON */
    assert_int_equal(
        run("compare '%s' '%s' '%s' -o '%s' --json --flip none --quiet", ref, a, b, dir),
        0);
    cJSON *doc = cJSON_Parse(out);
    assert_non_null(doc);
    const cJSON *tests = cJSON_GetObjectItem(doc, "tests");
    assert_int_equal(cJSON_GetArraySize(tests), 2);
    double d[2] = {0.1, 0.3};
    for (int i = 0; i < 2; i++) {
        const cJSON *t = cJSON_GetArrayItem(tests, i);
        assert_close(cJSON_GetObjectItem(t, "mse")->valuedouble, d[i] * d[i], 1e-5, 0);
        assert_close(cJSON_GetObjectItem(t, "relmse")->valuedouble, d[i] * d[i] / 0.26,
                     1e-5, 0);
        assert_null(cJSON_GetObjectItem(t, "images")); /* page matters stay on the page */
    }
    cJSON_Delete(doc);
    /* one folder per test, and the page */
    const char *files[] = {"report.html",    "report.json",         "test1/test.png",
                           "test1/test.exr", "test1/reference.png", "test2/relse.png",
                           "test2/test.exr"};
    for (size_t i = 0; i < sizeof files / sizeof *files; i++) {
        snprintf(path, sizeof path, "%s/%s", dir, files[i]);
        if (!exists(path)) fail_msg("no %s", path);
    }
    /* gates: b's relMSE 0.346 warns, a's 0.0385 passes; fail above 0.3 fails */
    assert_int_equal(run("compare '%s' '%s' '%s' -o '%s' --flip none --quiet --warn "
                         "'relmse > 0.1'",
                         ref, a, b, dir),
                     3);
    const char *last = out + strlen(out) - 1;
    while (last > out && last[-1] != '\n')
        last--;
    assert_non_null(strstr(last, "WARNING: relmse > 0.1"));
    /* the summary first: a row a test, no FLIP columns (none computed), the gate's
       verdicts, and the worst one in words */
    snprintf(path, sizeof path, "%s/report.json", dir);
    char *summary_text = mcp_test_read_text(path);
    cJSON *rep = cJSON_Parse(summary_text);
    free(summary_text);
    const cJSON *sum = cJSON_GetArrayItem(cJSON_GetObjectItem(rep, "sections"), 0);
    assert_string_equal(cJSON_GetObjectItem(sum, "title")->valuestring, "summary");
    const cJSON *table = cJSON_GetArrayItem(cJSON_GetObjectItem(sum, "tables"), 0);
    char *cols = cJSON_PrintUnformatted(cJSON_GetObjectItem(table, "columns"));
    assert_string_equal(cols, "[\"test\",\"relMSE\",\"PSNR (dB)\",\"gate\"]");
    free(cols);
    const cJSON *rows = cJSON_GetObjectItem(table, "rows");
    assert_string_equal(cJSON_GetArrayItem(cJSON_GetArrayItem(rows, 0), 3)->valuestring,
                        "pass");
    assert_string_equal(cJSON_GetArrayItem(cJSON_GetArrayItem(rows, 1), 3)->valuestring,
                        "warning");
    assert_close(cJSON_GetArrayItem(cJSON_GetArrayItem(rows, 1), 1)->valuedouble,
                 0.09 / 0.26, 1e-5, 0);
    const char *sv =
        cJSON_GetObjectItem(cJSON_GetObjectItem(sum, "verdict"), "text")->valuestring;
    assert_non_null(strstr(sv, "gate WARNING, first in "));
    assert_non_null(strstr(sv, "b.exr"));
    cJSON_Delete(rep);
    assert_int_equal(run("compare '%s' '%s' '%s' -o '%s' --flip none --quiet --warn "
                         "'relmse > 0.1' --fail 'mse > 0.05'",
                         ref, a, b, dir),
                     4);
    assert_non_null(strstr(out, "FAILURE: mse > 0.05"));
    assert_int_equal(
        run("compare '%s' '%s' -o '%s' --flip none --quiet --fail 'mse > 0.05'", ref, a,
            dir),
        0);
    assert_non_null(strstr(out, "\nPASS\n"));
    /* one test: the files directly in the folder, the rerun replaced test1/ */
    snprintf(path, sizeof path, "%s/test.exr", dir);
    assert_true(exists(path));
    snprintf(path, sizeof path, "%s/test1", dir);
    assert_false(exists(path));
    /* the section's verdict is the gate's, then the figures in words */
    snprintf(path, sizeof path, "%s/report.json", dir);
    char *text = mcp_test_read_text(path);
    doc = cJSON_Parse(text);
    free(text);
    const cJSON *s = cJSON_GetArrayItem(cJSON_GetObjectItem(doc, "sections"), 0);
    const cJSON *v = cJSON_GetObjectItem(s, "verdict");
    assert_string_equal(cJSON_GetObjectItem(v, "level")->valuestring, "good");
    assert_non_null(
        strstr(cJSON_GetObjectItem(v, "text")->valuestring, "gate PASS; relMSE"));
    cJSON_Delete(doc);
}

/* A test equal to the reference: every map holds one value (0: no error, the first
 * exposure), and the page says so on each instead of a flat square; FLIP's weighted
 * histograms are drawn as plots (every pixel in bucket 0, whose count is weighted by
 * its centre 0.005 and divided by the megapixels n / 2^20 (flip.h): 0.005 * 2^20),
 * their counts kept for report.json only. */
static void
test_identical_maps_and_histograms(void **state)
{
    (void)state;
    const char *ref = scratch("same_ref.exr"), *a = scratch("same_a.exr"),
               *dir = scratch("same_page");
    char path[4400];
    write_pair(ref, a, 0.0f);
    assert_int_equal(run("compare '%s' '%s' -o '%s' --quiet", ref, a, dir), 0);
    snprintf(path, sizeof path, "%s/report.json", dir);
    char *text = mcp_test_read_text(path);
    cJSON *doc = cJSON_Parse(text);
    free(text);
    const cJSON *s = cJSON_GetArrayItem(cJSON_GetObjectItem(doc, "sections"), 0);
    int maps = 0, flat = 0;
    const cJSON *im;
    cJSON_ArrayForEach(im, cJSON_GetObjectItem(s, "images"))
    {
        const cJSON *sc = cJSON_GetObjectItem(im, "scale");
        if (!sc) continue;
        maps++;
        const cJSON *one = cJSON_GetObjectItem(sc, "one_value");
        if (!cJSON_IsNumber(one))
            fail_msg("%s: no one_value",
                     cJSON_GetStringValue(cJSON_GetObjectItem(im, "path")));
        assert_float_equal(one->valuedouble, 0.0, 0);
        flat++;
    }
    /* LDR-FLIP, HDR-FLIP, its exposure, RelSE (24x16 is below the spectra's tile) */
    assert_int_equal(maps, 4);
    assert_int_equal(flat, 4);
    const char *titles[2] = {"weighted LDR-FLIP histogram",
                             "weighted HDR-FLIP histogram"};
    const cJSON *plots = cJSON_GetObjectItem(s, "plots");
    assert_int_equal(cJSON_GetArraySize(plots), 2);
    for (int k = 0; k < 2; k++) {
        const cJSON *pl = cJSON_GetArrayItem(plots, k);
        assert_string_equal(cJSON_GetObjectItem(pl, "title")->valuestring, titles[k]);
        const cJSON *se = cJSON_GetArrayItem(cJSON_GetObjectItem(pl, "series"), 0);
        const cJSON *y = cJSON_GetObjectItem(se, "y");
        assert_int_equal(cJSON_GetArraySize(y), 100);
        assert_close(cJSON_GetArrayItem(y, 0)->valuedouble, 0.005 * 1048576.0, 1e-9, 0);
        assert_float_equal(cJSON_GetArrayItem(y, 1)->valuedouble, 0.0, 0);
    }
    const cJSON *only = cJSON_GetObjectItem(s, "json_only");
    int listed = 0;
    const cJSON *k;
    cJSON_ArrayForEach(k, only) listed |= !strcmp(k->valuestring, "flip_histogram");
    assert_true(listed);
    cJSON_Delete(doc);
    snprintf(path, sizeof path, "%s/report.html", dir);
    text = mcp_test_read_text(path);
    int says = 0;
    for (const char *p = text; (p = strstr(p, "one value in every pixel: 0<br>")); p++)
        says++;
    assert_int_equal(says, 4);
    free(text);
}

/* base64 of the page back to bytes (the alphabet of report_html.c). */
static unsigned char *
unbase64(const char *s, size_t n, size_t *len)
{
    unsigned char *o = malloc(n / 4 * 3 + 3);
    size_t k = 0;
    unsigned v = 0;
    int bits = 0;
    for (size_t i = 0; i < n && s[i] != '='; i++) {
        const char *tab =
            "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        const char *p = strchr(tab, s[i]);
        assert_non_null(p);
        v = v << 6 | (unsigned)(p - tab);
        bits += 6;
        if (bits >= 8) {
            bits -= 8;
            o[k++] = (unsigned char)(v >> bits);
        }
    }
    *len = k;
    return o;
}

static void
test_page_embeds_linear_values(void **state)
{
    (void)state;
    /* HDR values over five decades: the page's RGBE holds each to 2^-8 of the pixel's
     * largest channel */
    const char *ref = scratch("hdr_ref.exr"), *test = scratch("hdr_test.exr"),
               *dir = scratch("hdr_page");
    mcp_image *t = mcp_test_random(20, 12, 3, 0.0f, 1.0f, 7, RGB);
    for (size_t i = 0; i < 20 * 12 * 3; i++)
        t->data[i] = powf(10.0f, -3.0f + 5.0f * t->data[i]);
    mcp_image *r = mcp_test_constant(20, 12, 3, 1.0f, RGB);
    assert_int_equal(mcp_image_write(t, test, NULL), 0);
    assert_int_equal(mcp_image_write(r, ref, NULL), 0);
    assert_int_equal(
        run("compare '%s' '%s' -o '%s' --quiet --exposure -1.5 --display aces", ref, test,
            dir),
        0);
    char path[4400];
    snprintf(path, sizeof path, "%s/report.html", dir);
    char *html = mcp_test_read_text(path);
    /* the display starts where --exposure and --display say */
    assert_non_null(strstr(html,
                           "class=\"dsp-exp\" type=\"range\" min=\"-10\" max=\"10\" "
                           "step=\"0.25\" value=\"-1.5\""));
    assert_non_null(strstr(html, "<option value=\"aces\" selected>"));
    /* the first HDR image is the test */
    const char *at = strstr(html, "data-hdr=\"");
    assert_non_null(at);
    at += strlen("data-hdr=\"");
    int w = 0, h = 0, used = 0;
    assert_int_equal(sscanf(at, "%d,%d,%n", &w, &h, &used), 2);
    assert_int_equal(w, 20);
    assert_int_equal(h, 12);
    at += used;
    size_t len = 0;
    unsigned char *rgbe = unbase64(at, strcspn(at, "\""), &len);
    assert_int_equal(len, 4 * 20 * 12);
    double worst = 0;
    for (int p = 0; p < 20 * 12; p++) {
        const unsigned char *q = rgbe + 4 * p;
        double f = ldexp(1.0, q[3] - 136), m = 0;
        for (int c = 0; c < 3; c++)
            m = fmax(m, t->data[3 * p + c]);
        for (int c = 0; c < 3; c++) {
            double back = q[3] ? (q[c] + 0.5) * f : 0;
            worst = fmax(worst, fabs(back - t->data[3 * p + c]) / m);
        }
    }
    assert_true(worst <= 1.0 / 256);
    free(rgbe);
    free(html);
    /* the EXR beside the page holds the render as it was */
    mcp_image *back = NULL;
    snprintf(path, sizeof path, "%s/test.exr", dir);
    assert_int_equal(mcp_image_read(path, NULL, &back), 0);
    assert_int_equal(back->width * back->height, 20 * 12);
    for (int p = 0; p < 20 * 12; p++) /* as written: half floats at worst (2^-11) */
        for (int c = 0; c < 3; c++)
            assert_close(mcp_image_px(back, p % 20, p / 20)[c], t->data[3 * p + c], 1e-3,
                         0);
    mcp_image_free(back);
    mcp_image_free(t);
    mcp_image_free(r);
}

static void
test_errors(void **state)
{
    (void)state;
    const char *ref = scratch("e_ref.exr"), *dir = scratch("e_page");
    mcp_image *r = mcp_test_constant(8, 8, 3, 0.5f, RGB);
    mcp_image *small = mcp_test_constant(4, 8, 3, 0.5f, RGB);
    const char *small_path = scratch("e_small.exr");
    assert_int_equal(mcp_image_write(r, ref, NULL), 0);
    assert_int_equal(mcp_image_write(small, small_path, NULL), 0);
    /* usage errors: exit 2, nothing written */
    assert_int_equal(run("compare '%s' -o '%s'", ref, dir), 2);
    assert_non_null(strstr(err, "give REF and at least one TEST"));
    assert_int_equal(run("compare '%s' '%s' -o '%s' --display sepia", ref, ref, dir), 2);
    assert_non_null(strstr(err, "unknown display 'sepia'"));
    assert_int_equal(run("compare '%s' '%s' -o '%s' --fail 'no_such > 1'", ref, ref, dir),
                     2);
    assert_non_null(strstr(err, "no figure 'no_such'"));
    /* a test of another size, found after the reference is read: one line, no folder */
    assert_int_equal(
        run("compare '%s' '%s' '%s' -o '%s' --quiet", ref, ref, small_path, dir), 1);
    assert_non_null(strstr(err, "does not match"));
    assert_non_null(strstr(err, "e_small.exr"));
    assert_ptr_equal(strchr(err, '\n'), err + strlen(err) - 1);
    assert_false(exists(dir));
    mcp_image_free(r);
    mcp_image_free(small);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_figures_and_gates),
        cmocka_unit_test(test_page_embeds_linear_values),
        cmocka_unit_test(test_identical_maps_and_histograms),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
