/* test_weights.c: blend/weights.c -- weights from curves, the blend formula, easy and
 * ideal blending, and one iteration (mcp_blend_step) on a procedural render with a
 * known truth (docs/mathematics.md §3; Denisova & Bocchi 2024 Eqs. 2, 4, 8, 14). */
#include "blend_testing.h"

#include <mcpost/estimate.h>
#include <mcpost/metrics.h>

#include <math.h>
#include <stdio.h>

#include "procedural.h"

static void
test_weights_from_curves(void **state)
{
    (void)state;
    /* 3x1: pixel 0 v = 0.04, SURE = 0.01 -> W = 16 sqrt(4) = 32 on the fly;
     * pixel 1 SURE = 0 -> inf; pixel 2 black (v = 0) -> 0, or inf when the denoiser
     * keeps zeros. */
    const float v[9] = {0.04f, 0.04f, 0.04f, 0.01f, 0.01f, 0.01f, 0, 0, 0};
    const float s[9] = {0.01f, 0.01f, 0.01f, 0, 0, 0, 0.5f, 0.5f, 0.5f};
    mcp_image *vi = rgb_from(3, 1, v), *si = rgb_from(3, 1, s), *curves = NULL, *w = NULL;
    const mcp_image *list[1] = {vi};
    double spp[1] = {16};
    assert_int_equal(mcp_blend_curves(list, spp, 1, NULL, &curves), 0);
    assert_int_equal(mcp_blend_weights(curves, si, NULL, &w), 0);
    for (int k = 0; k < 3; k++) {
        /* the curve is stored in float: 1e-6 */
        assert_close(w->data[k], 32, 1e-6, 0);
        assert_true(isinf(w->data[3 + k]));
        assert_true(w->data[6 + k] == 0);
    }
    mcp_image_free(w);
    mcp_blend_options o = mcp_blend_defaults();
    o.denoiser_keeps_zeros = 1;
    o.max_weight = 100;
    assert_int_equal(mcp_blend_weights(curves, si, &o, &w), 0);
    assert_true(w->data[3] == 100 && w->data[6] == 100); /* inf, capped */
    mcp_image_free(w);
    /* negative SURE must be fixed first */
    mcp_image_px(si, 0, 0)[1] = -1;
    assert_error_contains(mcp_blend_weights(curves, si, NULL, &w), "1 negative values");
    assert_null(w);
    mcp_image_free(curves);
    mcp_image_free(vi);
    mcp_image_free(si);
}

static void
test_mix(void **state)
{
    (void)state;
    const float n[3] = {1, 1, 1}, d[3] = {3, 3, 3}, wt[3] = {16, 0, INFINITY};
    mcp_image *ni = rgb_from(1, 1, n), *di = rgb_from(1, 1, d), *wi = rgb_from(1, 1, wt);
    mcp_image *r = NULL;
    assert_int_equal(mcp_blend_mix(ni, 16, di, wi, &r), 0);
    assert_close(r->data[0], 2.0, 1e-7, 0); /* (16 + 48) / 32 */
    assert_true(r->data[1] == 1 && r->data[2] == 3);
    mcp_image_free(r);
    assert_error_contains(mcp_blend_mix(ni, 0, di, wi, &r), "spp must be finite and > 0");
    mcp_image_free(ni);
    mcp_image_free(di);
    mcp_image_free(wi);
}

static void
test_easy(void **state)
{
    (void)state;
    const float n[3] = {1, 1, 1}, d[3] = {3, 3, 3}, v[3] = {0.1f, 0.1f, 0.1f};
    const float s[3] = {0.2f, 0.1f, 0.05f};
    mcp_image *ni = rgb_from(1, 1, n), *di = rgb_from(1, 1, d), *vi = rgb_from(1, 1, v);
    mcp_image *si = rgb_from(1, 1, s), *r = NULL;
    assert_int_equal(mcp_blend_easy(ni, di, vi, si, &r), 0);
    /* SURE > v: noisy; otherwise (ties too): denoised */
    assert_true(r->data[0] == 1 && r->data[1] == 3 && r->data[2] == 3);
    mcp_image_free(r);
    mcp_image_free(ni);
    mcp_image_free(di);
    mcp_image_free(vi);
    mcp_image_free(si);
}

static void
test_ideal_reproduces_reference(void **state)
{
    (void)state;
    /* Random n, d, R: wherever R lies strictly between n and d (so W = I (R - n)/(d - R)
     * is positive and finite), r = R up to float rounding of the inputs; where d = R,
     * r = d = R; elsewhere W = 0 and r = n (§3.6 clamps W at 0). */
    const int w = 64, h = 48;
    mcp_image *n = mcp_test_random(w, h, 3, 0, 2, 11, RGB);
    mcp_image *d = mcp_test_random(w, h, 3, 0, 2, 12, RGB);
    mcp_image *ref = mcp_test_random(w, h, 3, 0, 2, 13, RGB);
    for (int i = 0; i < 50; i++) /* a few exact d = R */
        d->data[i * 7] = ref->data[i * 7];
    mcp_image *r = NULL, *wt = NULL;
    assert_int_equal(mcp_blend_ideal(n, 64, d, ref, &r, &wt), 0);
    long between = 0, exact = 0, outside = 0;
    for (int i = 0; i < w * h * 3; i++) {
        double nv = n->data[i], dv = d->data[i], rv = ref->data[i];
        if (dv == rv) {
            assert_true(r->data[i] == ref->data[i] && isinf(wt->data[i]));
            exact++;
        } else if ((rv - nv) * (dv - rv) > 0) {
            /* r = R in double; one float rounding of the result, 1 ulp of values <= 2 */
            assert_close(r->data[i], rv, 0, 2.5e-7);
            assert_true(wt->data[i] > 0);
            between++;
        } else {
            assert_true(r->data[i] == n->data[i] && wt->data[i] == 0);
            outside++;
        }
    }
    assert_true(between > 1000 && exact == 50 && outside > 1000);
    mcp_image_free(r);
    mcp_image_free(wt);
    mcp_image *small = rgb_constant(2, 2, 0);
    assert_error_contains(mcp_blend_ideal(n, 64, d, small, &r, NULL), "does not match");
    assert_null(r);
    mcp_image_free(small);
    mcp_image_free(n);
    mcp_image_free(d);
    mcp_image_free(ref);
}

/* The four inputs of one step, w x h R, G, B: noisy and denoised in [0, 2], v in
 * [0, 0.02] with `blacks` zeros (black values), SURE in [-0.005, 0.02] with `blacks`
 * zeros (a perfect d); img = {n, d, v, s}. */
static void
step_inputs(int w, int h, int blacks, uint64_t seed, mcp_image *img[4])
{
    img[0] = mcp_test_random(w, h, 3, 0, 2, seed, RGB);
    img[1] = mcp_test_random(w, h, 3, 0, 2, seed + 1, RGB);
    img[2] = mcp_test_random(w, h, 3, 0, 0.02f, seed + 2, RGB);
    img[3] = mcp_test_random(w, h, 3, -0.005f, 0.02f, seed + 3, RGB);
    for (int i = 0; i < blacks; i++)
        img[2]->data[i * 17] = 0, img[3]->data[i * 13] = 0;
}

/* mcp_blend_step's fused on-the-fly pass (closed form, float) against the separate
 * steps (curve image, weights, mix), for both curves, with zeros, negative SURE and
 * black values. */
static void
test_step_matches_parts(void **state)
{
    (void)state;
    const int w = 40, h = 30;
    mcp_image *img[4];
    step_inputs(w, h, 40, 31, img);
    mcp_image *n = img[0], *d = img[1], *v = img[2], *s = img[3];
    for (int c = 0; c < 2; c++) {
        mcp_blend_options o = mcp_blend_defaults();
        o.curve = c ? MCP_CURVE_POWERLAW : MCP_CURVE_LOG;
        o.filter = MCP_BLEND_FILTER_NONE; /* keeps the zeros where they were put */
        o.safeguard = 0; /* the parts below do not include it (test_safeguard.c) */
        o.weights = MCP_BLEND_WEIGHTS_CURVES;
        mcp_blend_input in = {n, v, 32, d, s, NULL, NULL};
        mcp_blend_result res;
        assert_int_equal(mcp_blend_step(&in, &o, NULL, NULL, &res), 0);
        mcp_blend_estimates e;
        mcp_image *curves = NULL, *wt = NULL, *r = NULL;
        const mcp_image *vl[1];
        double spp[1] = {32};
        assert_int_equal(mcp_blend_prepare(v, s, &o, NULL, NULL, &e), 0);
        vl[0] = e.var_of_mean;
        assert_int_equal(mcp_blend_curves(vl, spp, 1, &o, &curves), 0);
        assert_int_equal(mcp_blend_weights(curves, e.sure, &o, &wt), 0);
        assert_int_equal(mcp_blend_mix(n, 32, d, wt, &r), 0);
        for (int i = 0; i < w * h * 3; i++) {
            /* the fixed SURE is the same; W agrees to float rounding of the curve
             * (1e-5 relative), the blend to 1e-5 of values <= 2 */
            assert_true(res.est.sure->data[i] == e.sure->data[i]);
            if (isinf(wt->data[i]))
                assert_true(isinf(res.weights->data[i]) || res.weights->data[i] == 65536);
            else
                assert_close(res.weights->data[i], wt->data[i], 1e-5, 0);
            assert_close(res.blend->data[i], r->data[i], 0, 1e-5);
        }
        mcp_image_free(curves);
        mcp_image_free(wt);
        mcp_image_free(r);
        mcp_blend_estimates_free(&e);
        mcp_blend_result_free(&res);
    }
    mcp_image_free(n);
    mcp_image_free(d);
    mcp_image_free(v);
    mcp_image_free(s);
}

/* An R, G, B, A copy of img (A = 1): pixels no longer packed R, G, B. */
static mcp_image *
with_alpha(const mcp_image *img)
{
    mcp_image *out = NULL;
    assert_int_equal(mcp_image_new(img->width, img->height, 4,
                                   (const char *[]){"R", "G", "B", "A"}, &out),
                     0);
    for (int p = 0; p < img->width * img->height; p++) {
        memcpy(out->data + 4 * p, img->data + 3 * p, 3 * sizeof(float));
        out->data[4 * p + 3] = 1.0f;
    }
    return out;
}

/* The fused pass runs four values at a time where the noisy and denoised images are
 * packed R, G, B and value by value where they are not: both give the same bits (41
 * columns: the vector loop has a tail), with zeros, NaN-free negatives and blacks. */
static void
test_step_vector_is_scalar(void **state)
{
    (void)state;
    const int w = 41, h = 7;
    mcp_image *img[4];
    step_inputs(w, h, 20, 41, img);
    mcp_image *n = img[0], *d = img[1], *v = img[2], *s = img[3];
    mcp_image *n4 = with_alpha(n), *d4 = with_alpha(d);
    for (int magnitude = 0; magnitude < 2; magnitude++) {
        mcp_blend_options o = mcp_blend_defaults();
        o.filter = MCP_BLEND_FILTER_NONE;
        o.negative_sure = magnitude ? MCP_NEG_SURE_MAGNITUDE : MCP_NEG_SURE_ZERO;
        o.max_weight = 100;                   /* the cap in play too */
        o.weights = MCP_BLEND_WEIGHTS_CURVES; /* the SSE pass (JS: test_safeguard.c) */
        mcp_blend_input packed = {n, v, 32, d, s, NULL, NULL},
                        strided = {n4, v, 32, d4, s, NULL, NULL};
        mcp_blend_result a, b;
        assert_int_equal(mcp_blend_step(&packed, &o, NULL, NULL, &a), 0);
        assert_int_equal(mcp_blend_step(&strided, &o, NULL, NULL, &b), 0);
        for (int i = 0; i < w * h * 3; i++) {
            assert_memory_equal(&a.weights->data[i], &b.weights->data[i], sizeof(float));
            assert_memory_equal(&a.blend->data[i], &b.blend->data[i], sizeof(float));
            assert_memory_equal(&a.est.sure->data[i], &b.est.sure->data[i],
                                sizeof(float));
        }
        mcp_blend_result_free(&a);
        mcp_blend_result_free(&b);
    }
    mcp_image_free(n), mcp_image_free(d), mcp_image_free(v), mcp_image_free(s);
    mcp_image_free(n4), mcp_image_free(d4);
}

static void
test_step_errors(void **state)
{
    (void)state;
    mcp_image *n = rgb_constant(4, 4, 1), *v = rgb_constant(4, 4, 0.1f);
    mcp_image *small = rgb_constant(3, 4, 1);
    mcp_blend_result res;
    mcp_blend_input in = {n, v, 16, n, NULL, NULL, NULL};
    assert_error_contains(mcp_blend_step(&in, NULL, NULL, NULL, &res),
                          "noisy, variance, denoised and SURE images are required");
    in.sure = v;
    in.denoised = small;
    assert_error_contains(mcp_blend_step(&in, NULL, NULL, NULL, &res), "does not match");
    assert_null(res.blend);
    assert_null(res.weights);
    assert_null(res.est.sure);
    in.denoised = n;
    in.spp = 0;
    assert_error_contains(mcp_blend_step(&in, NULL, NULL, NULL, &res),
                          "spp must be finite and > 0 (got 0)");
    mcp_blend_options o = mcp_blend_defaults();
    o.filter = MCP_BLEND_FILTER_DENOISER;
    in.spp = 16;
    assert_error_contains(mcp_blend_step(&in, &o, NULL, NULL, &res),
                          "filter 'denoiser' needs a denoiser");
    /* a curve image without the a.* and b.* channels */
    mcp_blend_input with = {n, v, 16, n, v, v, NULL};
    assert_error_contains(mcp_blend_step(&with, NULL, NULL, NULL, &res),
                          "no channel 'a.R'");
    /* the state carries the rule: crossed once, crossed for good */
    mcp_blend_state st = {0, 0};
    mcp_image *big = rgb_constant(4, 4, 1.0f);
    mcp_blend_input crossing = {n, v, 16, n, big, NULL, NULL};
    assert_int_equal(mcp_blend_step(&crossing, NULL, NULL, &st, &res), 0);
    assert_true(st.filtering_stopped && st.magnitude && !res.est.filtered);
    mcp_blend_result_free(&res);
    mcp_blend_input calm = {n, v,    32,  n,
                            v, NULL, NULL}; /* mean v = mean SURE: would filter */
    assert_int_equal(mcp_blend_step(&calm, NULL, NULL, &st, &res), 0);
    assert_true(!res.est.filtered && res.est.magnitude);
    mcp_blend_result_free(&res);
    mcp_image_free(big);
    mcp_image_free(small);
    mcp_image_free(n);
    mcp_image_free(v);
}

/* ---- a procedural series: on-the-fly and retrospective curves ---- */

enum { N_POINTS = 6 }; /* 4, 16, ..., 4096 spp */

/* A procedural series (fireflies off: one in 64^2 pixels makes MSE a lottery) with a
 * blur denoiser of sigma 2 px, which is biased: it smears the checkerboard edges. */
typedef struct {
    mcp_image *truth;
    mcp_dump *dump[N_POINTS];
    mcp_error_maps maps[N_POINTS];
    mcp_blend_estimates est[N_POINTS];
    double spp[N_POINTS];
} proc_series;

static void
proc_series_make(proc_series *ps)
{
    mcp_proc_scene scene = mcp_proc_scene_defaults();
    scene.firefly_probability = 0;
    assert_int_equal(mcp_proc_truth(&scene, &ps->truth, NULL), 0);
    mcp_denoiser *den = blur_denoiser(2.0, 9);
    mcp_sure_options so = mcp_sure_defaults();
    so.metric = MCP_METRIC_SE;
    mcp_blend_state st = {0, 0};
    for (int i = 0; i < N_POINTS; i++) {
        ps->spp[i] = 4 << (2 * i);
        assert_int_equal(mcp_proc_render(&scene, (int)ps->spp[i], 5, NULL, &ps->dump[i]),
                         0);
        assert_int_equal(mcp_error_maps_compute(ps->dump[i], den, &so, &ps->maps[i]), 0);
        assert_int_equal(mcp_blend_prepare(ps->dump[i]->var_of_mean, ps->maps[i].sure,
                                           NULL, NULL, &st, &ps->est[i]),
                         0);
    }
    den->destroy(den);
}

static void
proc_series_free(proc_series *ps)
{
    for (int i = 0; i < N_POINTS; i++) {
        mcp_blend_estimates_free(&ps->est[i]);
        mcp_error_maps_free(&ps->maps[i]);
        mcp_dump_free(ps->dump[i]);
    }
    mcp_image_free(ps->truth);
}

/* The MSE of the curve blend of point i with the given curves, with the safeguard
 * (the James-Stein cap over the default window) or without. */
static double
curve_mse(const proc_series *ps, int i, const mcp_image *curves, int safeguard)
{
    mcp_image *w = NULL, *r = NULL;
    double mse;
    const mcp_dump *dump = ps->dump[i];
    assert_int_equal(mcp_blend_weights(curves, ps->est[i].sure, NULL, &w), 0);
    assert_int_equal(mcp_blend_mix(dump->color, ps->spp[i], ps->maps[i].denoised, w, &r),
                     0);
    if (safeguard) {
        mcp_image *js = NULL, *rho = NULL;
        assert_int_equal(mcp_blend_james_stein(dump->color, ps->maps[i].denoised,
                                               dump->var_of_mean, 7, NULL, &js, &rho),
                         0);
        assert_int_equal(mcp_blend_safeguard(dump->color, ps->spp[i],
                                             ps->maps[i].denoised, rho, w, r, NULL),
                         0);
        mcp_image_free(js);
        mcp_image_free(rho);
    }
    assert_int_equal(mcp_mse(r, ps->truth, &mse), 0);
    mcp_image_free(w);
    mcp_image_free(r);
    return mse;
}

static void
test_series_converges_procedural(void **state)
{
    (void)state;
    proc_series ps;
    proc_series_make(&ps);
    const mcp_image *v[N_POINTS];
    for (int i = 0; i < N_POINTS; i++)
        v[i] = ps.est[i].var_of_mean;
    mcp_blend_options retro = mcp_blend_defaults();
    retro.fit = MCP_CURVE_FIT_RETROSPECTIVE;
    mcp_image *retro_curves = NULL;
    assert_int_equal(mcp_blend_curves(v, ps.spp, N_POINTS, &retro, &retro_curves), 0);
    printf("   spp  MSE noisy   denoised   on-the-fly retrospective safeguarded\n");
    for (int i = 0; i < N_POINTS; i++) {
        mcp_image *otf_curves = NULL;
        double noisy, den;
        assert_int_equal(mcp_blend_curves(&v[i], &ps.spp[i], 1, NULL, &otf_curves), 0);
        double otf = curve_mse(&ps, i, otf_curves, 0),
               ret = curve_mse(&ps, i, retro_curves, 0);
        double safe = curve_mse(&ps, i, otf_curves, 1);
        assert_int_equal(mcp_mse(ps.dump[i]->color, ps.truth, &noisy), 0);
        assert_int_equal(mcp_mse(ps.maps[i].denoised, ps.truth, &den), 0);
        printf("  %4g  %.3e  %.3e  %.3e  %.3e  %.3e\n", ps.spp[i], noisy, den, otf, ret,
               safe);
        mcp_image_free(otf_curves);
        /* Early on the blend beats both inputs. */
        if (ps.spp[i] <= 16)
            assert_true(otf < fmin(noisy, den) && ret < fmin(noisy, den));
        /* On the fly the curve has slope -2 (Eq. 11), so W / I = sqrt(v / SURE): where
         * d has a bias B >> sqrt(v), rho = W / (I + W) ~ sqrt(v) / B and the blend's
         * error is (1 - rho)^2 v + rho^2 B^2 ~ 2 v. It converges at the noisy image's
         * rate, with at most twice its MSE where the denoiser is biased. The
         * retrospective curve has the true slope (about -1), W / I ~ v / SURE, and the
         * bias term vanishes faster than v. */
        assert_true(otf <= 2.0 * noisy);
        /* The safeguard caps rho at the James-Stein weight ~ v / B^2 where the bias
         * shows (docs/blend.md "The safeguard"): the on-the-fly blend then ends within
         * 10% of the noisy MSE and is never above 1.5 x min(noisy, denoised). */
        assert_true(safe <= 1.5 * fmin(noisy, den));
        if (i == N_POINTS - 1) {
            assert_true(safe <= 1.1 * noisy);
            assert_true(ret <= 1.1 * noisy);
            assert_true(otf < 0.01 * den && ret < 0.01 * den);
        }
    }
    mcp_image_free(retro_curves);
    proc_series_free(&ps);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_weights_from_curves),
        cmocka_unit_test(test_mix),
        cmocka_unit_test(test_easy),
        cmocka_unit_test(test_ideal_reproduces_reference),
        cmocka_unit_test(test_step_matches_parts),
        cmocka_unit_test(test_step_vector_is_scalar),
        cmocka_unit_test(test_step_errors),
        cmocka_unit_test(test_series_converges_procedural),
    };
    return cmocka_run_group_tests_name("blend/weights", tests, NULL, NULL);
}
