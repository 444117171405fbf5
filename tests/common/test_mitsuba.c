/* test_mitsuba.c: the EXR layouts that Mitsuba 3's moment integrator and pbrt-v4's
 * GBufferFilm write, made from known per-sample data, read unaided: the mean, the
 * variance of the mean against the truth computed in RGB from the same samples, the
 * albedo and normal, and the variance source. */
#include "testing.h"

#include <mcpost/dump.h>
#include <mcpost/imageio.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define W 8
#define H 6
#define SPP 64

/* Mitsuba 3's sRGB <-> XYZ pair (srgb_to_xyz and its inverse). */
static const double TO_XYZ[3][3] = {{0.412453, 0.357580, 0.180423},
                                    {0.212671, 0.715160, 0.072169},
                                    {0.019334, 0.119193, 0.950227}};
static const double TO_RGB[3][3] = {{3.240479, -1.537150, -0.498535},
                                    {-0.969256, 1.875991, 0.041556},
                                    {0.055648, -0.204043, 1.057311}};

static uint64_t rng_state;

static double
uniform(void)
{
    rng_state = rng_state * 6364136223846793005ULL + 1442695040888963407ULL;
    return (double)(rng_state >> 11) / 9007199254740992.0;
}

/* Per-pixel truth from the samples, in RGB. */
typedef struct truth {
    double mean[H][W][3];  /* RGB mean */
    double var[H][W][3];   /* per-sample RGB variance / n */
    double bound[H][W][3]; /* (sum_j |M_rj| sd_j)^2 / n */
    double xyz[H][W][3];   /* XYZ mean */
    double m2[H][W][3];    /* XYZ second moment */
    double var_y[H][W];    /* variance of the mean of luminance Y */
} truth;

/* Samples of an RGB path tracer: mixed = 0: one colour per pixel times a random
 * brightness (shared chromaticity); mixed = 1: each sample one of two unrelated
 * colours (chromaticity varies). */
static void
make_samples(truth *t, int mixed, uint64_t seed)
{
    rng_state = seed;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            double c0[3], c1[3], s[SPP][3];
            for (int k = 0; k < 3; k++)
                c0[k] = 0.05 + uniform(), c1[k] = 0.05 + uniform();
            for (int i = 0; i < SPP; i++) {
                double b = -log(1 - uniform()); /* heavy-ish brightness */
                const double *c = mixed && uniform() < 0.5 ? c1 : c0;
                for (int k = 0; k < 3; k++)
                    s[i][k] = b * c[k];
            }
            double mr[3] = {0}, mx[3] = {0}, m2[3] = {0}, my = 0;
            for (int i = 0; i < SPP; i++)
                for (int j = 0; j < 3; j++) {
                    double v = 0;
                    for (int k = 0; k < 3; k++)
                        v += TO_XYZ[j][k] * s[i][k];
                    mr[j] += s[i][j] / SPP, mx[j] += v / SPP, m2[j] += v * v / SPP;
                }
            double vr[3] = {0}, vx[3] = {0};
            for (int i = 0; i < SPP; i++)
                for (int j = 0; j < 3; j++) {
                    double v = 0;
                    for (int k = 0; k < 3; k++)
                        v += TO_XYZ[j][k] * s[i][k];
                    vr[j] += (s[i][j] - mr[j]) * (s[i][j] - mr[j]) / SPP;
                    vx[j] += (v - mx[j]) * (v - mx[j]) / SPP;
                    if (j == 1) my += (v - mx[1]) * (v - mx[1]) / SPP;
                }
            for (int r = 0; r < 3; r++) {
                double a = 0;
                for (int j = 0; j < 3; j++)
                    a += fabs(TO_RGB[r][j]) * sqrt(vx[j]);
                t->mean[y][x][r] = mr[r];
                t->var[y][x][r] = vr[r] / SPP;
                t->bound[y][x][r] = a * a / SPP;
                t->xyz[y][x][r] = mx[r];
                t->m2[y][x][r] = m2[r];
            }
            t->var_y[y][x] = my / SPP;
        }
}

/* The channels, in the order Mitsuba 3's hdrfilm (pixel_format rgba, the default)
 * lays them out for <integrator type="moment"> holding one <integrator type="aov"
 * name="nested"> with aovs "albedo:albedo,nn:sh_normal" around a path tracer named
 * "path": R,G,B,A, then the moment integrator's AOVs -- the nested integrator's own
 * (its inner integrator's RGBA first, then its AOVs), then nested.X/Y/Z -- then the
 * m2_ twin of every one of them. with_rgb = 0: a film with pixel_format "xyz" has no
 * R,G,B (X,Y,Z would clash with nothing here: the test leaves the main image out). */
static const char *const MITSUBA_CHANNELS[] = {
    "R",
    "G",
    "B",
    "A",
    "nested.path.R",
    "nested.path.G",
    "nested.path.B",
    "nested.path.A",
    "nested.albedo.R",
    "nested.albedo.G",
    "nested.albedo.B",
    "nested.nn.X",
    "nested.nn.Y",
    "nested.nn.Z",
    "nested.X",
    "nested.Y",
    "nested.Z",
    "m2_nested.path.R",
    "m2_nested.path.G",
    "m2_nested.path.B",
    "m2_nested.path.A",
    "m2_nested.albedo.R",
    "m2_nested.albedo.G",
    "m2_nested.albedo.B",
    "m2_nested.nn.X",
    "m2_nested.nn.Y",
    "m2_nested.nn.Z",
    "m2_nested.X",
    "m2_nested.Y",
    "m2_nested.Z",
};
enum { N_MITSUBA = sizeof MITSUBA_CHANNELS / sizeof *MITSUBA_CHANNELS };

static float
mitsuba_value(const truth *t, int x, int y, const char *name)
{
    const char *base = strncmp(name, "m2_", 3) == 0 ? name + 3 : name;
    int sq = base != name;
    double v;
    int k = (int)strlen(base) - 1; /* the component letter */
    int comp = strchr("RXU", base[k])   ? 0
               : strchr("GYV", base[k]) ? 1
               : base[k] == 'A'         ? 3
                                        : 2;
    if (strcmp(base, "A") == 0 || strcmp(base, "nested.path.A") == 0)
        v = 1;
    else if (strlen(base) == 1 || strncmp(base, "nested.path.", 12) == 0)
        v = t->mean[y][x][comp];
    else if (strncmp(base, "nested.albedo.", 14) == 0)
        v = 0.25 * (comp + 1);
    else if (strncmp(base, "nested.nn.", 10) == 0)
        v = comp == 2 ? 1 : 0;
    else /* nested.X/Y/Z */
        return (float)(sq ? t->m2[y][x][comp] : t->xyz[y][x][comp]);
    return (float)(sq ? v * v : v); /* the other twins: not read */
}

static void
write_mitsuba(const truth *t, const char *path, int with_rgb)
{
    const char *names[N_MITSUBA];
    int n = 0;
    for (int i = 0; i < N_MITSUBA; i++)
        if (with_rgb || strlen(MITSUBA_CHANNELS[i]) > 1) names[n++] = MITSUBA_CHANNELS[i];
    mcp_image *img = NULL;
    assert_int_equal(mcp_image_new(W, H, n, names, &img), 0);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int c = 0; c < n; c++)
                mcp_image_px(img, x, y)[c] = mitsuba_value(t, x, y, names[c]);
    assert_int_equal(mcp_image_write(img, path, NULL), 0);
    mcp_image_free(img);
}

static mcp_dump *
read_with_spp(const char *path, double spp)
{
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = path;
    spec.spp = spp;
    mcp_dump *d = NULL;
    assert_int_equal(mcp_dump_load(&spec, &d), 0);
    return d;
}

static void
check_mitsuba(int mixed, int with_rgb)
{
    static truth t;
    make_samples(&t, mixed, 29 + (uint64_t)mixed);
    const char *path =
        mcp_test_path(with_rgb ? "mitsuba3_moment.exr" : "mitsuba3_xyz.exr");
    write_mitsuba(&t, path, with_rgb);

    /* no count in the file: the error says so */
    mcp_dump *d = NULL;
    assert_error_contains(mcp_dump_read(path, &d), "Mitsuba writes no sample count");

    d = read_with_spp(path, SPP);
    assert_int_equal(d->convention, MCP_CONV_MITSUBA);
    assert_int_equal(d->variance_source, MCP_VARSRC_XYZ_MOMENTS);
    assert_string_equal(mcp_variance_source_name(d->variance_source), "xyz-moments");
    assert_non_null(d->albedo);
    assert_non_null(d->normal);
    assert_null(d->cov_of_mean);
    double worst_exact = 0, worst_ratio = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            const float *m = mcp_image_px(d->color, x, y),
                        *v = mcp_image_px(d->var_of_mean, x, y);
            const float *a = mcp_image_px(d->albedo, x, y),
                        *nn = mcp_image_px(d->normal, x, y);
            for (int c = 0; c < 3; c++) {
                assert_float_equal(m[c], t.mean[y][x][c], 1e-4 * (1 + t.mean[y][x][c]));
                assert_float_equal(a[c], 0.25 * (c + 1), 1e-6);
                assert_float_equal(nn[c], c == 2 ? 1 : 0, 1e-6);
                /* never above the Cauchy-Schwarz bound of the truth */
                assert_true(v[c] <= t.bound[y][x][c] * (1 + 1e-3));
                assert_true(t.var[y][x][c] <= t.bound[y][x][c] * (1 + 1e-3));
                double rel = fabs(v[c] - t.var[y][x][c]) / t.var[y][x][c];
                if (rel > worst_exact) worst_exact = rel;
                double ratio = t.var[y][x][c] / v[c];
                if (ratio > worst_ratio) worst_ratio = ratio;
            }
            /* the luminance: its variance is Var Y / n, in the file exactly */
            double my = t.xyz[y][x][1], vy = (t.m2[y][x][1] - my * my) / SPP;
            assert_float_equal(vy, t.var_y[y][x], 2e-3 * t.var_y[y][x]);
        }
    if (!mixed) /* one chromaticity per pixel: each channel exact (float moments) */
        assert_true(worst_exact < 2e-3);
    else /* chromaticity varies: the correlated value can miss either way */
        assert_true(worst_exact > 1e-2);
    print_message("mitsuba mixed=%d rgb=%d: worst relative error %.3g, truth/ours %.3g\n",
                  mixed, with_rgb, worst_exact, worst_ratio);
    mcp_dump_free(d);
}

static void
test_mitsuba_moment_one_chromaticity(void **state)
{
    (void)state;
    check_mitsuba(0, 1);
}

static void
test_mitsuba_moment_mixed_chromaticity(void **state)
{
    (void)state;
    check_mitsuba(1, 1);
}

static void
test_mitsuba_moment_without_rgb(void **state)
{
    (void)state;
    check_mitsuba(0, 0); /* the mean from nested.X/Y/Z in linear sRGB */
}

/* The m2_ twins of the nested AOVs are no features, and a second nested colour
 * integrator is no reason to fail. */
static void
test_mitsuba_detects_only_moment_channels(void **state)
{
    (void)state;
    const char *names[] = {"R", "G", "B", "m2_R2", "foo.X", "foo.Y", "m2_foo.X"};
    mcp_image *img = NULL;
    assert_int_equal(mcp_image_new(2, 2, 7, names, &img), 0);
    assert_int_equal(mcp_dump_detect(img), MCP_CONV_PLAIN); /* no full triple */
    mcp_image_free(img);
}

/* pbrt-v4's GBufferFilm (src/pbrt/film.cpp): R,G,B, Albedo.*, P.*, dzdx, dzdy,
 * N.*, Ns.*, u, v, Variance.* (per sample), RelativeVariance.*, and the header's
 * samplesPerPixel. */
static void
test_pbrt_gbuffer(void **state)
{
    (void)state;
    static truth t;
    make_samples(&t, 1, 7);
    const char *names[] = {"R",
                           "G",
                           "B",

                           "Albedo.R",
                           "Albedo.G",
                           "Albedo.B",
                           "P.X",
                           "P.Y",
                           "P.Z",
                           "dzdx",
                           "dzdy",
                           "N.X",
                           "N.Y",
                           "N.Z",
                           "Ns.X",
                           "Ns.Y",
                           "Ns.Z",
                           "u",
                           "v",
                           "Variance.R",
                           "Variance.G",
                           "Variance.B",
                           "RelativeVariance.R",
                           "RelativeVariance.G",
                           "RelativeVariance.B"};
    const int n = (int)(sizeof names / sizeof *names);
    mcp_image *img = NULL;
    assert_int_equal(mcp_image_new(W, H, n, names, &img), 0);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            float *p = mcp_image_px(img, x, y);
            for (int c = 0; c < n; c++)
                p[c] = 0.5f;
            for (int c = 0; c < 3; c++) {
                double per_sample = t.var[y][x][c] * SPP;
                p[c] = (float)t.mean[y][x][c];
                p[3 + c] = 0.25f * (c + 1);
                p[11 + c] = c == 2 ? 1 : 0;
                p[14 + c] = c == 0 ? 1 : 0;
                p[19 + c] = (float)per_sample;
                p[22 + c] = (float)(per_sample / (t.mean[y][x][c] * t.mean[y][x][c]));
            }
        }
    assert_int_equal(mcp_attrs_set_int(&img->attrs, "samplesPerPixel", SPP), 0);
    const char *path = mcp_test_path("pbrt_gbuffer.exr");
    assert_int_equal(mcp_image_write(img, path, NULL), 0);
    assert_int_equal(mcp_dump_detect(img), MCP_CONV_PBRT);
    mcp_image_free(img);

    mcp_dump *d = NULL;
    assert_int_equal(mcp_dump_read(path, &d), 0);
    assert_int_equal(d->convention, MCP_CONV_PBRT);
    assert_int_equal(d->variance_source, MCP_VARSRC_PER_SAMPLE);
    assert_true(d->spp == SPP);
    assert_non_null(d->albedo);
    assert_non_null(d->normal);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int c = 0; c < 3; c++) {
                assert_float_equal(mcp_image_px(d->color, x, y)[c], t.mean[y][x][c],
                                   1e-5);
                assert_float_equal(mcp_image_px(d->var_of_mean, x, y)[c], t.var[y][x][c],
                                   1e-5 * t.var[y][x][c] + 1e-12);
                assert_float_equal(mcp_image_px(d->normal, x, y)[c], c == 2 ? 1 : 0, 0);
            }
    mcp_dump_free(d);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_mitsuba_moment_one_chromaticity),
        cmocka_unit_test(test_mitsuba_moment_mixed_chromaticity),
        cmocka_unit_test(test_mitsuba_moment_without_rgb),
        cmocka_unit_test(test_mitsuba_detects_only_moment_channels),
        cmocka_unit_test(test_pbrt_gbuffer),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
