/* test_group_jackknife.c: SURE's covariance term and variance from a render's own
 * checkpoints (estimate/group_jackknife.c, docs/mathematics.md §2.10) against closed
 * forms:
 *  - a linear denoiser (the 3x3 box, K_ii = 1/9 inside the image) on skewed noise
 *    (exponential samples): E[V] = v and E[C] = v/9, with equal groups and unequal ones;
 *  - members that are independent renders, not checkpoints of one: no groups;
 *  - a clamp that keeps only whether a pixel drew a firefly, where Stein's lemma (the
 *    probes' divergence) reads twice the covariance there is: the jackknife's is within
 *    a fifth of the closed form;
 *  - the series estimate takes the groups from the third member on, and none with
 *    sure_groups 0; the members before the groups start do not stop (held);
 *  - a per-sample variance 4x the truth: the probes take the groups' V, and the
 *    variance map is the box's true Var[F]; the increments' variance keeps its own, and
 *    so does a per-sample one 1.1x the truth.
 * Fixed seeds; each mean is checked within four of its standard errors over the
 * renders and that error is checked to be small. */
#include "box_denoiser.h"
#include "testing.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mcpost/estimate.h>
#include "../../estimate/internal.h"

#define W 24
#define H 24

/* One render: per value, samples mu * E with E ~ Exp(1) (variance mu²), or with
 * fireflies: mu, and mu + F with probability P. */
typedef struct render {
    int fireflies;
    double mu[3];
} render;

#define FIREFLY 8.0
#define FIREFLY_P 0.02

static double
draw(const render *r, int c, uint64_t *rng)
{
    if (r->fireflies)
        return r->mu[c] + (mcp_test_rand_uniform(rng) < FIREFLY_P ? FIREFLY : 0.0);
    return -r->mu[c] * log(1.0 - mcp_test_rand_uniform(rng));
}

static double
sample_variance(const render *r, int c)
{
    return r->fireflies ? FIREFLY * FIREFLY * FIREFLY_P * (1 - FIREFLY_P)
                        : r->mu[c] * r->mu[c];
}

/* Checkpoints of one render at spp[0] < ... < spp[count - 1] (or, with independent,
 * a fresh render for each), written as name_K.exr with `over` times the true variance
 * of the mean, from `source`; the series. */
static mcp_series *
write_checkpoints_as(const render *r, const double *spp, int count, int independent,
                     const char *name, uint64_t *rng, double over,
                     mcp_variance_source source)
{
    double *sum = calloc((size_t)W * H * 3, sizeof *sum);
    char **paths = calloc((size_t)count, sizeof *paths);
    int drawn = 0;
    for (int k = 0; k < count; k++) {
        if (independent) {
            memset(sum, 0, (size_t)W * H * 3 * sizeof *sum);
            drawn = 0;
        }
        for (; drawn < (int)spp[k]; drawn++)
            for (int i = 0; i < W * H * 3; i++)
                sum[i] += draw(r, i % 3, rng);
        mcp_dump *d = calloc(1, sizeof *d);
        d->color = mcp_test_rgb(W, H);
        d->var_of_mean = mcp_test_rgb(W, H);
        d->spp = spp[k];
        d->source = strdup(name);
        d->variance_source = source;
        for (int i = 0; i < W * H * 3; i++) {
            d->color->data[i] = (float)(sum[i] / spp[k]);
            d->var_of_mean->data[i] = (float)(over * sample_variance(r, i % 3) / spp[k]);
        }
        char file[128];
        snprintf(file, sizeof file, "%s_%d.exr", name, k);
        paths[k] = strdup(mcp_test_path(file));
        assert_int_equal(mcp_dump_write(d, paths[k], MCP_CONV_MCPOST, NULL), 0);
        mcp_dump_free(d);
    }
    mcp_series *s = NULL;
    assert_int_equal(mcp_series_from_paths((const char *const *)paths, spp, count, &s),
                     0);
    for (int k = 0; k < count; k++)
        free(paths[k]);
    free(paths);
    free(sum);
    return s;
}

static mcp_series *
write_checkpoints(const render *r, const double *spp, int count, int independent,
                  const char *name, uint64_t *rng)
{
    return write_checkpoints_as(r, spp, count, independent, name, rng, 1.0,
                                MCP_VARSRC_OF_MEAN);
}

/* The last member's group terms with at most `groups` groups. */
static void
last_member_terms(const mcp_series *s, const mcp_denoiser *den, int groups,
                  mcp__group_terms *g)
{
    mcp_dump *d = NULL;
    assert_int_equal(mcp_series_load(s, s->count - 1, &d), 0);
    assert_int_equal(mcp__series_group_terms(s, s->count - 1, d, den, groups, g), 0);
    mcp_dump_free(d);
}

/* mean and standard error of n values */
static void
mean_se(const double *x, int n, double *mean, double *se)
{
    double m = 0.0, ss = 0.0;
    for (int i = 0; i < n; i++)
        m += x[i];
    m /= n;
    for (int i = 0; i < n; i++)
        ss += (x[i] - m) * (x[i] - m);
    *mean = m;
    *se = sqrt(ss / (n - 1) / n);
}

/* Over RENDERS renders of checkpoints spp[]: Σ V / Σ v and Σ C / Σ (v/9) over the
 * values inside the image's border, each 1 within 4 standard errors, and the number
 * of groups found is `want_groups`. */
#define RENDERS 24
static void
check_linear(const double *spp, int count, int groups, int want_groups, uint64_t seed)
{
    const render r = {0, {0.2, 0.5, 1.0}};
    uint64_t rng = seed;
    double rv[RENDERS], rc[RENDERS];
    for (int t = 0; t < RENDERS; t++) {
        mcp_series *s = write_checkpoints(&r, spp, count, 0, "linear", &rng);
        mcp__group_terms g = {0};
        last_member_terms(s, &mcp_test_box_denoiser, groups, &g);
        assert_non_null(g.cov);
        assert_int_equal(g.groups, want_groups);
        double sv = 0.0, sjv = 0.0, sc = 0.0;
        for (int y = 1; y < H - 1; y++)
            for (int x = 1; x < W - 1; x++)
                for (int c = 0; c < 3; c++) {
                    const double v = sample_variance(&r, c) / spp[count - 1];
                    sv += v;
                    sjv += mcp_image_px(g.var, x, y)[c];
                    sc += mcp_image_px(g.cov, x, y)[c];
                }
        rv[t] = sjv / sv;
        rc[t] = sc / (sv / 9.0);
        mcp__group_terms_clear(&g);
        mcp_series_free(s);
    }
    double mv, sev, mc, sec;
    mean_se(rv, RENDERS, &mv, &sev);
    mean_se(rc, RENDERS, &mc, &sec);
    print_message("%d groups: V / v %.4f (se %.4f), C / (v K_ii) %.4f (se %.4f)\n",
                  want_groups, mv, sev, mc, sec);
    assert_true(fabs(mv - 1.0) < 4 * sev && sev < 0.02);
    assert_true(fabs(mc - 1.0) < 4 * sec && sec < 0.03);
}

static void
test_linear_equal_groups(void **state)
{
    (void)state;
    const double spp[4] = {8, 16, 24, 32};
    check_linear(spp, 4, 4, 4, 11);
}

static void
test_linear_unequal_groups(void **state)
{
    (void)state;
    /* four asked: the ends nearest 16, 32 and 48 samples are 16, 32 and 32 (taken),
       so three groups of 16, 16 and 32 samples */
    const double spp[4] = {8, 16, 32, 64};
    check_linear(spp, 4, 4, 3, 12);
}

static void
test_independent_members_give_no_groups(void **state)
{
    (void)state;
    const render r = {0, {0.2, 0.5, 1.0}};
    const double spp[4] = {8, 16, 24, 32};
    uint64_t rng = 13;
    mcp_series *s = write_checkpoints(&r, spp, 4, 1, "independent", &rng);
    mcp__group_terms g = {0};
    last_member_terms(s, &mcp_test_box_denoiser, 4, &g);
    assert_null(g.cov);
    assert_null(g.var);
    mcp_series_free(s);
    /* and the first member has no groups */
    s = write_checkpoints(&r, spp, 4, 0, "first", &rng);
    mcp_dump *d = NULL;
    assert_int_equal(mcp_series_load(s, 0, &d), 0);
    assert_int_equal(mcp__series_group_terms(s, 0, d, &mcp_test_box_denoiser, 4, &g), 0);
    assert_null(g.cov);
    mcp_dump_free(d);
    mcp_series_free(s);
}

/* ---- a clamp: d = mu where the value drew no firefly, else mu + F / (2 I) ---- */

#define CLAMP_MU 0.5
#define CLAMP_SPP 32.0

static int
clamp_apply(const mcp_denoiser *self, const mcp_denoise_input *in, mcp_image **out)
{
    (void)self;
    const double top = CLAMP_MU + FIREFLY / (2 * CLAMP_SPP);
    *out = mcp_test_rgb(in->color->width, in->color->height);
    const size_t n = (size_t)in->color->width * in->color->height * 3;
    for (size_t i = 0; i < n; i++)
        (*out)->data[i] = (float)fmin(in->color->data[i], top);
    return 0;
}

static const mcp_denoiser clamp_denoiser = {.name = "clamp", .apply = clamp_apply};

static void
test_fireflies_covariance(void **state)
{
    (void)state;
    /* n = mu + F B / I with B ~ Bin(I, P); d = mu when B = 0, else mu + F / (2I).
     * Cov(n, d) = (F / I)(F / 2I) Cov(B, [B > 0]) = (F / I)(F / 2I) I P q0, with
     * q0 = (1 - P)^I; Stein's v E[J] = v q0 (the slope is 1 only where B = 0) with
     * v = F² P (1 - P) / I: 1 / (2 (1 - P)) of it, about half. */
    const render r = {1, {CLAMP_MU, CLAMP_MU, CLAMP_MU}};
    const double spp[4] = {8, 16, 24, CLAMP_SPP}, I = CLAMP_SPP;
    const double q0 = pow(1 - FIREFLY_P, I);
    const double truth = FIREFLY / I * FIREFLY / (2 * I) * I * FIREFLY_P * q0;
    const double stein = FIREFLY * FIREFLY * FIREFLY_P * (1 - FIREFLY_P) / I * q0;
    uint64_t rng = 14;
    double ratio[RENDERS];
    for (int t = 0; t < RENDERS; t++) {
        mcp_series *s = write_checkpoints(&r, spp, 4, 0, "clamp", &rng);
        mcp__group_terms g = {0};
        last_member_terms(s, &clamp_denoiser, 4, &g);
        assert_non_null(g.cov);
        double sc = 0.0;
        for (int i = 0; i < W * H * 3; i++)
            sc += g.cov->data[i];
        ratio[t] = sc / (W * H * 3) / truth;
        mcp__group_terms_clear(&g);
        mcp_series_free(s);
    }
    double m, se;
    mean_se(ratio, RENDERS, &m, &se);
    print_message(
        "fireflies through a clamp: the jackknife's covariance %.3f (se %.3f) of "
        "the closed form; Stein's lemma %.3f\n",
        m, se, stein / truth);
    assert_true(stein / truth > 1.9);
    assert_true(fabs(m - 1.0) < 0.2 && se < 0.05);
}

static void
test_series_estimate_takes_groups(void **state)
{
    (void)state;
    const render r = {0, {0.2, 0.5, 1.0}};
    const double spp[4] = {8, 16, 24, 32};
    uint64_t rng = 15;
    mcp_series *s = write_checkpoints(&r, spp, 4, 0, "series", &rng);
    mcp_series_estimate_options o = mcp_series_estimate_defaults();
    for (int groups = -1; groups <= 0; groups++) {
        o.est.sure_groups = groups;
        mcp_series_estimate *e = NULL;
        assert_int_equal(
            mcp_estimate_series(s, &mcp_test_box_denoiser, &o, NULL, NULL, NULL, &e), 0);
        /* automatic: 3 and 4 groups from the third member on (two would leave one
           degree of freedom per value) */
        for (int i = 0; i < 4; i++)
            assert_int_equal(e->points[i].sure_groups, groups && i >= 2 ? i + 1 : 0);
        mcp_series_estimate_free(e);
    }
    /* a τ every member reaches: with the groups the first two checkpoints are held
       (F(τ) >= p, no stop) and the third stops; without them the first stops */
    o.n_taus = 1;
    o.taus[0] = 100.0;
    for (int groups = -1; groups <= 2; groups++) {
        if (groups == 1) continue; /* refused, below */
        o.est.sure_groups = groups;
        mcp_series_estimate *e = NULL;
        assert_int_equal(
            mcp_estimate_series(s, &mcp_test_box_denoiser, &o, NULL, NULL, NULL, &e), 0);
        const int first = groups == 0 ? 0 : groups == 2 ? 1 : 2; /* the first stop */
        for (int i = 0; i < 4; i++) {
            assert_true(e->points[i].cdf[0] >= o.est.p);
            assert_int_equal(e->points[i].stop[0], i >= first);
            assert_int_equal(e->points[i].held, i < first);
        }
        assert_true(e->first_spp[0] == spp[first]);
        mcp_series_estimate_free(e);
    }
    o.est.sure_groups = 1;
    mcp_series_estimate *e = NULL;
    assert_error_contains(
        mcp_estimate_series(s, &mcp_test_box_denoiser, &o, NULL, NULL, NULL, &e),
        "sure_groups must be");
    mcp_series_free(s);
}

/* mcp_estimate_series_each: the callback sees every member in turn, and a non-zero
 * return ends the series with its message, or with one that names the member. */
typedef struct member_calls {
    int calls, stop_at, with_message;
} member_calls;

static int
count_members(int done, int total, void *ctx)
{
    member_calls *c = ctx;
    assert_int_equal(done, ++c->calls);
    assert_int_equal(total, 4);
    if (done != c->stop_at) return 0;
    return c->with_message ? mcp_error("test: interrupted") : 1;
}

static void
test_series_estimate_each_member(void **state)
{
    (void)state;
    const render r = {0, {0.2, 0.5, 1.0}};
    const double spp[4] = {8, 16, 24, 32};
    uint64_t rng = 16;
    mcp_series *s = write_checkpoints(&r, spp, 4, 0, "each", &rng);
    mcp_series_estimate_options o = mcp_series_estimate_defaults();
    member_calls all = {0, 0, 0};
    mcp_series_estimate *e = NULL, *plain = NULL;
    assert_int_equal(mcp_estimate_series_each(s, &mcp_test_box_denoiser, &o, NULL,
                                              count_members, &all, &e),
                     0);
    assert_int_equal(all.calls, 4);
    /* the same estimate as without the callback */
    assert_int_equal(
        mcp_estimate_series(s, &mcp_test_box_denoiser, &o, NULL, NULL, NULL, &plain), 0);
    for (int i = 0; i < 4; i++)
        assert_true(e->points[i].cdf[0] == plain->points[i].cdf[0]);
    mcp_series_estimate_free(e);
    mcp_series_estimate_free(plain);
    for (int with_message = 0; with_message <= 1; with_message++) {
        member_calls stop = {0, 2, with_message};
        e = NULL;
        assert_error_contains(mcp_estimate_series_each(s, &mcp_test_box_denoiser, &o,
                                                       NULL, count_members, &stop, &e),
                              with_message ? "test: interrupted"
                                           : "estimate: stopped after member 2");
        assert_null(e);
        assert_int_equal(stop.calls, 2);
    }
    mcp_series_free(s);
}

/* A renderer's per-sample variance that overstates the noise 4x (as a stratified
 * sampler makes it): from the groups on, the probes take the groups' V, so that the
 * variance map Var[F] is the box's true v/9; a variance measured on the render's own
 * samples (the increments') keeps its own (4 v/9), and so does a per-sample one within
 * the series' rule (1.1x). Mean over RENDERS renders of the map's interior, each with
 * its own probes. */
static void
test_per_sample_variance_probes_from_groups(void **state)
{
    (void)state;
    const render r = {0, {0.2, 0.5, 1.0}};
    const double spp[4] = {8, 16, 24, 32};
    /* overstated 4x, per-sample: V; the increments': their own; per-sample within the
       series' rule (1.1x, not off): its own */
    const mcp_variance_source sources[3] = {MCP_VARSRC_PER_SAMPLE, MCP_VARSRC_INCREMENTS,
                                            MCP_VARSRC_PER_SAMPLE};
    const double over[3] = {4.0, 4.0, 1.1}, want[3] = {1.0, 4.0, 1.1};
    for (int k = 0; k < 3; k++) {
        uint64_t rng = 21;
        double ratio[RENDERS];
        for (int t = 0; t < RENDERS; t++) {
            mcp_series *s = write_checkpoints_as(&r, spp, 4, 0, "overstated", &rng,
                                                 over[k], sources[k]);
            /* the file's variance (auto would take the increments' for one this far
               off) */
            s->variance_from = MCP_SERIES_VARIANCE_FILE;
            mcp_dump *d = NULL;
            assert_int_equal(mcp_series_load(s, 3, &d), 0);
            assert_int_equal(d->variance_source, sources[k]);
            mcp__group_terms g = {0};
            assert_int_equal(
                mcp__series_group_terms(s, 3, d, &mcp_test_box_denoiser, 4, &g), 0);
            assert_non_null(g.var);
            mcp_estimate_options o = mcp_estimate_defaults();
            o.s2_pool = 0;
            o.sure.seed = (uint64_t)t; /* the probes' noise independent between renders */
            mcp_estimate *e = NULL;
            assert_int_equal(
                mcp__estimate_compute_groups(d, &mcp_test_box_denoiser, &o, &g, &e), 0);
            assert_int_equal(e->probes_from_groups, k == 0);
            double sum = 0.0, truth = 0.0;
            for (int y = 1; y < H - 1; y++)
                for (int x = 1; x < W - 1; x++)
                    for (int c = 0; c < 3; c++) {
                        sum += mcp_image_px(e->maps.var, x, y)[c];
                        truth += sample_variance(&r, c) / spp[3] / 9.0;
                    }
            ratio[t] = sum / truth;
            mcp_estimate_free(e);
            mcp__group_terms_clear(&g);
            mcp_dump_free(d);
            mcp_series_free(s);
        }
        double m, se;
        mean_se(ratio, RENDERS, &m, &se);
        print_message("%s variance, %gx the truth: Var[F] / truth %.3f (se %.3f)\n",
                      k == 1 ? "increments'" : "per-sample", over[k], m, se);
        assert_true(fabs(m - want[k]) < 4 * se + 0.02 * want[k] && se < 0.05 * want[k]);
    }
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_linear_equal_groups),
        cmocka_unit_test(test_linear_unequal_groups),
        cmocka_unit_test(test_independent_members_give_no_groups),
        cmocka_unit_test(test_fireflies_covariance),
        cmocka_unit_test(test_series_estimate_takes_groups),
        cmocka_unit_test(test_series_estimate_each_member),
        cmocka_unit_test(test_per_sample_variance_probes_from_groups),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
