/* test_vertical.c: perceptual/vertical.c -- iterative minimisation (direct binary
 * search) in the vertical search space: its output is drawn from the candidates, its
 * incremental energy matches a recomputation, the result is a local minimum (no single
 * pixel change lowers the energy), closed forms (C = 0: the candidate nearest the mean;
 * g = delta: the one nearest the surrogate), and the pMSE against the truth beats the
 * candidates' mean with the reference as surrogate (procedural scene and fixtures) and
 * with a denoised surrogate (fixtures). Ratios are printed. */
#include "perc_testing.h"

#include "../../perceptual/internal.h"

#include <math.h>
#include <omp.h>

/* Energies are sums of ~N * 3 double terms; the incremental one adds one rounded dE
 * per accepted change, each rounded on the scale of the energies it moves between. So
 * compare on the scale of the largest, the starting energy: 1e-9 of it (the brief's
 * bound) is orders above the drift even when a firefly at T = none makes single terms
 * 1e4 times the final energy. */
#define ENERGY_RTOL 1e-9

static void
check_result(const mcp_perc_result *r, const mcp_image *const *cands, int m,
             const mcp_image *surr, const mcp_perc_model *model)
{
    assert_non_null(r->image);
    assert_non_null(r->index);
    assert_null(r->permutation);
    perc_assert_from_candidates(r->image, r->index, cands, m);
    mcp_image *mean = NULL;
    double e;
    assert_int_equal(mcp_perc_mean(cands, m, &mean), 0);
    assert_int_equal(mcp_perc_energy(r->image, surr, mean, model, &e), 0);
    assert_close(r->energy_final, e, 0, ENERGY_RTOL * r->energy_initial);
    assert_true(r->energy_final <= r->energy_initial);
    mcp_image_free(mean);
}

/* No single candidate change at any pixel lowers E_C below rounding (a local minimum
 * of the vertical search space, which is what a converged pass certifies). */
static void
assert_local_minimum(const mcp_perc_result *r, const mcp_image *const *cands, int m,
                     const mcp_image *surr, const mcp_perc_model *model)
{
    int w = r->image->width, h = r->image->height;
    size_t n = (size_t)w * h;
    float *t_o = NULL, *t_s = NULL, *t_stack = NULL, *mean = NULL, *t_mean = NULL;
    assert_int_equal(mcp__rgb_tone(r->image, model->tone_map, &t_o), 0);
    assert_int_equal(mcp__rgb_tone(surr, model->tone_map, &t_s), 0);
    assert_int_equal(mcp__stack_tone(cands, m, model->tone_map, &t_stack), 0);
    assert_int_equal(mcp__mean_rgb(cands, m, &mean), 0);
    assert_int_equal(mcp__tone_rgb(mean, n, model->tone_map, &t_mean), 0);
    double *o = malloc(n * 3 * sizeof *o);
    for (size_t i = 0; i < n * 3; i++)
        o[i] = t_o[i];
    mcp__perc_state s;
    assert_int_equal(mcp__state_init(&s, model, w, h, t_s, t_mean, o), 0);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int j = 0; j < m; j++) {
                const float *t = t_stack + (((size_t)y * w + x) * m + j) * 3;
                double v[3] = {t[0], t[1], t[2]};
                double de = mcp__state_delta(&s, x, y, v);
                if (de < -1e-9 * s.energy / (double)n)
                    fail_msg("pixel %d, %d: candidate %d lowers E by %g", x, y, j, -de);
            }
    mcp__state_free(&s);
    free(o), free(t_o), free(t_s), free(t_stack), free(mean), free(t_mean);
}

static void
test_procedural_reference(void **state)
{
    (void)state;
    static const struct {
        int size, m, fireflies;
        uint64_t seed;
    } cases[] = {{48, 4, 1, 1}, {64, 4, 0, 2}, {37, 8, 1, 3}, {64, 2, 1, 4}};
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        perc_case c;
        perc_procedural(cases[i].size, cases[i].m, 1, cases[i].seed, cases[i].fireflies,
                        &c);
        mcp_perc_options o = mcp_perc_defaults();
        mcp_perc_result r;
        assert_int_equal(
            mcp_perc_vertical_iterative(perc_cands(&c), c.m, c.truth, &o, &r), 0);
        check_result(&r, perc_cands(&c), c.m, c.truth, &o.model);
        assert_true(r.passes < 100); /* converged: the last pass changed nothing */
        assert_local_minimum(&r, perc_cands(&c), c.m, c.truth, &o.model);
        double ours = perc_pmse(r.image, c.truth), mean = perc_mean_pmse(&c);
        print_message("procedural %dx%d M=%d%s: pMSE %.5f vs mean %.5f (ratio %.3f), %d "
                      "passes\n",
                      cases[i].size, cases[i].size, c.m,
                      cases[i].fireflies ? " fireflies" : "", ours, mean, ours / mean,
                      r.passes);
        assert_true(ours < mean);
        mcp_perc_result_free(&r);
        perc_case_free(&c);
    }
}

static void
test_init_mean_and_threads(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(40, 4, 1, 9, 1, &c);
    mcp_perc_options o = mcp_perc_defaults();
    o.init = MCP_PERC_INIT_MEAN;
    mcp_perc_result r, r1;
    assert_int_equal(mcp_perc_vertical_iterative(perc_cands(&c), c.m, c.truth, &o, &r),
                     0);
    check_result(&r, perc_cands(&c), c.m, c.truth, &o.model);
    assert_true(r.changes >= 40 * 40); /* every pixel leaves the mean */
    /* the same with one thread: bit for bit */
    int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    assert_int_equal(mcp_perc_vertical_iterative(perc_cands(&c), c.m, c.truth, &o, &r1),
                     0);
    omp_set_num_threads(threads);
    assert_int_equal(mcp_test_max_abs_diff(r.image, r1.image) == 0.0, 1);
    assert_true(r.energy_final == r1.energy_final);
    mcp_perc_result_free(&r1);
    /* the pass limit is honoured */
    o.passes = 1;
    assert_int_equal(mcp_perc_vertical_iterative(perc_cands(&c), c.m, c.truth, &o, &r1),
                     0);
    assert_int_equal(r1.passes, 1);
    perc_assert_from_candidates(r1.image, r1.index, perc_cands(&c), c.m);
    mcp_perc_result_free(&r1);
    mcp_perc_result_free(&r);
    perc_case_free(&c);
}

/* C = 0 leaves only |g|_1^2 |T(O) - T(mean)|^2: every pixel takes the candidate
 * nearest the mean in display space, whatever the surrogate. g = delta (a 1x1 user
 * kernel) with C = 1 makes E = |T(O) - T(I')|^2: the candidate nearest the surrogate. */
static void
test_closed_forms(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(24, 5, 1, 5, 1, &c);
    mcp_image *mean = NULL, *other = mcp_test_random(24, 24, 3, 0.0f, 1.0f, 3, NULL);
    assert_int_equal(mcp_perc_mean(perc_cands(&c), c.m, &mean), 0);
    static const double delta[1] = {1.0};
    for (int variant = 0; variant < 2; variant++) {
        mcp_perc_options o = mcp_perc_defaults();
        const mcp_image *target = mean;
        if (variant == 0) {
            o.model.confidence = 0.0;
        } else {
            o.model.user_kernel = delta;
            o.model.user_kernel_width = o.model.user_kernel_height = 1;
            target = other;
        }
        mcp_perc_result r;
        assert_int_equal(mcp_perc_vertical_iterative(perc_cands(&c), c.m, other, &o, &r),
                         0);
        perc_assert_from_candidates(r.image, r.index, perc_cands(&c), c.m);
        for (int y = 0; y < 24; y++)
            for (int x = 0; x < 24; x++) {
                const float *t = mcp_image_px(target, x, y);
                double best = INFINITY;
                for (int j = 0; j < c.m; j++) {
                    const float *q = mcp_image_px(c.cand[j], x, y);
                    double d = 0.0;
                    for (int ch = 0; ch < 3; ch++) {
                        double e = (double)mcp_tonemap_value(MCP_TONEMAP_CLAMP, q[ch]) -
                                   mcp_tonemap_value(MCP_TONEMAP_CLAMP, t[ch]);
                        d += e * e;
                    }
                    best = d < best ? d : best;
                }
                const float *o_px = mcp_image_px(r.image, x, y);
                double d = 0.0;
                for (int ch = 0; ch < 3; ch++) {
                    double e = (double)mcp_tonemap_value(MCP_TONEMAP_CLAMP, o_px[ch]) -
                               mcp_tonemap_value(MCP_TONEMAP_CLAMP, t[ch]);
                    d += e * e;
                }
                assert_close(d, best, 1e-12, 1e-15);
            }
        mcp_perc_result_free(&r);
    }
    mcp_image_free(other);
    mcp_image_free(mean);
    perc_case_free(&c);
}

/* Other models run and keep their invariants: ACES and no tone map, a Gaussian g from
 * viewing distance, h = g, a per-pixel confidence map. */
static void
test_models(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(32, 4, 1, 12, 1, &c);
    mcp_image *cmap = mcp_test_random(32, 32, 1, 0.2f, 1.0f, 4, NULL);
    for (int variant = 0; variant < 4; variant++) {
        mcp_perc_options o = mcp_perc_defaults();
        if (variant == 0) o.model.tone_map = MCP_TONEMAP_ACES;
        if (variant == 1) {
            o.model.tone_map = MCP_TONEMAP_NONE;
            o.model.filter_surrogate = 1;
        }
        if (variant == 2) {
            o.model.kernel.kind = MCP_PKERNEL_GAUSSIAN;
            o.model.kernel.distance_in = 30.0;
        }
        if (variant == 3) o.model.confidence_map = cmap;
        mcp_perc_result r;
        assert_int_equal(
            mcp_perc_vertical_iterative(perc_cands(&c), c.m, c.truth, &o, &r), 0);
        check_result(&r, perc_cands(&c), c.m, c.truth, &o.model);
        assert_local_minimum(&r, perc_cands(&c), c.m, c.truth, &o.model);
        mcp_perc_result_free(&r);
    }
    mcp_image_free(cmap);
    perc_case_free(&c);
}

static void
fixture_reference(const char *scene)
{
    perc_case c;
    if (perc_fixture(scene, 4, 1, &c)) return;
    mcp_perc_options o = mcp_perc_defaults();
    mcp_perc_result r;
    assert_int_equal(mcp_perc_vertical_iterative(perc_cands(&c), c.m, c.truth, &o, &r),
                     0);
    check_result(&r, perc_cands(&c), c.m, c.truth, &o.model);
    double ours = perc_pmse(r.image, c.truth), mean = perc_mean_pmse(&c);
    print_message("fixture %s, 4 x 1 spp, reference surrogate: pMSE %.5f vs mean %.5f "
                  "(ratio %.3f), %d passes\n",
                  scene, ours, mean, ours / mean, r.passes);
    assert_true(ours < mean);
    mcp_perc_result_free(&r);
    perc_case_free(&c);
}

static void
test_fixtures_reference(void **state)
{
    (void)state;
    fixture_reference("cornell");
    fixture_reference("texture");
}

static void
test_errors(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(8, 2, 1, 1, 0, &c);
    mcp_perc_result r;
    mcp_perc_options o = mcp_perc_defaults();
    mcp_image *small = mcp_test_constant(7, 8, 3, 0.5f, NULL);
    mcp_image_set_source(small, "small.exr");
    assert_error_contains(mcp_perc_vertical_iterative(perc_cands(&c), c.m, NULL, &o, &r),
                          "needs a surrogate");
    assert_null(r.image);
    assert_error_contains(mcp_perc_vertical_iterative(perc_cands(&c), 0, c.truth, &o, &r),
                          "at least one candidate image (got 0)");
    assert_error_contains(mcp_perc_vertical_iterative(perc_cands(&c), c.m, small, &o, &r),
                          "small.exr: size 7x8 does not match");
    o.passes = -1;
    assert_error_contains(
        mcp_perc_vertical_iterative(perc_cands(&c), c.m, c.truth, &o, &r),
        "passes must be >= 0 (got -1");
    o = mcp_perc_defaults();
    o.model.confidence = -0.5;
    assert_error_contains(
        mcp_perc_vertical_iterative(perc_cands(&c), c.m, c.truth, &o, &r),
        "confidence must be in [0, 1] (got -0.5)");
    mcp_image_free(small);
    perc_case_free(&c);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_procedural_reference),
        cmocka_unit_test(test_init_mean_and_threads),
        cmocka_unit_test(test_closed_forms),
        cmocka_unit_test(test_models),
        cmocka_unit_test(test_fixtures_reference),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests_name("perceptual/vertical", tests, NULL, NULL);
}
