/* surrogate.c: surrogates for the ground truth (docs/mathematics.md §4.3: I' is a
 * denoised average, any image the user gives, or the ground truth for best-case studies;
 * Chizhov et al. 2022 Sec. 5.1, 7.1). The user's image and the truth need no code;
 * this builds the candidates' mean and its denoised version. */
#include "internal.h"

#include <stdlib.h>
#include <string.h>

int
mcp_perc_mean(const mcp_image *const *cands, int m, mcp_image **out)
{
    float *mean = NULL;
    *out = NULL;
    if (mcp__mean_rgb(cands, m, &mean)) return -1;
    int rc = mcp__image_from_rgb(cands[0]->width, cands[0]->height, mean, out);
    free(mean);
    if (!rc && mcp_image_set_source(*out, "candidates' mean")) {
        mcp_image_free(*out);
        *out = NULL;
        rc = -1;
    }
    return rc;
}

/* The variance of the mean from the spread of the m candidates: sum (x - mean)^2 /
 * ((m - 1) m), for denoisers that weigh by the noise level. */
static int
variance_of_mean(const mcp_image *const *cands, int m, const mcp_image *mean,
                 mcp_image **out)
{
    static const char *const names[] = {"R", "G", "B"};
    int *rgb = mcp_malloc((size_t)m * 3 * sizeof *rgb);
    *out = NULL;
    if (!rgb || mcp__check_candidates(cands, m, NULL, rgb) ||
        mcp_image_new(mean->width, mean->height, 3, names, out)) {
        free(rgb);
        return -1;
    }
    int w = mean->width, h = mean->height;
#pragma omp parallel for if ((size_t)w * h >= 65536)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int c = 0; c < 3; c++) {
                double mu = mcp_image_px(mean, x, y)[c], s = 0.0;
                for (int j = 0; j < m; j++) {
                    double d = mcp_image_px(cands[j], x, y)[rgb[3 * j + c]] - mu;
                    s += d * d;
                }
                mcp_image_px(*out, x, y)[c] = (float)(s / ((double)(m - 1) * m));
            }
    free(rgb);
    return 0;
}

int
mcp_perc_surrogate_denoise(const mcp_image *const *cands, int m, const mcp_image *albedo,
                           const mcp_image *normal, const mcp_denoiser *den,
                           mcp_image **out)
{
    *out = NULL;
    if (!den) return mcp_error("surrogate: no denoiser given");
    mcp_image *mean = NULL, *var = NULL;
    if (mcp_perc_mean(cands, m, &mean) ||
        (m > 1 && variance_of_mean(cands, m, mean, &var))) {
        mcp_image_free(mean);
        return -1;
    }
    mcp_denoise_input in;
    memset(&in, 0, sizeof in); /* fields added later stay NULL */
    in.color = mean;
    in.albedo = albedo;
    in.normal = normal;
    in.variance = var;
    int rc = den->apply(den, &in, out);
    if (rc)
        mcp_error_prefix("surrogate: denoiser '%s': ", den->name ? den->name : "?");
    else if (mcp_image_set_source(*out, "denoised mean")) {
        mcp_image_free(*out);
        *out = NULL;
        rc = -1;
    }
    mcp_image_free(var);
    mcp_image_free(mean);
    return rc;
}
