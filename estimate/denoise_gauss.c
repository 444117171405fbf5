/* denoise_gauss.c: the `gauss` denoiser -- a Gaussian blur of the colour
 * (docs/mathematics.md §2.1). It is linear, so its Jacobian-vector product is the same
 * blur applied to the tangent, exactly. A baseline and a test object for SURE: it ignores
 * albedo, normal and variance.
 *
 * Settings (the table below, docs/denoisers.md): sigma [2] (px, > 0), radius
 * [auto: ceil(3 sigma)] (px, >= 0; the window is 2 radius + 1 wide). Borders replicate
 * (common/filter/filter.h). */
#include <mcpost/denoiser.h>

#include "internal.h"

#include <mcpost/filter.h>

#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

/* Radii beyond this cannot be meant: an image side is at most MCP_MAX_DIM. */
#define RADIUS_MAX MCP_MAX_DIM

typedef struct {
    double sigma_px;
    int radius;
    float *kernel; /* 2 radius + 1 taps, normalised */
} gauss_state;

/* ---- settings: the table (<mcpost/options.h>) ---- */

typedef struct {
    double sigma; /* px */
    int radius;   /* px; when not given, ceil(3 sigma) */
    uint64_t given;
} gauss_settings;

static const mcp_option gauss_options[] = {
    {.name = "sigma",
     .type = MCP_OPT_NUMBER,
     .offset = offsetof(gauss_settings, sigma),
     .def = "2",
     .doc = "standard deviation of the blur, px",
     .lo = 0,
     .hi = RADIUS_MAX,
     .bounds = MCP_OPT_LO_OPEN | MCP_OPT_HI},
    {.name = "radius",
     .type = MCP_OPT_INT,
     .offset = offsetof(gauss_settings, radius),
     .meta = "N",
     .doc = "the window is 2 radius + 1 px wide [ceil(3 sigma)]"},
    {0}};

static void
gauss_defaults(void *p)
{
    gauss_settings *g = p;
    g->sigma = 2.0;
}

const mcp_operation mcp__op_gauss;

/* The radius from sigma when none is given, and a given one checked (in px, as the
 * docs say it). */
static int
gauss_finish(void *p)
{
    gauss_settings *g = p;
    if (!mcp_operation_given(&mcp__op_gauss, &gauss_options[1], g)) {
        g->radius = g->sigma * 3 < RADIUS_MAX ? (int)ceil(3 * g->sigma) : RADIUS_MAX;
        return 0;
    }
    if (g->radius < 0 || g->radius > RADIUS_MAX)
        return mcp_error("gauss: radius must be in [0, %d] px (got %d)", RADIUS_MAX,
                         g->radius);
    return 0;
}

const mcp_operation mcp__op_gauss = {
    .name = "gauss",
    .denoiser = 1,
    .summary = "Gaussian blur of the colour; linear, exact JVP",
    .options = gauss_options,
    .size = sizeof(gauss_settings),
    .defaults = gauss_defaults,
    .finish = gauss_finish,
    .given_offset = offsetof(gauss_settings, given),
};

/* The keys, from the table (denoisers.c fills them in before the kinds are handed
 * out). */
const char *mcp__gauss_keys[MCP__DENOISER_KEYS_MAX];

/* The blur of a 3-channel image, as a new R,G,B image. */
static int
blur(const gauss_state *s, const mcp_image *img, mcp_image **out)
{
    static const char *const rgb[] = {"R", "G", "B"};
    mcp_image *o = NULL;
    int len = 2 * s->radius + 1;
    if (mcp_filter_separable(img, s->kernel, len, s->kernel, len, &o)) return -1;
    for (int c = 0; c < 3; c++)
        if (mcp_image_set_channel_name(o, c, rgb[c])) {
            mcp_image_free(o);
            return -1;
        }
    if (mcp_image_set_source(o, "gauss")) {
        mcp_image_free(o);
        return -1;
    }
    *out = o;
    return 0;
}

static int
gauss_apply(const mcp_denoiser *self, const mcp_denoise_input *in, mcp_image **out)
{
    *out = NULL;
    if (mcp__denoise_check_input("gauss", in)) return -1;
    return blur(self->state, in->color, out);
}

static int
gauss_jvp(const mcp_denoiser *self, const mcp_denoise_input *at,
          const mcp_denoise_tangent *t, int n, mcp_image **primal, mcp_image **out)
{
    const gauss_state *s = self->state;
    if (primal) *primal = NULL;
    for (int k = 0; k < n && out; k++)
        out[k] = NULL;
    if (mcp__denoise_check_input("gauss", at) ||
        mcp__denoise_check_tangents("gauss", at, t, n))
        return -1;
    if (n > 0 && !out) return mcp_error("gauss: no room for %d tangent outputs", n);
    for (int k = 0; k < n; k++)
        if (blur(s, t[k].color, &out[k])) goto fail;
    if (primal && blur(s, at->color, primal)) goto fail;
    return 0;
fail:
    for (int k = 0; k < n; k++) {
        mcp_image_free(out[k]);
        out[k] = NULL;
    }
    return -1;
}

static void
gauss_destroy(mcp_denoiser *self)
{
    gauss_state *s = self->state;
    free(s->kernel);
    free(self);
}

static int
gauss_create(const mcp_node *settings, const char *base_dir, mcp_denoiser **out)
{
    (void)base_dir;
    *out = NULL;
    gauss_settings g;
    if (mcp__options_from_node(&mcp__op_gauss, settings, NULL, &g)) return -1;
    double sigma = g.sigma;
    int radius = g.radius;
    mcp_denoiser *d = mcp__denoiser_new("gauss", sizeof(gauss_state));
    if (!d) return -1;
    gauss_state *s = d->state;
    s->sigma_px = sigma;
    s->radius = radius;
    s->kernel = mcp_malloc((size_t)(2 * radius + 1) * sizeof *s->kernel);
    d->destroy = gauss_destroy;
    if (!s->kernel || mcp_gaussian_kernel(sigma, radius, s->kernel)) {
        mcp_denoiser_free(d);
        return -1;
    }
    d->apply = gauss_apply;
    d->jvp = gauss_jvp;
    /* a pixel's value reads `radius` rows either side (at least one: any reach at all
       lets the estimate go in bands) */
    d->band_halo = radius > 0 ? radius : 1;
    *out = d;
    return 0;
}

const mcp_denoiser_kind mcp__denoiser_gauss = {
    "gauss",
    "Gaussian blur of the colour; linear, exact JVP "
    "(sigma [2] px, radius [ceil(3 sigma)] px)",
    mcp__gauss_keys,
    gauss_create,
    &mcp__op_gauss,
};
