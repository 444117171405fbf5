/* tonemap.c: tone maps, RGB channel lookup and the perceptual kernel g
 * (docs/mathematics.md §4.1-§4.2; docs/flip.md §2 for FLIP's tone curves). */
#define _POSIX_C_SOURCE 200809L /* strcasecmp */
#include <mcpost/tonemap.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#define PI_D 3.14159265358979323846

/* FLIP.h ToneMappingCoefficients: Reinhard's row is only used to pick exposures (the
 * map itself divides by 1 + luminance); ACES carries the 0.6 pre-exposure. */
static const float flip_coeffs[3][6] = {
    {0.0f, 1.0f, 0.0f, 0.0f, 1.0f, 1.0f},
    {0.6f * 0.6f * 2.51f, 0.6f * 0.03f, 0.0f, 0.6f * 0.6f * 2.43f, 0.6f * 0.59f, 0.14f},
    {0.231683f, 0.013791f, 0.0f, 0.18f, 0.3f, 0.018f},
};

static const char *const tonemap_names[] = {"none", "clamp", "aces", "hable", "reinhard"};

const mcp_wordlist mcp_tonemap_words = {"tone map", tonemap_names, 5};

int
mcp_tonemap_from_name(const char *name, mcp_tonemap *out)
{
    return mcp_wordlist_find(&mcp_tonemap_words, name, (int *)out);
}

const char *
mcp_tonemap_name(mcp_tonemap tm)
{
    return (unsigned)tm < 5 ? tonemap_names[tm] : "?";
}

static float
clamp01(float x)
{
    return x > 0.0f ? (x < 1.0f ? x : 1.0f) : 0.0f; /* NaN -> 0 */
}

/* (k0 x^2 + k1 x + k2) / (k3 x^2 + k4 x + k5) and its derivative. */
static float
rational(const float *k, float x)
{
    return (k[0] * x * x + k[1] * x + k[2]) / (k[3] * x * x + k[4] * x + k[5]);
}

static float
rational_slope(const float *k, float x)
{
    float n = k[0] * x * x + k[1] * x + k[2], d = k[3] * x * x + k[4] * x + k[5];
    float dn = 2.0f * k[0] * x + k[1], dd = 2.0f * k[3] * x + k[4];
    return (dn * d - n * dd) / (d * d);
}

static const float aces_narkowicz[6] = {2.51f, 0.03f, 0.0f, 2.43f, 0.59f, 0.14f};

float
mcp_tonemap_value(mcp_tonemap tm, float x)
{
    if (tm == MCP_TONEMAP_NONE) return x;
    if (!(x > 0.0f)) x = 0.0f;
    switch (tm) {
    case MCP_TONEMAP_ACES:
        return clamp01(rational(aces_narkowicz, x));
    case MCP_TONEMAP_HABLE:
        return clamp01(rational(flip_coeffs[2], x));
    case MCP_TONEMAP_REINHARD:
        return clamp01(x / (1.0f + x));
    default:
        return clamp01(x);
    }
}

float
mcp_tonemap_slope(mcp_tonemap tm, float x)
{
    if (tm == MCP_TONEMAP_NONE) return 1.0f;
    if (!(x >= 0.0f)) return 0.0f;
    float y, s;
    switch (tm) {
    case MCP_TONEMAP_ACES:
        y = rational(aces_narkowicz, x);
        s = rational_slope(aces_narkowicz, x);
        break;
    case MCP_TONEMAP_HABLE:
        y = rational(flip_coeffs[2], x);
        s = rational_slope(flip_coeffs[2], x);
        break;
    case MCP_TONEMAP_REINHARD:
        y = x / (1.0f + x);
        s = 1.0f / ((1.0f + x) * (1.0f + x));
        break;
    default:
        y = x;
        s = 1.0f;
        break;
    }
    return y < 1.0f ? s : 0.0f;
}

int
mcp_tonemap_apply(const mcp_image *img, mcp_tonemap tm, mcp_image **out)
{
    *out = NULL;
    if ((unsigned)tm >= 5) return mcp_error("tonemap: unknown tone map %d", (int)tm);
    mcp_image *o = NULL;
    if (mcp_image_new(img->width, img->height, img->channels,
                      (const char *const *)img->names, &o))
        return -1;
    int w = img->width, c = img->channels;
#pragma omp parallel for if ((size_t)w * img->height > 65536)
    for (int y = 0; y < img->height; y++) {
        float *dst = o->data + (size_t)y * w * c;
        for (int x = 0; x < w; x++) {
            const float *p = mcp_image_px(img, x, y);
            for (int k = 0; k < c; k++)
                dst[(size_t)x * c + k] = mcp_tonemap_value(tm, p[k]);
        }
    }
    if (img->source && mcp_image_set_source(o, img->source)) {
        mcp_image_free(o); /* out of memory: the name is needed in messages */
        return -1;
    }
    *out = o;
    return 0;
}

int
mcp_tonemap_flip_coefficients(mcp_tonemap tm, float k[6])
{
    int row = tm == MCP_TONEMAP_REINHARD ? 0
              : tm == MCP_TONEMAP_ACES   ? 1
              : tm == MCP_TONEMAP_HABLE  ? 2
                                         : -1;
    if (row < 0)
        return mcp_error("tone mapper must be aces, hable or reinhard (got '%s')",
                         mcp_tonemap_name(tm));
    memcpy(k, flip_coeffs[row], sizeof flip_coeffs[row]);
    return 0;
}

int
mcp_rgb_channels(const mcp_image *img, int rgb[3])
{
    static const char *const names[3] = {"R", "G", "B"};
    int n_found = mcp_image_rgb_by_name(img, rgb);
    if (n_found == 3) return 0;
    if (n_found == 0 && (img->channels == 3 || img->channels == 1)) {
        for (int k = 0; k < 3; k++)
            rgb[k] = img->channels == 3 ? k : 0;
        return 0;
    }
    for (int k = 0; k < 3; k++)
        if (rgb[k] < 0)
            return mcp_error("%s: no channel '%s'", img->source ? img->source : "image",
                             names[k]);
    return -1;
}

/* ---- the perceptual kernel ---- */

mcp_pkernel
mcp_pkernel_defaults(void)
{
    /* 300 dpi at 16 inches gives sigma = 0.80, the 3-tap kernel's sqrt(2/pi)
     * (Chizhov et al. 2022, Sec. 8: D = 4792/R inches). */
    return (mcp_pkernel){.kind = MCP_PKERNEL_TAP3, .dpi = 300.0, .distance_in = 16.0};
}

static const char *const pkernel_names[] = {"tap3", "gaussian"};
const mcp_wordlist mcp_pkernel_kind_words = {"perceptual kernel", pkernel_names, 2};

int
mcp_pkernel_kind_from_name(const char *name, mcp_pkernel_kind *out)
{
    return mcp_wordlist_find(&mcp_pkernel_kind_words, name, (int *)out);
}

const char *
mcp_pkernel_kind_name(mcp_pkernel_kind kind)
{
    return kind == MCP_PKERNEL_GAUSSIAN ? "gaussian" : "tap3";
}

double
mcp_pkernel_sigma_px(double dpi, double distance_in)
{
    double tau_deg = (180.0 / PI_D) * 2.0 * atan(1.0 / (2.0 * dpi * distance_in));
    return 0.00954 / tau_deg;
}

int
mcp_pkernel_taps(const mcp_pkernel *k, double **taps, int *radius)
{
    mcp_pkernel d = mcp_pkernel_defaults();
    if (!k) k = &d;
    *taps = NULL;
    if (k->kind == MCP_PKERNEL_TAP3) {
        double *t = mcp_malloc(3 * sizeof *t);
        if (!t) return -1;
        t[0] = t[2] = 1.0 / PI_D;
        t[1] = 1.0 - 2.0 / PI_D;
        *taps = t;
        *radius = 1;
        return 0;
    }
    if (k->kind != MCP_PKERNEL_GAUSSIAN)
        return mcp_error("pkernel: unknown kind %d", (int)k->kind);
    if (!(k->dpi > 0.0) || !isfinite(k->dpi))
        return mcp_error("pkernel: dpi must be > 0 (got %g)", k->dpi);
    if (!(k->distance_in > 0.0) || !isfinite(k->distance_in))
        return mcp_error("pkernel: distance_in must be > 0 (got %g)", k->distance_in);
    double sigma = mcp_pkernel_sigma_px(k->dpi, k->distance_in);
    if (!(sigma <= 1000.0))
        return mcp_error("pkernel: sigma %.3g px is too wide (dpi %g, distance_in %g)",
                         sigma, k->dpi, k->distance_in);
    int r = (int)ceil(3.0 * sigma);
    if (r < 1) r = 1;
    double *t = mcp_malloc((size_t)(2 * r + 1) * sizeof *t), sum = 0.0;
    if (!t) return -1;
    for (int i = -r; i <= r; i++)
        sum += t[i + r] = exp(-0.5 * i * i / (sigma * sigma));
    for (int i = 0; i <= 2 * r; i++)
        t[i] /= sum;
    *taps = t;
    *radius = r;
    return 0;
}

static int
clampi(int v, int lo, int hi)
{
    return v < lo ? lo : v > hi ? hi : v;
}

int
mcp_pkernel_filter(const mcp_image *img, const double *taps, int radius, mcp_image **out)
{
    *out = NULL;
    int w = img->width, h = img->height, c = img->channels;
    mcp_image *o = NULL;
    double *tmp = NULL;
    size_t n;
    if (radius < 0 || mcp_size_mul3((size_t)w, (size_t)h, (size_t)c, &n))
        return mcp_error("pkernel: bad size %dx%dx%d radius %d", w, h, c, radius);
    if (!(tmp = mcp_malloc(n * sizeof *tmp)) ||
        mcp_image_new(w, h, c, (const char *const *)img->names, &o)) {
        free(tmp);
        return -1;
    }
    /* x pass into double, then y pass; replicate (clamp-to-edge) borders (§4.3). */
#pragma omp parallel for if (n > 65536)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int k = 0; k < c; k++) {
                double s = 0.0;
                for (int t = -radius; t <= radius; t++)
                    s += taps[t + radius] *
                         mcp_image_px(img, clampi(x + t, 0, w - 1), y)[k];
                tmp[((size_t)y * w + x) * c + k] = s;
            }
#pragma omp parallel for if (n > 65536)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int k = 0; k < c; k++) {
                double s = 0.0;
                for (int t = -radius; t <= radius; t++)
                    s += taps[t + radius] *
                         tmp[((size_t)clampi(y + t, 0, h - 1) * w + x) * c + k];
                o->data[((size_t)y * w + x) * c + k] = (float)s;
            }
    free(tmp);
    if (img->source && mcp_image_set_source(o, img->source)) {
        mcp_image_free(o); /* out of memory: the name is needed in messages */
        return -1;
    }
    *out = o;
    return 0;
}
