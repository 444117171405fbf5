/* test_variance.c: estimate/variance.c and estimate/sampling_map.c against
 * independent truths.
 *
 * The JVP variance of a linear filter A is exact in expectation, E[(Av)_i²] =
 * (A Σ Aᵀ)_ii, and agrees with the empirical variance of the denoised output over
 * realizations of the noise (the bound asked: an image-mean ratio within [0.8, 1.25]).
 * The sampling map is checked against Eq. 3 computed by hand, and the counts must sum
 * exactly to the budget and stay within one sample of budget × weight. */
#include "box_denoiser.h"
#include "testing.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mcpost/estimate.h>
#include <mcpost/filter.h>
#include "../../estimate/internal.h"

#define W 24
#define H 20

static const char *const RGB[] = {"R", "G", "B"};

static double
mu_at(int x, int y, int c)
{
    return 0.2 + 0.3 * c + 0.03 * x + (y > H / 2 ? 0.8 : 0.0);
}

static double
sigma_at(int x, int y, int c)
{
    return 0.05 + 0.3 * (x + y) / (double)(W + H) + 0.02 * c;
}

static mcp_dump *
realization(uint64_t *rng)
{
    mcp_dump *d = calloc(1, sizeof *d);
    assert_non_null(d);
    d->color = mcp_test_rgb(W, H);
    d->var_of_mean = mcp_test_rgb(W, H);
    d->spp = 8;
    d->source = strdup("synthetic");
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int c = 0; c < 3; c++) {
                double s = sigma_at(x, y, c);
                mcp_image_px(d->color, x, y)[c] =
                    (float)(mu_at(x, y, c) + s * mcp_test_rand_normal(rng));
                mcp_image_px(d->var_of_mean, x, y)[c] = (float)(s * s);
            }
    return d;
}

/* (A Σ Aᵀ)_ii of the box filter. */
static double
box_variance(int x, int y, int c)
{
    double wgt[W * H] = {0}, v = 0.0;
    for (int dy = -1; dy <= 1; dy++)
        for (int dx = -1; dx <= 1; dx++) {
            int xx = x + dx < 0 ? 0 : x + dx >= W ? W - 1 : x + dx;
            int yy = y + dy < 0 ? 0 : y + dy >= H ? H - 1 : y + dy;
            wgt[yy * W + xx] += 1.0 / 9.0;
        }
    for (int q = 0; q < W * H; q++)
        if (wgt[q] != 0.0) {
            double s = sigma_at(q % W, q / W, c);
            v += wgt[q] * wgt[q] * s * s;
        }
    return v;
}

static double
image_mean(const mcp_image *img, int channels)
{
    double s = 0.0;
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++)
            for (int c = 0; c < channels; c++)
                s += mcp_image_px(img, x, y)[c];
    return s / ((double)img->width * img->height * channels);
}

/* ---- JVP variance ---- */

static void
test_jvp_variance_vs_empirical(void **state)
{
    (void)state;
    const int R = 200;
    /* empirical variance of box(X) over realizations, per value (Welford) */
    double *mean = calloc(W * H * 3, sizeof *mean), *m2 = calloc(W * H * 3, sizeof *m2);
    double jvp_mean = 0.0;
    uint64_t rng = 31;
    for (int r = 0; r < R; r++) {
        mcp_dump *d = realization(&rng);
        mcp_image *f = mcp_test_rgb(W, H);
        mcp_test_box3(d->color, f);
        for (int i = 0; i < W * H * 3; i++) {
            double v = f->data[i], dlt = v - mean[i];
            mean[i] += dlt / (r + 1);
            m2[i] += dlt * (v - mean[i]);
        }
        /* the JVP estimate from this realization, K = 1, its own seed */
        mcp_variance_options o = mcp_variance_defaults();
        o.seed = 100 + r;
        mcp_image *v = NULL;
        assert_int_equal(mcp_variance(d, &mcp_test_box_denoiser, &o, &v, NULL), 0);
        jvp_mean += image_mean(v, 3) / R;
        mcp_image_free(v);
        mcp_image_free(f);
        mcp_dump_free(d);
    }
    double emp = 0.0, exact = 0.0;
    for (int i = 0; i < W * H * 3; i++)
        emp += m2[i] / (R - 1) / (W * H * 3);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int c = 0; c < 3; c++)
                exact += box_variance(x, y, c) / (W * H * 3);
    double ratio = jvp_mean / emp;
    print_message("JVP variance (Rademacher, K=1, 200 realizations): image mean %.5g, "
                  "empirical %.5g, ratio %.4f; closed form %.5g\n",
                  jvp_mean, emp, ratio, exact);
    assert_true(ratio >= 0.8 && ratio <= 1.25);
    /* tighter: the mean of 200 K=1 estimates against the closed form. The estimate
     * of one value has relative spread sqrt(2)-ish; its image mean over 1440 values
     * and 200 seeds has well under 1% */
    assert_close(jvp_mean, exact, 0.02, 0);
    free(mean);
    free(m2);
}

/* Per value with many probes: converges to (A Σ Aᵀ)_ii. */
static void
test_jvp_variance_per_value(void **state)
{
    (void)state;
    uint64_t rng = 5;
    mcp_dump *d = realization(&rng);
    mcp_variance_options o = mcp_variance_defaults();
    o.n_probes = 400;
    mcp_image *v = NULL, *f = NULL;
    assert_int_equal(mcp_variance(d, &mcp_test_box_denoiser, &o, &v, &f), 0);
    double worst = 0.0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int c = 0; c < 3; c++) {
                double want = box_variance(x, y, c), got = mcp_image_px(v, x, y)[c];
                worst = fmax(worst, fabs(got / want - 1));
            }
    /* with Rademacher probes (Av)² has relative sd <= sqrt(2); over 400 probes
     * <= 7%, and 5 sd over 1440 values keeps a fixed seed safe */
    print_message("JVP variance, K=400: worst relative error %.3f\n", worst);
    assert_true(worst < 0.35);
    /* relative: divided by maxc(F)² + 1e-2 */
    mcp_image *vr = NULL;
    o.relative = 1;
    assert_int_equal(mcp_variance(d, &mcp_test_box_denoiser, &o, &vr, NULL), 0);
    for (int c = 0; c < 3; c++) {
        const float *pf = mcp_image_px(f, 7, 9);
        double m = fmax(fmax(pf[0], pf[1]), pf[2]);
        assert_close(mcp_image_px(vr, 7, 9)[c], mcp_image_px(v, 7, 9)[c] / (m * m + 1e-2),
                     1e-6, 0);
    }
    /* finite differences agree with the exact jvp on a linear filter */
    mcp_image *vfd = NULL;
    o.relative = 0;
    o.n_probes = 3;
    o.mc = 1;
    mcp_image *vex = NULL;
    assert_int_equal(mcp_variance(d, &mcp_test_box_denoiser, &o, &vfd, NULL), 0);
    o.mc = 0;
    assert_int_equal(mcp_variance(d, &mcp_test_box_denoiser, &o, &vex, NULL), 0);
    assert_true(mcp_test_max_abs_diff(vfd, vex) < 1e-6);
    mcp_image_free(vfd);
    mcp_image_free(vex);
    mcp_image_free(vr);
    mcp_image_free(v);
    mcp_image_free(f);
    mcp_dump_free(d);
}

/* ---- sampling map ---- */

static void
test_sampling_map_eq3(void **state)
{
    (void)state;
    uint64_t rng = 9;
    mcp_dump *d = realization(&rng);
    d->spp = 15;
    mcp_image *f = mcp_test_rgb(W, H), *var = mcp_test_rgb(W, H);
    mcp_test_box3(d->color, f);
    for (int i = 0; i < W * H * 3; i++)
        var->data[i] = (float)(0.01 + 0.001 * (i % 17));
    var->data[5] = -3.0f; /* a negative numerator (SURE can be): clipped per pixel */
    var->data[4] = -3.0f;
    var->data[3] = -3.0f;
    mcp_sampling_options o = mcp_sampling_defaults();
    o.blur_window = 1; /* no blur: compare with Eq. 3 directly */
    mcp_image *map = NULL;
    assert_int_equal(mcp_sampling_map(d, f, var, &o, &map), 0);
    assert_int_equal(map->channels, 1);
    double want[W * H], total = 0.0;
    for (int p = 0; p < W * H; p++) {
        double s = 0.0;
        for (int c = 0; c < 3; c++) {
            double fc = f->data[3 * p + c];
            s += var->data[3 * p + c] / (16.0 * (fc * fc + 1e-2));
        }
        want[p] = s / 3 > 0 ? s / 3 : 0;
        total += want[p];
    }
    for (int p = 0; p < W * H; p++)
        assert_close(map->data[p], want[p] / total, 1e-5, 1e-12);
    assert_true(map->data[1] == 0.0f);
    /* tone-mapped: T'(F)² Var / (n + 1), no relative division */
    o.kind = MCP_SAMPLING_TONEMAPPED;
    mcp_image *tm = NULL;
    assert_int_equal(mcp_sampling_map(d, f, var, &o, &tm), 0);
    total = 0.0;
    for (int p = 0; p < W * H; p++) {
        double s = 0.0;
        for (int c = 0; c < 3; c++) {
            double sl = mcp_tonemap_slope(MCP_TONEMAP_ACES, f->data[3 * p + c]);
            s += sl * sl * var->data[3 * p + c] / 16.0;
        }
        want[p] = s / 3 > 0 ? s / 3 : 0;
        total += want[p];
    }
    for (int p = 0; p < W * H; p++)
        assert_close(tm->data[p], want[p] / total, 1e-5, 1e-12);
    mcp_image_free(tm);
    mcp_image_free(map);
    mcp_image_free(f);
    mcp_image_free(var);
    mcp_dump_free(d);
}

/* An impulse spreads like the blur each kind asks for (σ 0.5 in 5x5; σ 4 in 17x17). */
static void
test_sampling_map_blur(void **state)
{
    (void)state;
    const int s = 41;
    mcp_dump *d = calloc(1, sizeof *d);
    d->color = mcp_test_rgb(s, s);
    d->spp = 1;
    d->source = strdup("impulse");
    mcp_image *f = mcp_test_rgb(s, s), *num = mcp_test_rgb(s, s);
    for (int c = 0; c < 3; c++)
        mcp_image_px(num, 20, 20)[c] = 1.0f;
    const mcp_sampling_kind kinds[2] = {MCP_SAMPLING_VARIANCE, MCP_SAMPLING_MC_SURE};
    const double sigma[2] = {0.5, 4.0};
    const int radius[2] = {2, 8};
    for (int k = 0; k < 2; k++) {
        mcp_sampling_options o = mcp_sampling_defaults();
        o.kind = kinds[k];
        mcp_image *map = NULL;
        assert_int_equal(mcp_sampling_map(d, f, num, &o, &map), 0);
        float g[17];
        assert_int_equal(mcp_gaussian_kernel(sigma[k], radius[k], g), 0);
        for (int dx = -radius[k] - 1; dx <= radius[k] + 1; dx++) {
            double want = abs(dx) <= radius[k] ? g[dx + radius[k]] * g[radius[k]] : 0.0;
            assert_close(mcp_image_px(map, 20 + dx, 20)[0], want, 1e-4, 1e-9);
        }
        mcp_image_free(map);
    }
    /* all zero: uniform */
    mcp_image *zero = mcp_test_rgb(s, s), *map = NULL;
    assert_int_equal(mcp_sampling_map(d, f, zero, NULL, &map), 0);
    assert_close(map->data[0], 1.0 / (s * s), 1e-6, 0);
    assert_close(map->data[s * s - 1], 1.0 / (s * s), 1e-6, 0);
    mcp_image_free(map);
    mcp_image_free(zero);
    mcp_image_free(f);
    mcp_image_free(num);
    mcp_dump_free(d);
}

static int64_t
count_sum(const mcp_image *c)
{
    int64_t s = 0;
    for (int i = 0; i < c->width * c->height; i++) {
        assert_true(c->data[i] == floorf(c->data[i]) && c->data[i] >= 0);
        s += (int64_t)c->data[i];
    }
    return s;
}

static void
test_sample_counts_sum_to_budget(void **state)
{
    (void)state;
    mcp_image *map = mcp_test_random(37, 23, 1, 0.0f, 1.0f, 12, NULL);
    for (int i = 0; i < 50; i++)
        map->data[i * 7] = 0.0f; /* zeros get nothing but their share of remainders */
    double total = 0.0;
    for (int i = 0; i < 37 * 23; i++)
        total += map->data[i];
    const int64_t budgets[] = {
        0, 1, 2, 7, 851, 852, 1000, 32 * 851 + 5, 10000019, (int64_t)1 << 32};
    for (size_t b = 0; b < sizeof budgets / sizeof *budgets; b++) {
        mcp_image *c = NULL;
        assert_int_equal(mcp_sample_counts(map, budgets[b], &c), 0);
        assert_string_equal(c->names[0], "SampleCount");
        assert_true(count_sum(c) == budgets[b]);
        for (int i = 0; i < 37 * 23; i++) { /* largest remainders: within 1 of quota */
            double q = (double)budgets[b] * map->data[i] / total;
            assert_true(c->data[i] >= floor(q) - 1e-9 * q &&
                        c->data[i] <= ceil(q) + 1e-9 * q);
        }
        mcp_image_free(c);
    }
    /* ties go to the lower pixel index: 10 equal weights, budget 3 */
    mcp_image *flat = mcp_test_constant(5, 2, 1, 0.25f, NULL), *c = NULL;
    assert_int_equal(mcp_sample_counts(flat, 3, &c), 0);
    for (int i = 0; i < 10; i++)
        assert_int_equal((int)c->data[i], i < 3 ? 1 : 0);
    mcp_image_free(c);
    /* errors */
    flat->data[4] = -1.0f;
    assert_error_contains(mcp_sample_counts(flat, 3, &c), "1 weights are negative");
    assert_null(c);
    flat->data[4] = 0.25f;
    assert_error_contains(mcp_sample_counts(flat, -2, &c),
                          "sample counts: budget must be in [0, 2^52] (got -2)");
    mcp_image *one = mcp_test_constant(1, 1, 1, 1.0f, NULL);
    assert_error_contains(mcp_sample_counts(one, 20000000, &c),
                          "more than a float holds");
    mcp_image_free(one);
    mcp_image_free(flat);
    mcp_image_free(map);
}

static void
test_postcorrection_variance(void **state)
{
    (void)state;
    mcp_image *v0 = mcp_test_random(4, 3, 3, 0, 1, 1, RGB),
              *v1 = mcp_test_random(4, 3, 3, 0, 1, 2, RGB),
              *vx = mcp_test_random(4, 3, 3, 0, 1, 3, RGB),
              *a = mcp_test_random(4, 3, 1, 0, 1, 4, NULL),
              *r = mcp_test_random(4, 3, 3, 0, 1, 5, RGB), *out = NULL;
    assert_int_equal(mcp_postcorrection_variance(v0, v1, vx, a, r, &out), 0);
    for (int i = 0; i < 12; i++)
        for (int c = 0; c < 3; c++) {
            double al = a->data[i], rh = r->data[3 * i + c];
            double want = rh * rh *
                              (al * al * v0->data[3 * i + c] +
                               (1 - al) * (1 - al) * v1->data[3 * i + c]) +
                          (1 - rh) * (1 - rh) * vx->data[3 * i + c];
            assert_close(out->data[3 * i + c], want, 1e-6, 1e-7);
        }
    mcp_image_free(out);
    mcp_image *small = mcp_test_random(2, 2, 3, 0, 1, 1, RGB);
    assert_error_contains(
        mcp_postcorrection_variance(v0, small, vx, a, r, &out),
        "post-correction variance: Var[F(x1)]: size 2x2 does not match 4x3");
    mcp_image_free(small);
    mcp_image *imgs[] = {v0, v1, vx, a, r};
    for (int i = 0; i < 5; i++)
        mcp_image_free(imgs[i]);
}

static void
test_errors(void **state)
{
    (void)state;
    mcp_sampling_kind k;
    assert_error_contains(mcp_sampling_kind_from_name("adaptive", &k),
                          "unknown sampling map 'adaptive' (known: variance, tonemapped, "
                          "mc-sure)");
    assert_int_equal(mcp_sampling_kind_from_name("MC-SURE", &k), 0);
    assert_int_equal(k, MCP_SAMPLING_MC_SURE);
    uint64_t rng = 1;
    mcp_dump *d = realization(&rng);
    mcp_variance_options o = mcp_variance_defaults();
    o.n_probes = 0;
    mcp_image *v = NULL;
    assert_error_contains(mcp_variance(d, &mcp_test_box_denoiser, &o, &v, NULL),
                          "variance: n_probes must be in [1, 1024] (got 0)");
    mcp_sampling_options so = mcp_sampling_defaults();
    so.blur_window = 4;
    assert_error_contains(mcp_sampling_map(d, d->color, d->color, &so, &v),
                          "blur_window must be odd");
    mcp_image *small = mcp_test_rgb(3, 3);
    assert_error_contains(mcp_sampling_map(d, small, d->color, NULL, &v),
                          "sampling map: denoised image: size 3x3 does not match 24x20");
    mcp_image_free(small);
    mcp_image_free(d->var_of_mean);
    d->var_of_mean = NULL;
    assert_error_contains(mcp_variance(d, &mcp_test_box_denoiser, NULL, &v, NULL),
                          "variance: synthetic has no variance");
    mcp_dump_free(d);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_jvp_variance_vs_empirical),
        cmocka_unit_test(test_jvp_variance_per_value),
        cmocka_unit_test(test_sampling_map_eq3),
        cmocka_unit_test(test_sampling_map_blur),
        cmocka_unit_test(test_sample_counts_sum_to_budget),
        cmocka_unit_test(test_postcorrection_variance),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests_name("estimate/variance", tests, NULL, NULL);
}
