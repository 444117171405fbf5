/* test_horizontal.c: perceptual/horizontal.c -- pixel swaps in the horizontal search
 * space: the permutation is a bijection within the travel limit, the prediction is the
 * input permuted by it, the energy bookkeeping matches a recomputation, a converged
 * run is a local minimum over the allowed swaps, and re-rendering the procedural scene
 * with the permuted seeds (ratios printed). Also mcp_perc_permute's checks. */
#include "perc_testing.h"

#include "../../perceptual/internal.h"

#include <math.h>
#include <stdlib.h>

static void
check_permutation(const mcp_image *map, int travel)
{
    int w = map->width, h = map->height;
    unsigned char *seen = calloc((size_t)w * h, 1);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *m = mcp_image_px(map, x, y);
            int sx = (int)m[0], sy = (int)m[1];
            assert_true(m[0] == (float)sx && m[1] == (float)sy);
            assert_true(sx >= 0 && sx < w && sy >= 0 && sy < h);
            assert_true(abs(sx - x) <= travel && abs(sy - y) <= travel);
            assert_int_equal(seen[(size_t)sy * w + sx]++, 0); /* a bijection */
        }
    free(seen);
}

static void
test_reference(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(48, 4, 1, 41, 1, &c);
    mcp_image *q = NULL, *permuted = NULL;
    assert_int_equal(mcp_perc_mean(perc_cands(&c), c.m, &q), 0);
    mcp_perc_options o = mcp_perc_defaults();
    mcp_perc_result r;
    assert_int_equal(mcp_perc_horizontal(q, c.truth, &o, &r), 0);
    assert_non_null(r.permutation);
    assert_null(r.index);
    check_permutation(r.permutation, 1);
    assert_int_equal(mcp_perc_permute(q, r.permutation, &permuted), 0);
    assert_true(mcp_test_max_abs_diff(permuted, r.image) == 0.0);
    double e;
    assert_int_equal(mcp_perc_energy(r.image, c.truth, NULL, &o.model, &e), 0);
    /* see test_vertical.c: 1e-9 on the scale of the starting energy */
    assert_close(r.energy_final, e, 0, 1e-9 * r.energy_initial);
    assert_true(r.energy_final < r.energy_initial);
    assert_true(r.passes <= 10 && r.changes > 0);
    /* with the truth as surrogate and C = 1, E / (N C) is the pMSE */
    double pred = perc_pmse(r.image, c.truth), base = perc_pmse(q, c.truth);
    assert_close(pred, r.energy_final / (48.0 * 48.0 * 3.0), 1e-6, 0);
    assert_true(pred < base);
    /* re-render with the permuted seeds: the same samples of other pixels' streams */
    mcp_proc_scene s = mcp_proc_scene_defaults();
    s.width = s.height = 48;
    mcp_image *again[4] = {0}, *again_mean = NULL;
    assert_int_equal(mcp_proc_render_samples(&s, 4, 1, 41, r.permutation, again), 0);
    assert_int_equal(mcp_perc_mean((const mcp_image *const *)again, 4, &again_mean), 0);
    double rer = perc_pmse(again_mean, c.truth);
    print_message(
        "horizontal 48x48 (4 spp), reference surrogate: prediction pMSE %.5f, "
        "re-rendered %.5f, input %.5f (ratios %.3f, %.3f), %d passes, %ld swaps\n",
        pred, rer, base, pred / base, rer / base, r.passes, r.changes);
    for (int j = 0; j < 4; j++)
        mcp_image_free(again[j]);
    mcp_image_free(again_mean);
    mcp_image_free(permuted);
    mcp_perc_result_free(&r);
    mcp_image_free(q);
    perc_case_free(&c);
}

/* Run to convergence, no allowed swap within the window lowers E_C (C < 1 here, so the
 * unary term and Q_init take part). */
static void
test_local_minimum(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(24, 2, 1, 43, 1, &c);
    mcp_image *q = NULL;
    assert_int_equal(mcp_perc_mean(perc_cands(&c), c.m, &q), 0);
    mcp_perc_options o = mcp_perc_defaults();
    o.passes = 200;
    o.radius = 2;
    o.travel = 2;
    o.model.confidence = 0.9;
    mcp_perc_result r;
    assert_int_equal(mcp_perc_horizontal(q, c.truth, &o, &r), 0);
    assert_true(r.passes < 200);
    check_permutation(r.permutation, 2);
    int w = 24, h = 24;
    size_t n = (size_t)w * h;
    float *t_o, *t_s, *t_q;
    assert_int_equal(mcp__rgb_tone(r.image, o.model.tone_map, &t_o), 0);
    assert_int_equal(mcp__rgb_tone(c.truth, o.model.tone_map, &t_s), 0);
    assert_int_equal(mcp__rgb_tone(q, o.model.tone_map, &t_q), 0);
    double *ov = malloc(n * 3 * sizeof *ov);
    for (size_t i = 0; i < n * 3; i++)
        ov[i] = t_o[i];
    mcp__perc_state s;
    assert_int_equal(mcp__state_init(&s, &o.model, w, h, t_s, t_q, ov), 0);
    assert_close(s.energy, r.energy_final, 0, 1e-9 * r.energy_initial);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int yj = y - 2; yj <= y + 2; yj++)
                for (int xj = x - 2; xj <= x + 2; xj++) {
                    if (xj < 0 || yj < 0 || xj >= w || yj >= h || (xj == x && yj == y))
                        continue;
                    const float *si = mcp_image_px(r.permutation, x, y);
                    const float *sj = mcp_image_px(r.permutation, xj, yj);
                    if (fabs(sj[0] - x) > 2 || fabs(sj[1] - y) > 2 ||
                        fabs(si[0] - xj) > 2 || fabs(si[1] - yj) > 2)
                        continue; /* not allowed */
                    double de = mcp__state_swap_delta(&s, x, y, xj, yj);
                    if (de < -1e-9 * s.energy / (double)n)
                        fail_msg("swap (%d,%d)-(%d,%d) lowers E by %g", x, y, xj, yj,
                                 -de);
                }
    mcp__state_free(&s);
    free(ov), free(t_o), free(t_s), free(t_q);
    mcp_perc_result_free(&r);
    mcp_image_free(q);
    perc_case_free(&c);
}

static void
test_errors(void **state)
{
    (void)state;
    mcp_image *q = mcp_test_random(6, 5, 3, 0.0f, 1.0f, 1, NULL), *out = NULL;
    mcp_perc_result r;
    mcp_perc_options o = mcp_perc_defaults();
    o.radius = 2;
    assert_error_contains(mcp_perc_horizontal(q, q, &o, &r),
                          "travel must be >= radius (got travel 1, radius 2)");
    assert_error_contains(mcp_perc_horizontal(q, NULL, NULL, &r), "needs a surrogate");
    mcp_image *map = mcp_test_constant(6, 5, 2, 0.0f, (const char *[]){"X", "Y"});
    map->data[7] = 5.0f; /* pixel (3, 0) takes Y = 5: outside the 6x5 image */
    mcp_image_set_source(map, "map.exr");
    assert_error_contains(mcp_perc_permute(q, map, &out),
                          "map.exr: pixel 3, 0 names source (0, 5), not a pixel");
    map->data[7] = 0.5f;
    assert_error_contains(mcp_perc_permute(q, map, &out), "(0, 0.5)");
    mcp_image *nomap = mcp_test_constant(6, 5, 2, 0.0f, (const char *[]){"U", "V"});
    assert_error_contains(mcp_perc_permute(q, nomap, &out), "no channel 'X'");
    assert_null(out);
    mcp_image_free(nomap);
    mcp_image_free(map);
    mcp_image_free(q);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_reference),
        cmocka_unit_test(test_local_minimum),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests_name("perceptual/horizontal", tests, NULL, NULL);
}
