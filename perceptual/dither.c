/* dither.c: threshold dithering in the vertical search space with a blue-noise mask
 * (docs/mathematics.md §4.8; Chizhov et al. 2022 Alg. 1 lines 16-23).
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
#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
#include <emmintrin.h>
#endif

/* The pick at one pixel: lo, the candidate with the largest luminance <= s, and hi,
 * the one with the smallest > s (the first on ties); lo when s - l_lo < B (l_hi -
 * l_lo), else hi; where only one exists, it; 0 when none does (NaNs: reported by the
 * caller). l[j * stride] are the candidates' luminances, B the threshold. */
static int
pick_one(const float *l, size_t stride, int m, float s, float threshold)
{
    int lo = -1, hi = -1;
    float l_lo = -INFINITY, l_hi = INFINITY;
    for (int j = 0; j < m; j++) {
        float v = l[(size_t)j * stride];
        int le = v <= s, a = le & (v > l_lo), b = !le & (v < l_hi);
        lo = a ? j : lo, l_lo = a ? v : l_lo;
        hi = b ? j : hi, l_hi = b ? v : l_hi;
    }
    if (lo < 0) return hi < 0 ? 0 : hi;
    if (hi < 0) return lo;
    return s - l_lo < threshold * (l_hi - l_lo) ? lo : hi;
}

#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
static inline __m128
select_ps(__m128 mask, __m128 a, __m128 b)
{
    return _mm_or_ps(_mm_and_ps(mask, a), _mm_andnot_ps(mask, b));
}

static inline __m128i
select_epi32(__m128i mask, __m128i a, __m128i b)
{
    return _mm_or_si128(_mm_and_si128(mask, a), _mm_andnot_si128(mask, b));
}
#endif

/* pick_one for a row: ls[x] the surrogate's luminances, thr[x] the thresholds. Four
 * pixels at a time in SSE2, with masks for the comparisons (which candidates bracket
 * s, and the threshold test, are coin tosses a branch would mispredict), the same
 * float operations as pick_one. */
static void
pick_row(const float *lum, size_t stride, int m, const float *ls, const float *thr, int w,
         int *pick)
{
    int x = 0;
#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
    const __m128i none = _mm_set1_epi32(-1), zero = _mm_setzero_si128();
    for (; x + 4 <= w; x += 4) {
        __m128 s = _mm_loadu_ps(ls + x), l_lo = _mm_set1_ps(-INFINITY),
               l_hi = _mm_set1_ps(INFINITY);
        __m128i lo = none, hi = none;
        for (int j = 0; j < m; j++) {
            __m128 v = _mm_loadu_ps(lum + (size_t)j * stride + x);
            __m128 le = _mm_cmple_ps(v, s);
            __m128 a = _mm_and_ps(le, _mm_cmpgt_ps(v, l_lo));
            __m128 b = _mm_andnot_ps(le, _mm_cmplt_ps(v, l_hi));
            __m128i jv = _mm_set1_epi32(j);
            l_lo = select_ps(a, v, l_lo), l_hi = select_ps(b, v, l_hi);
            lo = select_epi32(_mm_castps_si128(a), jv, lo);
            hi = select_epi32(_mm_castps_si128(b), jv, hi);
        }
        __m128 below =
            _mm_cmplt_ps(_mm_sub_ps(s, l_lo),
                         _mm_mul_ps(_mm_loadu_ps(thr + x), _mm_sub_ps(l_hi, l_lo)));
        __m128i has_lo = _mm_cmpgt_epi32(lo, none), no_hi = _mm_cmplt_epi32(hi, zero);
        __m128i take_lo =
            _mm_and_si128(has_lo, _mm_or_si128(no_hi, _mm_castps_si128(below)));
        __m128i upper = _mm_andnot_si128(no_hi, hi); /* hi, or 0 without one */
        _mm_storeu_si128((__m128i *)(pick + x), select_epi32(take_lo, lo, upper));
    }
#endif
    for (; x < w; x++)
        pick[x] = pick_one(lum + x, stride, m, ls[x], thr[x]);
}

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
        /* a row at a time: T and luminance of the surrogate (lum[m]) and of every
         * candidate (lum[j]) in contiguous loops, then the selection per pixel */
        float *tone = mcp_malloc((size_t)w * 3 * sizeof *tone);
        /* rows apart by an odd number of cache lines: at a power-of-two distance the
         * loads of one pixel's luminances would contend for the same cache set */
        size_t lstride = ((size_t)w + 15) / 16 * 16 + 16;
        float *lum = mcp_malloc(((size_t)m + 1) * lstride * sizeof *lum);
        float *thr = mcp_malloc((size_t)w * sizeof *thr);
        int *pick = mcp_malloc((size_t)w * sizeof *pick);
        int ok = tone && lum && thr && pick;
        failed += !ok;
#pragma omp for schedule(static)
        for (int y = 0; y < h; y++) {
            if (!ok) continue;
            for (int j = 0; j <= m; j++) {
                const mcp_image *img = j < m ? cands[j] : surrogate;
                n_bad += mcp__tone_row(img, j < m ? rgb + 3 * j : srgb, y, tm, tone);
                float *l = lum + (size_t)j * lstride;
                for (int x = 0; x < w; x++)
                    l[x] = mcp_luminance(tone[3 * x], tone[3 * x + 1], tone[3 * x + 2]);
            }
            /* the mask's row, tiled across the image */
            const float *brow = mcp_image_px(mask, 0, y % mask->height);
            for (int x = 0, mx = 0; x < w; x++, mx = mx + 1 == mask->width ? 0 : mx + 1)
                thr[x] = brow[mx * mask->pixel_stride];
            pick_row(lum, lstride, m, lum + (size_t)m * lstride, thr, w, pick);
            float *o = r.image->data + (size_t)y * w * 3;
            float *idx = r.index->data + (size_t)y * w;
            for (int x = 0; x < w; x++) {
                const float *cp = mcp_image_px(cands[pick[x]], x, y);
                const int *k = rgb + 3 * pick[x];
                o[3 * x] = cp[k[0]], o[3 * x + 1] = cp[k[1]], o[3 * x + 2] = cp[k[2]];
                idx[x] = (float)pick[x];
            }
        }
        free(tone), free(lum), free(thr), free(pick);
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
