/* denoise_gauss.c: the `gauss` denoiser -- a Gaussian blur of the colour
 * (docs/mathematics.md §2.1). It is linear, so its Jacobian-vector product is the same
 * blur applied to the tangent, exactly. A baseline and a test object for SURE: it ignores
 * albedo, normal and variance.
 *
 * Settings: sigma [2] (px, > 0), radius [ceil(3 sigma)] (px, >= 0; the window is
 * 2 radius + 1 wide). Borders replicate (common/filter.h). */
#include <mcpost/denoiser.h>

#include "internal.h"

#include <mcpost/filter.h>

#include <math.h>
#include <stdlib.h>

/* Radii beyond this cannot be meant: an image side is at most MCP_MAX_DIM. */
#define RADIUS_MAX MCP_MAX_DIM

typedef struct {
    double sigma_px;
    int radius;
    float *kernel; /* 2 radius + 1 taps, normalised */
} gauss_state;

static const char *const gauss_keys[] = {"sigma", "radius", NULL};

/* The blur of a 3-channel image, as a new R,G,B image. */
static int
blur(const gauss_state *s, const mcp_image *img, mcp_image **out)
{
    static const char *const rgb[] = {"R", "G", "B"};
    mcp_image *o = NULL;
    int len = 2 * s->radius + 1;
    if (mcp_filter_separable(img, s->kernel, len, s->kernel, len, &o))
        return -1;
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
    if (mcp__denoise_check_input("gauss", in))
        return -1;
    return blur(self->state, in->color, out);
}

static int
gauss_jvp(const mcp_denoiser *self, const mcp_denoise_input *at,
          const mcp_denoise_tangent *t, int n, mcp_image **primal, mcp_image **out)
{
    const gauss_state *s = self->state;
    if (primal)
        *primal = NULL;
    for (int k = 0; k < n && out; k++)
        out[k] = NULL;
    if (mcp__denoise_check_input("gauss", at) ||
        mcp__denoise_check_tangents("gauss", at, t, n))
        return -1;
    if (n > 0 && !out)
        return mcp_error("gauss: no room for %d tangent outputs", n);
    for (int k = 0; k < n; k++)
        if (blur(s, t[k].color, &out[k]))
            goto fail;
    if (primal && blur(s, at->color, primal))
        goto fail;
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
    double sigma = 2.0;
    if (mcp_node_opt_double(settings, "sigma", &sigma))
        return -1;
    if (!(sigma > 0) || sigma > RADIUS_MAX)
        return mcp_node_error(mcp_node_get(settings, "sigma"),
                              "gauss: sigma must be > 0 and <= %d px (got %g)",
                              RADIUS_MAX, sigma);
    int radius = sigma * 3 < RADIUS_MAX ? (int)ceil(3 * sigma) : RADIUS_MAX;
    const mcp_node *radius_node = mcp_node_get(settings, "radius");
    if (radius_node && mcp_node_int(radius_node, "radius", &radius))
        return -1;
    if (radius < 0 || radius > RADIUS_MAX)
        return mcp_node_error(radius_node, "gauss: radius must be in [0, %d] px (got %d)",
                              RADIUS_MAX, radius);
    mcp_denoiser *d = mcp__denoiser_new("gauss", sizeof(gauss_state));
    if (!d)
        return -1;
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
    *out = d;
    return 0;
}

const mcp_denoiser_kind mcp__denoiser_gauss = {
    "gauss",
    "Gaussian blur of the colour; linear, exact JVP "
    "(sigma [2] px, radius [ceil(3 sigma)] px)",
    gauss_keys,
    gauss_create,
};
