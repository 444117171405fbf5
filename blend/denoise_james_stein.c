/* denoise_james_stein.c: the `james-stein` denoiser -- another denoiser followed by the
 * James-Stein post-correction (post_correction.c), so that `estimate` can estimate the
 * error of the image a user keeps rather than of the raw denoised one (Firmino 2024
 * evaluated OIDN with this combiner, so that the denoiser's bias vanishes as samples
 * grow).
 *
 *     F(X) = ρ ⊙ d(X) + (1 − ρ) ⊙ X,    ρ from mcp_blend_james_stein at X
 *
 * The JVP holds the weights ρ constant, as the issue asks and as Firmino 2024 treat the
 * combiner (its weights depend on X only through window sums of (X − d)², whose
 * derivative is left out): J t = ρ ⊙ (J_d t) + (1 − ρ) ⊙ t. SURE therefore treats
 * ρ as a constant of F, like the variance nlm reads.
 *
 * Settings: inner (the denoiser's name) [unet], window [15: the blend's js_window] (odd),
 * and any other key, which goes to the inner denoiser: {name: james-stein, inner: unet,
 * weights: W.tza} or --denoiser james-stein --weights W.tza. */
#include <mcpost/blend.h>
#include <mcpost/denoiser.h>
#include <mcpost/yaml.h>

#include <stdlib.h>
#include <string.h>

typedef struct {
    mcp_denoiser self;
    mcp_denoiser *inner;
    int window;
} js_denoiser;

/* The combiner's weights ρ (of d) at `in`, given d = inner(in). */
static int
weights_at(const js_denoiser *js, const mcp_denoise_input *in, const mcp_image *d,
           mcp_image **rho)
{
    *rho = NULL;
    if (!in->variance)
        return mcp_error(
            "james-stein: the input has no variance (the combiner weighs the "
            "denoised image by it)");
    mcp_image *blend = NULL;
    /* the plain combiner: its self-influence would need the inner denoiser's
       divergence, a JVP per evaluation (docs/blend.md "Self-influence") */
    int rc =
        mcp_blend_james_stein(in->color, d, in->variance, js->window, NULL, &blend, rho);
    mcp_image_free(blend);
    return rc;
}

/* out = ρ ⊙ a + (1 − ρ) ⊙ b, a new R,G,B image (ρ: 1 or 3 channels). */
static int
combine(const mcp_image *rho, const mcp_image *a, const mcp_image *b, mcp_image **out)
{
    static const char *const rgb[] = {"R", "G", "B"};
    if (mcp_image_new(a->width, a->height, 3, rgb, out)) return -1;
    int rc_ = rho->channels >= 3;
    for (int y = 0; y < a->height; y++)
        for (int x = 0; x < a->width; x++) {
            const float *r = mcp_image_px(rho, x, y), *pa = mcp_image_px(a, x, y),
                        *pb = mcp_image_px(b, x, y);
            float *o = mcp_image_px(*out, x, y);
            for (int c = 0; c < 3; c++) {
                float w = r[rc_ ? c : 0];
                o[c] = w * pa[c] + (1 - w) * pb[c];
            }
        }
    return 0;
}

static int
js_apply(const mcp_denoiser *self, const mcp_denoise_input *in, mcp_image **out)
{
    const js_denoiser *js = (const js_denoiser *)self;
    *out = NULL;
    mcp_image *d = NULL, *rho = NULL;
    int rc = js->inner->apply(js->inner, in, &d) || weights_at(js, in, d, &rho) ||
             combine(rho, d, in->color, out);
    mcp_image_free(d);
    mcp_image_free(rho);
    return rc ? -1 : 0;
}

static int
js_jvp(const mcp_denoiser *self, const mcp_denoise_input *at,
       const mcp_denoise_tangent *t, int n, mcp_image **primal, mcp_image **out)
{
    const js_denoiser *js = (const js_denoiser *)self;
    if (primal) *primal = NULL;
    for (int k = 0; k < n && out; k++)
        out[k] = NULL;
    mcp_image *d = NULL, *rho = NULL;
    mcp_image **jd = n > 0 ? mcp_calloc((size_t)n, sizeof *jd) : NULL;
    int rc = -1;
    if ((n > 0 && !jd) || js->inner->jvp(js->inner, at, t, n, &d, jd) ||
        weights_at(js, at, d, &rho))
        goto done;
    for (int k = 0; k < n; k++)
        if (combine(rho, jd[k], t[k].color, &out[k])) goto done;
    if (primal && combine(rho, d, at->color, primal)) goto done;
    rc = 0;
done:
    for (int k = 0; k < n; k++) {
        mcp_image_free(jd ? jd[k] : NULL);
        if (rc && out) {
            mcp_image_free(out[k]);
            out[k] = NULL;
        }
    }
    free(jd);
    mcp_image_free(d);
    mcp_image_free(rho);
    return rc;
}

static void
js_destroy(mcp_denoiser *self)
{
    js_denoiser *js = (js_denoiser *)self;
    mcp_denoiser_free(js->inner);
    free(js);
}

/* The inner denoiser's settings: this map without name, inner and window, with
 * name = inner. Built as a view over the caller's nodes (nothing to free). */
static int
create_inner(const mcp_node *settings, const char *base_dir, mcp_denoiser **out)
{
    const char *inner = "unet";
    if (settings->kind == MCP_NODE_MAP && mcp_node_opt_string(settings, "inner", &inner))
        return -1;
    if (strcmp(inner, "james-stein") == 0)
        return mcp_node_error(mcp_node_get(settings, "inner"),
                              "james-stein: inner cannot be james-stein itself");
    mcp_node name = {.kind = MCP_NODE_SCALAR, .value = (char *)inner};
    mcp_node name_key = {.kind = MCP_NODE_SCALAR, .value = (char *)"name"};
    int cap = settings->kind == MCP_NODE_MAP ? settings->count + 1 : 1, n = 0;
    mcp_node **keys = mcp_calloc((size_t)cap, sizeof *keys),
             **items = mcp_calloc((size_t)cap, sizeof *items);
    int rc = -1;
    if (!keys || !items) goto done;
    name.line = name_key.line = settings->line;
    name.file = name_key.file = settings->file;
    keys[n] = &name_key, items[n++] = &name;
    for (int i = 0; settings->kind == MCP_NODE_MAP && i < settings->count; i++) {
        const char *k = settings->keys[i]->value;
        if (strcmp(k, "name") && strcmp(k, "inner") && strcmp(k, "window"))
            keys[n] = settings->keys[i], items[n++] = settings->items[i];
    }
    mcp_node map = {.kind = MCP_NODE_MAP,
                    .line = settings->line,
                    .column = settings->column,
                    .file = settings->file,
                    .count = n,
                    .items = items,
                    .keys = keys};
    rc = mcp_denoiser_create(&map, base_dir, out);
done:
    free(keys);
    free(items);
    return rc;
}

static int
js_create(const mcp_node *settings, const char *base_dir, mcp_denoiser **out)
{
    *out = NULL;
    int window = mcp_blend_defaults().js_window;
    if (settings->kind == MCP_NODE_MAP && mcp_node_opt_int(settings, "window", &window))
        return -1;
    if (window < 1 || window % 2 == 0 || window > 255)
        return mcp_node_error(mcp_node_get(settings, "window"),
                              "james-stein: window must be odd, 1 to 255 (got %d)",
                              window);
    js_denoiser *js = mcp_calloc(1, sizeof *js);
    if (!js) return -1;
    if (create_inner(settings, base_dir, &js->inner)) {
        free(js);
        return -1;
    }
    js->window = window;
    js->self.name = "james-stein";
    js->self.exact = js->inner->exact;
    js->self.uses_albedo = js->inner->uses_albedo;
    js->self.uses_normal = js->inner->uses_normal;
    js->self.apply = js_apply;
    js->self.jvp = js_jvp;
    js->self.destroy = js_destroy;
    *out = &js->self;
    return 0;
}

/* Its keys are its own and every built-in inner kind's (gauss, nlm and bilateral,
 * unet, external): the inner denoiser then checks the ones it is given, so a key that
 * kind lacks fails there, naming it. tests/blend/test_james_stein.c checks that this
 * list covers every kind's keys. */
static const char *const js_keys[] = {
    "inner",         "window",       "sigma",        "radius",         "patch_radius",
    "k_color",       "alpha",        "epsilon",      "sigma_color",    "use_variance",
    "variance_blur", "sigma_albedo", "sigma_normal", "sigma_spatial",  "weights",
    "input_scale",   "tile",         "fixed_bits",   "exact_tangents", "max_memory_mb",
    "command",       "format",       "delta",        "workdir",        NULL};

const mcp_denoiser_kind mcp__denoiser_james_stein = {
    "james-stein",
    "another denoiser (inner [unet]) followed by the James-Stein post-correction "
    "(window [15], the plain weight); the JVP holds the combiner's weights constant; "
    "other keys go to the inner denoiser",
    js_keys,
    js_create,
    NULL, /* reads its own keys: the inner denoiser's */
};
