/* denoise_default.c: the `default` denoiser -- what every command and stage uses when
 * none is named. OIDN's U-Net with the weights mcpost ships (weights/README.md), which
 * need colour, albedo and normal; for an input without albedo or normal it falls back
 * to the feature-guided `nlm` (which then guides by colour alone) and says so once.
 * OIDN's colour-only and colour+albedo weights are not shipped: their licence allows it,
 * but they are not in this project's copy of the 1.4 release. */
#include <mcpost/denoiser.h>
#include <mcpost/yaml.h>
#include <mcpost/progress.h>

#include "internal.h"

#include <stdlib.h>
#include <string.h>

typedef struct {
    mcp_denoiser self;
    mcp_denoiser *unet; /* NULL when no weights were found */
    mcp_denoiser *nlm;
    int noted; /* the fallback was announced */
} default_denoiser;

/* The denoiser for this input, announcing a fallback once. */
static const mcp_denoiser *
pick(const mcp_denoiser *self, const mcp_denoise_input *in)
{
    default_denoiser *d = (default_denoiser *)self;
    if (d->unet && in->albedo && in->normal) return d->unet;
    if (!d->noted) {
        d->noted = 1;
        d->self.name = "default (nlm)"; /* what the reports then name */
        mcp_note("denoiser: %s, so the default denoiser is nlm instead of the U-Net",
                 d->unet
                     ? "the input has no albedo and normal, which the U-Net's weights "
                       "need"
                     : "no U-Net weights were found");
    }
    return d->nlm;
}

static int
default_apply(const mcp_denoiser *self, const mcp_denoise_input *in, mcp_image **out)
{
    const mcp_denoiser *d = pick(self, in);
    return d->apply(d, in, out);
}

static int
default_jvp(const mcp_denoiser *self, const mcp_denoise_input *at,
            const mcp_denoise_tangent *t, int n, mcp_image **primal, mcp_image **out)
{
    const mcp_denoiser *d = pick(self, at);
    return d->jvp(d, at, t, n, primal, out);
}

static void
default_destroy(mcp_denoiser *self)
{
    default_denoiser *d = (default_denoiser *)self;
    mcp_denoiser_free(d->unet);
    mcp_denoiser_free(d->nlm);
    free(d);
}

static int
default_create(const mcp_node *settings, const char *base_dir, mcp_denoiser **out)
{
    *out = NULL;
    default_denoiser *d = mcp_calloc(1, sizeof *d);
    if (!d) return -1;
    mcp_node unet = {.kind = MCP_NODE_SCALAR, .value = (char *)"unet"},
             nlm = {.kind = MCP_NODE_SCALAR, .value = (char *)"nlm"};
    unet.line = nlm.line = settings->line;
    unet.file = nlm.file = settings->file;
    if (mcp_denoiser_create(&unet, base_dir, &d->unet))
        mcp_error_clear(); /* no weights: nlm for everything, said at first use */
    if (mcp_denoiser_create(&nlm, base_dir, &d->nlm)) {
        mcp_denoiser_free(d->unet);
        free(d);
        return -1;
    }
    d->self.name = d->unet ? "default (unet)" : "default (nlm)";
    d->self.exact = 1;
    d->self.uses_albedo = d->self.uses_normal = 1;
    d->self.apply = default_apply;
    d->self.jvp = default_jvp;
    d->self.destroy = default_destroy;
    d->self.pick = pick;
    *out = &d->self;
    return 0;
}

static const char *const default_keys[] = {NULL};

const mcp_denoiser_kind mcp__denoiser_default = {
    "default",
    "what is used when no denoiser is named: unet with the shipped weights; nlm for "
    "inputs without albedo and normal (said once)",
    default_keys,
    default_create,
    NULL, /* no settings */
};

const mcp_denoiser *
mcp__default_unet(const mcp_denoiser *d)
{
    return d && d->destroy == default_destroy ? ((const default_denoiser *)d)->unet
                                              : NULL;
}
