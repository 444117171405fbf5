/* test_unet.c: the .tza loader (estimate/tza.c) and the RT U-Net forward pass
 * (estimate/unet.c) against a plain double-precision reference written here, plus
 * the official OIDN 1.4 weights on the Cornell fixture when they are present. */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <mcpost/dump.h>
#include <mcpost/imageio.h>

#include "../../estimate/unet_internal.h"
#include "testing.h"
#include "tza_writer.h"

static const char *const names16[16] = {
    "enc_conv0",  "enc_conv1",  "enc_conv2",  "enc_conv3",  "enc_conv4",  "enc_conv5a",
    "enc_conv5b", "dec_conv4a", "dec_conv4b", "dec_conv3a", "dec_conv3b", "dec_conv2a",
    "dec_conv2b", "dec_conv1a", "dec_conv1b", "dec_conv0"};

/* A random network: 16 convs with the base topology and tiny channel counts
 * (ec1..ec5, dc4, dc3, dc2a, dc2b, dc1a, dc1b), He-scaled weights and positive
 * biases so that most ReLUs and outputs are active. */
typedef struct rnet {
    int ic, cin[16], cout[16];
    float *w[16], *b[16];
    char wname[16][32], bname[16][32];
    mcp_test_tza_tensor t[32];
} rnet;

static void
rnet_make(rnet *n, int ic, const int ch[11], uint64_t seed)
{
    const int ec1 = ch[0], ec2 = ch[1], ec3 = ch[2], ec4 = ch[3], ec5 = ch[4], dc4 = ch[5],
              dc3 = ch[6], dc2a = ch[7], dc2b = ch[8], dc1a = ch[9], dc1b = ch[10];
    const int cin[16] = {ic,       ec1, ec1,  ec2,  ec3,       ec4,  ec5, ec5 + ec3,
                         dc4,      dc4 + ec2, dc3, dc3 + ec1, dc2a, dc2b + ic, dc1a, dc1b};
    const int cout[16] = {ec1, ec1, ec2,  ec3,  ec4,  ec5,  ec5,  dc4,
                          dc4, dc3, dc3,  dc2a, dc2b, dc1a, dc1b, 3};
    n->ic = ic;
    uint64_t st = seed;
    for (int k = 0; k < 16; k++) {
        n->cin[k] = cin[k];
        n->cout[k] = cout[k];
        size_t nw = (size_t)cout[k] * cin[k] * 9;
        n->w[k] = malloc(nw * sizeof(float));
        n->b[k] = malloc((size_t)cout[k] * sizeof(float));
        /* He-scaled; the last layer smaller so outputs stay where PU^-1 is tame */
        double a = sqrt(6.0 / (cin[k] * 9.0)) * (k == 15 ? 0.1 : 1.0);
        for (size_t i = 0; i < nw; i++)
            n->w[k][i] = (float)((2 * mcp_test_rand_uniform(&st) - 1) * a);
        for (int o = 0; o < cout[k]; o++)
            n->b[k][o] = (float)(k == 15 ? 0.3 + 0.1 * mcp_test_rand_uniform(&st)
                                         : 0.1 * mcp_test_rand_uniform(&st));
        snprintf(n->wname[k], 32, "%s.weight", names16[k]);
        snprintf(n->bname[k], 32, "%s.bias", names16[k]);
        n->t[2 * k] = (mcp_test_tza_tensor){n->wname[k], 4, {cout[k], cin[k], 3, 3}, n->w[k]};
        n->t[2 * k + 1] = (mcp_test_tza_tensor){n->bname[k], 1, {cout[k]}, n->b[k]};
    }
}

static void
rnet_free(rnet *n)
{
    for (int k = 0; k < 16; k++) {
        free(n->w[k]);
        free(n->b[k]);
    }
}

/* ---- the plain reference, in double ---- */

static double *
ref_conv(const rnet *n, int k, const double *in, int h, int w, int relu)
{
    int ci = n->cin[k], co = n->cout[k];
    double *out = calloc((size_t)co * h * w, sizeof(double));
    for (int o = 0; o < co; o++)
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                double s = n->b[k][o];
                for (int i = 0; i < ci; i++)
                    for (int ky = 0; ky < 3; ky++)
                        for (int kx = 0; kx < 3; kx++) {
                            int yy = y + ky - 1, xx = x + kx - 1;
                            if (yy < 0 || yy >= h || xx < 0 || xx >= w)
                                continue;
                            s += (double)n->w[k][((o * ci + i) * 3 + ky) * 3 + kx] *
                                 in[((size_t)i * h + yy) * w + xx];
                        }
                out[((size_t)o * h + y) * w + x] = relu && s < 0 ? 0 : s;
            }
    return out;
}

static double *
ref_pool(const double *in, int c, int h, int w)
{
    double *out = malloc((size_t)c * (h / 2) * (w / 2) * sizeof(double));
    for (int k = 0; k < c; k++)
        for (int y = 0; y < h / 2; y++)
            for (int x = 0; x < w / 2; x++) {
                double m = -INFINITY;
                for (int dy = 0; dy < 2; dy++)
                    for (int dx = 0; dx < 2; dx++)
                        m = fmax(m, in[((size_t)k * h + 2 * y + dy) * w + 2 * x + dx]);
                out[((size_t)k * (h / 2) + y) * (w / 2) + x] = m;
            }
    return out;
}

/* concat(upsample2(a), b): a is ca x h/2 x w/2, b is cb x h x w */
static double *
ref_upcat(const double *a, int ca, const double *b, int cb, int h, int w)
{
    double *out = malloc((size_t)(ca + cb) * h * w * sizeof(double));
    for (int k = 0; k < ca; k++)
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++)
                out[((size_t)k * h + y) * w + x] = a[((size_t)k * (h / 2) + y / 2) * (w / 2) + x / 2];
    memcpy(out + (size_t)ca * h * w, b, (size_t)cb * h * w * sizeof(double));
    return out;
}

static const double A = 1.41283765e+03, B = 1.64593172e+00, C = 4.31384981e-01,
                    D = -2.94139609e-03, E = 1.92653254e-01, F = 6.26026094e-03,
                    G = 9.98620152e-01;

static double
ref_pu(double y)
{
    if (y <= 1.57945760e-06) return A * y;
    if (y <= 3.22087631e-02) return B * pow(y, C) + D;
    return E * log(y + F) + G;
}

static double
ref_pu_inv(double x)
{
    if (x <= 2.23151711e-03) return x / A;
    if (x <= 3.70974749e-01) return pow((x - D) / B, 1 / C);
    return exp((x - G) / E) - F;
}

static double
clampd(double v, double lo, double hi)
{
    return isnan(v) ? 0 : v < lo ? lo : v > hi ? hi : v;
}

/* OIDN 1.4 autoexposure, plainly (notes 3.3) */
static double
ref_autoexposure(const mcp_image *c)
{
    int H = c->height, W = c->width, hk = (H + 8) / 16, wk = (W + 8) / 16;
    hk = hk < 1 ? 1 : hk;
    wk = wk < 1 ? 1 : wk;
    double sum = 0;
    int kept = 0;
    for (int i = 0; i < hk; i++)
        for (int j = 0; j < wk; j++) {
            double L = 0;
            int cnt = 0;
            for (int y = i * H / hk; y < (i + 1) * H / hk; y++)
                for (int x = j * W / wk; x < (j + 1) * W / wk; x++, cnt++) {
                    const float *p = mcp_image_px(c, x, y);
                    L += 0.212671 * clampd(p[0], 0, FLT_MAX) + 0.715160 * clampd(p[1], 0, FLT_MAX) +
                         0.072169 * clampd(p[2], 0, FLT_MAX);
                }
            if (cnt && L / cnt > 1e-8) {
                sum += log2(L / cnt);
                kept++;
            }
        }
    return kept ? 0.18 / exp2(sum / kept) : 1.0;
}

/* The whole RT filter in double: returns a 3 x H x W array. */
static double *
ref_forward(const rnet *n, const mcp_image *col, const mcp_image *alb, const mcp_image *nrm,
            double scale)
{
    int H = col->height, W = col->width, hp = (H + 15) / 16 * 16, wp = (W + 15) / 16 * 16;
    int ic = n->ic;
    double ns = 1.0 / ref_pu(65504.0);
    if (scale <= 0) scale = ref_autoexposure(col);
    double *x = calloc((size_t)ic * hp * wp, sizeof(double));
    for (int y = 0; y < H; y++)
        for (int px = 0; px < W; px++) {
            size_t at = (size_t)y * wp + px, hw = (size_t)hp * wp;
            for (int k = 0; k < 3; k++) {
                x[k * hw + at] = ref_pu(clampd(mcp_image_px(col, px, y)[k] * scale, 0, FLT_MAX)) * ns;
                if (ic >= 6) x[(3 + k) * hw + at] = clampd(mcp_image_px(alb, px, y)[k], 0, 1);
                if (ic >= 9)
                    x[(6 + k) * hw + at] = clampd(mcp_image_px(nrm, px, y)[k], -1, 1) * 0.5 + 0.5;
            }
        }
    int h = hp, w = wp;
    double *e0 = ref_conv(n, 0, x, h, w, 1), *e1 = ref_conv(n, 1, e0, h, w, 1);
    double *p1 = ref_pool(e1, n->cout[1], h, w);
    double *e2 = ref_conv(n, 2, p1, h / 2, w / 2, 1), *p2 = ref_pool(e2, n->cout[2], h / 2, w / 2);
    double *e3 = ref_conv(n, 3, p2, h / 4, w / 4, 1), *p3 = ref_pool(e3, n->cout[3], h / 4, w / 4);
    double *e4 = ref_conv(n, 4, p3, h / 8, w / 8, 1), *p4 = ref_pool(e4, n->cout[4], h / 8, w / 8);
    double *e5a = ref_conv(n, 5, p4, h / 16, w / 16, 1), *e5b = ref_conv(n, 6, e5a, h / 16, w / 16, 1);
    double *c4 = ref_upcat(e5b, n->cout[6], p3, n->cout[3], h / 8, w / 8);
    double *d4a = ref_conv(n, 7, c4, h / 8, w / 8, 1), *d4b = ref_conv(n, 8, d4a, h / 8, w / 8, 1);
    double *c3 = ref_upcat(d4b, n->cout[8], p2, n->cout[2], h / 4, w / 4);
    double *d3a = ref_conv(n, 9, c3, h / 4, w / 4, 1), *d3b = ref_conv(n, 10, d3a, h / 4, w / 4, 1);
    double *c2 = ref_upcat(d3b, n->cout[10], p1, n->cout[1], h / 2, w / 2);
    double *d2a = ref_conv(n, 11, c2, h / 2, w / 2, 1), *d2b = ref_conv(n, 12, d2a, h / 2, w / 2, 1);
    double *c1 = ref_upcat(d2b, n->cout[12], x, ic, h, w);
    double *d1a = ref_conv(n, 13, c1, h, w, 1), *d1b = ref_conv(n, 14, d1a, h, w, 1);
    double *d0 = ref_conv(n, 15, d1b, h, w, 0);
    double *out = malloc((size_t)3 * H * W * sizeof(double));
    for (int k = 0; k < 3; k++)
        for (int y = 0; y < H; y++)
            for (int px = 0; px < W; px++)
                out[((size_t)k * H + y) * W + px] =
                    ref_pu_inv(clampd(d0[((size_t)k * hp + y) * wp + px], 0, FLT_MAX) / ns) / scale;
    double *all[] = {x, e0, e1, p1, e2, p2, e3, p3, e4, p4, e5a, e5b, c4, d4a, d4b,
                     c3, d3a, d3b, c2, d2a, d2b, c1, d1a, d1b, d0};
    for (size_t i = 0; i < sizeof all / sizeof *all; i++)
        free(all[i]);
    return out;
}

/* ---- test inputs ---- */

typedef struct inputs {
    mcp_image *col, *alb, *nrm;
} inputs;

static inputs
make_inputs(int w, int h, uint64_t seed)
{
    inputs in;
    in.col = mcp_test_random(w, h, 3, 0.0f, 4.0f, seed, NULL);
    in.alb = mcp_test_random(w, h, 3, -0.1f, 1.1f, seed + 1, NULL);
    in.nrm = mcp_test_random(w, h, 3, -1.2f, 1.2f, seed + 2, NULL);
    /* nasty values: the pre-processing sanitises them */
    mcp_image_px(in.col, 1 % w, 1 % h)[0] = NAN;
    mcp_image_px(in.col, 2 % w, 1 % h)[1] = -3.0f;
    mcp_image_px(in.col, 3 % w, 2 % h)[2] = INFINITY;
    mcp_image_px(in.alb, 0, 0)[1] = NAN;
    mcp_image_px(in.nrm, 4 % w, 3 % h)[2] = NAN;
    return in;
}

static void
free_inputs(inputs *in)
{
    mcp_image_free(in->col);
    mcp_image_free(in->alb);
    mcp_image_free(in->nrm);
}

static const int tiny[11] = {4, 5, 6, 7, 8, 9, 7, 6, 5, 6, 4};

/* The forward pass equals the reference to float accuracy. The tolerance: float32
 * accumulation over <= 9*73 terms per conv through 16 layers gives ~1e-6 relative on
 * the net output; PU^-1 amplifies relative errors of x by about x/(E*normScale) <= ~20
 * for these outputs, hence 1e-4 relative; 1e-7 absolute covers clamped (0) pixels. */
static void
check_forward(int ic, int w, int h, double scale)
{
    rnet n;
    rnet_make(&n, ic, tiny, 42 + ic);
    const char *path = mcp_test_path("tiny.tza");
    mcp_test_tza_write(path, n.t, 32, 'f');
    mcp__unet *net = NULL;
    assert_int_equal(mcp__unet_load(path, &net), 0);
    assert_int_equal(net->ic, ic);
    inputs in = make_inputs(w, h, 7);
    if (scale <= 0) /* an Inf colour makes autoexposure tiny and the output overflow */
        mcp_image_px(in.col, 3 % w, 2 % h)[2] = 5.0f;
    mcp_image *out = NULL;
    assert_int_equal(mcp__unet_forward(net, in.col, ic >= 6 ? in.alb : NULL,
                                       ic >= 9 ? in.nrm : NULL, scale, &out),
                     0);
    double *ref = ref_forward(&n, in.col, in.alb, in.nrm, scale);
    int nonzero = 0;
    for (int k = 0; k < 3; k++)
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                double r = ref[((size_t)k * h + y) * w + x];
                nonzero += r > 0;
                assert_close(mcp_image_px(out, x, y)[k], r, 1e-4, 1e-7);
            }
    assert_true(nonzero > w * h); /* the comparison is not vacuous */
    free(ref);
    mcp_image_free(out);
    free_inputs(&in);
    mcp__unet_free(net);
    rnet_free(&n);
}

static void
test_forward_matches_reference(void **state)
{
    (void)state;
    check_forward(9, 21, 13, 0.7);  /* padded to 32x16 */
    check_forward(9, 37, 20, -1.0); /* autoexposure */
    check_forward(6, 16, 16, 1.0);
    check_forward(3, 5, 3, 0.0);    /* smaller than one bin */
}

static void
test_autoexposure(void **state)
{
    (void)state;
    inputs in = make_inputs(45, 29, 3);
    assert_close(mcp__unet_autoexposure(in.col, 0), ref_autoexposure(in.col), 1e-12, 0);
    mcp_image *zero = mcp_test_constant(8, 8, 3, 0.0f, NULL);
    assert_close(mcp__unet_autoexposure(zero, 0), 1.0, 0, 0);
    mcp_image *grey = mcp_test_constant(40, 40, 3, 2.0f, NULL);
    assert_close(mcp__unet_autoexposure(grey, 1), 0.09, 1e-6, 0);
    mcp_image_free(zero);
    mcp_image_free(grey);
    free_inputs(&in);
}

static void
test_transfer_function(void **state)
{
    (void)state;
    /* the values of notes/oidn.md 3.2 */
    assert_close(mcp__pu_forward(0.18f), 0.2153, 5e-4, 0);
    assert_close(mcp__pu_forward(1.0f), 0.3189, 5e-4, 0);
    assert_close(mcp__pu_forward(100.0f), 0.6015, 5e-4, 0);
    assert_close(mcp__pu_forward(65504.0f), 1.0, 1e-6, 0);
    assert_close(mcp__pu_forward(0.0f), 0.0, 0, 0);
    const float ys[] = {1e-7f, 1.5e-6f, 1e-4f, 0.03f, 0.04f, 1.0f, 1000.0f};
    for (size_t i = 0; i < sizeof ys / sizeof *ys; i++)
        assert_close(mcp__pu_inverse(mcp__pu_forward(ys[i])), ys[i], 2e-5, 0);
}

/* float16 files load to the half-rounded float32 values exactly, and so give the
 * same output bit for bit as a float32 file holding those rounded values; against
 * the unrounded net the output moves by about the half rounding (2^-11 relative). */
static void
test_half_weights(void **state)
{
    (void)state;
    rnet n;
    rnet_make(&n, 9, tiny, 5);
    const char *ph = mcp_test_path("tiny_h.tza"), *pf = mcp_test_path("tiny_f.tza"),
               *pr = mcp_test_path("tiny_r.tza");
    mcp_test_tza_write(ph, n.t, 32, 'h');
    mcp_test_tza_write(pf, n.t, 32, 'f');
    mcp__tza *tza = NULL;
    assert_int_equal(mcp__tza_read(ph, &tza), 0);
    assert_int_equal(tza->count, 32);
    for (int k = 0; k < 32; k++) {
        const mcp__tza_tensor *t = mcp__tza_find(tza, n.t[k].name);
        assert_non_null(t);
        assert_int_equal(t->dtype, 'h');
        for (size_t i = 0; i < t->count; i++) {
            float r = mcp__half_to_float(mcp_test_float_to_half(n.t[k].data[i]));
            assert_true(t->data[i] == r);
            assert_close(t->data[i], n.t[k].data[i], 1.0 / 2048, 6e-8);
            ((float *)n.t[k].data)[i] = r; /* round the net in place */
        }
    }
    mcp__tza_free(tza);
    mcp_test_tza_write(pr, n.t, 32, 'f');
    mcp__unet *nh = NULL, *nf = NULL, *nr = NULL;
    assert_int_equal(mcp__unet_load(ph, &nh), 0);
    assert_int_equal(mcp__unet_load(pf, &nf), 0);
    assert_int_equal(mcp__unet_load(pr, &nr), 0);
    assert_int_equal(nh->v2, 1);
    inputs in = make_inputs(24, 17, 9);
    mcp_image *oh = NULL, *of = NULL, *orr = NULL;
    assert_int_equal(mcp__unet_forward(nh, in.col, in.alb, in.nrm, 0.5, &oh), 0);
    assert_int_equal(mcp__unet_forward(nf, in.col, in.alb, in.nrm, 0.5, &of), 0);
    assert_int_equal(mcp__unet_forward(nr, in.col, in.alb, in.nrm, 0.5, &orr), 0);
    assert_true(mcp_test_max_abs_diff(oh, orr) == 0.0);
    for (int y = 0; y < 17; y++)
        for (int x = 0; x < 24; x++)
            for (int k = 0; k < 3; k++)
                assert_close(mcp_image_px(oh, x, y)[k], mcp_image_px(of, x, y)[k], 0.05, 1e-4);
    mcp_image_free(oh);
    mcp_image_free(of);
    mcp_image_free(orr);
    free_inputs(&in);
    mcp__unet_free(nh);
    mcp__unet_free(nf);
    mcp__unet_free(nr);
    rnet_free(&n);
}

static unsigned char *
slurp(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    fseek(f, 0, SEEK_END);
    *n = (size_t)ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *b = malloc(*n);
    assert_int_equal(fread(b, 1, *n, f), *n);
    fclose(f);
    return b;
}

static void
test_bad_files(void **state)
{
    (void)state;
    rnet n;
    rnet_make(&n, 9, tiny, 11);
    const char *good = mcp_test_path("good.tza"), *bad = mcp_test_path("bad.tza");
    mcp_test_tza_write(good, n.t, 32, 'f');
    size_t size;
    unsigned char *b = slurp(good, &size);
    mcp__unet *net = NULL;

    assert_error_contains(mcp__unet_load(mcp_test_path("absent.tza"), &net),
                          "cannot open weights");
    mcp_test_write_bytes(bad, b, 7);
    assert_error_contains(mcp__unet_load(bad, &net), "truncated .tza header");
    b[0] ^= 0xff;
    mcp_test_write_bytes(bad, b, size);
    assert_error_contains(mcp__unet_load(bad, &net), "not a .tza file (magic 0x41");
    b[0] ^= 0xff;
    b[2] = 3;
    mcp_test_write_bytes(bad, b, size);
    assert_error_contains(mcp__unet_load(bad, &net), "unsupported .tza version 3.0");
    b[2] = 2;
    mcp_test_write_bytes(bad, b, 200); /* cut before the table */
    assert_error_contains(mcp__unet_load(bad, &net), "truncated .tza file (table at");
    mcp_test_write_bytes(bad, b, size - 5); /* cut inside the table */
    assert_error_contains(mcp__unet_load(bad, &net), "truncated tensor table");
    assert_null(net);
    free(b);

    /* data offsets beyond the end: a table moved onto a short file */
    mcp_test_tza_write(good, n.t, 2, 'f');
    b = slurp(good, &size);
    size_t table = 0;
    for (int i = 0; i < 8; i++) table |= (size_t)b[4 + i] << (8 * i);
    unsigned char *c = calloc(size, 1);
    memcpy(c, b, 12);
    memcpy(c + 64, b + table, size - table); /* table at 64, data offsets now past it */
    c[4] = 64, c[5] = 0, c[6] = 0;
    mcp_test_write_bytes(bad, c, 64 + size - table);
    assert_error_contains(mcp__unet_load(bad, &net), "enc_conv0.weight': data truncated");
    free(c);
    free(b);

    mcp_test_tza_write(bad, n.t, 32, 'B');
    assert_error_contains(mcp__unet_load(bad, &net), "unsupported dtype 'B'");
    /* a missing tensor */
    mcp_test_tza_write(bad, n.t, 31, 'f');
    assert_error_contains(mcp__unet_load(bad, &net), "missing tensor 'dec_conv0.bias'");
    /* _large weights, recognised by enc_conv1b */
    mcp_test_tza_tensor big[33];
    memcpy(big, n.t, sizeof n.t);
    big[32] = (mcp_test_tza_tensor){"enc_conv1b.weight", 1, {1}, n.b[0]};
    mcp_test_tza_write(bad, big, 33, 'f');
    assert_error_contains(mcp__unet_load(bad, &net), "unet_large weights are not supported");
    /* inconsistent channels */
    memcpy(big, n.t, sizeof n.t);
    big[22].dims[1] = 5; /* dec_conv2a.weight: 5 inputs, needs 7 + 4 */
    mcp_test_tza_write(bad, big, 32, 'f');
    assert_error_contains(mcp__unet_load(bad, &net),
                          "'dec_conv2a.weight' is 6x5, expected 11 input channels");
    assert_null(net);

    /* the forward pass asks for the features the weights read */
    mcp_test_tza_write(good, n.t, 32, 'f');
    assert_int_equal(mcp__unet_load(good, &net), 0);
    inputs in = make_inputs(8, 8, 1);
    mcp_image *out = NULL;
    assert_error_contains(mcp__unet_forward(net, in.col, in.alb, NULL, 1.0, &out),
                          "need the normal");
    mcp_image *small = mcp_test_random(4, 8, 3, 0, 1, 3, NULL);
    assert_error_contains(mcp__unet_forward(net, in.col, small, in.nrm, 1.0, &out),
                          "does not match");
    assert_null(out);
    mcp_image_free(small);
    free_inputs(&in);
    mcp__unet_free(net);
    rnet_free(&n);
}

/* ---- the official OIDN 1.4 weights ---- */

static const char *
weights_path(void)
{
    const char *env = getenv("MCPOST_OIDN_WEIGHTS");
    static char buf[4096];
    if (env && *env)
        return env;
    snprintf(buf, sizeof buf, "%s/../shared/oidn-weights/rt_hdr_alb_nrm.tza",
             MCP_TEST_SOURCE_DIR);
    return buf;
}

static void
test_real_weights_load(void **state)
{
    (void)state;
    const char *path = weights_path();
    if (access(path, R_OK) != 0) {
        print_message("skipped: no OIDN weights at %s (set MCPOST_OIDN_WEIGHTS)\n", path);
        skip();
    }
    mcp__tza *tza = NULL;
    assert_int_equal(mcp__tza_read(path, &tza), 0);
    assert_int_equal(tza->count, 32);
    assert_string_equal(tza->tensors[0].name, "enc_conv0.weight");
    assert_string_equal(tza->tensors[31].name, "dec_conv0.bias");
    const mcp__tza_tensor *w0 = mcp__tza_find(tza, "enc_conv0.weight"),
                          *b0 = mcp__tza_find(tza, "enc_conv0.bias");
    assert_int_equal(w0->dims[0], 32);
    assert_int_equal(w0->dims[1], 9);
    assert_close(w0->data[0], -0.0357516, 1e-5, 0);
    assert_close(w0->data[1], 0.0338633, 1e-5, 0);
    assert_close(w0->data[2], -0.00377733, 1e-5, 0);
    assert_close(b0->data[0], 0.00151733, 1e-5, 0);
    assert_close(b0->data[1], -0.0011578, 1e-5, 0);
    assert_close(b0->data[2], 0.0523451, 1e-5, 0);
    size_t total = 0;
    for (int k = 0; k < tza->count; k++) total += tza->tensors[k].count;
    assert_int_equal(total, 919811);
    mcp__tza_free(tza);
    mcp__unet *net = NULL;
    assert_int_equal(mcp__unet_load(path, &net), 0);
    assert_int_equal(net->ic, 9);
    assert_int_equal(net->conv[13].cin, 73);
    mcp__unet_free(net);
}

static double
rel_mse(const mcp_image *c, const mcp_image *r, const int *ri)
{
    double s = 0;
    for (int y = 0; y < c->height; y++)
        for (int x = 0; x < c->width; x++)
            for (int k = 0; k < 3; k++) {
                double a = mcp_image_px(c, x, y)[k], b = mcp_image_px(r, x, y)[ri[k]];
                s += (a - b) * (a - b) / (b * b + 0.01);
            }
    return s / (3.0 * c->width * c->height);
}

static double
now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static void
test_real_weights_cornell(void **state)
{
    (void)state;
    const char *path = weights_path();
    if (access(path, R_OK) != 0) {
        print_message("skipped: no OIDN weights at %s (set MCPOST_OIDN_WEIGHTS)\n", path);
        skip();
    }
    mcp__unet *net = NULL;
    mcp_dump *dump = NULL;
    mcp_image *ref = NULL, *out = NULL;
    assert_int_equal(mcp__unet_load(path, &net), 0);
    assert_int_equal(
        mcp_dump_read(MCP_TEST_SOURCE_DIR "/samples/fixtures/cornell/series/cornell_spp0016.exr",
                      &dump),
        0);
    assert_int_equal(mcp_image_read(MCP_TEST_SOURCE_DIR
                                    "/samples/fixtures/cornell/cornell_reference.exr",
                                    NULL, &ref),
                     0);
    assert_non_null(dump->albedo);
    assert_non_null(dump->normal);
    int ri[3];
    assert_int_equal(mcp_image_channels(ref, (const char *[]){"R", "G", "B"}, 3, ri), 0);
    double t0 = now_s();
    assert_int_equal(mcp__unet_forward(net, dump->color, dump->albedo, dump->normal, 0, &out),
                     0);
    double secs = now_s() - t0;
    double noisy = rel_mse(dump->color, ref, ri), den = rel_mse(out, ref, ri);
    print_message("cornell 16 spp %dx%d: relMSE noisy %.5f, unet %.5f (%.1fx lower); "
                  "forward %.3f s (%.2f GMAC/s)\n",
                  out->width, out->height, noisy, den, noisy / den, secs,
                  125406.0 * ((out->width + 15) / 16 * 16) * ((out->height + 15) / 16 * 16) /
                      secs * 1e-9);
    assert_true(den < 0.25 * noisy);
    mcp_image_free(out);
    mcp_image_free(ref);
    mcp_dump_free(dump);
    mcp__unet_free(net);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_transfer_function),
        cmocka_unit_test(test_autoexposure),
        cmocka_unit_test(test_forward_matches_reference),
        cmocka_unit_test(test_half_weights),
        cmocka_unit_test(test_bad_files),
        cmocka_unit_test(test_real_weights_load),
        cmocka_unit_test(test_real_weights_cornell),
    };
    return cmocka_run_group_tests_name("estimate/unet", tests, NULL, NULL);
}
