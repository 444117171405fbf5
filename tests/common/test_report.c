/* test_report.c: common/report/report.c (JSON sections, tables, plots, the self-contained
 * HTML page) and common/report/plot.c (SVG plots with linear, log and logit axes). */
#include "testing.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mcpost/imageio.h>
#include <mcpost/plot.h>
#include <mcpost/report.h>
#include "../../common/report/internal.h"

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
    /* nested objects are nested tables, not "a.b" rows or JSON text */
    assert_non_null(strstr(html, "<th>flip_hdr</th><td><table class=\"kv\"><tr><th>mean"
                                 "</th><td class=\"num\">0.0625</td></tr></table></td>"));
    assert_non_null(strstr(html, "<th>mse</th><td class=\"num\">0.125</td>"));
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
    assert_int_equal(count(html, "<script"), 1); /* the inline comparison script */
    assert_null(strstr(html, "<link"));
    /* the 2x2 PNG is shown at 160x its size (a whole factor up to 320 px) */
    assert_non_null(strstr(html, "alt=\"maps/tiny.png\" width=\"320\" height=\"320\""));
    free(html);
    snprintf(path, sizeof path, "%s/report.json", dir);
    char *json = mcp_test_read_text(path);
    cJSON *doc = cJSON_Parse(json);
    assert_non_null(doc);
    assert_int_equal(cJSON_GetArraySize(cJSON_GetObjectItem(doc, "sections")), 2);
    cJSON_Delete(doc);
    free(json);
}

/* What issue 17 asked of the page: lists and objects as tables and lists, maps with
 * their colour bar, a verdict first, and a comparison of same-size images. */
static void
test_html_values_maps_verdicts(void **state)
{
    (void)state;
    const char *dir = mcp_test_path("report2");
    char cmd[4200], path[4200];
    snprintf(cmd, sizeof cmd, "mkdir -p '%s'", dir);
    assert_int_equal(system(cmd), 0);
    unsigned char rgb[4 * 2 * 3] = {0};
    const char *names[3] = {"a.png", "b.png", "map.png"};
    for (int i = 0; i < 3; i++) {
        snprintf(path, sizeof path, "%s/%s", dir, names[i]);
        assert_int_equal(mcp_write_rgb8(rgb, 4, 2, path), 0);
    }
    mcp_report *r = NULL;
    assert_int_equal(mcp_report_new("values", &r), 0);
    cJSON *s = mcp_report_section(r, "info", "lists");
    cJSON *chans = cJSON_AddArrayToObject(s, "channels");
    cJSON *c0 = cJSON_CreateObject(), *c1 = cJSON_CreateObject();
    cJSON_AddStringToObject(c0, "name", "R");
    cJSON_AddNumberToObject(c0, "min", 0.5);
    cJSON_AddStringToObject(c1, "name", "G");
    cJSON_AddNumberToObject(c1, "nan", 3); /* a key only the second one has */
    cJSON_AddItemToArray(chans, c0);
    cJSON_AddItemToArray(chans, c1);
    cJSON *outs = cJSON_AddArrayToObject(s, "outputs");
    cJSON_AddItemToArray(outs, cJSON_CreateString("/a/long/path/to/some/output.exr"));
    cJSON_AddItemToArray(outs, cJSON_CreateString("/a/long/path/to/another/one.exr"));
    cJSON *spp = cJSON_AddArrayToObject(s, "spp");
    cJSON_AddItemToArray(spp, cJSON_CreateNumber(1));
    cJSON_AddItemToArray(spp, cJSON_CreateNumber(2));
    cJSON_AddArrayToObject(s, "empty");
    /* an object of records (the blend's final errors per method): one table */
    cJSON *fin = cJSON_AddObjectToObject(s, "final");
    cJSON_AddNumberToObject(fin, "spp", 1024);
    cJSON_AddNumberToObject(cJSON_AddObjectToObject(fin, "noisy"), "mse", 0.5);
    cJSON_AddNumberToObject(cJSON_AddObjectToObject(fin, "curves"), "mse", 0.25);
    assert_int_equal(mcp_report_set_verdict(s, MCP_VERDICT_BAD, "first %d", 1), 0);
    assert_int_equal(mcp_report_set_verdict(s, MCP_VERDICT_GOOD, "stop: yes, %g%%", 99.9),
                     0);
    cJSON *s2 = mcp_report_section(r, "estimate", "maps");
    assert_int_equal(mcp_report_add_image(s2, "a.png", "noisy"), 0);
    cJSON *map = mcp_report_add_map(s2, "map.png", "error", MCP_COLORMAP_GRAY, 1e-5, 1.0,
                                    MCP_AXIS_LOG, "relative error");
    assert_non_null(map);
    assert_int_equal(mcp_report_map_add_mark(map, 0.01, "tau"), 0);
    assert_int_equal(mcp_report_add_image(s2, "b.png", "reference"), 0);
    assert_non_null(mcp_report_add_map(s2, "map.png", "linear", MCP_COLORMAP_GRAY, 0.0,
                                       2.0, MCP_AXIS_LINEAR, NULL));
    assert_null(mcp_report_add_map(s2, "map.png", "bad", MCP_COLORMAP_GRAY, 0.0, 1.0,
                                   MCP_AXIS_LOG, "x"));
    assert_non_null(strstr(mcp_error_message(), "report: map 'map.png'"));
    assert_null(mcp_report_add_map(s2, "map.png", "bad", MCP_COLORMAP_GRAY, 1.0, 1.0,
                                   MCP_AXIS_LINEAR, "x"));
    assert_error_contains(mcp_report_map_add_mark(s2, 1.0, "x"), "report: not a map");
    mcp_error_clear();

    /* the JSON: the verdict replaced, the scale with its mark */
    const cJSON *v = cJSON_GetObjectItem(s, "verdict");
    assert_string_equal(cJSON_GetObjectItem(v, "level")->valuestring, "good");
    assert_string_equal(cJSON_GetObjectItem(v, "text")->valuestring, "stop: yes, 99.9%");
    const cJSON *sc = cJSON_GetObjectItem(map, "scale");
    assert_string_equal(cJSON_GetObjectItem(sc, "colormap")->valuestring, "gray");
    assert_string_equal(cJSON_GetObjectItem(sc, "axis")->valuestring, "log");
    assert_float_equal(cJSON_GetObjectItem(sc, "min")->valuedouble, 1e-5, 0);
    assert_int_equal(cJSON_GetArraySize(cJSON_GetObjectItem(sc, "marks")), 1);

    char *html = NULL;
    assert_int_equal(mcp_report_html(r, dir, &html), 0);
    /* the verdict comes right after the heading */
    assert_non_null(
        strstr(html, "</h2>\n<p class=\"verdict good\">stop: yes, 99.9%</p>"));
    assert_null(strstr(html, "first 1"));
    /* a list of objects: one table, a column for every key any of them has */
    assert_non_null(strstr(html, "<tr><th>name</th><th>min</th><th>nan</th></tr>"));
    assert_non_null(strstr(html, "<tr><td>G</td><td></td><td class=\"num\">3</td></tr>"));
    /* long strings: a list; short numbers: one line; nothing: "none" */
    assert_non_null(strstr(html, "<ul class=\"list\"><li>/a/long/path/to/some/output.exr"
                                 "</li><li>"));
    assert_non_null(strstr(html, "<th>spp</th><td>1, 2</td>"));
    assert_non_null(strstr(html, "<th>empty</th><td><span class=\"dim\">none</span>"));
    assert_non_null(strstr(html,
                           "<tr><th>spp</th><td class=\"num\">1024</td></tr></table>"
                           "<div class=\"scroll\"><table class=\"data nested\"><tr><th>"
                           "</th><th>mse</th></tr>\n<tr><td>noisy</td><td class=\"num\">"
                           "0.5</td></tr>\n<tr><td>curves</td>"));
    assert_null(strstr(html, "[{"));
    assert_null(strstr(html, "{&quot;"));
    /* the colour bar: gray runs from black to white; decades 10^-5 ... 1 at every 20%;
     * tau = 0.01 sits at (log10(0.01) + 5) / 5 = 60% */
    assert_non_null(strstr(html, "linear-gradient(to right,#000000 0.0%,"));
    assert_non_null(strstr(html, ",#ffffff 100.0%)"));
    assert_non_null(strstr(
        html, "<span class=\"first\" style=\"left:0.00%\">10<sup>-5</sup></span>"));
    assert_non_null(
        strstr(html, "<span class=\"mid\" style=\"left:60.00%\">10<sup>-2</sup></span>"));
    assert_non_null(strstr(html, "<span class=\"last\" style=\"left:100.00%\">1</span>"));
    assert_non_null(strstr(html, "<i class=\"mark\" style=\"left:60.00%\"></i>"));
    assert_non_null(strstr(html, "&#9650; tau = 0.01"));
    assert_non_null(strstr(html, "<div class=\"unit\">relative error</div>"));
    /* the linear map: 0, 0.5, 1, 1.5, 2 */
    assert_non_null(strstr(html, "<span class=\"mid\" style=\"left:75.00%\">1.5</span>"));
    assert_int_equal(count(html, "class=\"cbar\""), 2);
    /* the comparison: the four 4x2 images, left the first photo, right the last one;
     * shown 160x (640 px across) */
    assert_int_equal(count(html, "class=\"compare\" hidden"), 1);
    assert_non_null(strstr(html, "<option value=\"im1_0\" selected>noisy</option>"));
    assert_non_null(strstr(html, "<option value=\"im1_2\" selected>reference</option>"));
    assert_non_null(strstr(html, "style=\"width:640px;aspect-ratio:4/2\""));
    assert_non_null(strstr(html,
                           "id=\"im1_1\" class=\"px\" alt=\"map.png\" width=\"320\" "
                           "height=\"160\""));
    free(html);
    mcp_report_free(r);
}

/* A map whose picture holds one value in every pixel says the value across it, with a
 * mark on its colour bar; a map of log10 values reports 10^v (and 0 for -30); a map
 * with two values is left alone. */
static void
test_one_value_map(void **state)
{
    (void)state;
    const char *dir = mcp_test_path("report_flat");
    char cmd[4200], path[4200];
    snprintf(cmd, sizeof cmd, "mkdir -p '%s'", dir);
    assert_int_equal(system(cmd), 0);
    unsigned char rgb[4 * 2 * 3] = {0};
    snprintf(path, sizeof path, "%s/map.png", dir);
    assert_int_equal(mcp_write_rgb8(rgb, 4, 2, path), 0);
    mcp_image *flat = mcp_test_constant(4, 2, 2, 0.25f, NULL);
    mcp_image *log_zero = mcp_test_constant(4, 2, 1, -30.0f, NULL);
    mcp_image *log_tenth = mcp_test_constant(4, 2, 1, -1.0f, NULL);
    mcp_image *ramp = mcp_test_ramp(4, 2, 1, NULL);
    assert_non_null(flat), assert_non_null(log_zero), assert_non_null(log_tenth);
    assert_non_null(ramp);
    flat->data[1] = 7.0f; /* channel 1 varies; channel 0 is 0.25 everywhere */
    mcp_report *r = NULL;
    assert_int_equal(mcp_report_new("flat", &r), 0);
    cJSON *s = mcp_report_section(r, "metrics", "maps");
    /* a linear scale to a percentile's value: ticks of three digits */
    assert_non_null(mcp_report_add_map(s, "map.png", "ticks", MCP_COLORMAP_MAGMA, 0.0,
                                       14.2949, MCP_AXIS_LINEAR, NULL));
    cJSON *m[5];
    for (int i = 0; i < 5; i++) {
        m[i] = mcp_report_add_map(
            s, "map.png", "a map", MCP_COLORMAP_MAGMA, i == 2 || i == 3 ? 1e-5 : 0.0, 1.0,
            i == 2 || i == 3 ? MCP_AXIS_LOG : MCP_AXIS_LINEAR, NULL);
        assert_non_null(m[i]);
    }
    assert_int_equal(mcp__report_map_one_value(m[0], flat, 0, 0, 1.0), 0);
    assert_int_equal(mcp__report_map_one_value(m[1], flat, 1, 0, 1.0), 0);
    assert_int_equal(mcp__report_map_one_value(m[2], log_zero, 0, 1, 1.0), 0);
    assert_int_equal(mcp__report_map_one_value(m[3], log_tenth, 0, 1, 1.0), 0);
    /* a sampling map's weights in multiples of the mean: 8 pixels of 1/8 read 1 */
    mcp_image *weights = mcp_test_constant(4, 2, 1, 0.125f, NULL);
    assert_int_equal(mcp__report_map_one_value(m[4], weights, 0, 0, 8.0), 0);
    const double want[5] = {0.25, NAN, 0.0, 0.1, 1.0};
    for (int i = 0; i < 5; i++) {
        const cJSON *v =
            cJSON_GetObjectItem(cJSON_GetObjectItem(m[i], "scale"), "one_value");
        if (isnan(want[i])) {
            assert_null(v);
        } else {
            assert_true(cJSON_IsNumber(v));
            assert_close(v->valuedouble, want[i], 1e-6, 0);
        }
    }
    assert_int_equal(mcp__report_map_one_value(m[1], ramp, 0, 0, 1.0), 0);
    assert_null(cJSON_GetObjectItem(cJSON_GetObjectItem(m[1], "scale"), "one_value"));
    char *html = NULL;
    assert_int_equal(mcp_report_html(r, dir, &html), 0);
    /* four maps say their value across the picture; every map keeps its colour bar */
    assert_int_equal(count(html, "class=\"onevalue\""), 4);
    assert_non_null(strstr(html, "one value in every pixel: 0.25<br>no map to show"));
    assert_non_null(strstr(html, "one value in every pixel: 0.1<br>"));
    assert_non_null(strstr(html, "one value in every pixel: 1<br>"));
    assert_int_equal(count(html, "class=\"cbar\""), 6);
    assert_non_null(strstr(html, "style=\"left:75.00%\">10.7</span>"));
    assert_non_null(strstr(html, "style=\"left:100.00%\">14.3</span>"));
    /* the mark: 0.25 on the linear 0..1 bar at 25%; 0.1 on the log bar 1e-5..1 at 80% */
    assert_non_null(strstr(html, "<i class=\"mark\" style=\"left:25.00%\"></i>"));
    assert_non_null(strstr(html, "<i class=\"mark\" style=\"left:80.00%\"></i>"));
    assert_non_null(strstr(html, "&#9650; every pixel = 0.25"));
    free(html);
    mcp_report_free(r);
    mcp_image_free(flat), mcp_image_free(log_zero), mcp_image_free(log_tenth);
    mcp_image_free(ramp), mcp_image_free(weights);
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

/* Bars (histograms): each bar centred on its x and as wide as the gap between the
 * x's, standing on y = 0, its height proportional to y; a zero bar is not drawn; the
 * translucent fill lets a second series' bars show through. */
static void
test_plot_bars(void **state)
{
    (void)state;
    const double x[3] = {0.25, 0.5, 0.75}, y[3] = {2, 0, 4};
    mcp_plot_series s[2] = {{"a", MCP_SERIES_BARS, x, y, 3, 0},
                            {"b", MCP_SERIES_BARS, x, y, 3, 0}};
    mcp_plot plot = {"h", "x", "y", MCP_AXIS_LINEAR, MCP_AXIS_LINEAR, s, 2, 0, 0};
    char *svg = NULL;
    assert_int_equal(mcp_plot_svg(&plot, &svg), 0);
    const char *g = strstr(svg, "fill-opacity=\"0.45\"");
    assert_non_null(g);
    double bx[2], by[2], bw[2], bh[2];
    const char *r = g;
    for (int i = 0; i < 2; i++) {
        r = strstr(r, "<rect x=");
        assert_non_null(r);
        assert_int_equal(sscanf(r,
                                "<rect x=\"%lf\" y=\"%lf\" width=\"%lf\" height=\"%lf\"",
                                &bx[i], &by[i], &bw[i], &bh[i]),
                         4);
        r++;
    }
    assert_close(bw[0], bw[1], 0, 0.011);                 /* both 0.25 wide */
    assert_close(bx[1] - bx[0], 2 * bw[0], 0, 0.011);     /* centres 0.5 apart */
    assert_close(bh[1], 2 * bh[0], 0, 0.011);             /* 4 against 2 */
    assert_close(by[0] + bh[0], by[1] + bh[1], 0, 0.011); /* one foot: y = 0 */
    assert_int_equal(count(svg, "fill-opacity=\"0.45\" stroke="),
                     2 + 2); /* groups, legend */
    mcp_series_style st;
    assert_int_equal(mcp_series_style_from_name("bars", &st), 0);
    assert_int_equal(st, MCP_SERIES_BARS);
    assert_string_equal(mcp_series_style_name(MCP_SERIES_BARS), "bars");
    free(svg);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_sections_tables_plots_json),
        cmocka_unit_test(test_html_self_contained),
        cmocka_unit_test(test_html_values_maps_verdicts),
        cmocka_unit_test(test_one_value_map),
        cmocka_unit_test(test_plot_axes),
        cmocka_unit_test(test_plot_bars),
    };
    return cmocka_run_group_tests_name("common/report", tests, NULL, NULL);
}
