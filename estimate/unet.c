/* unet.c: OIDN's RT U-Net forward pass (notes/oidn.md 1.2, 3): HDR pre-processing
 * (input scale or autoexposure, PU transfer function, albedo/normal clamps), the 16
 * 3x3 convolutions with ReLU, 2x2 max pools, nearest 2x upsampling and skip concats,
 * then the inverse transfer function. Whole image as one tile, padded to 16.
 * Activations are planar (CHW) float32; each is freed as soon as it is consumed.
 * Convolutions are direct loops, blocked over output channels and x, OpenMP over
 * (channel block, row); a GEMM path is issue 6 follow-up work. */
#include "unet_internal.h"
#include "internal.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const conv_names[MCP__UNET_NCONV] = {
    "enc_conv0",  "enc_conv1",  "enc_conv2",  "enc_conv3",  "enc_conv4",  "enc_conv5a",
    "enc_conv5b", "dec_conv4a", "dec_conv4b", "dec_conv3a", "dec_conv3b", "dec_conv2a",
    "dec_conv2b", "dec_conv1a", "dec_conv1b", "dec_conv0"};

enum { E0, E1, E2, E3, E4, E5A, E5B, D4A, D4B, D3A, D3B, D2A, D2B, D1A, D1B, D0 };

/* ---- transfer function (notes 3.2, 3.6) ---- */

#define PU_A 1.41283765e+03f
#define PU_B 1.64593172e+00f
#define PU_C 4.31384981e-01f
#define PU_D -2.94139609e-03f
#define PU_E 1.92653254e-01f
#define PU_F 6.26026094e-03f
#define PU_G 9.98620152e-01f
#define PU_Y0 1.57945760e-06f
#define PU_Y1 3.22087631e-02f
#define PU_X0 2.23151711e-03f
#define PU_X1 3.70974749e-01f

static float
pu_raw(float y)
{
    if (y <= PU_Y0)
        return PU_A * y;
    if (y <= PU_Y1)
        return PU_B * powf(y, PU_C) + PU_D;
    return PU_E * logf(y + PU_F) + PU_G;
}

static float
pu_raw_inverse(float x)
{
    if (x <= PU_X0)
        return x / PU_A;
    if (x <= PU_X1)
        return powf((x - PU_D) / PU_B, 1.0f / PU_C);
    return expf((x - PU_G) / PU_E) - PU_F;
}

/* dPU/dy: C1 at both breakpoints (notes 3.2) */
static float
pu_slope(float y)
{
    if (y <= PU_Y0)
        return PU_A;
    if (y <= PU_Y1)
        return PU_B * PU_C * powf(y, PU_C - 1.0f);
    return PU_E / (y + PU_F);
}

/* d PU^-1 / dx */
static float
pu_inverse_slope(float x)
{
    if (x <= PU_X0)
        return 1.0f / PU_A;
    if (x <= PU_X1)
        return powf((x - PU_D) / PU_B, 1.0f / PU_C - 1.0f) / (PU_B * PU_C);
    return expf((x - PU_G) / PU_E) / PU_E;
}

static float
norm_scale(void)
{
    return 1.0f / pu_raw(65504.0f);
}

float
mcp__pu_forward(float y)
{
    return pu_raw(y) * norm_scale();
}

float
mcp__pu_inverse(float x)
{
    return pu_raw_inverse(x / norm_scale());
}

/* ---- loading ---- */

void
mcp__unet_free(mcp__unet *net)
{
    if (!net)
        return;
    for (int k = 0; k < MCP__UNET_NCONV; k++) {
        free(net->conv[k].weight);
        free(net->conv[k].bias);
    }
    free(net);
}

/* The input channels each conv must have, given the outputs before it. */
static int
expected_cin(const mcp__unet *n, int k)
{
    const mcp__unet_conv *c = n->conv;
    switch (k) {
    case E0: return n->ic;
    case D4A: return c[E5B].cout + c[E3].cout; /* concat(up, pool3) */
    case D3A: return c[D4B].cout + c[E2].cout; /* concat(up, pool2) */
    case D2A: return c[D3B].cout + c[E1].cout; /* concat(up, pool1) */
    case D1A: return c[D2B].cout + n->ic;      /* concat(up, input) */
    default: return c[k - 1].cout;
    }
}

int
mcp__unet_from_tza(const mcp__tza *tza, const char *source, mcp__unet **out)
{
    *out = NULL;
    const char *src = source ? source : "weights";
    if (mcp__tza_find(tza, "enc_conv1b.weight"))
        return mcp_error("%s: unet_large weights are not supported (only the base and "
                         "small RT U-Net)",
                         src);
    if (mcp__tza_find(tza, "dec_conv5a.weight"))
        return mcp_error("%s: OIDN 1.0-1.2 weights (5 pools) are not supported", src);
    mcp__unet *net = mcp_calloc(1, sizeof *net);
    if (!net)
        return -1;
    for (int k = 0; k < MCP__UNET_NCONV; k++) {
        char wn[64], bn[64];
        snprintf(wn, sizeof wn, "%s.weight", conv_names[k]);
        snprintf(bn, sizeof bn, "%s.bias", conv_names[k]);
        const mcp__tza_tensor *w = mcp__tza_find(tza, wn), *b = mcp__tza_find(tza, bn);
        if (!w || !b) {
            mcp_error("%s: missing tensor '%s' (not an OIDN RT U-Net)", src, w ? bn : wn);
            goto fail;
        }
        if (w->ndims != 4 || w->dims[2] != 3 || w->dims[3] != 3 || b->ndims != 1 ||
            b->dims[0] != w->dims[0]) {
            mcp_error("%s: tensor '%s' has shape not [O][I][3][3] with a bias of O", src,
                      wn);
            goto fail;
        }
        mcp__unet_conv *c = &net->conv[k];
        c->cout = w->dims[0];
        c->cin = w->dims[1];
        if (k == E0) {
            net->ic = c->cin;
            net->v2 = w->dtype == 'h';
            if (c->cin != 3 && c->cin != 6 && c->cin != 9) {
                mcp_error("%s: '%s' has %d input channels (expected 3, 6 or 9)", src, wn,
                          c->cin);
                goto fail;
            }
        }
        int want = expected_cin(net, k);
        if (c->cin != want || (k == D0 && c->cout != 3)) {
            mcp_error("%s: tensor '%s' is %dx%d, expected %d input channels%s", src, wn,
                      c->cout, c->cin, want, k == D0 ? " and 3 outputs" : "");
            goto fail;
        }
        if (!(c->weight = mcp_malloc(w->count * sizeof(float))) ||
            !(c->bias = mcp_malloc(b->count * sizeof(float))))
            goto fail;
        memcpy(c->weight, w->data, w->count * sizeof(float));
        memcpy(c->bias, b->data, b->count * sizeof(float));
    }
    *out = net;
    return 0;
fail:
    mcp__unet_free(net);
    return -1;
}

int
mcp__unet_load(const char *path, mcp__unet **out)
{
    *out = NULL;
    mcp__tza *tza = NULL;
    if (mcp__tza_read(path, &tza))
        return -1;
    int rc = mcp__unet_from_tza(tza, path, out);
    mcp__tza_free(tza);
    return rc;
}

/* ---- layers on batches of planar tensors ----
 * A batch holds n images of c x h x w: image 0 is the primal, images 1 .. n-1 are
 * tangents at it. A layer passes tangents through its linearisation at the primal:
 * convolutions without the bias, the primal's ReLU mask, the primal's max-pool choice;
 * upsampling and concatenation copy (notes/oidn.md 3.7). */

typedef struct batch {
    int n, c, h, w;
    float *d; /* image k, channel i: d + ((size_t)k * c + i) * h * w */
} batch;

#define OB 8  /* output channels per block */
#define XT 64 /* columns per block */

static size_t
plane_size(const batch *b)
{
    return (size_t)b->h * (size_t)b->w;
}

static float *
plane(const batch *b, int k, int i)
{
    return b->d + ((size_t)k * b->c + i) * plane_size(b);
}

static int
batch_new(batch *b, int n, int c, int h, int w)
{
    *b = (batch){n, c, h, w, NULL};
    b->d = mcp_calloc((size_t)n * c * h * w, sizeof(float));
    return b->d ? 0 : -1;
}

static void
batch_free(batch *b)
{
    free(b->d);
    b->d = NULL;
}

/* out = conv3x3(concat(a, b)) (b may be NULL), the bias on image 0 only; then, with
 * relu, every image is zeroed where image 0's pre-activation is not > 0. */
static int
conv_into(const mcp__unet_conv *L, const batch *a, const batch *b, int relu, batch *out)
{
    const int n = a->n, h = a->h, w = a->w, ca = a->c, cb = b ? b->c : 0;
    const int cin = ca + cb, cout = L->cout, nob = (cout + OB - 1) / OB;
    if (cin != L->cin)
        return mcp_error("unet: layer of %d input channels given %d", L->cin, cin);
    if (batch_new(out, n, cout, h, w))
        return -1;
#pragma omp parallel for collapse(3) schedule(dynamic, 4)
    for (int k = 0; k < n; k++) {
        for (int ob = 0; ob < nob; ob++) {
            for (int y = 0; y < h; y++) {
                float acc[OB][XT];
                const int o0 = ob * OB, on = cout - o0 < OB ? cout - o0 : OB;
                for (int x0 = 0; x0 < w; x0 += XT) {
                    const int xn = w - x0 < XT ? w - x0 : XT;
                    for (int o = 0; o < on; o++)
                        for (int x = 0; x < xn; x++)
                            acc[o][x] = k == 0 ? L->bias[o0 + o] : 0.0f;
                    for (int i = 0; i < cin; i++) {
                        const float *src = i < ca ? plane(a, k, i) : plane(b, k, i - ca);
                        for (int ky = 0; ky < 3; ky++) {
                            const int yy = y + ky - 1;
                            if (yy < 0 || yy >= h)
                                continue;
                            const float *row = src + (size_t)yy * (size_t)w;
                            for (int kx = 0; kx < 3; kx++) {
                                const int dx = kx - 1;
                                /* x + dx inside [0, w) */
                                const int xs = x0 > -dx ? x0 : -dx;
                                const int xe = x0 + xn < w - dx ? x0 + xn : w - dx;
                                const float *r = row + dx;
                                for (int o = 0; o < on; o++) {
                                    const float wt =
                                        L->weight[((size_t)(o0 + o) * cin + i) * 9 + ky * 3 + kx];
                                    float *ac = acc[o] - x0;
#pragma omp simd
                                    for (int x = xs; x < xe; x++)
                                        ac[x] += wt * r[x];
                                }
                            }
                        }
                    }
                    for (int o = 0; o < on; o++)
                        memcpy(plane(out, k, o0 + o) + (size_t)y * w + x0, acc[o],
                               (size_t)xn * sizeof(float));
                }
            }
        }
    }
    if (!relu)
        return 0;
    const size_t hw = plane_size(out);
#pragma omp parallel for schedule(static)
    for (int o = 0; o < cout; o++) {
        float *p0 = plane(out, 0, o);
        for (size_t j = 0; j < hw; j++)
            if (!(p0[j] > 0.0f))
                for (int k = 0; k < n; k++)
                    plane(out, k, o)[j] = 0.0f;
    }
    return 0;
}

/* *t = conv(concat(*t, skip)); the old *t and the skip (when given) are freed. */
static int
conv_replace(const mcp__unet_conv *L, batch *t, batch *skip, int relu)
{
    batch out;
    if (conv_into(L, t, skip, relu, &out))
        return -1;
    batch_free(t);
    if (skip)
        batch_free(skip);
    *t = out;
    return 0;
}

/* 2x2 max pool of every image at image 0's arg-max (the first maximum in scan order,
 * as PyTorch picks it). */
static int
maxpool_into(const batch *in, batch *out)
{
    const int h2 = in->h / 2, w2 = in->w / 2, w = in->w;
    if (batch_new(out, in->n, in->c, h2, w2))
        return -1;
#pragma omp parallel for collapse(2) schedule(static)
    for (int i = 0; i < in->c; i++)
        for (int y = 0; y < h2; y++) {
            const float *src0 = plane(in, 0, i);
            for (int x = 0; x < w2; x++) {
                const size_t at = (size_t)2 * y * w + 2 * x;
                const size_t cand[4] = {at, at + 1, at + w, at + w + 1};
                size_t best = cand[0];
                for (int c = 1; c < 4; c++)
                    if (src0[cand[c]] > src0[best])
                        best = cand[c];
                for (int k = 0; k < in->n; k++)
                    plane(out, k, i)[(size_t)y * w2 + x] = plane(in, k, i)[best];
            }
        }
    return 0;
}

/* *skip = maxpool(*t), and *t is freed. */
static int
pool_to(batch *t, batch *skip)
{
    if (maxpool_into(t, skip))
        return -1;
    batch_free(t);
    return 0;
}

static int
pool_replace(batch *t)
{
    batch out;
    if (pool_to(t, &out))
        return -1;
    *t = out;
    return 0;
}

/* *t = nearest 2x upsampling of *t. */
static int
upsample_replace(batch *t)
{
    batch out;
    if (batch_new(&out, t->n, t->c, 2 * t->h, 2 * t->w))
        return -1;
    const int planes = t->n * t->c, h = t->h, w = t->w;
#pragma omp parallel for collapse(2) schedule(static)
    for (int k = 0; k < planes; k++)
        for (int y = 0; y < 2 * h; y++) {
            const float *src = t->d + ((size_t)k * h + y / 2) * w;
            float *dst = out.d + ((size_t)k * 2 * h + y) * 2 * w;
            for (int x = 0; x < 2 * w; x++)
                dst[x] = src[x / 2];
        }
    batch_free(t);
    *t = out;
    return 0;
}

/* The network on a pre-processed input batch x (consumed); *t receives dec_conv0's
 * output, before the output clamp. */
static int
network(const mcp__unet *net, batch *x, batch *t)
{
    const mcp__unet_conv *c = net->conv;
    batch p1 = {0}, p2 = {0}, p3 = {0};
    *t = (batch){0};
    int rc = conv_into(&c[E0], x, NULL, 1, t) || conv_replace(&c[E1], t, NULL, 1) ||
             pool_to(t, &p1) || conv_into(&c[E2], &p1, NULL, 1, t) ||
             pool_to(t, &p2) || conv_into(&c[E3], &p2, NULL, 1, t) ||
             pool_to(t, &p3) || conv_into(&c[E4], &p3, NULL, 1, t) ||
             pool_replace(t) || conv_replace(&c[E5A], t, NULL, 1) ||
             conv_replace(&c[E5B], t, NULL, 1) ||
             /* decoder: concat(upsampled, skip) */
             upsample_replace(t) || conv_replace(&c[D4A], t, &p3, 1) ||
             conv_replace(&c[D4B], t, NULL, 1) ||
             upsample_replace(t) || conv_replace(&c[D3A], t, &p2, 1) ||
             conv_replace(&c[D3B], t, NULL, 1) ||
             upsample_replace(t) || conv_replace(&c[D2A], t, &p1, 1) ||
             conv_replace(&c[D2B], t, NULL, 1) ||
             upsample_replace(t) || conv_replace(&c[D1A], t, x, 1) ||
             conv_replace(&c[D1B], t, NULL, 1) ||
             /* no ReLU on the last conv (1.4); the output clamp makes 2.x's ReLU moot */
             conv_replace(&c[D0], t, NULL, 0);
    batch_free(&p1), batch_free(&p2), batch_free(&p3), batch_free(x);
    if (rc)
        batch_free(t);
    return rc ? -1 : 0;
}

/* ---- pre-/post-processing ---- */

static float
sanitize(float v, float lo, float hi)
{
    if (!(v == v))
        return 0.0f;
    return v < lo ? lo : v > hi ? hi : v;
}

double
mcp__unet_autoexposure(const mcp_image *color, int v2)
{
    const int H = color->height, W = color->width;
    int hk = v2 ? (H + 15) / 16 : (H + 8) / 16, wk = v2 ? (W + 15) / 16 : (W + 8) / 16;
    hk = hk < 1 ? 1 : hk;
    wk = wk < 1 ? 1 : wk;
    double log_sum = 0.0;
    int kept = 0;
    for (int i = 0; i < hk; i++) {
        const int y0 = (int)((int64_t)i * H / hk), y1 = (int)((int64_t)(i + 1) * H / hk);
        for (int j = 0; j < wk; j++) {
            const int x0 = (int)((int64_t)j * W / wk), x1 = (int)((int64_t)(j + 1) * W / wk);
            double sum = 0.0;
            for (int y = y0; y < y1; y++)
                for (int x = x0; x < x1; x++) {
                    const float *p = mcp_image_px(color, x, y);
                    sum += 0.212671 * sanitize(p[0], 0.0f, FLT_MAX) +
                           0.715160 * sanitize(p[1], 0.0f, FLT_MAX) +
                           0.072169 * sanitize(p[2], 0.0f, FLT_MAX);
                }
            const int n = (y1 - y0) * (x1 - x0);
            const double L = n > 0 ? sum / n : 0.0;
            if (L > 1e-8) {
                log_sum += log2(L);
                kept++;
            }
        }
    }
    return kept ? 0.18 / exp2(log_sum / kept) : 1.0;
}

static int
check_aux(const char *what, const mcp_image *color, const mcp_image *aux, int needed)
{
    if (!needed)
        return 0;
    if (!aux)
        return mcp_error("unet: these weights need the %s", what);
    if (aux->channels < 3)
        return mcp_error("%s: unet %s needs 3 channels (got %d)", aux->source, what,
                         aux->channels);
    return mcp_image_same_size(color, aux) ? 0 : -1;
}

/* d/dy of the clamp to [lo, hi]: 1 inside, boundaries included (as autograd's clamp);
 * 0 outside and for NaN. */
static float
clamp_slope(float v, float lo, float hi)
{
    return v >= lo && v <= hi ? 1.0f : 0.0f;
}

/* The input batch: image 0 the pre-processed colour | albedo | normal (notes 3.2,
 * 3.4), image 1 + k its tangent along t[k]; padding is 0 in every image. */
static int
preprocess(const mcp__unet *net, const mcp_image *color, const mcp_image *albedo,
           const mcp_image *normal, float s_in, const mcp_denoise_tangent *t, int n,
           batch *x)
{
    const int H = color->height, W = color->width, ic = net->ic;
    if (batch_new(x, 1 + n, ic, (H + 15) / 16 * 16, (W + 15) / 16 * 16))
        return -1;
    const float ns = norm_scale();
    const int wp = x->w;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < H; y++)
        for (int px = 0; px < W; px++) {
            const size_t at = (size_t)y * wp + px;
            const float *p = mcp_image_px(color, px, y);
            for (int ch = 0; ch < 3; ch++) {
                const float v = p[ch] * s_in, yv = sanitize(v, 0.0f, FLT_MAX);
                plane(x, 0, ch)[at] = pu_raw(yv) * ns;
                const float slope = clamp_slope(v, 0.0f, FLT_MAX) * s_in * ns * pu_slope(yv);
                for (int k = 0; k < n; k++)
                    plane(x, 1 + k, ch)[at] = slope * mcp_image_px(t[k].color, px, y)[ch];
            }
            if (ic >= 6) {
                const float *q = mcp_image_px(albedo, px, y);
                for (int ch = 0; ch < 3; ch++) {
                    plane(x, 0, 3 + ch)[at] = sanitize(q[ch], 0.0f, 1.0f);
                    const float slope = clamp_slope(q[ch], 0.0f, 1.0f);
                    for (int k = 0; k < n; k++)
                        if (t[k].albedo)
                            plane(x, 1 + k, 3 + ch)[at] =
                                slope * mcp_image_px(t[k].albedo, px, y)[ch];
                }
            }
            if (ic >= 9) {
                const float *q = mcp_image_px(normal, px, y);
                for (int ch = 0; ch < 3; ch++) {
                    plane(x, 0, 6 + ch)[at] = sanitize(q[ch], -1.0f, 1.0f) * 0.5f + 0.5f;
                    const float slope = 0.5f * clamp_slope(q[ch], -1.0f, 1.0f);
                    for (int k = 0; k < n; k++)
                        if (t[k].normal)
                            plane(x, 1 + k, 6 + ch)[at] =
                                slope * mcp_image_px(t[k].normal, px, y)[ch];
                }
            }
        }
    return 0;
}

/* Crops image k of the network output to H x W and maps it back (notes 3.6): the
 * primal through the clamp and PU^-1, a tangent through their derivatives there. */
static int
postprocess(const batch *t, int k, int W, int H, float s_out, mcp_image **out)
{
    if (mcp__rgb_new(W, H, "unet", out))
        return -1;
    const float ns = norm_scale();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < H; y++)
        for (int px = 0; px < W; px++) {
            float *dst = mcp_image_px(*out, px, y);
            const size_t at = (size_t)y * t->w + px;
            for (int ch = 0; ch < 3; ch++) {
                const float v = plane(t, 0, ch)[at], xs = sanitize(v, 0.0f, FLT_MAX) / ns;
                dst[ch] = k == 0 ? pu_raw_inverse(xs) * s_out
                                 : clamp_slope(v, 0.0f, FLT_MAX) * s_out *
                                       pu_inverse_slope(xs) / ns * plane(t, k, ch)[at];
            }
        }
    return 0;
}

int
mcp__unet_run(const mcp__unet *net, const mcp_image *color, const mcp_image *albedo,
              const mcp_image *normal, double input_scale, const mcp_denoise_tangent *t,
              int n, mcp_image **out, mcp_image **jt)
{
    if (out)
        *out = NULL;
    for (int k = 0; k < n; k++)
        jt[k] = NULL;
    if (!color || color->channels < 3)
        return mcp_error("unet: colour needs 3 channels");
    if (check_aux("albedo", color, albedo, net->ic >= 6) ||
        check_aux("normal", color, normal, net->ic >= 9))
        return -1;
    for (int k = 0; k < n; k++) {
        if (!t[k].color)
            return mcp_error("unet: tangent %d has no colour part", k);
        const mcp_image *parts[3] = {t[k].color, t[k].albedo, t[k].normal};
        for (int i = 0; i < 3; i++)
            if (parts[i] && (parts[i]->channels < 3 ? mcp_error("%s: has %d channels, "
                                                                "not 3",
                                                                parts[i]->source,
                                                                parts[i]->channels)
                                                    : !mcp_image_same_size(color, parts[i])))
                return mcp_error_prefix("unet: tangent %d: ", k);
    }
    /* The exposure is a constant of F, also for its JVP: it is computed once on the
     * primal colour, as a renderer fixes the exposure of a frame (notes 3.7). */
    const double scale_in =
        input_scale > 0 ? input_scale : mcp__unet_autoexposure(color, net->v2);
    if (!(scale_in > 0 && scale_in < 1e30))
        return mcp_error("unet: bad input scale %g", scale_in);
    const float s_in = (float)scale_in, s_out = 1.0f / s_in;
    batch x, y;
    if (preprocess(net, color, albedo, normal, s_in, t, n, &x) || network(net, &x, &y))
        return -1;
    int rc = 0;
    if (out)
        rc = postprocess(&y, 0, color->width, color->height, s_out, out);
    for (int k = 0; k < n && !rc; k++)
        rc = postprocess(&y, 1 + k, color->width, color->height, s_out, &jt[k]);
    batch_free(&y);
    if (rc) {
        if (out) {
            mcp_image_free(*out);
            *out = NULL;
        }
        for (int k = 0; k < n; k++) {
            mcp_image_free(jt[k]);
            jt[k] = NULL;
        }
    }
    return rc;
}

int
mcp__unet_forward(const mcp__unet *net, const mcp_image *color, const mcp_image *albedo,
                  const mcp_image *normal, double input_scale, mcp_image **out)
{
    return mcp__unet_run(net, color, albedo, normal, input_scale, NULL, 0, out, NULL);
}
