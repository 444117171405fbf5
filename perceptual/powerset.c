/* powerset.c: the power-set search space (docs/mathematics.md §4.5: the means of all 2^M
 * - 1 non-empty subsets of the M per-pixel estimates, capped by max_subsets; Chizhov et
 * al. 2022 Sec. 4.3) searched by the vertical iterative minimisation.
 *
 * Under a cap, the subsets kept are the M single estimates, the mean of all M, then
 * pairs, triples, ... each size in lexicographic order: the singles give the plain
 * vertical method's space, the full mean the 'mean' start, and small subsets keep the
 * most variety per candidate. */
#include "internal.h"

#include <stdlib.h>
#include <string.h>

int
mcp_perc_subset_masks(int m, int max_subsets, uint64_t *masks, int *count)
{
    if (m < 1 || m > 63)
        return mcp_error("power set: candidates must number 1 to 63 (got %d)", m);
    if (max_subsets < 1)
        return mcp_error("power set: max_subsets must be >= 1 (got %d)", max_subsets);
    int k = 0;
#define PUSH(mask)                                                                       \
    do {                                                                                 \
        if (k < max_subsets) {                                                           \
            if (masks) masks[k] = (mask);                                                \
            k++;                                                                         \
        }                                                                                \
    } while (0)
    for (int i = 0; i < m; i++)
        PUSH(1ull << i);
    if (m > 1) PUSH((1ull << m) - 1);
    int idx[64];
    for (int size = 2; size < m && k < max_subsets; size++) {
        for (int i = 0; i < size; i++)
            idx[i] = i;
        for (;;) { /* combinations of `size` out of m, in lexicographic order */
            uint64_t mask = 0;
            for (int i = 0; i < size; i++)
                mask |= 1ull << idx[i];
            PUSH(mask);
            if (k >= max_subsets) break;
            int i = size - 1;
            while (i >= 0 && idx[i] == m - size + i)
                i--;
            if (i < 0) break;
            idx[i]++;
            for (int j = i + 1; j < size; j++)
                idx[j] = idx[j - 1] + 1;
        }
    }
#undef PUSH
    *count = k;
    return 0;
}

/* The linear mean of subset `mask` at pixel p, in double summed in candidate order
 * (the search space and the output must use the very same values). */
static void
subset_mean(const mcp_image *const *cands, const int *rgb, int x, int y, uint64_t mask,
            float out[3])
{
    double s[3] = {0.0, 0.0, 0.0};
    int count = 0;
    for (int j = 0; mask >> j; j++) {
        if (!((mask >> j) & 1)) continue;
        const float *p = mcp_image_px(cands[j], x, y);
        s[0] += p[rgb[3 * j]], s[1] += p[rgb[3 * j + 1]], s[2] += p[rgb[3 * j + 2]];
        count++;
    }
    for (int c = 0; c < 3; c++)
        out[c] = (float)(s[c] / count);
}

int
mcp_perc_power_set(const mcp_image *const *cands, int m, const mcp_image *surrogate,
                   const mcp_perc_options *opt, mcp_perc_result *out)
{
    mcp_perc_options d = mcp_perc_defaults();
    if (!opt) opt = &d;
    memset(out, 0, sizeof *out);
    if (!surrogate) return mcp_error("power-set: needs a surrogate");
    int *rgb = NULL, *choice = NULL, *start = NULL, k = 0, rc = -1;
    uint64_t *masks = NULL;
    float *t = NULL, *t_surr = NULL, *mean = NULL, *t_mean = NULL, *lin = NULL;
    size_t n = 0, total;
    mcp_perc_result r = {0};
    double t0 = mcp__seconds();
    if (mcp__check_run(opt, cands, m, surrogate) || mcp_perc_subset_masks(m, 1, NULL, &k))
        return -1;
    int w = cands[0]->width, h = cands[0]->height;
    n = (size_t)w * h;
    int cap = opt->max_subsets;
    if ((uint64_t)cap > (1ull << m) - 1) cap = (int)((1ull << m) - 1);
    if (mcp_size_mul3(n, (size_t)cap, 3, &total))
        return mcp_error("power-set: %d subsets of %dx%d are too many", cap, w, h);
    if (!(rgb = mcp_malloc((size_t)m * 3 * sizeof *rgb)) ||
        !(masks = mcp_malloc((size_t)cap * sizeof *masks)) ||
        mcp__check_candidates(cands, m, NULL, rgb) ||
        mcp_perc_subset_masks(m, cap, masks, &k) ||
        !(t = mcp_malloc(total * sizeof *t)) ||
        !(choice = mcp_malloc(n * sizeof *choice)))
        goto done;
    /* the search space: T of every subset mean, pixel-major [n][k][3] */
    mcp_tonemap tm = opt->model.tone_map;
#pragma omp parallel for if (n * k >= 65536)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t p = (size_t)y * w + x;
            for (int s = 0; s < k; s++) {
                float v[3], *dst = t + (p * k + s) * 3;
                subset_mean(cands, rgb, x, y, masks[s], v);
                dst[0] = mcp__tone(tm, v[0]), dst[1] = mcp__tone(tm, v[1]);
                dst[2] = mcp__tone(tm, v[2]);
            }
        }
    int full = -1; /* the mean of all candidates, when kept */
    for (int s = 0; s < k; s++)
        if (masks[s] == (1ull << m) - 1) full = s;
    if (opt->init == MCP_PERC_INIT_MEAN && full >= 0) {
        if (!(start = mcp_malloc(n * sizeof *start))) goto done;
        for (size_t p = 0; p < n; p++)
            start[p] = full;
    }
    if (mcp__rgb_tone(surrogate, tm, &t_surr) || mcp__mean_rgb(cands, m, &mean) ||
        mcp__tone_rgb(mean, n, tm, &t_mean) ||
        mcp__vertical_iterate(opt, w, h, k, t, t_surr, t_mean, start, choice, &r) ||
        !(lin = mcp_malloc(n * 3 * sizeof *lin)))
        goto done;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t p = (size_t)y * w + x;
            subset_mean(cands, rgb, x, y, masks[choice[p]], lin + p * 3);
        }
    if (mcp__image_from_rgb(w, h, lin, &r.image) ||
        mcp__index_image(w, h, choice, &r.index))
        goto done;
    r.seconds = mcp__seconds() - t0;
    *out = r;
    memset(&r, 0, sizeof r);
    rc = 0;
done:
    mcp_perc_result_free(&r);
    free(rgb), free(masks), free(t), free(t_surr), free(mean), free(t_mean), free(lin);
    free(choice), free(start);
    return rc;
}
