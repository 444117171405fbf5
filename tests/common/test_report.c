/* test_report.c: common/report.c (JSON sections, tables, plots, the self-contained
 * HTML page) and common/plot.c (SVG plots with linear, log and logit axes). */
#include "testing.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mcpost/imageio.h>
#include <mcpost/plot.h>
#include <mcpost/report.h>

static int
count(const char *hay, const char *needle)
{
    int n = 0;
    for (const char *p = hay; (p = strstr(p, needle)); p += strlen(needle))
        n++;
    return n;
}

static void
test_sections_tables_plots_json(void **state)
{
    (void)state;
    mcp_report *r = NULL;
    assert_int_equal(mcp_report_new("a run", &r), 0);
    cJSON *s = mcp_report_section(r, "metrics", "noisy vs reference");
    assert_non_null(s);
    cJSON_AddNumberToObject(s, "mse", 0.25);
    cJSON *t =
        mcp_report_add_table(s, "errors", (const char *const[]){"name", "spp", "mse"}, 3);
    assert_non_null(t);
    assert_int_equal(mcp_report_table_add_row(t, "sid", "cornell", 16, 0.5), 0);
    assert_int_equal(mcp_report_table_add_row(t, "sid", NULL, 32, INFINITY), 0);
    assert_int_equal(mcp_report_table_add_row(t, "sid", "x", 64, NAN), 0);
    assert_error_contains(
        mcp_report_table_add_row(t, "sd", "x", 1.0),
        "report: table 'errors' has 3 columns, row format 'sd' gives 2");
    assert_error_contains(mcp_report_table_add_row(t, "sxd", "x", 1, 1.0),
                          "report: bad row format letter 'x'");
    cJSON *p = mcp_report_add_plot(s, "curve", "spp", MCP_AXIS_LOG, "MSE", MCP_AXIS_LOG);
    assert_non_null(p);
    const double x[3] = {1, 2, 4}, y[3] = {1, 0.5, NAN};
    cJSON *ser = mcp_report_plot_add_series(p, "true", MCP_SERIES_LINE_POINTS, x, y, 3);
    assert_non_null(ser);
    assert_int_equal(mcp_report_series_set_dashed(ser, 1), 0);

    char *text = cJSON_PrintUnformatted(mcp_report_json(r));
    cJSON *back = cJSON_Parse(text);
    assert_non_null(back);
    const cJSON *sec = cJSON_GetArrayItem(cJSON_GetObjectItem(back, "sections"), 0);
    assert_string_equal(cJSON_GetObjectItem(sec, "stage")->valuestring, "metrics");
    const cJSON *rows = cJSON_GetObjectItem(
        cJSON_GetArrayItem(cJSON_GetObjectItem(sec, "tables"), 0), "rows");
    assert_int_equal(cJSON_GetArraySize(rows), 3);
    assert_true(cJSON_IsNull(cJSON_GetArrayItem(cJSON_GetArrayItem(rows, 1), 0)));
    assert_string_equal(cJSON_GetArrayItem(cJSON_GetArrayItem(rows, 1), 2)->valuestring,
                        "inf");
    assert_true(cJSON_IsNull(cJSON_GetArrayItem(cJSON_GetArrayItem(rows, 2), 2)));
    const cJSON *plot = cJSON_GetArrayItem(cJSON_GetObjectItem(sec, "plots"), 0);
    assert_string_equal(
        cJSON_GetObjectItem(cJSON_GetObjectItem(plot, "x"), "scale")->valuestring, "log");
    const cJSON *s0 = cJSON_GetArrayItem(cJSON_GetObjectItem(plot, "series"), 0);
    assert_true(cJSON_IsTrue(cJSON_GetObjectItem(s0, "dashed")));
    assert_string_equal(cJSON_GetObjectItem(s0, "style")->valuestring, "line+points");
    assert_true(cJSON_IsNull(cJSON_GetArrayItem(cJSON_GetObjectItem(s0, "y"), 2)));
    cJSON_Delete(back);
    free(text);
    mcp_report_free(r);
}

static void
test_html_self_contained(void **state)
{
    (void)state;
    const char *dir = mcp_test_path("report1");
    char cmd[4200];
    snprintf(cmd, sizeof cmd, "mkdir -p '%s/maps'", dir);
    assert_int_equal(system(cmd), 0);
    /* A real PNG, a fake ".png" whose bytes we know, and an EXR. */
    unsigned char rgb[2 * 2 * 3] = {255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255};
    char path[4200];
    snprintf(path, sizeof path, "%s/maps/tiny.png", dir);
    assert_int_equal(mcp_write_rgb8(rgb, 2, 2, path), 0);
    snprintf(path, sizeof path, "%s/abc.png", dir);
    mcp_test_write_text(path, "abcd");
    mcp_image *img =
        mcp_test_constant(2, 2, 3, 0.5f, (const char *const[]){"R", "G", "B"});
    snprintf(path, sizeof path, "%s/map.exr", dir);
    assert_int_equal(mcp_image_write(img, path, NULL), 0);
    mcp_image_free(img);

    mcp_report *r = NULL;
    assert_int_equal(mcp_report_new("Title <&>", &r), 0);
    cJSON *s = mcp_report_section(r, "metrics", "first");
    cJSON_AddNumberToObject(s, "mse", 0.125);
    cJSON_AddStringToObject(s, "psnr", "inf");
    cJSON *nested = cJSON_AddObjectToObject(s, "flip_hdr");
    cJSON_AddNumberToObject(nested, "mean", 0.0625);
    assert_int_equal(mcp_report_add_image(s, "maps/tiny.png", "a tiny map"), 0);
    assert_int_equal(mcp_report_add_image(s, "abc.png", NULL), 0);
    assert_int_equal(mcp_report_add_image(s, "map.exr", "float map"), 0);
    assert_int_equal(mcp_report_add_image(s, "gone.png", "missing"), 0);
    cJSON *t = mcp_report_add_table(s, "tab", (const char *const[]){"a", "b"}, 2);
    mcp_report_table_add_row(t, "sd", "row<1>", 3.5);
    cJSON *p = mcp_report_add_plot(s, "percentiles", "percentile", MCP_AXIS_LOGIT,
                                   "RelSE", MCP_AXIS_LOG);
    const double px[4] = {0.5, 0.9, 0.99, 0.999}, py[4] = {1e-4, 1e-3, 1e-2, 1e-1};
    mcp_report_plot_add_series(p, "true", MCP_SERIES_LINE, px, py, 4);
    mcp_report_plot_add_series(p, "estimated", MCP_SERIES_LINE, px, py, 4);
    cJSON *s2 = mcp_report_section(r, "other", "second");
    cJSON_AddBoolToObject(s2, "ok", 1);
    assert_int_equal(mcp_report_write(r, dir), 0);
    mcp_report_free(r);

    snprintf(path, sizeof path, "%s/report.html", dir);
    char *html = mcp_test_read_text(path);
    assert_non_null(strstr(html, "<title>Title &lt;&amp;&gt;</title>"));
    assert_non_null(strstr(html, "<style>"));
    assert_non_null(strstr(html, "<th>flip_hdr.mean</th><td>0.0625</td>"));
    assert_non_null(strstr(html, "<th>mse</th><td>0.125</td>"));
    assert_non_null(strstr(html, "<td>row&lt;1&gt;</td>"));
    assert_non_null(strstr(html, "src=\"data:image/png;base64,YWJjZA==\""));
    assert_int_equal(count(html, "src=\"data:image/png;base64,"), 2);
    assert_non_null(strstr(html, "not viewable in a browser: <code>map.exr</code>"));
    assert_non_null(strstr(html, "missing or too large to embed: <code>gone.png</code>"));
    assert_int_equal(count(html, "<svg "), 1);
    assert_non_null(strstr(html, "href=\"#s1\""));
    /* Nothing is fetched: no external src/href (the SVG namespace is not a fetch). */
    assert_null(strstr(html, "src=\"http"));
    assert_null(strstr(html, "href=\"http"));
    assert_null(strstr(html, "<script"));
    assert_null(strstr(html, "<link"));
    free(html);
    snprintf(path, sizeof path, "%s/report.json", dir);
    char *json = mcp_test_read_text(path);
    cJSON *doc = cJSON_Parse(json);
    assert_non_null(doc);
    assert_int_equal(cJSON_GetArraySize(cJSON_GetObjectItem(doc, "sections")), 2);
    cJSON_Delete(doc);
    free(json);
}

static void
test_plot_axes(void **state)
{
    (void)state;
    /* Firmino 2024's error-percentile plot: logit x, log y. */
    const double p[5] = {0.5, 0.9, 0.99, 0.999, 1.0},
                 e[5] = {1e-5, 1e-4, 1e-3, 1e-2, 1e-1};
    mcp_plot_series s = {"true RelSE", MCP_SERIES_LINE, p, e, 5, 0};
    mcp_plot plot = {"percentiles",
                     "percentile",
                     "relative squared error",
                     MCP_AXIS_LOGIT,
                     MCP_AXIS_LOG,
                     &s,
                     1,
                     0,
                     0};
    char *svg = NULL;
    assert_int_equal(mcp_plot_svg(&plot, &svg), 0);
    assert_true(strncmp(svg, "<svg xmlns=\"http://www.w3.org/2000/svg\"", 39) == 0);
    assert_non_null(strstr(svg, ">0.99<"));
    assert_non_null(strstr(svg, ">0.999<"));
    assert_non_null(strstr(svg, ">1e-05<"));
    assert_non_null(strstr(svg, ">0.01<")); /* the p = 1 point (0.1) is left out */
    /* p = 1 cannot be shown on a logit axis: the path has the four other points. */
    const char *d = strstr(svg, "<path");
    assert_non_null(d);
    assert_int_equal(count(d, "L"), 3);
    assert_non_null(strstr(svg, ">true RelSE<"));
    free(svg);

    /* Linear axes: "nice" ticks. */
    const double x[3] = {0, 5, 10}, y[3] = {-1, 0, 1};
    mcp_plot_series s2 = {NULL, MCP_SERIES_SCATTER, x, y, 3, 0};
    mcp_plot lin = {NULL, "x", "y", MCP_AXIS_LINEAR, MCP_AXIS_LINEAR, &s2, 1, 320, 200};
    assert_int_equal(mcp_plot_svg(&lin, &svg), 0);
    assert_int_equal(count(svg, "<circle"), 3);
    assert_non_null(strstr(svg, ">10<"));
    assert_non_null(strstr(svg, ">-1<"));
    free(svg);

    /* Nothing showable on log axes fails with the title. */
    const double neg[2] = {-1, 0};
    mcp_plot_series s3 = {"neg", MCP_SERIES_LINE, neg, neg, 2, 0};
    mcp_plot bad = {"empty", NULL, NULL, MCP_AXIS_LOG, MCP_AXIS_LOG, &s3, 1, 0, 0};
    assert_error_contains(mcp_plot_svg(&bad, &svg),
                          "plot 'empty': no points to show on log/log axes");
    assert_null(svg);
    mcp_axis_scale sc;
    assert_error_contains(mcp_axis_scale_from_name("symlog", &sc),
                          "unknown axis scale 'symlog'");
    assert_close(mcp_logistic(mcp_logit(0.99)), 0.99, 1e-12, 0);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_sections_tables_plots_json),
        cmocka_unit_test(test_html_self_contained),
        cmocka_unit_test(test_plot_axes),
    };
    return cmocka_run_group_tests_name("common/report", tests, NULL, NULL);
}
