/* test_self_influence.c: blend/self_influence.c -- the denoiser's self-influence
 * kappa = sum Cov(n, d) / sum v read back from SURE -- against its truth: the exact
 * diagonal of a linear blur, and for nlm the covariance of n and d measured over 48
 * renders; then the James-Stein combiner that uses it, against its closed-form risk
 * (docs/blend.md "Self-influence"). */
#include "blend_testing.h"

#include <mcpost/denoiser.h>
#include <mcpost/estimate.h>
#include "procedural.h"

#include <math.h>
#include <stdio.h>

enum { SIZE = 64 };

/* The procedural scene at SIZE x SIZE, fireflies off (a firefly's variance would be
 * most of sum v). */
static mcp_proc_scene
small_scene(void)
{
    mcp_proc_scene s = mcp_proc_scene_defaults();
    s.width = s.height = SIZE;
    s.firefly_probability = 0;
    return s;
}

/* kappa of den on dump, from one SURE with one probe (the blend's default). */
static void
kappa_of(const mcp_dump *dump, const mcp_denoiser *den, uint64_t seed, double kappa[3],
         mcp_image **denoised)
{
    mcp_sure_options so = mcp_sure_defaults();
    so.metric = MCP_METRIC_SE;
    so.seed = seed;
    mcp_error_maps maps;
    assert_int_equal(mcp_error_maps_compute(dump, den, &so, &maps), 0);
    assert_int_equal(mcp_blend_self_influence(dump->color, maps.denoised,
                                              dump->var_of_mean, maps.sure, kappa),
                     0);
    if (denoised) {
        *denoised = maps.denoised;
        maps.denoised = NULL;
    }
    mcp_error_maps_free(&maps);
}

/* Renders r of the procedural scene at spp without fireflies, or, gaussian = 1, its
 * truth plus Gaussian noise of one such render's variance (v fixed: what Stein's
 * lemma, behind SURE's divergence, assumes). */
static void
noisy_dump(const mcp_proc_scene *scene, const mcp_image *truth, int spp, int gaussian,
           int r, mcp_dump **out)
{
    assert_int_equal(mcp_proc_render(scene, spp, gaussian ? 1 : 100 + r, NULL, out), 0);
    if (!gaussian) return;
    mcp_dump *d = *out;
    uint64_t rng = 5000 + r;
    size_t n = (size_t)truth->width * truth->height * 3;
    for (size_t i = 0; i < n; i++)
        d->color->data[i] = (float)(truth->data[i] + sqrt(d->var_of_mean->data[i]) *
                                                         mcp_test_rand_normal(&rng));
}

/* One probe's estimate of sum v dd/dn carries (v - e^2) / 2 per value: a standard
 * deviation of sqrt(sum v^2 / 2) / sum v in kappa, 0.015-0.03 on these 64 x 64 images
 * (the off-diagonal terms add to it). The mean over RENDERS is within 4 of its own
 * standard deviations of the truth. */
enum { RENDERS = 48 };

/* A linear blur: Cov(n_i, d_i) = K_ii v_i exactly, K_ii the blur of a one-pixel
 * impulse read at the impulse (borders included). */
static void
test_blur_diagonal(void **state)
{
    (void)state;
    mcp_proc_scene scene = small_scene();
    mcp_denoiser *den = blur_denoiser(1.0, 5);
    mcp_image *impulse = rgb_constant(SIZE, SIZE, 0), *k_ii = rgb_constant(SIZE, SIZE, 0);
    for (int i = 0; i < SIZE * SIZE; i++) {
        impulse->data[3 * i] = 1;
        mcp_image *b = NULL;
        assert_int_equal(mcp_gaussian_blur(impulse, 5, 1.0, &b), 0);
        for (int c = 0; c < 3; c++)
            k_ii->data[3 * i + c] = b->data[3 * i];
        mcp_image_free(b);
        impulse->data[3 * i] = 0;
    }
    double k[RENDERS][3], truth[RENDERS][3];
    for (int r = 0; r < RENDERS; r++) {
        mcp_dump *dump = NULL;
        noisy_dump(&scene, NULL, 64, 0, r, &dump);
        double num[3] = {0, 0, 0}, sum_v[3] = {0, 0, 0};
        kappa_of(dump, den, 7 + r, k[r], NULL);
        for (int i = 0; i < SIZE * SIZE * 3; i++) {
            num[i % 3] += (double)dump->var_of_mean->data[i] * k_ii->data[i];
            sum_v[i % 3] += dump->var_of_mean->data[i];
        }
        for (int c = 0; c < 3; c++)
            truth[r][c] = num[c] / sum_v[c];
        mcp_dump_free(dump);
    }
    for (int c = 0; c < 3; c++) {
        double m = 0, m2 = 0, t = 0;
        for (int r = 0; r < RENDERS; r++) {
            double d = k[r][c] - truth[r][c];
            m += d / RENDERS;
            m2 += d * d / RENDERS;
            t += truth[r][c] / RENDERS;
        }
        double se = sqrt((m2 - m * m) / (RENDERS - 1));
        printf("  blur, channel %d: kappa - truth %+.4f (se %.4f), truth %.4f\n", c, m,
               se, t);
        assert_true(fabs(m) < 4 * se);
        assert_true(se < 0.01);
    }
    mcp_image_free(impulse);
    mcp_image_free(k_ii);
    den->destroy(den);
}

/* nlm, which is not linear, at 4 spp: sum_i Cov(n_i, d_i) / sum_i v_i measured over the
 * renders, against the mean estimate. With Gaussian noise of a fixed v (Stein's lemma
 * exact) the two agree within 4 standard errors (0.330 and 0.335). On the renders
 * themselves (skewed noise, and a v estimated from the same samples that nlm reads)
 * SURE's divergence sees less (0.31 against 0.44): checked to lie between 0.5 and 1 of
 * the measured one. */
static void
nlm_covariance(int gaussian, double *estimate, double *se, double *measured)
{
    enum { N = SIZE * SIZE * 3 };
    mcp_proc_scene scene = small_scene();
    mcp_image *truth = NULL;
    assert_int_equal(mcp_proc_truth(&scene, &truth, NULL), 0);
    mcp_denoiser *den = NULL;
    assert_int_equal(mcp_denoiser_create_from_args("nlm", NULL, 0, &den), 0);
    double *sn = calloc(N, sizeof(double)), *sd = calloc(N, sizeof(double)),
           *snd = calloc(N, sizeof(double)), *sv = calloc(N, sizeof(double));
    assert_true(sn && sd && snd && sv);
    double m = 0, m2 = 0;
    for (int r = 0; r < RENDERS; r++) {
        mcp_dump *dump = NULL;
        mcp_image *d = NULL;
        noisy_dump(&scene, truth, 4, gaussian, r, &dump);
        double kappa[3];
        kappa_of(dump, den, 31 + r, kappa, &d);
        double km = (kappa[0] + kappa[1] + kappa[2]) / 3;
        m += km / RENDERS;
        m2 += km * km / RENDERS;
        for (int i = 0; i < N; i++) {
            double n = dump->color->data[i], di = d->data[i];
            sn[i] += n;
            sd[i] += di;
            snd[i] += n * di;
            sv[i] += dump->var_of_mean->data[i];
        }
        mcp_image_free(d);
        mcp_dump_free(dump);
    }
    double cov = 0, var = 0;
    for (int i = 0; i < N; i++) {
        cov += (snd[i] - sn[i] * sd[i] / RENDERS) / (RENDERS - 1);
        var += sv[i] / RENDERS;
    }
    *estimate = m;
    *se = sqrt((m2 - m * m) / (RENDERS - 1));
    *measured = cov / var;
    free(sn), free(sd), free(snd), free(sv);
    mcp_image_free(truth);
    mcp_denoiser_free(den);
}

static void
test_nlm_covariance(void **state)
{
    (void)state;
    double k, se, measured;
    nlm_covariance(1, &k, &se, &measured);
    printf("  nlm, Gaussian noise: kappa %.4f (se %.4f), measured Cov(n, d) / v %.4f\n",
           k, se, measured);
    /* the measured ratio has its own noise: 48 renders, ~1% */
    assert_true(measured > 0.2 && measured < 0.8);
    assert_true(fabs(k - measured) < 4 * se + 0.01 * measured);
    nlm_covariance(0, &k, &se, &measured);
    printf("  nlm, the renders: kappa %.4f (se %.4f), measured %.4f\n", k, se, measured);
    assert_true(k > 0.5 * measured && k < measured);
}

/* The combiner with d = mu + b + a (n - mu): self-influence a, a bias of b^2 = beta v
 * per value. Over a 15x15 window |n - d|^2 concentrates at p v ((1 - a)^2 + beta), so
 * rho = min(1, share (p - 2) / p / ((1 - a)^2 + beta)) and the error per value is
 * v ((1 - rho (1 - a))^2 + rho^2 beta): for a = 0.7, beta = 1 the plain weight
 * (share 1) ends 1.37x the noisy image's error, the corrected one (share
 * min(1, 1.5 (1 - a)) = 0.45) 0.94x. Interior values, 16 seeds, within 2%. */
static void
test_combiner_risk(void **state)
{
    (void)state;
    enum { W = 96, WINDOW = 15 };
    const double a = 0.7, beta = 1.0, v = 0.01, p = WINDOW * WINDOW;
    const double kappa[3] = {a, a, a};
    double err[2] = {0, 0}, noisy = 0;
    for (int seed = 0; seed < 16; seed++) {
        uint64_t rng = 1000 + seed;
        mcp_image *n = rgb_constant(W, W, 0), *d = rgb_constant(W, W, 0),
                  *var = rgb_constant(W, W, (float)v);
        for (int i = 0; i < W * W * 3; i++) {
            double e = sqrt(v) * mcp_test_rand_normal(&rng);
            double b = (i % 2 ? 1 : -1) * sqrt(beta * v); /* mu = 0 */
            n->data[i] = (float)e;
            d->data[i] = (float)(b + a * e);
        }
        for (int corrected = 0; corrected < 2; corrected++) {
            mcp_image *r = NULL;
            assert_int_equal(mcp_blend_james_stein(n, d, var, WINDOW,
                                                   corrected ? kappa : NULL, &r, NULL),
                             0);
            for (int y = WINDOW; y < W - WINDOW; y++)
                for (int x = WINDOW; x < W - WINDOW; x++)
                    for (int c = 0; c < 3; c++) {
                        double e = mcp_image_px(r, x, y)[c];
                        err[corrected] += e * e;
                        if (!corrected) {
                            double en = mcp_image_px(n, x, y)[c];
                            noisy += en * en;
                        }
                    }
            mcp_image_free(r);
        }
        mcp_image_free(n), mcp_image_free(d), mcp_image_free(var);
    }
    double want[2];
    for (int corrected = 0; corrected < 2; corrected++) {
        double share = corrected ? fmin(1.0, 1.5 * (1 - a)) : 1.0;
        double rho = fmin(1.0, share * (p - 2) / p / ((1 - a) * (1 - a) + beta));
        want[corrected] = pow(1 - rho * (1 - a), 2) + rho * rho * beta;
    }
    printf("  combiner / noisy: plain %.4f (closed form %.4f), corrected %.4f (%.4f)\n",
           err[0] / noisy, want[0], err[1] / noisy, want[1]);
    for (int corrected = 0; corrected < 2; corrected++)
        assert_true(fabs(err[corrected] / noisy / want[corrected] - 1) < 0.02);
    assert_true(err[0] > noisy && err[1] < noisy);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_blur_diagonal),
        cmocka_unit_test(test_nlm_covariance),
        cmocka_unit_test(test_combiner_risk),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
