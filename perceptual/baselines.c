/* baselines.c: the a-posteriori methods of Heitz & Belcour 2019, for comparison
 * (docs/mathematics.md §4.10).
 *
 * histogram (vertical): sort a pixel's M estimates by luminance and take the one at
 *   index floor(B_p M) (B the blue-noise threshold in [0, 1)).
 * permutation (horizontal): in tiles of [8x8] (smaller at the right and bottom
 *   edges), sort the pixels by luminance and the positions by mask value; the
 *   position with the k-th smallest threshold takes the k-th darkest pixel's seed
 *   (and, in the prediction, its value).
 * Both sort by the luminance of the linear estimates, as the original (they know no
 * tone map); ties keep the lower index, so results are deterministic. */
#include "internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

int
mcp_perc_histogram(const mcp_image *const *cands, int m, const mcp_perc_options *opt,
                   mcp_perc_result *out)
{
    mcp_perc_options d = mcp_perc_defaults();
    if (!opt) opt = &d;
    memset(out, 0, sizeof *out);
    if (mcp__check_run(opt, cands, m, NULL)) return -1;
    double t0 = mcp__seconds();
    int w = cands[0]->width, h = cands[0]->height, rc = -1;
    size_t n = (size_t)w * h;
    int *rgb = mcp_malloc((size_t)m * 3 * sizeof *rgb);
    int *choice = mcp_malloc(n * sizeof *choice);
    const mcp_image *mask = NULL;
    mcp_image *owned = NULL;
    mcp_perc_result r = {0};
    if (!rgb || !choice || mcp__check_candidates(cands, m, NULL, rgb) ||
        mcp__mask(opt, &mask, &owned))
        goto done;
    int failed = 0;
#pragma omp parallel reduction(+ : failed) if (n >= 16384)
    {
        int *order = mcp_malloc((size_t)m * sizeof *order);
        float *lum = mcp_malloc((size_t)m * sizeof *lum);
        failed += !order || !lum;
#pragma omp for
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w && order && lum; x++) {
                for (int j = 0; j < m; j++) { /* insertion sort: M is small, and stable */
                    const float *p = mcp_image_px(cands[j], x, y);
                    float l = mcp_luminance(p[rgb[3 * j]], p[rgb[3 * j + 1]],
                                            p[rgb[3 * j + 2]]);
                    int i = j;
                    for (; i > 0 && lum[i - 1] > l; i--)
                        lum[i] = lum[i - 1], order[i] = order[i - 1];
                    lum[i] = l, order[i] = j;
                }
                int k = (int)(mcp__mask_at(mask, x, y) * m);
                choice[(size_t)y * w + x] = order[k < m ? k : m - 1];
            }
        free(order);
        free(lum);
    }
    if (failed) {
        mcp_error("histogram: out of memory");
        goto done;
    }
    if (mcp__pick_image(cands, m, choice, &r.image) ||
        mcp__index_image(w, h, choice, &r.index))
        goto done;
    r.passes = 1;
    r.energy_initial = r.energy_final = NAN;
    r.seconds = mcp__seconds() - t0;
    *out = r;
    memset(&r, 0, sizeof r);
    rc = 0;
done:
    mcp_perc_result_free(&r);
    mcp_image_free(owned);
    free(rgb), free(choice);
    return rc;
}

typedef struct {
    float key;
    int index;
} keyed;

static int
by_key(const void *a, const void *b)
{
    const keyed *p = a, *q = b;
    if (p->key != q->key) return p->key < q->key ? -1 : 1;
    return (p->index > q->index) - (p->index < q->index);
}

int
mcp_perc_permutation(const mcp_image *q, const mcp_perc_options *opt,
                     mcp_perc_result *out)
{
    static const char *const xy_names[] = {"X", "Y"};
    mcp_perc_options d = mcp_perc_defaults();
    if (!opt) opt = &d;
    memset(out, 0, sizeof *out);
    const mcp_image *qs[1] = {q};
    if (mcp__check_run(opt, qs, 1, NULL)) return -1;
    double t0 = mcp__seconds();
    int w = q->width, h = q->height, tile = opt->tile, rgb[3], rc = -1;
    const mcp_image *mask = NULL;
    mcp_image *owned = NULL;
    mcp_perc_result r = {0};
    keyed *pix = mcp_malloc((size_t)tile * tile * sizeof *pix);
    keyed *pos = mcp_malloc((size_t)tile * tile * sizeof *pos);
    if (!pix || !pos || mcp_rgb_channels(q, rgb) || mcp__mask(opt, &mask, &owned) ||
        mcp_image_new(w, h, 2, xy_names, &r.permutation))
        goto done;
    for (int ty = 0; ty < h; ty += tile)
        for (int tx = 0; tx < w; tx += tile) {
            int tw = tx + tile <= w ? tile : w - tx, th = ty + tile <= h ? tile : h - ty,
                k = 0;
            for (int y = ty; y < ty + th; y++)
                for (int x = tx; x < tx + tw; x++, k++) {
                    const float *p = mcp_image_px(q, x, y);
                    pix[k] = (keyed){mcp_luminance(p[rgb[0]], p[rgb[1]], p[rgb[2]]), k};
                    pos[k] = (keyed){mcp__mask_at(mask, x, y), k};
                }
            qsort(pix, (size_t)k, sizeof *pix, by_key);
            qsort(pos, (size_t)k, sizeof *pos, by_key);
            for (int i = 0; i < k; i++) {
                int dst = pos[i].index, src = pix[i].index;
                float *m = mcp_image_px(r.permutation, tx + dst % tw, ty + dst / tw);
                m[0] = (float)(tx + src % tw), m[1] = (float)(ty + src / tw);
            }
        }
    mcp_image *q_rgb = NULL;
    int bad =
        mcp__rgb_image(q, &q_rgb) || mcp_perc_permute(q_rgb, r.permutation, &r.image);
    mcp_image_free(q_rgb);
    if (bad) goto done;
    r.passes = 1;
    r.changes = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *m = mcp_image_px(r.permutation, x, y);
            r.changes += m[0] != (float)x || m[1] != (float)y;
        }
    r.energy_initial = r.energy_final = NAN;
    r.seconds = mcp__seconds() - t0;
    *out = r;
    memset(&r, 0, sizeof r);
    rc = 0;
done:
    mcp_perc_result_free(&r);
    mcp_image_free(owned);
    free(pix), free(pos);
    return rc;
}
