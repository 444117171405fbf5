/* dither.c: threshold dithering in the vertical search space with a blue-noise mask
 * (SPEC "perceptual"; Chizhov et al. 2022 Alg. 1 lines 16-23).
 *
 * On luminance: s = lum(T(I'_p)), l_j = lum(T(Q_j)); lower = the candidate with the
 * largest l_j <= s, upper = the one with the smallest l_j > s (ties: the first); take
 * lower when s - l_lower < B_p (l_upper - l_lower), else upper; where only one exists,
 * take it. No sorting: one scan per pixel. B is the void-and-cluster mask, tiled.
 * Luminance is taken of the tone-mapped colour, in the model's display space. */
#include "internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

int
mcp_perc_dither(const mcp_image *const *cands, int m, const mcp_image *surrogate,
                const mcp_perc_options *opt, mcp_perc_result *out)
{
    static const char *const rgb_names[] = {"R", "G", "B"}, *const idx_names[] = {
                                                                "index"};
    mcp_perc_options d = mcp_perc_defaults();
    if (!opt) opt = &d;
    memset(out, 0, sizeof *out);
    if (!surrogate) return mcp_error("dither: needs a surrogate");
    if (mcp__check_run(opt, cands, m, surrogate)) return -1;
    double t0 = mcp__seconds();
    int w = cands[0]->width, h = cands[0]->height, rc = -1, srgb[3];
    int *rgb = mcp_malloc((size_t)m * 3 * sizeof *rgb);
    const mcp_image *mask = NULL;
    mcp_image *owned = NULL;
    mcp_perc_result r = {0};
    if (!rgb || mcp__check_candidates(cands, m, NULL, rgb) ||
        mcp_rgb_channels(surrogate, srgb) || mcp__mask(opt, &mask, &owned) ||
        mcp_image_new(w, h, 3, rgb_names, &r.image) ||
        mcp_image_new(w, h, 1, idx_names, &r.index))
        goto done;
    mcp_tonemap tm = opt->model.tone_map;
    long n_bad = 0;
    int failed = 0;
#pragma omp parallel reduction(+ : n_bad, failed) if ((size_t)w * h >= 16384)
    {
        /* luminances, with sentinels -inf (no lower yet) at m and +inf at m + 1 */
        float *lum = malloc(((size_t)m + 2) * sizeof *lum);
        failed += !lum;
#pragma omp for
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w && lum; x++) {
                const float *sp = mcp_image_px(surrogate, x, y);
                n_bad += !isfinite(sp[srgb[0]]) + !isfinite(sp[srgb[1]]) +
                         !isfinite(sp[srgb[2]]);
                float s =
                    mcp_luminance(mcp__tone(tm, sp[srgb[0]]), mcp__tone(tm, sp[srgb[1]]),
                                  mcp__tone(tm, sp[srgb[2]]));
                lum[m] = -INFINITY, lum[m + 1] = INFINITY;
                int lo = m, hi = m + 1;
                /* index updates by masks, not branches: which candidate brackets s is
                 * data-dependent, and mispredictions would dominate the scan */
                for (int j = 0; j < m; j++) {
                    const float *cp = mcp_image_px(cands[j], x, y);
                    const int *k = rgb + 3 * j;
                    n_bad +=
                        !isfinite(cp[k[0]]) + !isfinite(cp[k[1]]) + !isfinite(cp[k[2]]);
                    float l =
                        mcp_luminance(mcp__tone(tm, cp[k[0]]), mcp__tone(tm, cp[k[1]]),
                                      mcp__tone(tm, cp[k[2]]));
                    lum[j] = l;
                    int le = l <= s, a = le & (l > lum[lo]), b = !le & (l < lum[hi]);
                    lo += (j - lo) & -a;
                    hi += (j - hi) & -b;
                }
                int pick;
                if (lo == m) /* only an upper one (or NaNs everywhere: reported below) */
                    pick = hi == m + 1 ? 0 : hi;
                else if (hi == m + 1)
                    pick = lo;
                else {
                    int take_lo =
                        s - lum[lo] < mcp__mask_at(mask, x, y) * (lum[hi] - lum[lo]);
                    pick = hi + ((lo - hi) & -take_lo);
                }
                const float *cp = mcp_image_px(cands[pick], x, y);
                float *o = r.image->data + ((size_t)y * w + x) * 3;
                o[0] = cp[rgb[3 * pick]], o[1] = cp[rgb[3 * pick + 1]];
                o[2] = cp[rgb[3 * pick + 2]];
                r.index->data[(size_t)y * w + x] = (float)pick;
            }
        free(lum);
    }
    if (failed) {
        mcp_error("dither: out of memory");
        goto done;
    }
    if (n_bad) {
        mcp_error("dither: the inputs hold %ld non-finite values", n_bad);
        goto done;
    }
    r.passes = 1;
    r.energy_initial = r.energy_final = NAN; /* mcp_perc_energy computes it */
    r.seconds = mcp__seconds() - t0;
    *out = r;
    memset(&r, 0, sizeof r);
    rc = 0;
done:
    mcp_perc_result_free(&r);
    mcp_image_free(owned);
    free(rgb);
    return rc;
}
