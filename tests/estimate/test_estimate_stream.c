/* test_estimate_stream.c: the estimate of a dump read a band of rows at a time
 * (estimate/estimate.c's mcp__estimate_streamed, estimate_bands.c's
 * mcp__error_maps_streamed) against mcp_estimate_compute on the dump read whole: F(X),
 * SURE and Var[F] pooled, as the bands hand them out, and SURE^r, Var^r, the sampling
 * map, the sample counts, the blocks, F(τ) and the percentiles, bit for bit. gauss of
 * small and large reach (a halo wider than a band) and nlm; the metrics se and relse;
 * the pooling of s² at radius 0, 1 and 3 (windows into the next band); the three
 * sampling maps; bands of 64 rows over 150 (the last one short). The same one-line
 * error for a bad value in a later band; and what it leaves to the whole estimate: a
 * dump in another format, the default denoiser, the perceptual metric, bands turned
 * off. */
#include "testing.h"

#include <mcpost/denoiser.h>
#include <mcpost/dump.h>
#include <mcpost/estimate.h>
#include <mcpost/imageio.h>
#include <math.h>
#include <procedural.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "../../common/dump/internal.h"
#include "../../estimate/internal.h"

#define W 40
#define H 150

/* The rows a streamed estimate hands out, put together into whole images. */
typedef struct caught {
    mcp_image *img[3]; /* F(X), SURE, Var[F] */
    int rows, calls;
} caught;

static int
catch_rows(void *ctx, const mcp__estimate_rows *r)
{
    caught *c = ctx;
    const mcp_image *src[3] = {r->denoised, r->sure, r->var};
    assert_int_equal(r->width, W);
    assert_int_equal(r->height, H);
    assert_int_equal(r->y0, c->rows); /* in order, each row once */
    for (int i = 0; i < 3; i++) {
        if (!c->img[i])
            assert_int_equal(mcp_image_new(W, H, src[i]->channels,
                                           (const char *const *)src[i]->names,
                                           &c->img[i]),
                             0);
        assert_int_equal(src[i]->height, r->y1 - r->y0);
        for (int y = r->y0; y < r->y1; y++)
            memcpy(mcp_image_px(c->img[i], 0, y), mcp_image_px(src[i], 0, y - r->y0),
                   (size_t)W * src[i]->channels * sizeof(float));
    }
    c->rows = r->y1;
    c->calls++;
    return 0;
}

static void
caught_free(caught *c)
{
    for (int i = 0; i < 3; i++)
        mcp_image_free(c->img[i]);
}

/* A W x H render of spp samples. */
static mcp_dump *
render(int spp, uint64_t seed)
{
    mcp_proc_scene scene = mcp_proc_scene_defaults();
    scene.width = W;
    scene.height = H;
    mcp_dump *d = NULL;
    assert_int_equal(mcp_proc_render(&scene, spp, seed, NULL, &d), 0);
    return d;
}

/* d written as name in the scratch folder (the path, kept until the next call). */
static const char *
write_dump(const mcp_dump *d, const char *name)
{
    static char path[4096];
    snprintf(path, sizeof path, "%s", mcp_test_path(name));
    assert_int_equal(mcp_dump_write(d, path, MCP_CONV_MCPOST, NULL), 0);
    return path;
}

static mcp_denoiser *
denoiser(const char *name, const char *opt)
{
    mcp_denoiser *d = NULL;
    assert_int_equal(mcp_denoiser_create_from_args(name, &opt, opt ? 1 : 0, &d), 0);
    return d;
}

/* The streamed estimate of the file at path, streaming; *c what it handed out. */
static mcp_estimate *
streamed(const char *path, const mcp_denoiser *den, const mcp_estimate_options *o,
         caught *c)
{
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = path;
    const mcp__estimate_sink sink = {catch_rows, c};
    mcp_estimate *e = NULL;
    int done = 0;
    /* without the parts the denoiser does not read, as `mcpost estimate` asks */
    if (mcp__estimate_streamed(&spec, mcp__dump_parts_unread(den, 0), den, o, &sink, &e,
                               &done))
        fail_msg("%s", mcp_error_message());
    assert_int_equal(done, 1);
    return e;
}

static mcp_estimate *
whole(const char *path, const mcp_denoiser *den, const mcp_estimate_options *o)
{
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = path;
    mcp_dump *d = NULL;
    mcp_estimate *e = NULL;
    setenv("MCPOST_ESTIMATE_BAND_ROWS", "whole", 1);
    if (mcp_dump_load(&spec, &d) || mcp_estimate_compute(d, den, o, &e))
        fail_msg("%s", mcp_error_message());
    setenv("MCPOST_ESTIMATE_BAND_ROWS", "64", 1);
    mcp_dump_free(d);
    return e;
}

static void
assert_same_estimate(const mcp_estimate *s, const caught *c, const mcp_estimate *w)
{
    const mcp_error_maps *m = &s->maps, *v = &w->maps;
    assert_null(m->denoised); /* handed out, not held */
    assert_null(m->sure);
    assert_null(m->var);
    assert_null(m->sigma_rel); /* freed once the blocks were cut */
    assert_int_equal(c->rows, H);
    assert_true(c->calls >= 3);
    mcp_test_assert_same_image(c->img[0], v->denoised);
    mcp_test_assert_same_image(c->img[1], v->sure);
    mcp_test_assert_same_image(c->img[2], v->var);
    mcp_test_assert_same_image(m->sure_rel, v->sure_rel);
    mcp_test_assert_same_image(m->var_rel, v->var_rel);
    mcp_test_assert_same_image(s->sampling_map, w->sampling_map);
    if (w->sample_counts) mcp_test_assert_same_image(s->sample_counts, w->sample_counts);
    assert_int_equal(s->blocks->count, w->blocks->count);
    assert_true(s->cdf_at_tau == w->cdf_at_tau);
    assert_int_equal(s->stop, w->stop);
    assert_int_equal(s->no_variance, w->no_variance);
    assert_int_equal(s->s2_pool, w->s2_pool);
    assert_int_equal(s->probes, w->probes);
    assert_int_equal((int)s->variance_source, (int)w->variance_source);
    for (int i = 0; i < s->n_percentiles; i++)
        assert_true(s->percentile_tau[i] == w->percentile_tau[i]);
}

static void
test_streamed_is_whole(void **state)
{
    (void)state;
    mcp_dump *d = render(8, 7);
    const char *path = write_dump(d, "stream.exr");
    mcp_dump_free(d);
    /* reach 5 and 72 rows (more than a band), nlm's 13 */
    mcp_denoiser *dens[3] = {denoiser("gauss", "sigma=1.5"),
                             denoiser("gauss", "sigma=24"), denoiser("nlm", "radius=3")};
    static const mcp_sampling_kind kinds[3] = {
        MCP_SAMPLING_VARIANCE, MCP_SAMPLING_TONEMAPPED, MCP_SAMPLING_MC_SURE};
    static const int pools[3] = {-1, 0, 3};
    int runs = 0;
    for (int di = 0; di < 3; di++)
        for (int metric = 0; metric < 2; metric++)
            for (int v = 0; v < 3; v++) {
                mcp_estimate_options o = mcp_estimate_defaults();
                o.sure.metric = metric ? MCP_METRIC_SE : MCP_METRIC_RELSE;
                o.sampling.kind = kinds[v];
                o.s2_pool = pools[(v + di) % 3];
                o.budget = v == 1 ? 0 : 5000;
                caught c = {0};
                mcp_estimate *s = streamed(path, dens[di], &o, &c),
                             *w = whole(path, dens[di], &o);
                assert_same_estimate(s, &c, w);
                caught_free(&c);
                mcp_estimate_free(s);
                mcp_estimate_free(w);
                runs++;
            }
    assert_int_equal(runs, 18);
    for (int di = 0; di < 3; di++)
        mcp_denoiser_free(dens[di]);
}

/* NaN in the colour in the third band: the whole read's line, and no estimate. */
static void
test_same_error(void **state)
{
    (void)state;
    mcp_dump *d = render(4, 9);
    mcp_image_px(d->color, 11, 140)[1] = NAN;
    const char *path = write_dump(d, "bad.exr");
    mcp_dump_free(d);
    mcp_denoiser *g = denoiser("gauss", NULL);
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = path;
    mcp_dump *whole_dump = NULL;
    assert_int_equal(mcp_dump_load(&spec, &whole_dump), -1);
    char line[2048];
    snprintf(line, sizeof line, "%s", mcp_error_message());
    mcp_estimate *e = NULL;
    int done = 0;
    const mcp_estimate_options o = mcp_estimate_defaults();
    assert_int_equal(mcp__estimate_streamed(&spec, 0, g, &o, NULL, &e, &done), -1);
    assert_int_equal(done, 1);
    assert_null(e);
    assert_string_equal(mcp_error_message(), line);
    print_message("both: %s\n", line);
    mcp_denoiser_free(g);
}

/* What goes to the whole estimate: *done 0, nothing set, no error. */
static void
assert_left_whole(const char *path, const mcp_denoiser *den,
                  const mcp_estimate_options *o)
{
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = path;
    mcp_estimate *e = NULL;
    int done = 1;
    mcp_error_clear();
    assert_int_equal(mcp__estimate_streamed(&spec, 0, den, o, NULL, &e, &done), 0);
    assert_int_equal(done, 0);
    assert_null(e);
    assert_string_equal(mcp_error_message(), "");
}

static void
test_left_whole(void **state)
{
    (void)state;
    mcp_dump *d = render(4, 11);
    const char *exr = write_dump(d, "left.exr");
    char pfm[4096];
    snprintf(pfm, sizeof pfm, "%s", mcp_test_path("left.pfm"));
    assert_int_equal(mcp_image_write(d->color, pfm, NULL), 0);
    mcp_dump_free(d);
    mcp_denoiser *g = denoiser("gauss", NULL), *def = NULL;
    assert_int_equal(mcp_denoiser_create_from_args("default", NULL, 0, &def), 0);
    mcp_estimate_options o = mcp_estimate_defaults();
    assert_left_whole(pfm, g, &o);   /* not an EXR */
    assert_left_whole(exr, def, &o); /* picks its denoiser by the dump */
    o.sure.metric = MCP_METRIC_RELSE_PERCEPTUAL;
    assert_left_whole(exr, g, &o);
    o = mcp_estimate_defaults();
    setenv("MCPOST_ESTIMATE_BAND_ROWS", "whole", 1);
    assert_left_whole(exr, g, &o);
    setenv("MCPOST_ESTIMATE_BAND_ROWS", "64", 1);
    mcp_denoiser_free(def);
    mcp_denoiser_free(g);
}

static int
bands_of_64(void **state)
{
    (void)state;
    return setenv("MCPOST_ESTIMATE_BAND_ROWS", "64", 1);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_streamed_is_whole),
        cmocka_unit_test(test_same_error),
        cmocka_unit_test(test_left_whole),
    };
    return cmocka_run_group_tests(tests, bands_of_64, NULL);
}
