/* test_flip_stats.c: FLIP's statistics (common/metrics/flip_stats.c) against closed forms
 * on synthetic error maps, and against NVIDIA's own tool (FLIP v1.6, tool/FLIP-tool.cpp)
 * built here with g++ from MCPOST_FLIP_ANCHOR (a checkout of NVlabs/flip v1.6; the
 * CMake variable of the same name, or the environment at configure time). Without
 * those sources or g++ the comparison is skipped, saying why. */
#define _POSIX_C_SOURCE 200809L /* setenv, popen */
#include "testing.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include <mcpost/flip.h>
#include <mcpost/imageio.h>
#include "../../common/metrics/internal.h"

/* ---- closed forms ---- */

/* Values whose float sums are exact (dyadic, few): the strict "exceeds" rule decides.
 * 0.25, 0.25, 0.5 (shuffled) sum to 1; the running sums in order are 0.25, 0.5, 1.
 * p = 0.5: 0.5 does not exceed 0.5, so the median is the third value, 0.5;
 * p = 0.25: the second value's 0.5 exceeds 0.25 first, so q1 = 0.25; q3 = 0.5. */
static void
test_exact_rule(void **state)
{
    (void)state;
    const float v[3] = {0.5f, 0.25f, 0.25f};
    mcp_flip_stats s;
    assert_int_equal(mcp_flip_statistics(v, 3, &s), 0);
    assert_true(s.weighted_median == 0.5);
    assert_true(s.weighted_q1 == 0.25);
    assert_true(s.weighted_q3 == 0.5);
    assert_true(s.min == 0.25 && s.max == 0.5);
    assert_int_equal(s.pixels, 3);
    /* 0.25 / width(0.01f) = 25.0000006 -> bucket 25; 0.5 -> 50 */
    assert_int_equal(s.histogram[25], 2);
    assert_int_equal(s.histogram[50], 1);
    /* a map of zeros: nothing exceeds 0, so 0 (the tool's initial value) */
    const float z[4] = {0};
    assert_int_equal(mcp_flip_statistics(z, 4, &s), 0);
    assert_true(s.weighted_median == 0.0 && s.max == 0.0 && s.min == 0.0);
    assert_int_equal(s.histogram[0], 4);
    double p;
    assert_int_equal(mcp_flip_weighted_percentile(v, 3, 0.9, &p), 0);
    assert_true(p == 0.5); /* 0.9 is exceeded only by the last sum, 1 */
}

/* Uniform errors on (0, 1): weighted by the error itself, the density is 2v, the
 * cumulative v^2, so the weighted median is sqrt(1/2), the quartiles sqrt(1/4) and
 * sqrt(3/4). n = 200000 values (i + 0.5) / n in a shuffled order: the discrete answer
 * is within 1/n of the continuous one, and the float running sums' rounding (about
 * sqrt(n) ulps of the total, ~1e-5 relative) moves it by less than 1e-4. Each of the
 * 100 buckets holds exactly n/100 values: the grid points sit 2.5e-6 from the edges
 * k * 0.01f, far more than a float's rounding of them. */
static void
test_uniform_closed_form(void **state)
{
    (void)state;
    enum { N = 200000 };
    float *v = malloc(N * sizeof *v);
    assert_non_null(v);
    for (int i = 0; i < N; i++)
        v[i] = (float)((i + 0.5) / N);
    uint64_t seed = 7;
    for (int i = N - 1; i > 0; i--) { /* Fisher-Yates: the order must not matter */
        int j = (int)(mcp_test_rand_u64(&seed) % (uint64_t)(i + 1));
        float t = v[i];
        v[i] = v[j], v[j] = t;
    }
    mcp_flip_stats s;
    assert_int_equal(mcp_flip_statistics(v, N, &s), 0);
    assert_close(s.weighted_median, sqrt(0.5), 0, 1e-4);
    assert_close(s.weighted_q1, 0.5, 0, 1e-4);
    assert_close(s.weighted_q3, sqrt(0.75), 0, 1e-4);
    assert_close(s.min, 0.5 / N, 1e-6, 0);
    assert_close(s.max, 1.0 - 0.5 / N, 0, 1e-7);
    for (int i = 0; i < MCP_FLIP_HISTOGRAM_BUCKETS; i++) {
        assert_int_equal(s.histogram[i], N / 100);
        /* the tool's plot: count * centre / megapixels */
        assert_close(mcp_flip_weighted_bucket(&s, i),
                     (N / 100) * (i + 0.5) / 100.0 / (N / 1048576.0), 1e-12, 0);
    }
    /* the weighted percentile alone agrees with the statistics */
    double p;
    assert_int_equal(mcp_flip_weighted_percentile(v, N, 0.5, &p), 0);
    assert_true(p == s.weighted_median);
    free(v);
}

/* The tool's bucket rule at the edges: 0.01f / 0.01f is bucket 1, 1.0 the last,
 * values outside [0, 1] in none (min and max still see them). */
static void
test_histogram_edges(void **state)
{
    (void)state;
    const float v[5] = {0.0f, 0.01f, 1.0f, 1.5f, -0.25f};
    mcp_flip_stats s;
    assert_int_equal(mcp_flip_statistics(v, 5, &s), 0);
    assert_int_equal(s.histogram[0], 1);
    assert_int_equal(s.histogram[1], 1);
    assert_int_equal(s.histogram[99], 1);
    long long total = 0;
    for (int i = 0; i < MCP_FLIP_HISTOGRAM_BUCKETS; i++)
        total += s.histogram[i];
    assert_int_equal(total, 3);
    assert_true(s.min == -0.25 && s.max == 1.5);
    const float bad[2] = {0.5f, NAN};
    assert_error_contains(mcp_flip_statistics(bad, 2, &s), "value 1 is not finite");
    assert_error_contains(mcp_flip_weighted_percentile(v, 5, 1.5, &(double){0}),
                          "p must be in [0, 1]");
}

/* ---- NVIDIA's tool ---- */

static const char *
anchor_dir(void)
{
    const char *env = getenv("MCPOST_FLIP_ANCHOR");
    return env && *env ? env : NULL;
}

static long
mtime_of(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 ? (long)st.st_mtime : -1;
}

/* The tool built into the scratch folder (kept there between runs, rebuilt when its
 * sources are newer); NULL with *why set when it cannot be. */
static const char *
flip_tool(const char **why)
{
    static char exe[4096], src[4096], hdr[4096], helpers[4096];
    static int state; /* 0 not tried, 1 built, -1 not available */
    static char reason[4400];
    if (state) {
        *why = reason;
        return state > 0 ? exe : NULL;
    }
    state = -1;
    *why = reason;
    if (!anchor_dir()) {
        snprintf(
            reason, sizeof reason,
            "MCPOST_FLIP_ANCHOR is not set (a checkout of NVlabs/flip v1.6; CMake or "
            "the environment)");
        return NULL;
    }
    snprintf(src, sizeof src, "%s/cpp/tool/FLIP-tool.cpp", anchor_dir());
    snprintf(hdr, sizeof hdr, "%s/cpp/FLIP.h", anchor_dir());
    snprintf(helpers, sizeof helpers, "%s/cpp/tool/FLIPToolHelpers.h", anchor_dir());
    snprintf(exe, sizeof exe, "%s", mcp_test_path("nvidia-flip"));
    *why = reason;
    if (mtime_of(src) < 0) {
        snprintf(reason, sizeof reason,
                 "no NVIDIA FLIP sources at %s (set MCPOST_FLIP_ANCHOR, CMake or "
                 "environment, to a copy of NVlabs/flip v1.6 src)",
                 src);
        return NULL;
    }
    if (system("command -v g++ >/dev/null 2>&1") != 0) {
        snprintf(reason, sizeof reason, "no g++ to build NVIDIA's FLIP tool");
        return NULL;
    }
    long built = mtime_of(exe);
    if (built < 0 || built < mtime_of(src) || built < mtime_of(hdr) ||
        built < mtime_of(helpers)) {
        char cmd[13000];
        snprintf(cmd, sizeof cmd,
                 "g++ -O3 -fopenmp -std=c++17 -w -o '%s.tmp' '%s' >'%s.log' 2>&1 && "
                 "mv '%s.tmp' '%s'",
                 exe, src, exe, exe, exe);
        fprintf(stderr, "building NVIDIA's FLIP tool (about a minute): %s\n", src);
        if (system(cmd) != 0) {
            snprintf(reason, sizeof reason, "g++ could not build %s (see %s.log)", src,
                     exe);
            fail_msg("%s", reason);
        }
    }
    state = 1;
    return exe;
}

/* The numbers of the last line of the tool's --csv output: mean, weighted median,
 * 1st and 3rd weighted quartile, min, max (six decimals). */
static void
read_tool_csv(const char *path, double out[6])
{
    char *text = mcp_test_read_text(path);
    char *line = strrchr(text, '\n');
    while (line && line > text && line[1] == '\0') { /* the last non-empty line */
        *line = '\0';
        line = strrchr(text, '\n');
    }
    line = line ? line + 1 : text;
    /* "ref","test","mean","median","q1","q3","min","max","time" */
    char *f = line;
    for (int field = 0; field < 8; field++) {
        f = strchr(f, '"');
        assert_non_null(f);
        f++;
        char *end = strchr(f, '"');
        assert_non_null(end);
        if (field >= 2) out[field - 2] = strtod(f, NULL);
        f = end + 1;
        if (*f == ',') f++;
    }
    free(text);
}

/* dataFLIP = [c0, c1, ...] of the tool's weighted-histogram script. */
static void
read_tool_counts(const char *path, long long counts[MCP_FLIP_HISTOGRAM_BUCKETS])
{
    char *text = mcp_test_read_text(path);
    char *p = strstr(text, "dataFLIP = [");
    assert_non_null(p);
    p += strlen("dataFLIP = [");
    for (int i = 0; i < MCP_FLIP_HISTOGRAM_BUCKETS; i++) {
        char *end;
        counts[i] = strtoll(p, &end, 10);
        assert_true(end != p);
        p = end + strspn(end, ", ");
    }
    free(text);
}

/* One pair through the tool and through mcp_flip_*: the six numbers agree within
 * 1e-5 (per-pixel values agree within 1e-4 by docs/flip.md, in practice ~1e-6, and the
 * tool prints six decimals); the bucket counts differ only by pixels that sit within 1e-5
 * of a bucket edge, where the two builds' last-bit differences may put them apart. */
static void
compare_with_tool(const char *tool, const char *test_path, const char *ref_path, int hdr)
{
    const char *dir = mcp_test_path("tool-out");
    char cmd[20000], csv[4200];
    snprintf(csv, sizeof csv, "%s/pooled.csv", dir);
    snprintf(
        cmd, sizeof cmd,
        "rm -rf '%s' && mkdir -p '%s' && cd '%s' && '%s' -r '%s' -t '%s' -nerm -nexm "
        "-v 0 -hist -c '%s' >tool.log 2>&1",
        dir, dir, dir, tool, ref_path, test_path, csv);
    assert_int_equal(system(cmd), 0);
    double want[6];
    read_tool_csv(csv, want);
    char py[4300];
    snprintf(cmd, sizeof cmd, "ls '%s'/weighted_histogram.*.py", dir);
    FILE *ls = popen(cmd, "r");
    assert_non_null(ls);
    assert_non_null(fgets(py, sizeof py, ls));
    pclose(ls);
    py[strcspn(py, "\n")] = '\0';
    long long counts[MCP_FLIP_HISTOGRAM_BUCKETS];
    read_tool_counts(py, counts);

    mcp_image *test = NULL, *ref = NULL, *map = NULL;
    assert_int_equal(mcp_image_read(test_path, NULL, &test), 0);
    assert_int_equal(mcp_image_read(ref_path, NULL, &ref), 0);
    mcp_flip_result r;
    mcp_flip_options o = mcp_flip_defaults();
    if (hdr)
        assert_int_equal(mcp_flip_hdr(test, ref, &o, &r, &map, NULL), 0);
    else
        assert_int_equal(mcp_flip_ldr(test, ref, &o, &r, &map), 0);
    const mcp_flip_stats *s = &r.stats;
    const double got[6] = {
        r.mean, s->weighted_median, s->weighted_q1, s->weighted_q3, s->min, s->max};
    static const char *const names[6] = {"mean",
                                         "weighted median",
                                         "1st weighted quartile",
                                         "3rd weighted quartile",
                                         "min",
                                         "max"};
    for (int k = 0; k < 6; k++) {
        printf("  %-22s tool %.6f  mcpost %.8f\n", names[k], want[k], got[k]);
        assert_close(got[k], want[k], 0, 1e-5);
    }
    long long moved = 0, near_edge = 0, total = 0;
    size_t n = (size_t)map->width * map->height;
    for (int i = 0; i < MCP_FLIP_HISTOGRAM_BUCKETS; i++) {
        moved += llabs(counts[i] - s->histogram[i]);
        total += counts[i];
    }
    for (size_t j = 0; j < n; j++) {
        double b = map->data[j] / (double)0.01f;
        near_edge += fabs(b - floor(b + 0.5)) * 0.01 < 1e-5;
    }
    printf("  histogram: %lld pixels, %lld counted apart, %lld within 1e-5 of an edge\n",
           total, moved, near_edge);
    assert_int_equal(total, (long long)n);
    assert_true(moved <= 2 * near_edge);
    mcp_image_free(map);
    mcp_image_free(test);
    mcp_image_free(ref);
}

static void
test_against_nvidia_tool(void **state)
{
    (void)state;
    const char *why = NULL, *tool = flip_tool(&why);
    if (!tool) {
        printf("skipped: %s\n", why);
        skip();
    }
    const char *fx = MCP_TEST_SOURCE_DIR "/samples/fixtures/cornell";
    char test[4096], ref[4096];
    /* HDR-FLIP: the tool takes an .exr reference as HDR */
    snprintf(test, sizeof test, "%s/series/cornell_spp0016.exr", fx);
    snprintf(ref, sizeof ref, "%s/cornell_reference.exr", fx);
    compare_with_tool(tool, test, ref, 1);
    /* LDR-FLIP: 8-bit sRGB PNGs of a render and the reference, which both sides
     * decode to linear */
    mcp_image *a = NULL, *b = NULL;
    snprintf(test, sizeof test, "%s/series/cornell_spp0004.exr", fx);
    assert_int_equal(mcp_image_read(test, NULL, &a), 0);
    assert_int_equal(mcp_image_read(ref, NULL, &b), 0);
    snprintf(test, sizeof test, "%s", mcp_test_path("spp0004.png"));
    snprintf(ref, sizeof ref, "%s", mcp_test_path("reference.png"));
    mcp_image *rgb_a = NULL, *rgb_b = NULL;
    int ca[3], cb[3];
    assert_int_equal(mcp_rgb_channels(a, ca) || mcp_rgb_channels(b, cb), 0);
    assert_int_equal(mcp_image_copy_channels(a, ca, 3, &rgb_a), 0);
    assert_int_equal(mcp_image_copy_channels(b, cb, 3, &rgb_b), 0);
    assert_int_equal(mcp_image_write(rgb_a, test, NULL), 0);
    assert_int_equal(mcp_image_write(rgb_b, ref, NULL), 0);
    mcp_image_free(rgb_a);
    mcp_image_free(rgb_b);
    mcp_image_free(a);
    mcp_image_free(b);
    compare_with_tool(tool, test, ref, 0);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_exact_rule),
        cmocka_unit_test(test_uniform_closed_form),
        cmocka_unit_test(test_histogram_edges),
        cmocka_unit_test(test_against_nvidia_tool),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
