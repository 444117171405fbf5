/* box_denoiser.c: the linear 3x3 box denoiser for tests (see box_denoiser.h). */
#include "box_denoiser.h"
#include "testing.h"

mcp_image *
mcp_test_rgb(int w, int h)
{
    mcp_image *img = NULL;
    assert_int_equal(mcp_image_new(w, h, 3, (const char *[]){"R", "G", "B"}, &img), 0);
    return img;
}

static int
clampi(int v, int hi)
{
    return v < 0 ? 0 : v > hi ? hi : v;
}

void
mcp_test_box3(const mcp_image *in, mcp_image *out)
{
    for (int y = 0; y < in->height; y++)
        for (int x = 0; x < in->width; x++)
            for (int c = 0; c < 3; c++) {
                double s = 0.0;
                for (int dy = -1; dy <= 1; dy++)
                    for (int dx = -1; dx <= 1; dx++)
                        s += mcp_image_px(in, clampi(x + dx, in->width - 1),
                                          clampi(y + dy, in->height - 1))[c];
                mcp_image_px(out, x, y)[c] = (float)(s / 9.0);
            }
}

static int
box_apply(const mcp_denoiser *self, const mcp_denoise_input *in, mcp_image **out)
{
    (void)self;
    *out = mcp_test_rgb(in->color->width, in->color->height);
    mcp_test_box3(in->color, *out);
    return 0;
}

static int
box_jvp(const mcp_denoiser *self, const mcp_denoise_input *at,
        const mcp_denoise_tangent *t, int n, mcp_image **primal, mcp_image **out)
{
    if (primal) box_apply(self, at, primal);
    for (int k = 0; k < n; k++) {
        out[k] = mcp_test_rgb(at->color->width, at->color->height);
        mcp_test_box3(t[k].color, out[k]);
    }
    return 0;
}

const mcp_denoiser mcp_test_box_denoiser = {
    .name = "box3", .exact = 1, .apply = box_apply, .jvp = box_jvp};
