/* test_compare.c: perceptual/compare.c and optimize.c -- scores against metrics.h, the
 * comparison of every method on one input (Chizhov et al. 2022 Table 1; printed) with
 * the procedural renderer re-rendering the horizontal methods' permutations, running
 * methods by name, and every option check. */
#include "perc_testing.h"

#include <math.h>
#include <string.h>
#include "../../perceptual/internal.h"

typedef struct {
    int calls, rerenders;
    double vertical_energy;
    mcp_proc_scene scene;
    uint64_t seed;
    int m;
} ctx;

static int
on_result(void *p, mcp_perc_method method, const mcp_perc_result *r,
          const mcp_image *again)
{
    ctx *c = p;
    c->calls++;
    assert_non_null(r->image);
    assert_true((again != NULL) == mcp_perc_method_is_horizontal(method));
    if (method == MCP_PERC_VERTICAL_ITERATIVE) c->vertical_energy = r->energy_final;
    return 0;
}

/* Re-renders the m one-sample images with the permuted streams; their mean. */
static int
rerender(void *p, mcp_perc_method method, const mcp_image *perm, mcp_image **out)
{
    ctx *c = p;
    (void)method;
    mcp_image *img[PERC_MAX_M] = {0};
    c->rerenders++;
    if (mcp_proc_render_samples(&c->scene, c->m, 1, c->seed, perm, img)) return -1;
    int rc = mcp_perc_mean((const mcp_image *const *)img, c->m, out);
    for (int j = 0; j < c->m; j++)
        mcp_image_free(img[j]);
    return rc;
}

static double
num(const cJSON *row, const char *key)
{
    const cJSON *v = cJSON_GetObjectItem(row, key);
    assert_true(cJSON_IsNumber(v));
    return v->valuedouble;
}

static void
test_compare_table(void **state)
{
    (void)state;
    perc_case c;
    int size = 64;
    perc_procedural(size, 4, 1, 71, 1, &c);
    ctx k = {.seed = 71, .m = 4};
    k.scene = mcp_proc_scene_defaults();
    k.scene.width = k.scene.height = size;
    mcp_perc_compare_options o = mcp_perc_compare_defaults();
    o.base.mask.use_cache = 0; /* tests leave ~/.cache alone */
    o.reference = c.truth;
    o.rerender = rerender;
    o.rerender_ctx = &k;
    o.on_result = on_result;
    o.on_result_ctx = &k;
    cJSON *t = NULL;
    assert_int_equal(mcp_perc_compare(perc_cands(&c), c.m, c.truth, &o, &t), 0);
    assert_int_equal(cJSON_GetArraySize(t), 2 + MCP_PERC_N_METHODS);
    assert_int_equal(k.calls, MCP_PERC_N_METHODS);
    assert_int_equal(k.rerenders, 2);
    const char *names[2 + MCP_PERC_N_METHODS] = {"mean", "surrogate"};
    for (int i = 0; i < MCP_PERC_N_METHODS; i++)
        names[2 + i] = mcp_perc_method_name((mcp_perc_method)i);
    double mean_pmse = 0.0, pmse[2 + MCP_PERC_N_METHODS];
    print_message("%-20s %10s %10s %10s %10s %8s\n", "method (64x64, M=4)", "pMSE",
                  "ratio", "MSE", "low-freq", "seconds");
    for (int i = 0; i < 2 + MCP_PERC_N_METHODS; i++) {
        const cJSON *row = cJSON_GetArrayItem(t, i);
        assert_string_equal(cJSON_GetObjectItem(row, "method")->valuestring, names[i]);
        pmse[i] = num(row, "pmse");
        num(row, "mse");
        num(row, "energy");
        num(row, "low_freq_fraction");
        if (i == 0) mean_pmse = pmse[i];
        if (i >= 2) {
            mcp_perc_method m = (mcp_perc_method)(i - 2);
            assert_int_equal(cJSON_IsTrue(cJSON_GetObjectItem(row, "rerendered")),
                             mcp_perc_method_is_horizontal(m));
        }
        const cJSON *sec = cJSON_GetObjectItem(row, "seconds");
        print_message("%-20s %10.5f %10.3f %10.4f %10.4f %8.4f\n", names[i], pmse[i],
                      pmse[i] / mean_pmse, num(row, "mse"), num(row, "low_freq_fraction"),
                      cJSON_IsNumber(sec) ? sec->valuedouble : 0.0);
    }
    /* the vertical row's energy is its E_C / (N C); with the truth as surrogate that is
     * its pMSE too (metrics.h filters in float: 1e-6) */
    const cJSON *vrow = cJSON_GetArrayItem(t, 2);
    assert_close(num(vrow, "energy"), k.vertical_energy / (size * size * 3.0), 1e-6, 0);
    assert_close(num(vrow, "energy"), num(vrow, "pmse"), 1e-6, 0);
    /* Table 1's ordering on this input: ours below the mean and below the baselines */
    double vert = pmse[2], ps = pmse[3], ed = pmse[4], hist = pmse[7];
    assert_true(vert < mean_pmse && ps < mean_pmse && ed < mean_pmse);
    assert_true(vert < hist && ed < hist);
    cJSON_Delete(t);
    /* without a reference: energies only */
    o = mcp_perc_compare_defaults();
    o.base.mask.use_cache = 0;
    assert_int_equal(mcp_perc_compare(perc_cands(&c), c.m, c.truth, &o, &t), 0);
    assert_int_equal(cJSON_GetArraySize(t), 1 + MCP_PERC_N_METHODS);
    assert_null(cJSON_GetObjectItem(cJSON_GetArrayItem(t, 1), "pmse"));
    assert_false(
        cJSON_IsTrue(cJSON_GetObjectItem(cJSON_GetArrayItem(t, 5), "rerendered")));
    cJSON_Delete(t);
    assert_error_contains(mcp_perc_compare(perc_cands(&c), c.m, NULL, &o, &t),
                          "needs a surrogate");
    perc_case_free(&c);
}

static void
test_score(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(40, 2, 1, 73, 1, &c);
    mcp_perc_scores s;
    mcp_image *spec = NULL;
    double pm, mse;
    assert_int_equal(
        mcp_perc_score(c.cand[0], c.truth, NULL, c.truth, NULL, 32, &s, &spec), 0);
    assert_int_equal(mcp_pmse(c.cand[0], c.truth, NULL, &pm), 0);
    assert_int_equal(mcp_mse(c.cand[0], c.truth, &mse), 0);
    assert_true(s.pmse == pm && s.mse == mse);
    assert_close(s.energy, pm, 1e-6, 0);
    assert_true(s.low_freq_fraction > 0.0 && s.low_freq_fraction < 1.0);
    assert_non_null(spec);
    assert_int_equal(spec->width, 32); /* one 32x32 tile fits in 40x40 */
    mcp_image_free(spec);
    /* a user kernel is scored by the model itself; below one tile, no spectrum */
    static const double k[9] = {0, 0.1, 0, 0.1, 0.6, 0.1, 0, 0.1, 0};
    mcp_perc_model m = mcp_perc_model_defaults();
    m.user_kernel = k;
    m.user_kernel_width = m.user_kernel_height = 3;
    double e;
    assert_int_equal(mcp_perc_score(c.cand[0], NULL, NULL, c.truth, &m, 64, &s, &spec),
                     0);
    assert_int_equal(mcp_perc_energy(c.cand[0], c.truth, NULL, &m, &e), 0);
    assert_close(s.pmse, e / (40.0 * 40.0 * 3.0), 1e-12, 0);
    assert_true(isnan(s.energy) && isnan(s.low_freq_fraction));
    assert_null(spec);
    perc_case_free(&c);
}

static void
test_optimize_and_names(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(16, 3, 1, 75, 1, &c);
    for (int i = 0; i < MCP_PERC_N_METHODS; i++) {
        mcp_perc_method m;
        assert_int_equal(
            mcp_perc_method_from_name(mcp_perc_method_name((mcp_perc_method)i), &m), 0);
        assert_int_equal((int)m, i);
        mcp_perc_options o = mcp_perc_defaults();
        o.method = m;
        o.mask.use_cache = 0;
        mcp_perc_result r;
        assert_int_equal(mcp_perc_optimize(perc_cands(&c), c.m, c.truth, &o, &r), 0);
        assert_non_null(r.image);
        assert_int_equal(r.permutation != NULL, mcp_perc_method_is_horizontal(m));
        assert_int_equal(r.index != NULL, !mcp_perc_method_is_horizontal(m));
        if (r.index && m != MCP_PERC_POWER_SET) /* its index names subsets */
            perc_assert_from_candidates(r.image, r.index, perc_cands(&c), c.m);
        mcp_perc_result_free(&r);
    }
    mcp_perc_method m;
    mcp_perc_init init;
    assert_error_contains(mcp_perc_method_from_name("simulated-annealing", &m),
                          "unknown perceptual method 'simulated-annealing' (known: "
                          "vertical-iterative,");
    assert_int_equal(mcp_perc_init_from_name("MEAN", &init), 0);
    assert_int_equal(init, MCP_PERC_INIT_MEAN);
    assert_string_equal(mcp_perc_init_name(init), "mean");
    assert_error_contains(mcp_perc_init_from_name("zero", &init), "unknown start 'zero'");
    perc_case_free(&c);
}

static void
test_checks(void **state)
{
    (void)state;
    static const struct {
        int field;
        const char *needle;
    } cases[] = {{0, "unknown method 99"},
                 {1, "passes must be >= 0"},
                 {2, "max_subsets must be >= 1 (got 0)"},
                 {3, "radius must be in [1, 8] (got 9)"},
                 {4, "tile must be in [2, 256] (got 300)"},
                 {5, "mask_sigma must be in (0, mask_size/4] (got 40)"},
                 {6, "unknown tone map 42"},
                 {7, "unknown start 5"}};
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        mcp_perc_options o = mcp_perc_defaults();
        switch (cases[i].field) {
        case 0:
            o.method = (mcp_perc_method)99;
            break;
        case 1:
            o.passes = -3;
            break;
        case 2:
            o.max_subsets = 0;
            break;
        case 3:
            o.radius = 9, o.travel = 9;
            break;
        case 4:
            o.tile = 300;
            break;
        case 5:
            o.mask.sigma = 40.0;
            break;
        case 6:
            o.model.tone_map = (mcp_tonemap)42;
            break;
        case 7:
            o.init = (mcp_perc_init)5;
            break;
        }
        assert_error_contains(mcp_perc_check(&o), cases[i].needle);
    }
    mcp_perc_options o = mcp_perc_defaults();
    assert_int_equal(mcp_perc_check(&o), 0);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_compare_table),
        cmocka_unit_test(test_score),
        cmocka_unit_test(test_optimize_and_names),
        cmocka_unit_test(test_checks),
    };
    return cmocka_run_group_tests_name("perceptual/compare", tests, NULL, NULL);
}
