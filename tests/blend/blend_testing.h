/* blend_testing.h: helpers for the blend tests (header-only, static): RGB images from
 * values, and a linear test denoiser -- a Gaussian blur, whose Jacobian is the blur
 * itself, so its jvp is exact -- that needs nothing from estimate's denoiser table. */
#ifndef MCP_BLEND_TESTING_H
#define MCP_BLEND_TESTING_H

#include "testing.h"

#include <mcpost/blend.h>
#include <mcpost/filter.h>

#include <stdlib.h>
#include <string.h>

static const char *const RGB[3] = {"R", "G", "B"};

/* A w x h RGB image with every value v. */
static inline mcp_image *
rgb_constant(int w, int h, float v)
{
    return mcp_test_constant(w, h, 3, v, RGB);
}

/* A w x h RGB image from values[] (w * h * 3, row-major, interleaved). */
static inline mcp_image *
rgb_from(int w, int h, const float *values)
{
    mcp_image *img = rgb_constant(w, h, 0);
    memcpy(img->data, values, (size_t)w * h * 3 * sizeof(float));
    return img;
}

/* ---- a blur denoiser ---- */

typedef struct {
    double sigma_px;
    int window;
} blur_state;

static inline int
blur_apply(const mcp_denoiser *self, const mcp_denoise_input *in, mcp_image **out)
{
    const blur_state *s = self->state;
    return mcp_gaussian_blur(in->color, s->window, s->sigma_px, out);
}

static inline int
blur_jvp(const mcp_denoiser *self, const mcp_denoise_input *at,
         const mcp_denoise_tangent *t, int n, mcp_image **primal, mcp_image **out)
{
    const blur_state *s = self->state;
    for (int k = 0; k < n; k++)
        out[k] = NULL;
    if (primal && blur_apply(self, at, primal)) return -1;
    for (int k = 0; k < n; k++)
        if (mcp_gaussian_blur(t[k].color, s->window, s->sigma_px, &out[k])) return -1;
    return 0;
}

static inline void
blur_destroy(mcp_denoiser *self)
{
    free(self->state);
    free(self);
}

/* A Gaussian-blur "denoiser" of sigma_px in a window; free with mcp_denoiser_free or
 * self->destroy. */
static inline mcp_denoiser *
blur_denoiser(double sigma_px, int window)
{
    mcp_denoiser *d = calloc(1, sizeof *d);
    blur_state *s = calloc(1, sizeof *s);
    assert_non_null(d);
    assert_non_null(s);
    s->sigma_px = sigma_px;
    s->window = window;
    d->name = "test-blur";
    d->exact = 1;
    d->apply = blur_apply;
    d->jvp = blur_jvp;
    d->destroy = blur_destroy;
    d->state = s;
    return d;
}

#endif
