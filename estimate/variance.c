/* variance.c: the variance of the denoised image by Jacobian-vector products
 * (docs/mathematics.md §2.5; Firmino 2023 Eqs. 1-2).
 *
 * With Rademacher probes v (v_p = L_p r_p, L_p L_pᵀ = Σ̂_p), E[(Jv)_i²] = (J Σ̂ Jᵀ)_ii,
 * the first-order (delta-method) variance of F_i. K probes are averaged. The SURE
 * pipeline reuses its Gaussian probes instead (Firmino 2024 Alg. 2 line 5), which has
 * the same expectation; mcp_estimate_options.variance_rademacher picks this route. */
#include "estimate.h"
#include "internal.h"

#include <mcpost/flip.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>

mcp_variance_options
mcp_variance_defaults(void)
{
    mcp_variance_options o;
    memset(&o, 0, sizeof o);
    o.n_probes = 1;
    o.seed = 0;
    o.relative = 0;
    o.mc = 0;
    o.fd_delta = 0.1;
    return o;
}

int
mcp__variance_from_jvps(const mcp_image *const *jv, int n, mcp_error_metric metric,
                        double ppd, const mcp_image *denominator, mcp_image **var,
                        mcp_image **var_rel)
{
    *var = NULL;
    if (var_rel) *var_rel = NULL;
    int w = jv[0]->width, h = jv[0]->height;
    mcp_image **m = mcp_calloc((size_t)n, sizeof *m);
    if (!m) return -1;
    int rc = -1;
    if (metric == MCP_METRIC_RELSE_PERCEPTUAL) /* the variance of MF: (M J v)² */
        for (int k = 0; k < n; k++)
            if (mcp_flip_csf_apply(jv[k], ppd, &m[k])) goto done;
    if (mcp__image_new(w, h, 3, NULL, "variance of the denoised image", var) ||
        (var_rel && mcp__image_new(w, h, 3, NULL,
                                   "relative variance of the denoised image", var_rel)))
        goto done;
    {
        mcp_image *v = *var, *vr = var_rel ? *var_rel : NULL;
        const mcp_image *const *src =
            metric == MCP_METRIC_RELSE_PERCEPTUAL ? (const mcp_image *const *)m : jv;
        double inv_n = 1.0 / n;
#pragma omp parallel for schedule(static)
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                double den = denominator ? mcp_image_px(denominator, x, y)[0] : 1.0;
                float *pv = mcp_image_px(v, x, y);
                for (int c = 0; c < 3; c++) {
                    double s = 0.0;
                    for (int k = 0; k < n; k++) {
                        double j = mcp_image_px(src[k], x, y)[c];
                        s += j * j;
                    }
                    pv[c] = (float)(s * inv_n);
                    if (vr) mcp_image_px(vr, x, y)[c] = (float)(s * inv_n / den);
                }
            }
    }
    rc = 0;
done:
    for (int k = 0; k < n; k++)
        mcp_image_free(m[k]);
    free(m);
    if (rc) {
        mcp_image_free(*var);
        *var = NULL;
        if (var_rel) {
            mcp_image_free(*var_rel);
            *var_rel = NULL;
        }
    }
    return rc;
}

/* maxc(F)² + EPS_REL per pixel, 1 channel. */
static int
relative_denominator(const mcp_image *f, mcp_image **out)
{
    static const char *const name[1] = {"denominator"};
    if (mcp__image_new(f->width, f->height, 1, name, "denominator", out)) return -1;
    mcp_image *o = *out;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < f->height; y++)
        for (int x = 0; x < f->width; x++) {
            const float *p = mcp_image_px(f, x, y);
            double m = fmax(fmax(p[0], p[1]), p[2]);
            mcp_image_px(o, x, y)[0] = (float)(m * m + MCP_EPS_REL);
        }
    return 0;
}

int
mcp_variance(const mcp_dump *dump, const mcp_denoiser *den,
             const mcp_variance_options *opt, mcp_image **var, mcp_image **denoised)
{
    *var = NULL;
    if (denoised) *denoised = NULL;
    mcp_variance_options o = opt ? *opt : mcp_variance_defaults();
    if (o.n_probes < 1 || o.n_probes > 1024)
        return mcp_error("variance: n_probes must be in [1, 1024] (got %d)", o.n_probes);
    if (!(o.fd_delta > 0.0) || !isfinite(o.fd_delta))
        return mcp_error("variance: fd_delta must be > 0 (got %g)", o.fd_delta);
    if (mcp__check_dump("variance", dump)) return -1;
    if (!den) return mcp_error("variance: missing denoiser");
    int k = o.n_probes, rc = -1;
    mcp_image **v = mcp_calloc((size_t)k, sizeof *v),
              **jv = mcp_calloc((size_t)k, sizeof *jv);
    mcp_denoise_tangent *t = mcp_calloc((size_t)k, sizeof *t);
    mcp_image *f = NULL, *den_img = NULL, *abs_var = NULL, *rel_var = NULL;
    if (!v || !jv || !t) goto done;
    for (int j = 0; j < k; j++) {
        if (mcp_probe_rademacher(dump, o.seed, j, &v[j])) goto done;
        t[j].color = v[j];
    }
    mcp_denoise_input in = mcp_denoise_input_of(dump);
    if (mcp__jvp(den, &in, t, k, o.mc, o.fd_delta, &f, jv)) goto done;
    if (!f && den->apply(den, &in, &f)) {
        mcp_error_prefix("%s: ", den->name);
        goto done;
    }
    if ((o.relative && relative_denominator(f, &den_img)) ||
        mcp__variance_from_jvps((const mcp_image *const *)jv, k, MCP_METRIC_SE, 0.0,
                                den_img, &abs_var, o.relative ? &rel_var : NULL))
        goto done;
    if (o.relative) {
        *var = rel_var;
        rel_var = NULL;
    } else {
        *var = abs_var;
        abs_var = NULL;
    }
    if (denoised) {
        *denoised = f;
        f = NULL;
    }
    rc = 0;
done:
    if (v)
        for (int j = 0; j < k; j++)
            mcp_image_free(v[j]);
    if (jv)
        for (int j = 0; j < k; j++)
            mcp_image_free(jv[j]);
    free(v);
    free(jv);
    free(t);
    mcp_image_free(f);
    mcp_image_free(den_img);
    mcp_image_free(abs_var);
    mcp_image_free(rel_var);
    return rc;
}
