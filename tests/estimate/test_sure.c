/* test_sure.c: estimate/sure.c and estimate/probes.c against independent truths.
 *
 * The denoisers here are linear filters written in this file (a 3x3 box with
 * replicate borders, and a joint colour + albedo filter), so the expected squared
 * error has a closed form, E[(F_i - μ_i)²] = ((A - I)μ)_i² + (A Σ Aᵀ)_ii, and noise
 * with a known covariance can be drawn as often as we like. Statistical checks use
 * fixed seeds and compare a mean over R realizations with the truth within 3 standard
 * errors (a false alarm about 0.3% of the time for a fixed seed, so they are
 * deterministic, and 3 SE still catches a bias of a few percent at R = 200). When the
 * built-in `bilateral` denoiser exists, it is checked against the empirical MSE the
 * same way. */
#include "box_denoiser.h"
#include "testing.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#include <mcpost/estimate.h>
#include <mcpost/flip.h>
#include "../../common/dump/internal.h"
#include "../../estimate/internal.h"

#define W 32
#define H 24
#define R_REALIZATIONS 200

/* ---- linear test denoisers ---- */

/* out = 3x3 box of in (replicate borders), every channel. */
/* Joint: F = box(x) + BETA (a - box(a)) with a the albedo, linear in both. */
#define BETA 0.5

static void
joint_eval(const mcp_image *x, const mcp_image *a, mcp_image *out)
{
    mcp_image *ba = mcp_test_rgb(x->width, x->height);
    mcp_test_box3(x, out);
    if (a) {
        mcp_test_box3(a, ba);
        for (int y = 0; y < x->height; y++)
            for (int i = 0; i < x->width; i++)
                for (int c = 0; c < 3; c++)
                    mcp_image_px(out, i, y)[c] +=
                        (float)(BETA *
                                (mcp_image_px(a, i, y)[c] - mcp_image_px(ba, i, y)[c]));
    }
    mcp_image_free(ba);
}

static int
joint_apply(const mcp_denoiser *self, const mcp_denoise_input *in, mcp_image **out)
{
    (void)self;
    *out = mcp_test_rgb(in->color->width, in->color->height);
    joint_eval(in->color, in->albedo, *out);
    return 0;
}

static int
joint_jvp(const mcp_denoiser *self, const mcp_denoise_input *at,
          const mcp_denoise_tangent *t, int n, mcp_image **primal, mcp_image **out)
{
    if (primal) joint_apply(self, at, primal);
    for (int k = 0; k < n; k++) {
        out[k] = mcp_test_rgb(at->color->width, at->color->height);
        joint_eval(t[k].color, t[k].albedo, out[k]);
    }
    return 0;
}

static const mcp_denoiser joint_denoiser = {.name = "joint",
                                            .exact = 1,
                                            .uses_albedo = 1,
                                            .apply = joint_apply,
                                            .jvp = joint_jvp};

/* ---- a scene with known mean and covariance ---- */

static double
mu_at(int x, int y, int c)
{
    double v = 0.3 + 0.2 * c + 0.02 * x + 0.01 * y;
    if (x >= 8 && x < 16 && y >= 6 && y < 14) v += 1.5;
    return v;
}

static double
sigma_at(int x, int y, int c)
{
    (void)y;
    return 0.1 + 0.2 * x / (double)W + 0.05 * c;
}

#define RHO 0.4 /* correlation between colour channels */

static void
cov_at(int x, int y, double s[9])
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            s[3 * i + j] = (i == j ? 1.0 : RHO) * sigma_at(x, y, i) * sigma_at(x, y, j);
}

static void
chol3(const double a[9], double l[9])
{
    memset(l, 0, 9 * sizeof *l);
    for (int j = 0; j < 3; j++) {
        double d = a[3 * j + j];
        for (int k = 0; k < j; k++)
            d -= l[3 * j + k] * l[3 * j + k];
        l[3 * j + j] = sqrt(d);
        for (int i = j + 1; i < 3; i++) {
            double s = a[3 * i + j];
            for (int k = 0; k < j; k++)
                s -= l[3 * i + k] * l[3 * j + k];
            l[3 * i + j] = s / l[3 * j + j];
        }
    }
}

static mcp_image *
mean_image(void)
{
    mcp_image *m = mcp_test_rgb(W, H);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int c = 0; c < 3; c++)
                mcp_image_px(m, x, y)[c] = (float)mu_at(x, y, c);
    return m;
}

/* A dump with colour μ + L z (z from *rng), the exact variance and covariance. */
static mcp_dump *
realization(uint64_t *rng, int with_cov)
{
    mcp_dump *d = calloc(1, sizeof *d);
    assert_non_null(d);
    static const char *const cov_names[] = {"RG", "RB", "GB"};
    d->color = mcp_test_rgb(W, H);
    d->var_of_mean = mcp_test_rgb(W, H);
    if (with_cov) assert_int_equal(mcp_image_new(W, H, 3, cov_names, &d->cov_of_mean), 0);
    d->spp = 16;
    d->source = strdup("synthetic");
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            double s[9], l[9], z[3];
            cov_at(x, y, s);
            if (!with_cov) s[1] = s[2] = s[3] = s[5] = s[6] = s[7] = 0.0;
            chol3(s, l);
            for (int c = 0; c < 3; c++)
                z[c] = mcp_test_rand_normal(rng);
            for (int c = 0; c < 3; c++) {
                double e = l[3 * c] * z[0] + l[3 * c + 1] * z[1] + l[3 * c + 2] * z[2];
                mcp_image_px(d->color, x, y)[c] = (float)(mu_at(x, y, c) + e);
                mcp_image_px(d->var_of_mean, x, y)[c] = (float)s[4 * c];
            }
            if (with_cov) {
                float *o = mcp_image_px(d->cov_of_mean, x, y);
                o[0] = (float)s[1];
                o[1] = (float)s[2];
                o[2] = (float)s[5];
            }
        }
    return d;
}

/* The mean over values of E[(box(X) - μ)²]: ((A - I)μ)² + Σ_q A_pq² Σ_q,cc. */
static double
box_expected_mse(int with_cov)
{
    (void)with_cov; /* A acts per channel, so only the diagonal of Σ enters */
    double total = 0.0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            double wgt[W * H] = {0}; /* A_pq for this p (replicate borders fold taps) */
            for (int dy = -1; dy <= 1; dy++)
                for (int dx = -1; dx <= 1; dx++) {
                    int xx = x + dx < 0 ? 0 : x + dx >= W ? W - 1 : x + dx;
                    int yy = y + dy < 0 ? 0 : y + dy >= H ? H - 1 : y + dy;
                    wgt[yy * W + xx] += 1.0 / 9.0;
                }
            for (int c = 0; c < 3; c++) {
                double am = 0.0, var = 0.0;
                for (int q = 0; q < W * H; q++)
                    if (wgt[q] != 0.0) {
                        am += wgt[q] * mu_at(q % W, q / W, c);
                        double sg = sigma_at(q % W, q / W, c);
                        var += wgt[q] * wgt[q] * sg * sg;
                    }
                double bias = am - mu_at(x, y, c);
                total += bias * bias + var;
            }
        }
    return total / (W * H * 3);
}

static double
image_mean(const mcp_image *img)
{
    double s = 0.0;
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++)
            for (int c = 0; c < 3; c++)
                s += mcp_image_px(img, x, y)[c];
    return s / ((double)img->width * img->height * 3);
}

/* mean over values of (F - μ)², F from the denoiser on d. */
static double
true_mse(const mcp_denoiser *den, const mcp_dump *d, const mcp_image *mu)
{
    mcp_denoise_input in = {0};
    in.color = d->color;
    in.albedo = d->albedo;
    mcp_image *f = NULL;
    assert_int_equal(den->apply(den, &in, &f), 0);
    double s = 0.0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int c = 0; c < 3; c++) {
                double e = (double)mcp_image_px(f, x, y)[c] - mcp_image_px(mu, x, y)[c];
                s += e * e;
            }
    mcp_image_free(f);
    return s / (W * H * 3);
}

typedef struct running {
    double n, mean, m2;
} running;

static void
push(running *r, double v)
{
    r->n += 1;
    double d = v - r->mean;
    r->mean += d / r->n;
    r->m2 += d * (v - r->mean);
}

static double
std_error(const running *r)
{
    return sqrt(r->m2 / (r->n - 1) / r->n);
}

/* ---- the estimator formula itself ---- */

static void
test_formula_is_alg2(void **state)
{
    (void)state;
    uint64_t rng = 11;
    mcp_dump *d = realization(&rng, 1);
    mcp_sure_options o = mcp_sure_defaults();
    o.n_probes = 2;
    o.seed = 5;
    mcp_error_maps m;
    assert_int_equal(mcp_error_maps_compute(d, &mcp_test_box_denoiser, &o, &m), 0);
    mcp_probe p[2];
    mcp_image *jp[2], *f = mcp_test_rgb(W, H);
    mcp_test_box3(d->color, f);
    for (int k = 0; k < 2; k++) {
        assert_int_equal(mcp_probe_gaussian(d, NULL, 5, k, &p[k]), 0);
        jp[k] = mcp_test_rgb(W, H);
        mcp_test_box3(p[k].color, jp[k]);
    }
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            const float *pf = mcp_image_px(f, x, y);
            double mc = fmax(fmax(pf[0], pf[1]), pf[2]), den = mc * mc + 1e-2;
            for (int c = 0; c < 3; c++) {
                double diff = pf[c] - mcp_image_px(d->color, x, y)[c], t = 0.0, v = 0.0;
                for (int k = 0; k < 2; k++) {
                    double e = mcp_image_px(p[k].color, x, y)[c];
                    double je = mcp_image_px(jp[k], x, y)[c];
                    t += e * (2 * je - e);
                    v += je * je;
                }
                double sure = diff * diff + t / 2, var = v / 2;
                assert_close(mcp_image_px(m.sure, x, y)[c], sure, 1e-5, 1e-7);
                assert_close(mcp_image_px(m.sure_rel, x, y)[c], sure / den, 1e-5, 1e-7);
                assert_close(mcp_image_px(m.var, x, y)[c], var, 1e-5, 1e-9);
                assert_close(mcp_image_px(m.var_rel, x, y)[c], var / den, 1e-5, 1e-9);
                assert_close(mcp_image_px(m.sigma_rel, x, y)[c],
                             mcp_image_px(d->var_of_mean, x, y)[c] / den, 1e-5, 1e-9);
            }
            assert_close(mcp_image_px(m.denominator, x, y)[0], den, 1e-6, 0);
        }
    /* mcp_sure gives the scaled map of the metric */
    mcp_image *s = NULL;
    assert_int_equal(mcp_sure(d, &mcp_test_box_denoiser, &o, &s), 0);
    assert_true(mcp_test_max_abs_diff(s, m.sure_rel) == 0.0);
    mcp_image_free(s);
    o.metric = MCP_METRIC_SE;
    assert_int_equal(mcp_sure(d, &mcp_test_box_denoiser, &o, &s), 0);
    assert_true(mcp_test_max_abs_diff(s, m.sure) == 0.0);
    mcp_image_free(s);
    for (int k = 0; k < 2; k++) {
        mcp_probe_clear(&p[k]);
        mcp_image_free(jp[k]);
    }
    mcp_image_free(f);
    mcp_error_maps_free(&m);
    mcp_dump_free(d);
}

/* The estimate hands its evaluation to the maps (mcp__error_maps_from_own_probes):
 * the same values, bit for bit, as the copying call, with F(X) and five of the
 * probes' and JVPs' images taken for the maps (slots NULL), none for
 * relse-perceptual, none beyond those five, and none offered twice. */
static void
test_maps_in_the_probes_images(void **state)
{
    (void)state;
    uint64_t rng = 23;
    mcp_dump *d = realization(&rng, 1);
    const int ks[] = {1, 2, 3, 4};
    const mcp_error_metric metrics[] = {MCP_METRIC_RELSE, MCP_METRIC_SE,
                                        MCP_METRIC_RELSE_PERCEPTUAL};
    for (size_t mi = 0; mi < sizeof metrics / sizeof *metrics; mi++)
        for (size_t ki = 0; ki < sizeof ks / sizeof *ks; ki++) {
            const int k = ks[ki];
            mcp_sure_options o = mcp_sure_defaults();
            o.metric = metrics[mi];
            mcp_image *f = mcp_test_rgb(W, H), *probes[4], *jvps[4];
            mcp_test_box3(d->color, f);
            for (int j = 0; j < k; j++) {
                mcp_probe p;
                assert_int_equal(mcp_probe_gaussian(d, NULL, 9, j, &p), 0);
                probes[j] = p.color;
                jvps[j] = mcp_test_rgb(W, H);
                mcp_test_box3(probes[j], jvps[j]);
            }
            mcp_error_maps copied, owned;
            assert_int_equal(mcp_error_maps_from_probes(
                                 d, f, (const mcp_image *const *)probes,
                                 (const mcp_image *const *)jvps, k, &o, &copied),
                             0);
            assert_int_equal(
                mcp__error_maps_from_own_probes(d, &f, probes, jvps, k, &o, NULL, &owned),
                0);
            const mcp_image *a[] = {copied.denoised,   copied.sure,    copied.sure_rel,
                                    copied.var,        copied.var_rel, copied.sigma_rel,
                                    copied.denominator};
            const mcp_image *b[] = {owned.denoised,   owned.sure,    owned.sure_rel,
                                    owned.var,        owned.var_rel, owned.sigma_rel,
                                    owned.denominator};
            for (int i = 0; i < 7; i++) {
                assert_int_equal(a[i]->channels, b[i]->channels);
                for (int c = 0; c < a[i]->channels; c++)
                    assert_string_equal(a[i]->names[c], b[i]->names[c]);
                assert_string_equal(a[i]->source ? a[i]->source : "",
                                    b[i]->source ? b[i]->source : "");
                assert_int_equal(a[i]->attrs.count, b[i]->attrs.count);
                assert_true(mcp_test_max_abs_diff(a[i], b[i]) == 0.0);
            }
            int taken = 0;
            for (int j = 0; j < k; j++)
                taken += (probes[j] == NULL) + (jvps[j] == NULL);
            const int perceptual = metrics[mi] == MCP_METRIC_RELSE_PERCEPTUAL;
            assert_int_equal(taken, perceptual ? 0 : (2 * k < 5 ? 2 * k : 5));
            assert_true(perceptual ? f != NULL : f == NULL);
            for (int j = 0; j < k; j++) {
                mcp_image_free(probes[j]);
                mcp_image_free(jvps[j]);
            }
            mcp_image_free(f);
            mcp_error_maps_free(&copied);
            mcp_error_maps_free(&owned);
        }
    /* an image offered twice (as a probe and as a JVP) is not taken: the maps would
       share it */
    mcp_probe p0, p1;
    assert_int_equal(mcp_probe_gaussian(d, NULL, 9, 0, &p0), 0);
    assert_int_equal(mcp_probe_gaussian(d, NULL, 9, 1, &p1), 0);
    mcp_image *f = mcp_test_rgb(W, H), *j1 = mcp_test_rgb(W, H);
    mcp_test_box3(d->color, f);
    mcp_test_box3(p1.color, j1);
    mcp_image *probes[2] = {p0.color, p1.color}, *jvps[2] = {p0.color, j1};
    mcp_error_maps copied, owned;
    assert_int_equal(mcp_error_maps_from_probes(d, f, (const mcp_image *const *)probes,
                                                (const mcp_image *const *)jvps, 2, NULL,
                                                &copied),
                     0);
    assert_int_equal(
        mcp__error_maps_from_own_probes(d, &f, probes, jvps, 2, NULL, NULL, &owned), 0);
    assert_ptr_equal(probes[0], p0.color);
    assert_ptr_equal(jvps[0], p0.color);
    assert_null(probes[1]);
    assert_null(jvps[1]);
    assert_true(mcp_test_max_abs_diff(copied.sure, owned.sure) == 0.0);
    assert_true(mcp_test_max_abs_diff(copied.var_rel, owned.var_rel) == 0.0);
    mcp_image_free(p0.color);
    mcp_error_maps_free(&copied);
    mcp_error_maps_free(&owned);
    mcp_dump_free(d);
}

/* ---- unbiasedness ---- */

static void
test_unbiased_linear_closed_form(void **state)
{
    (void)state;
    const double truth = box_expected_mse(1);
    mcp_image *mu = mean_image();
    running sure = {0}, emp = {0}, diff = {0};
    uint64_t rng = 2024;
    for (int r = 0; r < R_REALIZATIONS; r++) {
        mcp_dump *d = realization(&rng, 1);
        mcp_sure_options o = mcp_sure_defaults();
        o.metric = MCP_METRIC_SE;
        o.seed = 1000 + r;
        mcp_image *s = NULL;
        assert_int_equal(mcp_sure(d, &mcp_test_box_denoiser, &o, &s), 0);
        double ms = image_mean(s), me = true_mse(&mcp_test_box_denoiser, d, mu);
        push(&sure, ms);
        push(&emp, me);
        push(&diff, ms - me);
        mcp_image_free(s);
        mcp_dump_free(d);
    }
    print_message(
        "SURE (box, K=1, colour covariance): mean %.6g +- %.2g, closed form %.6g "
        "(%.2f SE); empirical MSE %.6g +- %.2g\n",
        sure.mean, std_error(&sure), truth, (sure.mean - truth) / std_error(&sure),
        emp.mean, std_error(&emp));
    assert_true(fabs(sure.mean - truth) <= 3 * std_error(&sure));
    assert_true(fabs(emp.mean - truth) <= 3 * std_error(&emp)); /* the scene is right */
    assert_true(fabs(diff.mean) <= 3 * std_error(&diff));
    mcp_image_free(mu);
}

/* SURE_M against the empirical perceptual error, paired per realization. */
static void
test_unbiased_perceptual(void **state)
{
    (void)state;
    const double ppd = 8.0; /* small kernels for a 32 x 24 image */
    mcp_image *mu = mean_image();
    running diff = {0}, sure = {0};
    uint64_t rng = 77;
    for (int r = 0; r < R_REALIZATIONS; r++) {
        mcp_dump *d = realization(&rng, 1);
        mcp_sure_options o = mcp_sure_defaults();
        o.metric = MCP_METRIC_RELSE_PERCEPTUAL;
        o.ppd = ppd;
        o.seed = 5000 + r;
        mcp_error_maps m;
        assert_int_equal(mcp_error_maps_compute(d, &mcp_test_box_denoiser, &o, &m), 0);
        /* truth: (M(F - μ))² in the same units (sure is not divided) */
        mcp_image *e = mcp_test_rgb(W, H), *me = NULL;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                for (int c = 0; c < 3; c++)
                    mcp_image_px(e, x, y)[c] =
                        mcp_image_px(m.denoised, x, y)[c] - mcp_image_px(mu, x, y)[c];
        assert_int_equal(mcp_flip_csf_apply(e, ppd, &me), 0);
        double t = 0.0;
        for (size_t i = 0; i < (size_t)W * H * 3; i++)
            t += (double)me->data[i] * me->data[i];
        t /= W * H * 3;
        double s = image_mean(m.sure);
        push(&diff, s - t);
        push(&sure, s);
        mcp_image_free(e);
        mcp_image_free(me);
        mcp_error_maps_free(&m);
        mcp_dump_free(d);
    }
    print_message("SURE_M (box, ppd 8): mean %.6g; SURE_M - (M(F-mu))^2 = %.3g +- %.2g "
                  "(%.2f SE)\n",
                  sure.mean, diff.mean, std_error(&diff), diff.mean / std_error(&diff));
    assert_true(fabs(diff.mean) <= 3 * std_error(&diff));
    mcp_image_free(mu);
}

/* Joint SURE: colour and albedo noise correlated; the joint estimate is unbiased and
 * plain SURE (which ignores Cov(x, a)) is not. */
#define SIGMA_A 0.2
#define RHO_XA 0.6

static void
add_albedo(mcp_dump *d, uint64_t *rng, const double *zx_scale)
{
    (void)zx_scale;
    d->albedo = mcp_test_rgb(W, H);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int c = 0; c < 3; c++) {
                /* a = ν + ρ σ_a (x - μ)/σ_x + sqrt(1 - ρ²) σ_a z: Cov(x, a) = ρ σ_x σ_a
                 */
                double sx = sigma_at(x, y, c);
                double ex = mcp_image_px(d->color, x, y)[c] - mu_at(x, y, c);
                double a =
                    0.5 + RHO_XA * SIGMA_A * ex / sx +
                    sqrt(1 - RHO_XA * RHO_XA) * SIGMA_A * mcp_test_rand_normal(rng);
                mcp_image_px(d->albedo, x, y)[c] = (float)a;
            }
}

static void
test_joint_sure(void **state)
{
    (void)state;
    mcp_image *cross = NULL, *avar = mcp_test_rgb(W, H);
    assert_int_equal(mcp_image_new(W, H, 9, NULL, &cross), 0);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int c = 0; c < 3; c++) {
                mcp_image_px(cross, x, y)[4 * c] =
                    (float)(RHO_XA * sigma_at(x, y, c) * SIGMA_A);
                mcp_image_px(avar, x, y)[c] = (float)(SIGMA_A * SIGMA_A);
            }
    /* the albedo mean ν = 0.5 is flat, so the truth is that of box(x) plus the
     * noise that BETA (a - box(a)) adds */
    mcp_image *mu = mean_image();
    running joint = {0}, joint_novar = {0}, plain = {0};
    uint64_t rng = 99;
    for (int r = 0; r < R_REALIZATIONS; r++) {
        mcp_dump *d = realization(&rng, 0);
        add_albedo(d, &rng, NULL);
        double t = true_mse(&joint_denoiser, d, mu);
        mcp_feature_covariance fc = {0};
        fc.color_albedo = cross;
        fc.albedo_var = avar;
        mcp_sure_options o = mcp_sure_defaults();
        o.metric = MCP_METRIC_SE;
        o.seed = 300 + r;
        o.features = &fc;
        mcp_image *s = NULL;
        assert_int_equal(mcp_sure(d, &joint_denoiser, &o, &s), 0);
        push(&joint, image_mean(s) - t);
        mcp_image_free(s);
        fc.albedo_var = NULL; /* the smallest consistent feature covariance */
        assert_int_equal(mcp_sure(d, &joint_denoiser, &o, &s), 0);
        push(&joint_novar, image_mean(s) - t);
        mcp_image_free(s);
        o.features = NULL;
        assert_int_equal(mcp_sure(d, &joint_denoiser, &o, &s), 0);
        push(&plain, image_mean(s) - t);
        mcp_image_free(s);
        mcp_dump_free(d);
    }
    print_message("joint SURE - MSE: %.3g +- %.2g (%.2f SE); without feature variance "
                  "%.3g +- %.2g; plain SURE - MSE: %.3g +- %.2g (%.1f SE, biased)\n",
                  joint.mean, std_error(&joint), joint.mean / std_error(&joint),
                  joint_novar.mean, std_error(&joint_novar), plain.mean,
                  std_error(&plain), plain.mean / std_error(&plain));
    assert_true(fabs(joint.mean) <= 3 * std_error(&joint));
    assert_true(fabs(joint_novar.mean) <= 3 * std_error(&joint_novar));
    assert_true(fabs(plain.mean) > 10 * std_error(&plain));
    mcp_image_free(cross);
    mcp_image_free(avar);
    mcp_image_free(mu);
}

/* ---- MC-SURE and K ---- */

static void
test_mc_sure_equals_exact_for_linear(void **state)
{
    (void)state;
    uint64_t rng = 3;
    mcp_dump *d = realization(&rng, 1);
    mcp_sure_options o = mcp_sure_defaults();
    o.metric = MCP_METRIC_SE;
    o.n_probes = 3;
    mcp_image *exact = NULL, *fd = NULL;
    assert_int_equal(mcp_sure(d, &mcp_test_box_denoiser, &o, &exact), 0);
    const double deltas[] = {1e-2, 0.1, 1.0};
    for (int i = 0; i < 3; i++) {
        o.mc_sure = 1;
        o.fd_delta = deltas[i];
        assert_int_equal(mcp_sure(d, &mcp_test_box_denoiser, &o, &fd), 0);
        /* a linear F has exact finite differences; what is left is float rounding of
         * F(X + δε) - F(X) (values ~2, steps ~δσ), about 1e-7 * 2 / δ relative to σ² */
        double tol = 4e-6 / deltas[i];
        double err = mcp_test_max_abs_diff(fd, exact);
        print_message("MC-SURE delta %g: max |MC-SURE - SURE| = %.3g\n", deltas[i], err);
        assert_true(err <= tol);
        mcp_image_free(fd);
    }
    mcp_image_free(exact);
    mcp_dump_free(d);
}

/* The probe term's variance falls as 1/K. */
static void
test_more_probes_less_noise(void **state)
{
    (void)state;
    uint64_t rng = 8;
    mcp_dump *d = realization(&rng, 1);
    running v[2];
    memset(v, 0, sizeof v);
    const int ks[2] = {1, 4};
    for (int i = 0; i < 2; i++)
        for (int s = 0; s < 60; s++) {
            mcp_sure_options o = mcp_sure_defaults();
            o.metric = MCP_METRIC_SE;
            o.n_probes = ks[i];
            o.seed = 7000 + s;
            mcp_image *m = NULL;
            assert_int_equal(mcp_sure(d, &mcp_test_box_denoiser, &o, &m), 0);
            push(&v[i], image_mean(m));
            mcp_image_free(m);
        }
    double ratio = (v[1].m2 / (v[1].n - 1)) / (v[0].m2 / (v[0].n - 1));
    print_message("variance of SURE over probe seeds, K=4 / K=1: %.3f (expect 0.25)\n",
                  ratio);
    /* 60 seeds: the ratio of two sample variances has a spread of about +-40% */
    assert_true(ratio > 0.1 && ratio < 0.5);
    mcp_dump_free(d);
}

/* ---- probes ---- */

static void
probe_moments(const mcp_dump *d, int rademacher, int n, int px, int py, double cov[9])
{
    memset(cov, 0, 9 * sizeof *cov);
    for (int k = 0; k < n; k++) {
        mcp_probe p = {0};
        mcp_image *v = NULL;
        if (rademacher)
            assert_int_equal(mcp_probe_rademacher(d, 42, k, &v), 0);
        else
            assert_int_equal(mcp_probe_gaussian(d, NULL, 42, k, &p), 0);
        const float *e = mcp_image_px(rademacher ? v : p.color, px, py);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                cov[3 * i + j] += (double)e[i] * e[j] / n;
        mcp_probe_clear(&p);
        mcp_image_free(v);
    }
}

static void
test_probe_covariance(void **state)
{
    (void)state;
    uint64_t rng = 1;
    mcp_dump *d = realization(&rng, 1);
    const int n = 4000;
    for (int rad = 0; rad < 2; rad++) {
        double cov[9], s[9];
        probe_moments(d, rad, n, 20, 7, cov);
        cov_at(20, 7, s);
        for (int i = 0; i < 9; i++) /* sample covariance: sd about s_ii s_jj sqrt(2/n) */
            assert_close(cov[i], s[i], 0,
                         5 * sqrt(2.0 / n) * sqrt(s[4 * (i / 3)] * s[4 * (i % 3)]));
    }
    /* diagonal only: Rademacher entries are exactly +-sigma */
    mcp_image_free(d->cov_of_mean);
    d->cov_of_mean = NULL;
    mcp_image *v = NULL;
    assert_int_equal(mcp_probe_rademacher(d, 3, 0, &v), 0);
    for (int c = 0; c < 3; c++)
        assert_close(fabs(mcp_image_px(v, 5, 5)[c]), sigma_at(5, 5, c), 1e-6, 0);
    mcp_image_free(v);
    mcp_dump_free(d);
}

/* Σ̂ with a negative eigenvalue: the probe covariance is Σ̂ with it clamped to 0. */
static void
test_probe_clamps_negative_eigenvalues(void **state)
{
    (void)state;
    uint64_t rng = 4;
    mcp_dump *d = realization(&rng, 1);
    /* at one pixel: variances 1, 1, 1 and covariances 0.9, 0.9, -0.9 (not PSD:
     * eigenvalues 1.9, 1.9, -0.8) */
    for (int c = 0; c < 3; c++)
        mcp_image_px(d->var_of_mean, 3, 3)[c] = 1.0f;
    float *o = mcp_image_px(d->cov_of_mean, 3, 3);
    o[0] = 0.9f, o[1] = 0.9f, o[2] = -0.9f;
    /* clamped: Σ + 0.8 v vᵀ with v the unit eigenvector of -0.8, (1, -1, -1)/√3 */
    const double vv[3] = {1 / sqrt(3.0), -1 / sqrt(3.0), -1 / sqrt(3.0)};
    const double s[9] = {1, 0.9, 0.9, 0.9, 1, -0.9, 0.9, -0.9, 1};
    const int n = 6000;
    double cov[9];
    probe_moments(d, 0, n, 3, 3, cov);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double want = s[3 * i + j] + 0.8 * vv[i] * vv[j];
            assert_close(cov[3 * i + j], want, 0, 5 * sqrt(2.0 / n) * 1.9);
        }
    mcp_dump_free(d);
}

static void
test_probes_do_not_depend_on_threads(void **state)
{
    (void)state;
#ifdef _OPENMP
    uint64_t rng = 6;
    mcp_dump *d = realization(&rng, 1);
    mcp_image *a = NULL, *b = NULL;
    int saved = omp_get_max_threads();
    omp_set_num_threads(1);
    mcp_sure_options o = mcp_sure_defaults();
    o.n_probes = 2;
    assert_int_equal(mcp_sure(d, &mcp_test_box_denoiser, &o, &a), 0);
    omp_set_num_threads(3);
    assert_int_equal(mcp_sure(d, &mcp_test_box_denoiser, &o, &b), 0);
    omp_set_num_threads(saved);
    assert_true(mcp_test_max_abs_diff(a, b) == 0.0);
    mcp_image_free(a);
    mcp_image_free(b);
    mcp_dump_free(d);
#endif
}

/* Whether rows y0 .. of whole equal band's, bit for bit. */
static void
assert_rows_equal(const mcp_image *whole, const mcp_image *band, int y0)
{
    for (int y = 0; y < band->height; y++)
        assert_memory_equal(mcp_image_px(whole, 0, y0 + y), mcp_image_px(band, 0, y),
                            (size_t)band->width * 3 * sizeof(float));
}

/* A probe drawn for a band of rows (a dump read in bands) is those rows of the whole
 * image's probe, bit for bit: Gaussian with the colour covariance (a draw per pixel)
 * and without it (rows of normals drawn in vectors), and Rademacher with and without
 * it; bands at the top, inside and at the bottom. */
static void
test_probe_rows_are_the_whole_probes(void **state)
{
    (void)state;
    static const int bands[3][2] = {{0, 5}, {7, 19}, {H - 3, H}};
    for (int with_cov = 0; with_cov < 2; with_cov++) {
        uint64_t rng = 21;
        mcp_dump *d = realization(&rng, with_cov);
        for (int k = 0; k < 3; k++) {
            mcp_probe whole;
            mcp_image *rad = NULL;
            assert_int_equal(mcp_probe_gaussian(d, NULL, 17, k, &whole), 0);
            assert_int_equal(mcp_probe_rademacher(d, 17, k, &rad), 0);
            for (int b = 0; b < 3; b++) {
                const int y0 = bands[b][0], y1 = bands[b][1];
                mcp_dump band;
                assert_int_equal(mcp__dump_rows_view(d, y0, y1, &band), 0);
                mcp_probe p;
                mcp_image *r = NULL;
                assert_int_equal(mcp__probe_gaussian_rows(&band, y0, NULL, 17, k, &p), 0);
                assert_int_equal(mcp__probe_rademacher_rows(&band, y0, 17, k, &r), 0);
                assert_int_equal(p.color->height, y1 - y0);
                assert_rows_equal(whole.color, p.color, y0);
                assert_rows_equal(rad, r, y0);
                mcp_probe_clear(&p);
                mcp_image_free(r);
                mcp__dump_rows_view_free(&band);
            }
            mcp_probe_clear(&whole);
            mcp_image_free(rad);
        }
        mcp_dump_free(d);
    }
}

/* Box-Muller's own ln u, sin 2 pi u and cos 2 pi u (probes.c) against libm's double
 * functions at every argument the draws give them that a stride of 61 hits (2^24 / 61:
 * 275 thousand, the smallest u and u = 1 among them): ln within 2e-7 relative (a few
 * float roundings; 1e-7 near u = 1, where ln u is small, measured absolutely), sin and
 * cos within 3e-7 absolute. Then a diagonal probe (whose rows are drawn in vectors)
 * against the same streams drawn one normal at a time (mcp__rng_normal): the same bits.
 */
static void
test_box_muller_functions(void **state)
{
    (void)state;
    double worst_log = 0, worst_trig = 0;
    for (uint32_t k = 0; k < (1u << 24); k += 61) {
        const float u1 = (float)(k + 1) * 0x1.0p-24f, u2 = (float)k * 0x1.0p-24f;
        const double want = log((double)u1), got = mcp__log_unit(u1);
        const double err = fabs(got - want) / (fabs(want) > 0.5 ? fabs(want) : 0.5);
        worst_log = err > worst_log ? err : worst_log;
        float sn, cs;
        mcp__sincos_turn(u2, &sn, &cs);
        const double th = 2 * 3.14159265358979323846 * (double)u2;
        const double e2 = fmax(fabs(sn - sin(th)), fabs(cs - cos(th)));
        worst_trig = e2 > worst_trig ? e2 : worst_trig;
    }
    const float one = 1.0f, tiny = 0x1.0p-24f;
    assert_true(mcp__log_unit(one) == 0.0f);
    assert_close(mcp__log_unit(tiny), log((double)tiny), 2e-7 * 16.7, 0);
    if (worst_log > 2e-7 || worst_trig > 3e-7)
        fail_msg("ln worst %.3g (relative), sin/cos worst %.3g", worst_log, worst_trig);

    uint64_t rng = 8;
    mcp_dump *d = realization(&rng, 1);
    mcp_image_free(d->cov_of_mean);
    d->cov_of_mean = NULL;
    mcp_probe p;
    assert_int_equal(mcp_probe_gaussian(d, NULL, 77, 2, &p), 0);
    const int w = p.color->width;
    for (int y = 0; y < p.color->height; y++)
        for (int x = 0; x < w; x++) {
            mcp__rng r;
            mcp__rng_init(&r, 77, 1 /* STREAM_GAUSS */, 2, (uint64_t)y * w + x);
            const float *var = mcp_image_px(d->var_of_mean, x, y);
            for (int c = 0; c < 3; c++) {
                const float want = (float)(sqrt(var[c] > 0.0f ? (double)var[c] : 0.0) *
                                           mcp__rng_normal(&r));
                if (mcp_image_px(p.color, x, y)[c] != want)
                    fail_msg("probe at %d,%d channel %d: %a, one at a time %a", x, y, c,
                             (double)mcp_image_px(p.color, x, y)[c], (double)want);
            }
        }
    mcp_probe_clear(&p);
    mcp_dump_free(d);
}

/* ---- the probes' variance floor (probe_floor.c) ---- */

/* A variance of 1 + c everywhere but a lone firefly (100) at (5, 5), a quiet pixel
 * (0.01) at (20, 12) and a black one (0: every sample equal) at (8, 20), with a
 * covariance of correlation 0.8 between every channel pair: with radius 1 the quiet
 * pixel is raised to its window's median, 1 + c, the black one keeps its 0, the firefly
 * keeps its own value and none of its neighbours takes any of it (a window mean would
 * have given them 11.9 + c), every other value is unchanged, and the correlations stay
 * 0.8. Radius 0 copies; the automatic radius is the denoiser's (1 for the U-Net). */
static void
test_probe_floor(void **state)
{
    (void)state;
    static const char *const cov_names[] = {"RG", "RB", "GB"};
    static const int pair[3][2] = {{0, 1}, {0, 2}, {1, 2}};
    mcp_dump d = {0};
    d.color = mcp_test_rgb(W, H);
    d.var_of_mean = mcp_test_rgb(W, H);
    assert_int_equal(mcp_image_new(W, H, 3, cov_names, &d.cov_of_mean), 0);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            float *v = mcp_image_px(d.var_of_mean, x, y);
            for (int c = 0; c < 3; c++)
                v[c] = x == 5 && y == 5     ? 100.0f
                       : x == 20 && y == 12 ? 0.01f
                       : x == 8 && y == 20  ? 0.0f
                                            : 1.0f + c;
            for (int k = 0; k < 3; k++)
                mcp_image_px(d.cov_of_mean, x, y)[k] =
                    (float)(0.8 * sqrt((double)v[pair[k][0]] * v[pair[k][1]]));
        }
    mcp_image *var = NULL, *cov = NULL;
    assert_int_equal(mcp__probe_variance_floor(&d, 1, &var, &cov), 0);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            const float *v = mcp_image_px(var, x, y), *cv = mcp_image_px(cov, x, y);
            for (int c = 0; c < 3; c++) {
                const float want = x == 5 && y == 5    ? 100.0f
                                   : x == 8 && y == 20 ? 0.0f
                                                       : 1.0f + c;
                assert_float_equal(v[c], want, 0.0);
            }
            for (int k = 0; k < 3 && !(x == 8 && y == 20); k++) {
                const double corr = cv[k] / sqrt((double)v[pair[k][0]] * v[pair[k][1]]);
                assert_float_equal(corr, 0.8, 1e-6);
            }
        }
    mcp_image_free(var);
    mcp_image_free(cov);
    /* radius 0: the dump's own values */
    assert_int_equal(mcp__probe_variance_floor(&d, 0, &var, &cov), 0);
    assert_memory_equal(var->data, d.var_of_mean->data, sizeof(float) * 3 * W * H);
    mcp_image_free(var);
    mcp_image_free(cov);
    assert_int_not_equal(
        mcp__probe_variance_floor(&d, MCP__PROBE_FLOOR_MAX + 1, &var, &cov), 0);
    assert_null(var);
    /* random values, one in ten 0, radius 1 (its column-sorted fast path) and 2: every
       nonzero value the larger of its own and the median of its clipped window, sorted
       here */
    uint64_t rng = 99;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int c = 0; c < 3; c++)
                mcp_image_px(d.var_of_mean, x, y)[c] =
                    (x * 7 + y * 3 + c) % 10 == 0
                        ? 0.0f
                        : (float)exp(2.0 * mcp_test_rand_normal(&rng));
    for (int radius = 1; radius <= 2; radius++) {
        assert_int_equal(mcp__probe_variance_floor(&d, radius, &var, NULL), 0);
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                for (int c = 0; c < 3; c++) {
                    float window[25];
                    int n = 0;
                    for (int yy = y - radius; yy <= y + radius; yy++)
                        for (int xx = x - radius; xx <= x + radius; xx++)
                            if (xx >= 0 && yy >= 0 && xx < W && yy < H)
                                window[n++] = mcp_image_px(d.var_of_mean, xx, yy)[c];
                    for (int i = 0; i < n; i++) /* selection sort */
                        for (int j = i + 1; j < n; j++)
                            if (window[j] < window[i]) {
                                float t = window[i];
                                window[i] = window[j], window[j] = t;
                            }
                    const float own = mcp_image_px(d.var_of_mean, x, y)[c],
                                want = own == 0.0f || own > window[n / 2] ? own
                                                                          : window[n / 2];
                    assert_float_equal(mcp_image_px(var, x, y)[c], want, 0.0);
                }
        mcp_image_free(var);
    }
    /* the automatic radius */
    mcp_denoiser *den = NULL;
    assert_int_equal(mcp_denoiser_create_from_args("nlm", NULL, 0, &den), 0);
    assert_int_equal(mcp_estimate_auto_probe_floor(&d, den, MCP_METRIC_RELSE), 0);
    mcp_denoiser_free(den);
    if (mcp_denoiser_create_from_args("unet", NULL, 0, &den) == 0) {
        assert_int_equal(mcp_estimate_auto_probe_floor(&d, den, MCP_METRIC_RELSE), 1);
        assert_int_equal(mcp_estimate_auto_probe_floor(&d, den, MCP_METRIC_SE), 1);
        assert_int_equal(
            mcp_estimate_auto_probe_floor(&d, den, MCP_METRIC_RELSE_PERCEPTUAL), 0);
        mcp_denoiser_free(den);
    }
    mcp_image_free(d.color);
    mcp_image_free(d.var_of_mean);
    mcp_image_free(d.cov_of_mean);
}

/* ---- the built-in bilateral denoiser (non-linear), when it exists ---- */

static void
test_unbiased_bilateral(void **state)
{
    (void)state;
    mcp_denoiser *den = NULL;
    assert_int_equal(mcp_denoiser_create_from_args("bilateral", NULL, 0, &den), 0);
    mcp_image *mu = mean_image();
    running diff = {0}, emp = {0};
    uint64_t rng = 515;
    for (int r = 0; r < R_REALIZATIONS; r++) {
        mcp_dump *d = realization(&rng, 0);
        mcp_sure_options o = mcp_sure_defaults();
        o.metric = MCP_METRIC_SE;
        o.seed = 9000 + r;
        mcp_error_maps m;
        assert_int_equal(mcp_error_maps_compute(d, den, &o, &m), 0);
        double t = 0.0;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                for (int c = 0; c < 3; c++) {
                    double e = (double)mcp_image_px(m.denoised, x, y)[c] - mu_at(x, y, c);
                    t += e * e;
                }
        t /= W * H * 3;
        push(&diff, image_mean(m.sure) - t);
        push(&emp, t);
        mcp_error_maps_free(&m);
        mcp_dump_free(d);
    }
    print_message("bilateral: SURE - empirical MSE = %.3g +- %.2g (%.2f SE; MSE %.4g)\n",
                  diff.mean, std_error(&diff), diff.mean / std_error(&diff), emp.mean);
    assert_true(fabs(diff.mean) <= 3 * std_error(&diff));
    mcp_image_free(mu);
    mcp_denoiser_free(den);
}

/* ---- errors ---- */

static void
test_errors(void **state)
{
    (void)state;
    uint64_t rng = 1;
    mcp_dump *d = realization(&rng, 1);
    mcp_sure_options o = mcp_sure_defaults();
    mcp_image *s = NULL;
    o.n_probes = 0;
    assert_error_contains(mcp_sure(d, &mcp_test_box_denoiser, &o, &s),
                          "sure: n_probes must be in [1, 1024] (got 0)");
    assert_null(s);
    o = mcp_sure_defaults();
    o.fd_delta = 0.0;
    assert_error_contains(mcp_sure(d, &mcp_test_box_denoiser, &o, &s),
                          "fd_delta must be > 0 (got 0)");
    o = mcp_sure_defaults();
    o.ppd = -1;
    assert_error_contains(mcp_sure(d, &mcp_test_box_denoiser, &o, &s),
                          "ppd must be >= 0 (got -1)");
    assert_error_contains(mcp_sure(d, NULL, NULL, &s), "sure: missing denoiser");
    mcp_error_metric m;
    assert_error_contains(mcp_error_metric_from_name("mse", &m),
                          "unknown metric 'mse' (known: relse, relse-perceptual, se)");
    assert_int_equal(mcp_error_metric_from_name("RelSE-Perceptual", &m), 0);
    assert_int_equal(m, MCP_METRIC_RELSE_PERCEPTUAL);
    assert_string_equal(mcp_error_metric_name(MCP_METRIC_SE), "se");
    /* joint SURE without albedo in the dump */
    mcp_image *cross = NULL;
    assert_int_equal(mcp_image_new(W, H, 9, NULL, &cross), 0);
    mcp_feature_covariance fc = {0};
    fc.color_albedo = cross;
    o = mcp_sure_defaults();
    o.features = &fc;
    assert_error_contains(mcp_sure(d, &mcp_test_box_denoiser, &o, &s),
                          "colour-albedo covariance given but synthetic has no albedo");
    mcp_image_free(cross);
    /* from_probes with a wrong-size jvp */
    mcp_image *f = mcp_test_rgb(W, H), *small = mcp_test_rgb(4, 4);
    const mcp_image *pp[1] = {f}, *jj[1] = {small};
    mcp_error_maps maps;
    assert_error_contains(mcp_error_maps_from_probes(d, f, pp, jj, 1, NULL, &maps),
                          "sure: jvp 0 must have 3 channels and the dump's size");
    mcp_image_free(f);
    mcp_image_free(small);
    /* no variance */
    mcp_image_free(d->var_of_mean);
    d->var_of_mean = NULL;
    assert_error_contains(mcp_sure(d, &mcp_test_box_denoiser, NULL, &s),
                          "sure: synthetic has no variance");
    mcp_dump_free(d);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_formula_is_alg2),
        cmocka_unit_test(test_maps_in_the_probes_images),
        cmocka_unit_test(test_unbiased_linear_closed_form),
        cmocka_unit_test(test_unbiased_perceptual),
        cmocka_unit_test(test_joint_sure),
        cmocka_unit_test(test_mc_sure_equals_exact_for_linear),
        cmocka_unit_test(test_more_probes_less_noise),
        cmocka_unit_test(test_probe_covariance),
        cmocka_unit_test(test_probe_clamps_negative_eigenvalues),
        cmocka_unit_test(test_probes_do_not_depend_on_threads),
        cmocka_unit_test(test_probe_rows_are_the_whole_probes),
        cmocka_unit_test(test_box_muller_functions),
        cmocka_unit_test(test_unbiased_bilateral),
        cmocka_unit_test(test_probe_floor),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests_name("estimate/sure", tests, NULL, NULL);
}
