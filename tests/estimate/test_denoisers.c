/* test_denoisers.c: the denoiser table and the built-in denoisers (estimate/denoisers.c,
 * denoise_gauss.c, denoise_nlm.c; docs/mathematics.md §2.1).
 *
 * Truth comes from closed forms and naive versions: gauss against a direct 2D
 * convolution and linearity; nlm against a naive double-precision transcription of its
 * formula; every Jacobian-vector product against central finite differences, both of
 * the float denoiser itself and (for nlm) of the double version; denoising against a
 * known noise-free image. Also: several tangents in one call equal separate calls,
 * results do not depend on the thread count, errors name what is wrong, and the
 * `mcpost denoise` command. */
#include "denoiser_settings.h"
#include "testing.h"

#include <mcpost/denoiser.h>
#include <mcpost/imageio.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* ---- helpers ---- */

/* The kinds that are built in and exact, created from their bare name: every kind but
 * those that wrap something outside (an external command, a weights file), which
 * test_external.c and test_unet.c test, and james-stein and default, which use the
 * U-Net (tests/blend/test_james_stein.c, tests/cli/test_cli.c). */
static int
self_contained(const mcp_denoiser_kind *k)
{
    return strcmp(k->name, "external") != 0 && strcmp(k->name, "unet") != 0 &&
           strcmp(k->name, "james-stein") != 0 && strcmp(k->name, "default") != 0;
}

#define FOR_EACH_BUILTIN(k)                                                              \
    for (const mcp_denoiser_kind *const *k = mcp_denoiser_kinds(); *k; k++)              \
        if (self_contained(*k))

static mcp_image *
rgb(int w, int h)
{
    static const char *const names[] = {"R", "G", "B"};
    mcp_image *img = NULL;
    if (mcp_image_new(w, h, 3, names, &img)) fail_msg("%s", mcp_error_message());
    return img;
}

static size_t
n_values(const mcp_image *img)
{
    return (size_t)img->width * img->height * 3;
}

static void
assert_same_bits(const mcp_image *a, const mcp_image *b)
{
    assert_int_equal(a->width, b->width);
    assert_int_equal(a->height, b->height);
    assert_memory_equal(a->data, b->data, n_values(a) * sizeof(float));
}

/* A synthetic render with a known truth: a piecewise-smooth image (albedo cells and a
 * disc under a smooth light), the albedo and a two-plane normal as features, and
 * Gaussian noise of standard deviation noise_rel * truth (its variance is given). */
typedef struct {
    mcp_image *truth, *color, *albedo, *normal, *variance;
} scene;

static scene
make_scene(int w, int h, double noise_rel, uint64_t seed)
{
    scene s = {rgb(w, h), rgb(w, h), rgb(w, h), rgb(w, h), rgb(w, h)};
    static const float palette[4][3] = {
        {0.8f, 0.2f, 0.1f}, {0.1f, 0.6f, 0.2f}, {0.2f, 0.3f, 0.9f}, {0.7f, 0.7f, 0.6f}};
    uint64_t st = seed;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            int cell = ((x / 9) + 2 * (y / 7)) % 4;
            double dx = x - 0.6 * w, dy = y - 0.4 * h;
            if (dx * dx + dy * dy < 0.06 * w * h) cell = 3;
            int wall = y < h / 3;
            double light = 1.2 + 0.3 * sin(0.02 * x + 0.03 * y);
            size_t i = ((size_t)y * w + x) * 3;
            for (int c = 0; c < 3; c++) {
                double t = palette[cell][c] * light;
                double sd = noise_rel * t + 1e-3;
                s.truth->data[i + c] = (float)t;
                s.albedo->data[i + c] = palette[cell][c];
                s.normal->data[i + c] =
                    wall ? (c == 2 ? -1.0f : 0.0f) : (c == 1 ? 1.0f : 0.0f);
                s.variance->data[i + c] = (float)(sd * sd);
                s.color->data[i + c] = (float)(t + sd * mcp_test_rand_normal(&st));
            }
        }
    return s;
}

static void
free_scene(scene *s)
{
    mcp_image_free(s->truth);
    mcp_image_free(s->color);
    mcp_image_free(s->albedo);
    mcp_image_free(s->normal);
    mcp_image_free(s->variance);
}

static mcp_denoise_input
input_of(const scene *s)
{
    mcp_denoise_input in = {s->color, s->albedo, s->normal, s->variance};
    return in;
}

/* A tangent like a SURE probe: N(0, scale^2) per value, scale = the square root of
 * `variance` (or 0.05 without one). */
static mcp_image *
probe(const mcp_image *like, const mcp_image *variance, uint64_t seed)
{
    mcp_image *t = rgb(like->width, like->height);
    uint64_t st = seed;
    for (size_t i = 0; i < n_values(t); i++)
        t->data[i] = (float)(mcp_test_rand_normal(&st) *
                             (variance ? sqrt(variance->data[i]) : 0.05));
    return t;
}

/* out = x + a t (packed images). */
static mcp_image *
axpy(const mcp_image *x, double a, const mcp_image *t)
{
    mcp_image *o = rgb(x->width, x->height);
    for (size_t i = 0; i < n_values(o); i++)
        o->data[i] = (float)(x->data[i] + a * t->data[i]);
    return o;
}

static mcp_image *
apply(const mcp_denoiser *d, const mcp_denoise_input *in)
{
    mcp_image *out = NULL;
    if (d->apply(d, in, &out)) fail_msg("%s apply: %s", d->name, mcp_error_message());
    return out;
}

/* F(in with colour x + a tc and albedo/normal + a ta/tn). */
static mcp_image *
apply_moved(const mcp_denoiser *d, const mcp_denoise_input *in,
            const mcp_denoise_tangent *t, double a)
{
    mcp_image *x = axpy(in->color, a, t->color), *al = NULL, *nr = NULL;
    mcp_denoise_input moved = *in;
    moved.color = x;
    if (t->albedo) moved.albedo = al = axpy(in->albedo, a, t->albedo);
    if (t->normal) moved.normal = nr = axpy(in->normal, a, t->normal);
    mcp_image *out = apply(d, &moved);
    mcp_image_free(x);
    mcp_image_free(al);
    mcp_image_free(nr);
    return out;
}

/* The fourth-order central difference of F along t, in double from float F:
 * [8 (F(x + d t) - F(x - d t)) - (F(x + 2d t) - F(x - 2d t))] / (12 d). Its truncation
 * error is O(d^4), so d can stay large enough that float rounding of F (~1e-7 F,
 * divided by d) does not matter. */
static double *
central_difference(const mcp_denoiser *d, const mcp_denoise_input *in,
                   const mcp_denoise_tangent *t, double delta)
{
    mcp_image *p1 = apply_moved(d, in, t, delta), *m1 = apply_moved(d, in, t, -delta);
    mcp_image *p2 = apply_moved(d, in, t, 2 * delta);
    mcp_image *m2 = apply_moved(d, in, t, -2 * delta);
    size_t n = n_values(p1);
    double *fd = malloc(n * sizeof *fd);
    assert_non_null(fd);
    for (size_t i = 0; i < n; i++)
        fd[i] = (8.0 * ((double)p1->data[i] - m1->data[i]) -
                 ((double)p2->data[i] - m2->data[i])) /
                (12 * delta);
    mcp_image_free(p1);
    mcp_image_free(m1);
    mcp_image_free(p2);
    mcp_image_free(m2);
    return fd;
}

static double
rel_diff_to(const mcp_image *a, const double *b)
{
    double num = 0, den = 0;
    for (size_t i = 0; i < n_values(a); i++) {
        double d = a->data[i] - b[i];
        num += d * d;
        den += b[i] * b[i];
    }
    return sqrt(num / den);
}

/* ---- the table and creation ---- */

static void
test_kinds_table(void **state)
{
    (void)state;
    const mcp_denoiser_kind *const *k = mcp_denoiser_kinds();
    int n = 0, gauss = 0, nlm = 0, bilateral = 0;
    for (; k[n]; n++) {
        assert_non_null(k[n]->summary);
        assert_non_null(k[n]->keys);
        assert_non_null(k[n]->create);
        gauss |= strcmp(k[n]->name, "gauss") == 0;
        nlm |= strcmp(k[n]->name, "nlm") == 0;
        bilateral |= strcmp(k[n]->name, "bilateral") == 0;
        if (!self_contained(k[n])) continue;
        /* every kind is created from its bare name, and is exact (built in) */
        char yaml[64];
        snprintf(yaml, sizeof yaml, "%s", k[n]->name);
        mcp_denoiser *d = mcp_test_denoiser(yaml);
        assert_string_equal(d->name, k[n]->name);
        assert_int_equal(d->exact, 1);
        assert_non_null(d->apply);
        assert_non_null(d->jvp);
        mcp_denoiser_free(d);
    }
    assert_true(n >= 3);
    assert_true(gauss && nlm && bilateral);
    mcp_denoiser_free(NULL);
}

static void
test_create_forms(void **state)
{
    (void)state;
    mcp_denoiser *d = mcp_test_denoiser("{name: gauss, sigma: 1.5, radius: 3}");
    assert_string_equal(d->name, "gauss");
    assert_int_equal(d->uses_albedo, 0);
    mcp_denoiser_free(d);
    d = mcp_test_denoiser("name: nlm\nradius: 2\nuse_variance: false\nsigma_albedo: 0\n");
    assert_int_equal(d->uses_albedo, 0);
    assert_int_equal(d->uses_normal, 1);
    mcp_denoiser_free(d);

    const char *opts[] = {"sigma=1.5", "radius=3"};
    d = NULL;
    assert_int_equal(mcp_denoiser_create_from_args("gauss", opts, 2, &d), 0);
    assert_string_equal(d->name, "gauss");
    mcp_denoiser_free(d);
    const char *nlm_opts[] = {"radius=2", "k_color=.6", "use_variance=no",
                              "sigma_color=1e-1"};
    assert_int_equal(mcp_denoiser_create_from_args("nlm", nlm_opts, 4, &d), 0);
    mcp_denoiser_free(d);
    assert_int_equal(mcp_denoiser_create_from_args("nlm", NULL, 0, &d), 0);
    mcp_denoiser_free(d);
}

static void
test_create_errors(void **state)
{
    (void)state;
    mcp_test_denoiser_fails(
        "blur", "job.yaml:1: unknown denoiser 'blur' (known: gauss, nlm, bilateral");
    mcp_test_denoiser_fails("{name: blur}", "job.yaml:1: unknown denoiser 'blur'");
    mcp_test_denoiser_fails("[gauss]", "job.yaml:1: denoiser must be a name or a map");
    mcp_test_denoiser_fails("{sigma: 2}",
                            "job.yaml:1: missing key 'name' in denoiser settings");
    mcp_test_denoiser_fails(
        "name: gauss\nsigma: 2\nsigmaa: 3\n",
        "job.yaml:3: unknown key 'sigmaa' in denoiser 'gauss' (known: name, "
        "sigma, radius)");
    mcp_test_denoiser_fails("name: nlm\nradus: 3\n",
                            "job.yaml:2: unknown key 'radus' in denoiser "
                            "'nlm'");
    mcp_test_denoiser_fails("{name: gauss, sigma: -1}",
                            "job.yaml:1: gauss: sigma must be > 0");
    mcp_test_denoiser_fails("{name: gauss, sigma: 0}", "sigma must be > 0");
    mcp_test_denoiser_fails("{name: gauss, sigma: abc}",
                            "job.yaml:1: sigma must be a number (got "
                            "'abc')");
    mcp_test_denoiser_fails("{name: gauss, radius: -2}",
                            "gauss: radius must be in [0, 65536] px "
                            "(got -2)");
    mcp_test_denoiser_fails("{name: gauss, radius: 2.5}",
                            "radius must be an integer (got '2.5')");
    mcp_test_denoiser_fails("{name: nlm, radius: 100}",
                            "nlm: radius must be in [0, 64] (got 100)");
    mcp_test_denoiser_fails("{name: nlm, patch_radius: -1}",
                            "nlm: patch_radius must be in [0, 16]");
    mcp_test_denoiser_fails("{name: nlm, k_color: 0}", "nlm: k_color must be > 0");
    mcp_test_denoiser_fails("{name: nlm, epsilon: 0}", "nlm: epsilon must be > 0");
    mcp_test_denoiser_fails("{name: nlm, alpha: -1}", "nlm: alpha must be >= 0");
    mcp_test_denoiser_fails("{name: nlm, sigma_albedo: -0.1}",
                            "nlm: sigma_albedo must be >= 0");
    mcp_test_denoiser_fails("{name: bilateral, sigma_spatial: -1}",
                            "job.yaml:1: bilateral: sigma_spatial must be >= 0");
    mcp_test_denoiser_fails("{name: nlm, use_variance: maybe}",
                            "use_variance must be true or "
                            "false (got 'maybe')");
    mcp_test_denoiser_fails("{name: nlm, radius: [1, 2]}",
                            "radius must be an integer, not a list");

    mcp_denoiser *d = (mcp_denoiser *)&d;
    assert_error_contains(
        mcp_denoiser_create_from_args("blur", NULL, 0, &d),
        "unknown denoiser 'blur' (known: gauss, nlm, bilateral, external");
    assert_null(d);
    assert_error_contains(mcp_denoiser_create_from_args(NULL, NULL, 0, &d),
                          "no denoiser named");
    const char *bad1[] = {"sigma"};
    assert_error_contains(mcp_denoiser_create_from_args("gauss", bad1, 1, &d),
                          "--denoiser-opt: bad option 'sigma' (want key=value)");
    const char *bad2[] = {"radius=3", "sigmaa=2"};
    assert_error_contains(mcp_denoiser_create_from_args("gauss", bad2, 2, &d),
                          "--denoiser-opt:2: unknown key 'sigmaa' in denoiser 'gauss'");
    const char *bad3[] = {"sigma=1", "sigma=2"};
    assert_error_contains(mcp_denoiser_create_from_args("gauss", bad3, 2, &d),
                          "--denoiser-opt: key 'sigma' given twice");
    const char *bad4[] = {"name=nlm"};
    assert_error_contains(mcp_denoiser_create_from_args("gauss", bad4, 1, &d),
                          "the name is given by --denoiser");
    /* values that YAML would misread are quoted, so they stay strings */
    const char *bad5[] = {"sigma={1: 2}"};
    assert_error_contains(mcp_denoiser_create_from_args("gauss", bad5, 1, &d),
                          "--denoiser-opt:1: sigma must be a number (got '{1: 2}')");
    const char *bad6[] = {"radius=", "sigma=1"};
    assert_error_contains(mcp_denoiser_create_from_args("gauss", bad6, 2, &d),
                          "--denoiser-opt:1: radius must be an integer (got '')");
    assert_null(d);
}

static void
test_input_of_dump(void **state)
{
    (void)state;
    mcp_dump dump = {0};
    dump.color = rgb(4, 3);
    dump.albedo = rgb(4, 3);
    dump.var_of_mean = rgb(4, 3);
    mcp_denoise_input in = mcp_denoise_input_of(&dump);
    assert_ptr_equal(in.color, dump.color);
    assert_ptr_equal(in.albedo, dump.albedo);
    assert_null(in.normal);
    assert_ptr_equal(in.variance, dump.var_of_mean);
    in = mcp_denoise_input_of(NULL);
    assert_null(in.color);
    mcp_image_free(dump.color);
    mcp_image_free(dump.albedo);
    mcp_image_free(dump.var_of_mean);
}

/* ---- errors at apply / jvp time ---- */

static void
test_input_errors(void **state)
{
    (void)state;
    scene s = make_scene(12, 10, 0.1, 1);
    mcp_image *small = rgb(11, 10), *four = NULL, *out = (mcp_image *)&out;
    assert_int_equal(mcp_image_new(12, 10, 4, NULL, &four), 0);
    FOR_EACH_BUILTIN(kind)
    {
        const char *name = (*kind)->name;
        mcp_denoiser *d = mcp_test_denoiser(name);
        mcp_denoise_input in = {0};
        char msg[128];
        snprintf(msg, sizeof msg, "%s: no colour given", name);
        assert_error_contains(d->apply(d, &in, &out), msg);
        assert_null(out);
        in.color = four;
        snprintf(msg, sizeof msg, "%s: colour must have 3 channels (got 4)", name);
        assert_error_contains(d->apply(d, &in, &out), msg);
        in = input_of(&s);
        in.albedo = small;
        assert_error_contains(d->apply(d, &in, &out), "albedo: ");
        assert_error_contains(d->apply(d, &in, &out), "does not match");
        in = input_of(&s);
        in.variance = four;
        assert_error_contains(d->apply(d, &in, &out), "variance must have 3 channels");

        in = input_of(&s);
        mcp_denoise_tangent t[2] = {{s.color, NULL, NULL}, {small, NULL, NULL}};
        mcp_image *outs[2] = {(mcp_image *)&out, (mcp_image *)&out};
        mcp_image *prim = (mcp_image *)&out;
        assert_error_contains(d->jvp(d, &in, t, 2, &prim, outs), "tangent 1 colour: ");
        assert_null(outs[0]);
        assert_null(outs[1]);
        assert_null(prim);
        t[1].color = NULL;
        assert_error_contains(d->jvp(d, &in, t, 2, NULL, outs),
                              "tangent 1 has no colour");
        t[1].color = s.color;
        t[1].normal = four;
        assert_error_contains(d->jvp(d, &in, t, 2, NULL, outs),
                              "tangent 1 normal must have 3 channels");
        assert_error_contains(d->jvp(d, &in, t, -1, NULL, outs),
                              "number of tangents must be >= 0 (got -1)");
        /* no tangents: only the primal */
        assert_int_equal(d->jvp(d, &in, NULL, 0, &prim, NULL), 0);
        mcp_image *ref = apply(d, &in);
        assert_same_bits(prim, ref);
        mcp_image_free(prim);
        mcp_image_free(ref);
        mcp_denoiser_free(d);
    }
    mcp_image_free(small);
    mcp_image_free(four);
    free_scene(&s);
}

/* NaN and Inf in the colour (renders have them) stay within the window they fall in:
 * the call succeeds and pixels farther than the window are finite. */
static void
test_nasty_values(void **state)
{
    (void)state;
    scene s = make_scene(48, 44, 0.2, 2);
    mcp_image_px(s.color, 5, 5)[1] = NAN;
    mcp_image_px(s.color, 36, 30)[0] = INFINITY;
    mcp_image_px(s.color, 37, 30)[2] = -INFINITY;
    mcp_image_px(s.variance, 20, 40)[0] = NAN;
    mcp_image *t0 = probe(s.color, NULL, 4);
    mcp_denoise_tangent t = {t0, NULL, NULL};
    FOR_EACH_BUILTIN(k)
    {
        mcp_denoiser *d = mcp_test_denoiser((*k)->name);
        mcp_denoise_input in = input_of(&s);
        mcp_image *prim = NULL, *jt = NULL;
        assert_int_equal(d->jvp(d, &in, &t, 1, &prim, &jt), 0);
        int far = 0;
        for (int y = 0; y < 44; y++)
            for (int x = 0; x < 48; x++) {
                /* every window here is at most 2 * 6 + 1 or 2 * 9 + 1 wide */
                if ((abs(x - 5) <= 10 && abs(y - 5) <= 10) ||
                    (abs(x - 36) <= 11 && abs(y - 30) <= 10))
                    continue;
                far++;
                for (int c = 0; c < 3; c++) {
                    assert_true(isfinite(mcp_image_px(prim, x, y)[c]));
                    assert_true(isfinite(mcp_image_px(jt, x, y)[c]));
                }
            }
        assert_true(far > 1000);
        mcp_image_free(prim);
        mcp_image_free(jt);
        mcp_denoiser_free(d);
    }
    mcp_image_free(t0);
    free_scene(&s);
}

/* ---- gauss ---- */

static void
test_gauss_is_direct_convolution(void **state)
{
    (void)state;
    int w = 37, h = 23, r = 4;
    double sigma = 1.3;
    mcp_image *x = mcp_test_random(w, h, 3, -1, 2, 7, NULL);
    mcp_denoiser *d = mcp_test_denoiser("{name: gauss, sigma: 1.3, radius: 4}");
    mcp_denoise_input in = {x, NULL, NULL, NULL};
    mcp_image *out = apply(d, &in);
    assert_string_equal(out->names[0], "R");
    assert_string_equal(out->names[2], "B");
    double k[9], sum = 0;
    for (int i = -r; i <= r; i++)
        sum += k[i + r] = exp(-i * i / (2 * sigma * sigma));
    double max_err = 0;
    for (int y = 0; y < h; y++)
        for (int xx = 0; xx < w; xx++)
            for (int c = 0; c < 3; c++) {
                double acc = 0;
                for (int j = -r; j <= r; j++)
                    for (int i = -r; i <= r; i++) {
                        int sx = xx + i < 0 ? 0 : xx + i >= w ? w - 1 : xx + i;
                        int sy = y + j < 0 ? 0 : y + j >= h ? h - 1 : y + j;
                        acc += k[i + r] * k[j + r] / (sum * sum) *
                               mcp_image_px(x, sx, sy)[c];
                    }
                double e = fabs(acc - mcp_image_px(out, xx, y)[c]);
                max_err = e > max_err ? e : max_err;
            }
    /* float kernel and float accumulation of 81 terms of size <= 2 */
    assert_true(max_err < 2e-6);
    mcp_image_free(out);
    mcp_image_free(x);
    mcp_denoiser_free(d);
}

static void
test_gauss_is_linear(void **state)
{
    (void)state;
    mcp_image *x = mcp_test_random(40, 30, 3, 0, 1, 1, NULL);
    mcp_image *y = mcp_test_random(40, 30, 3, -2, 5, 2, NULL);
    mcp_image *mix = rgb(40, 30), *want = rgb(40, 30);
    double a = 0.7, b = -1.9;
    for (size_t i = 0; i < n_values(mix); i++)
        mix->data[i] = (float)(a * x->data[i] + b * y->data[i]);
    mcp_denoiser *d = mcp_test_denoiser("gauss");
    mcp_denoise_input ix = {x, NULL, NULL, NULL}, iy = {y, NULL, NULL, NULL};
    mcp_denoise_input im = {mix, NULL, NULL, NULL};
    mcp_image *fx = apply(d, &ix), *fy = apply(d, &iy), *fm = apply(d, &im);
    for (size_t i = 0; i < n_values(want); i++)
        want->data[i] = (float)(a * fx->data[i] + b * fy->data[i]);
    /* float rounding of values up to ~10 */
    assert_true(mcp_test_max_abs_diff(fm, want) < 1e-5);
    /* and the JVP is the filter itself, whatever the point */
    mcp_image *jt = NULL;
    mcp_denoise_tangent t = {y, NULL, NULL};
    assert_int_equal(d->jvp(d, &ix, &t, 1, NULL, &jt), 0);
    assert_same_bits(jt, fy);
    mcp_image_free(jt);
    mcp_image_free(fx);
    mcp_image_free(fy);
    mcp_image_free(fm);
    mcp_image_free(x);
    mcp_image_free(y);
    mcp_image_free(mix);
    mcp_image_free(want);
    mcp_denoiser_free(d);
}

/* ---- nlm against a naive double-precision transcription ---- */

typedef struct {
    int radius, patch;
    double k, alpha, eps, sigma_albedo, sigma_normal, sigma_spatial;
    const char *yaml; /* the same settings for the denoiser */
} naive_params;

static int
clampi(int v, int hi)
{
    return v < 0 ? 0 : v > hi ? hi : v;
}

/* The formula of denoise_nlm.c, written out for one pixel at a time in double, with
 * the variance used as given (the test turns variance_blur off). x, v, a, n: packed
 * w x h x 3 (a, n may be NULL); out likewise. */
static void
naive_nlm(const naive_params *p, int w, int h, const double *x, const double *v,
          const double *a, const double *n, double *out)
{
    double norm = 1.0 / (3.0 * (2 * p->patch + 1) * (2 * p->patch + 1));
    for (int py = 0; py < h; py++)
        for (int px = 0; px < w; px++) {
            double wsum = 0, num[3] = {0, 0, 0};
            for (int oy = -p->radius; oy <= p->radius; oy++)
                for (int ox = -p->radius; ox <= p->radius; ox++) {
                    double dc = 0;
                    for (int sy = -p->patch; sy <= p->patch; sy++)
                        for (int sx = -p->patch; sx <= p->patch; sx++) {
                            int ia =
                                (clampi(py + sy, h - 1) * w + clampi(px + sx, w - 1));
                            int ib = (clampi(py + oy + sy, h - 1) * w +
                                      clampi(px + ox + sx, w - 1));
                            for (int c = 0; c < 3; c++) {
                                double va = v[3 * ia + c], vb = v[3 * ib + c];
                                double d = x[3 * ia + c] - x[3 * ib + c];
                                dc += (d * d - p->alpha * (va + fmin(va, vb))) /
                                      (p->eps + p->k * p->k * (va + vb));
                            }
                        }
                    dc *= norm;
                    /* max(0, dc), rounded off over |dc| < 0.2 into a parabola */
                    double kink = 0.2;
                    double lw = dc <= -kink  ? 0
                                : dc >= kink ? -dc
                                             : -(dc + kink) * (dc + kink) / (4 * kink);
                    int ip = py * w + px;
                    int iq = clampi(py + oy, h - 1) * w + clampi(px + ox, w - 1);
                    for (int c = 0; c < 3; c++) {
                        if (a) {
                            double d = a[3 * ip + c] - a[3 * iq + c];
                            lw -= d * d / (2 * p->sigma_albedo * p->sigma_albedo);
                        }
                        if (n) {
                            double d = n[3 * ip + c] - n[3 * iq + c];
                            lw -= d * d / (2 * p->sigma_normal * p->sigma_normal);
                        }
                    }
                    if (p->sigma_spatial > 0)
                        lw -= (ox * ox + oy * oy) /
                              (2 * p->sigma_spatial * p->sigma_spatial);
                    double wt = exp(lw);
                    wsum += wt;
                    for (int c = 0; c < 3; c++)
                        num[c] += wt * x[3 * iq + c];
                }
            for (int c = 0; c < 3; c++)
                out[3 * (py * w + px) + c] = num[c] / wsum;
        }
}

static double *
to_double(const mcp_image *img, double a, const mcp_image *t)
{
    double *o = malloc(n_values(img) * sizeof *o);
    assert_non_null(o);
    for (size_t i = 0; i < n_values(img); i++)
        o[i] = img->data[i] + (t ? a * t->data[i] : 0);
    return o;
}

/* The float denoiser against the naive double version for settings p: F itself, and
 * J t (colour tangent; colour, albedo and normal tangent) against double central
 * differences. */
static void
check_against_naive(const naive_params *p)
{
    int w = 21, h = 17;
    scene s = make_scene(w, h, 0.2, 5);
    mcp_denoiser *d = mcp_test_denoiser(p->yaml);
    mcp_denoise_input in = input_of(&s);
    mcp_image *tc = probe(s.color, s.variance, 11);
    mcp_image *ta = mcp_test_random(w, h, 3, -0.05, 0.05, 12, NULL);
    mcp_image *tn = mcp_test_random(w, h, 3, -0.1, 0.1, 13, NULL);
    mcp_denoise_tangent t[2] = {{tc, NULL, NULL}, {tc, ta, tn}};
    mcp_image *prim = NULL, *jt[2] = {NULL, NULL};
    assert_int_equal(d->jvp(d, &in, t, 2, &prim, jt), 0);

    double *x = to_double(s.color, 0, NULL), *v = to_double(s.variance, 0, NULL);
    double *a = to_double(s.albedo, 0, NULL), *n = to_double(s.normal, 0, NULL);
    size_t nv = n_values(prim);
    double *ref = malloc(nv * sizeof *ref), *fp = malloc(nv * sizeof *fp);
    double *fm = malloc(nv * sizeof *fm), *fd = malloc(nv * sizeof *fd);
    assert_true(ref && fp && fm && fd);
    naive_nlm(p, w, h, x, v, a, n, ref);
    /* float sums of up to 49 offsets x 75 terms: about 1e-7 relative, as measured */
    double err = rel_diff_to(prim, ref);
    print_message("%s\n  F: float vs naive double %.2e\n", p->yaml, err);
    assert_true(err < 1e-5);

    /* with d = 1e-6 the double differences have truncation ~1e-12 and rounding
     * ~1e-10, far below the float JVP's own rounding (~1e-7) */
    double delta = 1e-6;
    for (int k = 0; k < 2; k++) {
        double *xp = to_double(s.color, delta, tc), *xm = to_double(s.color, -delta, tc);
        double *ap = k ? to_double(s.albedo, delta, ta) : NULL;
        double *am = k ? to_double(s.albedo, -delta, ta) : NULL;
        double *np = k ? to_double(s.normal, delta, tn) : NULL;
        double *nm = k ? to_double(s.normal, -delta, tn) : NULL;
        naive_nlm(p, w, h, xp, v, k ? ap : a, k ? np : n, fp);
        naive_nlm(p, w, h, xm, v, k ? am : a, k ? nm : n, fm);
        for (size_t i = 0; i < nv; i++)
            fd[i] = (fp[i] - fm[i]) / (2 * delta);
        err = rel_diff_to(jt[k], fd);
        print_message("  J t (%s) vs double central difference: %.2e\n",
                      k ? "colour and features" : "colour", err);
        assert_true(err < 1e-5);
        free(xp);
        free(xm);
        free(ap);
        free(am);
        free(np);
        free(nm);
    }
    free(fp);
    free(fm);
    free(fd);
    free(ref);
    free(x);
    free(v);
    free(a);
    free(n);
    mcp_image_free(prim);
    mcp_image_free(jt[0]);
    mcp_image_free(jt[1]);
    mcp_image_free(tc);
    mcp_image_free(ta);
    mcp_image_free(tn);
    mcp_denoiser_free(d);
    free_scene(&s);
}

static void
test_nlm_matches_naive_double(void **state)
{
    (void)state;
    naive_params patch = {3,
                          1,
                          0.45,
                          1.0,
                          1e-4,
                          0.2,
                          0.3,
                          0,
                          "{name: nlm, radius: 3, patch_radius: 1, k_color: 0.45, "
                          "alpha: 1, epsilon: 1e-4, variance_blur: 0, "
                          "sigma_albedo: 0.2, sigma_normal: 0.3}"};
    check_against_naive(&patch);
    naive_params pixel = {4,
                          0,
                          2.0,
                          0.5,
                          1e-3,
                          0.1,
                          0.5,
                          1.5,
                          "{name: bilateral, radius: 4, k_color: 2, alpha: 0.5, "
                          "epsilon: 1e-3, variance_blur: 0, sigma_albedo: 0.1, "
                          "sigma_normal: 0.5, sigma_spatial: 1.5}"};
    check_against_naive(&pixel);
}

/* ---- every built-in: JVP against finite differences of the float denoiser ---- */

static void
check_jvp_fd(const char *yaml, const scene *s, const mcp_denoise_tangent *t, double delta,
             double tol)
{
    mcp_denoiser *d = mcp_test_denoiser(yaml);
    mcp_denoise_input in = input_of(s);
    mcp_image *jt = NULL;
    assert_int_equal(d->jvp(d, &in, t, 1, NULL, &jt), 0);
    double *fd = central_difference(d, &in, t, delta);
    double err = rel_diff_to(jt, fd);

    print_message("%-60s |Jt - FD| / |FD| = %.2e\n", yaml, err);
    assert_true(err < tol);
    free(fd);
    mcp_image_free(jt);
    mcp_denoiser_free(d);
}

static void
test_jvp_finite_differences(void **state)
{
    (void)state;
    scene s = make_scene(48, 40, 0.15, 3);
    mcp_image *tc = probe(s.color, s.variance, 21);
    mcp_image *ta = mcp_test_random(48, 40, 3, -0.02, 0.02, 22, NULL);
    mcp_denoise_tangent t = {tc, NULL, NULL}, tf = {tc, ta, ta};
    /* The tangent has the noise's scale and delta = 1e-2 of it: the fourth-order
     * difference then has truncation ~1e-8 and float-rounding error ~1e-7 / 1e-2, well
     * under the 1e-3 asked of the JVP (nlm's kink at dc = 0 adds a little where a
     * patch distance crosses it). */
    FOR_EACH_BUILTIN(k)
    {
        char yaml[64];
        snprintf(yaml, sizeof yaml, "%s", (*k)->name);
        check_jvp_fd(yaml, &s, &t, 1e-2, 1e-3);
        check_jvp_fd(yaml, &s, &tf, 1e-2, 1e-3);
    }
    /* nlm's variants: no variance (sigma_color), no features, small epsilon */
    check_jvp_fd("{name: nlm, use_variance: false, sigma_color: 0.1}", &s, &t, 1e-2,
                 1e-3);
    check_jvp_fd("{name: nlm, sigma_albedo: 0, sigma_normal: 0, radius: 4, "
                 "patch_radius: 1}",
                 &s, &t, 1e-2, 1e-3);
    /* smoother (wider bandwidth): rounding dominates, so a larger step */
    check_jvp_fd("{name: nlm, k_color: 1.5, variance_blur: 2, alpha: 2}", &s, &tf, 3e-2,
                 1e-3);
    mcp_image_free(tc);
    mcp_image_free(ta);
    free_scene(&s);
}

/* A constant shift of every colour changes no colour difference, so nlm (and any
 * normalised filter) moves by the same constant: J 1 = 1. */
static void
test_jvp_of_constant_shift(void **state)
{
    (void)state;
    scene s = make_scene(40, 36, 0.2, 8);
    mcp_image *one = mcp_test_constant(40, 36, 3, 1.0f, NULL);
    mcp_denoise_tangent t = {one, NULL, NULL};
    FOR_EACH_BUILTIN(k)
    {
        mcp_denoiser *d = mcp_test_denoiser((*k)->name);
        mcp_denoise_input in = input_of(&s);
        mcp_image *jt = NULL;
        assert_int_equal(d->jvp(d, &in, &t, 1, NULL, &jt), 0);
        /* float sums of ~200 weights */
        assert_true(mcp_test_max_abs_diff(jt, one) < 1e-5);
        mcp_image_free(jt);
        mcp_denoiser_free(d);
    }
    mcp_image_free(one);
    free_scene(&s);
}

/* ---- several tangents in one pass ---- */

static void
test_tangents_in_one_pass(void **state)
{
    (void)state;
    scene s = make_scene(45, 38, 0.2, 4);
    mcp_image *t0 = probe(s.color, s.variance, 1), *t1 = probe(s.color, s.variance, 2);
    mcp_image *t2 = probe(s.color, NULL, 3),
              *ta = mcp_test_random(45, 38, 3, -.1, .1, 4, NULL);
    mcp_denoise_tangent t[3] = {{t0, NULL, NULL}, {t1, ta, NULL}, {t2, NULL, ta}};
    FOR_EACH_BUILTIN(k)
    {
        mcp_denoiser *d = mcp_test_denoiser((*k)->name);
        mcp_denoise_input in = input_of(&s);
        mcp_image *prim = NULL, *all[3] = {NULL, NULL, NULL};
        assert_int_equal(d->jvp(d, &in, t, 3, &prim, all), 0);
        mcp_image *ref = apply(d, &in);
        assert_same_bits(prim, ref);
        for (int i = 0; i < 3; i++) {
            mcp_image *one = NULL;
            assert_int_equal(d->jvp(d, &in, &t[i], 1, NULL, &one), 0);
            assert_same_bits(all[i], one);
            mcp_image_free(one);
            mcp_image_free(all[i]);
        }
        mcp_image_free(ref);
        mcp_image_free(prim);
        mcp_denoiser_free(d);
    }
    mcp_image_free(t0);
    mcp_image_free(t1);
    mcp_image_free(t2);
    mcp_image_free(ta);
    free_scene(&s);
}

/* ---- results do not depend on the thread count ---- */

static void
test_thread_count_independence(void **state)
{
    (void)state;
#ifdef _OPENMP
    /* taller than several strips of rows, large enough to run in parallel */
    scene s = make_scene(90, 150, 0.2, 9);
    mcp_image *t0 = probe(s.color, s.variance, 5);
    mcp_denoise_tangent t = {t0, s.albedo, NULL};
    int saved = omp_get_max_threads();
    FOR_EACH_BUILTIN(k)
    {
        mcp_denoiser *d = mcp_test_denoiser((*k)->name);
        mcp_denoise_input in = input_of(&s);
        mcp_image *ref_p = NULL, *ref_j = NULL;
        omp_set_num_threads(1);
        assert_int_equal(d->jvp(d, &in, &t, 1, &ref_p, &ref_j), 0);
        for (int n = 2; n <= 5; n += 3) {
            mcp_image *p = NULL, *j = NULL;
            omp_set_num_threads(n);
            assert_int_equal(d->jvp(d, &in, &t, 1, &p, &j), 0);
            assert_same_bits(p, ref_p);
            assert_same_bits(j, ref_j);
            mcp_image_free(p);
            mcp_image_free(j);
        }
        mcp_image_free(ref_p);
        mcp_image_free(ref_j);
        mcp_denoiser_free(d);
    }
    omp_set_num_threads(saved);
    mcp_image_free(t0);
    free_scene(&s);
#else
    skip();
#endif
}

/* ---- denoising quality ---- */

static double
mse(const mcp_image *a, const mcp_image *truth)
{
    double s = 0;
    for (size_t i = 0; i < n_values(a); i++) {
        double d = (double)a->data[i] - truth->data[i];
        s += d * d;
    }
    return s / n_values(a);
}

static void
test_nlm_denoises(void **state)
{
    (void)state;
    scene s = make_scene(96, 80, 0.25, 6);
    mcp_denoise_input in = input_of(&s);
    mcp_denoiser *d = mcp_test_denoiser("nlm");
    mcp_image *out = apply(d, &in);
    double before = mse(s.color, s.truth), after = mse(out, s.truth);
    print_message("nlm on the synthetic scene: MSE %.3g -> %.3g (%.1fx)\n", before, after,
                  before / after);
    assert_true(after * 3 <= before);
    mcp_image_free(out);

    /* the albedo keeps edges: without features the same filter does worse */
    mcp_denoiser *plain =
        mcp_test_denoiser("{name: nlm, sigma_albedo: 0, sigma_normal: 0}");
    out = apply(plain, &in);
    double plain_mse = mse(out, s.truth);
    print_message("  without albedo and normal: MSE %.3g\n", plain_mse);
    assert_true(after < plain_mse);
    mcp_image_free(out);

    /* the cross-bilateral variant */
    mcp_denoiser *bil = mcp_test_denoiser("bilateral");
    out = apply(bil, &in);
    double bil_mse = mse(out, s.truth);
    print_message("  bilateral: MSE %.3g (%.1fx)\n", bil_mse, before / bil_mse);
    assert_true(bil_mse * 3 <= before);
    mcp_image_free(out);
    mcp_denoiser_free(bil);

    /* without variance, a fixed noise level of the right size works too */
    mcp_denoiser *novar =
        mcp_test_denoiser("{name: nlm, use_variance: false, sigma_color: 0.3}");
    out = apply(novar, &in);
    double novar_mse = mse(out, s.truth);
    print_message("  with sigma_color instead of the variance: MSE %.3g\n", novar_mse);
    assert_true(novar_mse * 2 <= before);
    mcp_image_free(out);
    mcp_denoiser_free(d);
    mcp_denoiser_free(plain);
    mcp_denoiser_free(novar);
    free_scene(&s);
}

/* ---- the command ---- */

static void
write_scene_files(const scene *s)
{
    assert_int_equal(mcp_image_write(s->color, mcp_test_path("color.exr"), NULL), 0);
    assert_int_equal(mcp_image_write(s->albedo, mcp_test_path("albedo.exr"), NULL), 0);
    assert_int_equal(mcp_image_write(s->variance, mcp_test_path("var.exr"), NULL), 0);
    mcp_image *n = NULL;
    static const char *const xyz[] = {"X", "Y", "Z"};
    assert_int_equal(mcp_image_copy(s->normal, &n), 0);
    for (int c = 0; c < 3; c++)
        assert_int_equal(mcp_image_set_channel_name(n, c, xyz[c]), 0);
    assert_int_equal(mcp_image_write(n, mcp_test_path("normal.exr"), NULL), 0);
    mcp_image_free(n);
}

/* Channels R, G, B of a file, in that order (EXR stores them sorted by name). */
static mcp_image *
read_or_fail(const char *path)
{
    mcp_image *img = NULL, *rgb3 = NULL;
    int idx[3];
    if (mcp_image_read(path, NULL, &img) ||
        mcp_image_channels(img, (const char *[]){"R", "G", "B"}, 3, idx) ||
        mcp_image_copy_channels(img, idx, 3, &rgb3))
        fail_msg("%s", mcp_error_message());
    mcp_attrs_clear(&rgb3->attrs);
    assert_int_equal(mcp_attrs_copy(&img->attrs, &rgb3->attrs), 0);
    mcp_image_free(img);
    return rgb3;
}

static void
test_command(void **state)
{
    (void)state;
    char out[8192], err[8192], args[4096];
    assert_int_equal(
        mcp_test_run_mcpost("denoise --list", out, sizeof out, err, sizeof err), 0);
    assert_non_null(strstr(out, "gauss"));
    assert_non_null(strstr(out, "nlm"));
    assert_non_null(strstr(out, "patch_radius"));

    scene s = make_scene(40, 34, 0.2, 10);
    write_scene_files(&s);
    mcp_image *t = probe(s.color, s.variance, 3);
    assert_int_equal(mcp_image_write(t, mcp_test_path("t.exr"), NULL), 0);
    snprintf(args, sizeof args,
             "denoise --color %s --albedo %s --normal %s --variance-of-mean %s "
             "--denoiser nlm --denoiser-opt radius=4 --denoiser-opt k_color=0.5 "
             "-o %s --tangent %s",
             mcp_test_path("color.exr"), mcp_test_path("albedo.exr"),
             mcp_test_path("normal.exr"), mcp_test_path("var.exr"),
             mcp_test_path("den.exr"), mcp_test_path("t.exr"));
    assert_int_equal(mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err), 0);

    /* the same through the library */
    const char *opts[] = {"radius=4", "k_color=0.5"};
    mcp_denoiser *d = NULL;
    assert_int_equal(mcp_denoiser_create_from_args("nlm", opts, 2, &d), 0);
    mcp_denoise_input in = input_of(&s);
    mcp_denoise_tangent tan = {t, NULL, NULL};
    mcp_image *prim = NULL, *jt = NULL;
    assert_int_equal(d->jvp(d, &in, &tan, 1, &prim, &jt), 0);
    mcp_image *got = read_or_fail(mcp_test_path("den.exr"));
    mcp_image *got_jt = read_or_fail(mcp_test_path("den_jvp.exr"));
    assert_same_bits(got, prim);
    assert_same_bits(got_jt, jt);
    const mcp_attr *attr = mcp_attrs_find(&got->attrs, "mcpost.denoiser");
    assert_non_null(attr);
    assert_string_equal(attr->s, "nlm");
    mcp_image_free(got);
    mcp_image_free(got_jt);

    /* errors: one line "mcpost: ...", status 1; usage errors status 2 */
    snprintf(args, sizeof args, "denoise --color %s --denoiser blur -o %s",
             mcp_test_path("color.exr"), mcp_test_path("x.exr"));
    assert_int_equal(mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err), 1);
    assert_non_null(
        strstr(err, "mcpost: unknown denoiser 'blur' (known: gauss, nlm, bilateral"));
    snprintf(args, sizeof args,
             "denoise --color %s --denoiser gauss --denoiser-opt "
             "sigma=-3 -o %s",
             mcp_test_path("color.exr"), mcp_test_path("x.exr"));
    assert_int_equal(mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err), 1);
    assert_non_null(strstr(err, "mcpost: --denoiser-opt:1: gauss: sigma must be > 0"));
    snprintf(args, sizeof args, "denoise --color %s --denoiser gauss --tangent %s -o %s",
             mcp_test_path("color.exr"), mcp_test_path("missing.exr"),
             mcp_test_path("x.exr"));
    assert_int_equal(mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err), 1);
    assert_non_null(strstr(err, "missing.exr"));
    assert_int_equal(
        mcp_test_run_mcpost("denoise --denoiser gauss", out, sizeof out, err, sizeof err),
        2);
    assert_non_null(strstr(err, "no input"));
    /* no --denoiser: the default, which for colour alone is nlm, said once; the same
       image as --denoiser nlm */
    snprintf(args, sizeof args, "denoise --color %s -o %s", mcp_test_path("color.exr"),
             mcp_test_path("x.exr"));
    assert_int_equal(mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err), 0);
    assert_non_null(strstr(err, "the default denoiser is nlm instead of the U-Net"));
    snprintf(args, sizeof args, "denoise --color %s --denoiser nlm -o %s",
             mcp_test_path("color.exr"), mcp_test_path("x_nlm.exr"));
    assert_int_equal(mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err), 0);
    {
        mcp_image *a = NULL, *b = NULL;
        assert_int_equal(mcp_image_read(mcp_test_path("x.exr"), NULL, &a), 0);
        assert_int_equal(mcp_image_read(mcp_test_path("x_nlm.exr"), NULL, &b), 0);
        assert_true(mcp_test_max_abs_diff(a, b) == 0);
        mcp_image_free(a);
        mcp_image_free(b);
    }

    mcp_image_free(prim);
    mcp_image_free(jt);
    mcp_image_free(t);
    mcp_denoiser_free(d);
    free_scene(&s);
}

/* A render dump in a file: the command reads its colour, features and variance. */
static void
test_command_on_dump(void **state)
{
    (void)state;
    scene s = make_scene(36, 30, 0.2, 12);
    mcp_dump dump = {0};
    dump.color = s.color;
    dump.albedo = s.albedo;
    dump.normal = s.normal;
    dump.var_of_mean = s.variance;
    dump.spp = 16;
    const char *path = mcp_test_path("dump.exr");
    assert_int_equal(mcp_dump_write(&dump, path, MCP_CONV_PBRT, NULL), 0);
    char out[4096], err[4096], args[4096];
    snprintf(args, sizeof args, "denoise %s --denoiser nlm -o %s", path,
             mcp_test_path("dump_nlm.exr"));
    assert_int_equal(mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err), 0);
    mcp_dump *back = NULL;
    assert_int_equal(mcp_dump_read(path, &back), 0);
    mcp_denoiser *d = mcp_test_denoiser("nlm");
    mcp_denoise_input in = mcp_denoise_input_of(back);
    assert_non_null(in.variance);
    mcp_image *want = apply(d, &in), *got = read_or_fail(mcp_test_path("dump_nlm.exr"));
    assert_same_bits(got, want);
    mcp_image_free(want);
    mcp_image_free(got);
    mcp_dump_free(back);
    mcp_denoiser_free(d);
    free_scene(&s);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_kinds_table),
        cmocka_unit_test(test_create_forms),
        cmocka_unit_test(test_create_errors),
        cmocka_unit_test(test_input_of_dump),
        cmocka_unit_test(test_input_errors),
        cmocka_unit_test(test_nasty_values),
        cmocka_unit_test(test_gauss_is_direct_convolution),
        cmocka_unit_test(test_gauss_is_linear),
        cmocka_unit_test(test_nlm_matches_naive_double),
        cmocka_unit_test(test_jvp_finite_differences),
        cmocka_unit_test(test_jvp_of_constant_shift),
        cmocka_unit_test(test_tangents_in_one_pass),
        cmocka_unit_test(test_thread_count_independence),
        cmocka_unit_test(test_nlm_denoises),
        cmocka_unit_test(test_command),
        cmocka_unit_test(test_command_on_dump),
    };
    return cmocka_run_group_tests_name("estimate/denoisers", tests, NULL, NULL);
}
