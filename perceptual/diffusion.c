/* diffusion.c: error diffusion in the vertical search space (SPEC "perceptual";
 * Chizhov et al. 2022 Alg. 1 lines 8-15; Floyd & Steinberg 1976).
 *
 * O := I' (the surrogate); serpentine scan; each pixel takes the candidate nearest
 * (squared RGB distance) to its current value, and the difference is pushed to the
 * unvisited neighbours with weights 7/16 (ahead), 3/16 (below behind), 5/16 (below)
 * and 1/16 (below ahead), mirrored on rows scanned right to left. Weights that fall
 * outside the image are dropped, not renormalised. Values live in display space T,
 * the space of the error model (with T = none this is plain linear RGB).
 *
 * The scan is serial; what does not depend on it (tone-mapping the candidates and the
 * surrogate) is done for blocks of rows in parallel beforehand. Two rows of
 * accumulated error are kept. */
#include "internal.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define BLOCK 16 /* rows tone-mapped at once, in parallel, before their serial scan */

/* T of row y of img's channels ch into dst[x][3]; returns the count of non-finite
 * values. Packed RGB rows, the common case, are one contiguous (vectorised) loop. */
static long
tone_row(const mcp_image *img, const int ch[3], int y, mcp_tonemap tm, float *dst)
{
    int w = img->width;
    long bad = 0;
    const float *src = mcp_image_px(img, 0, y);
    if (img->pixel_stride == 3 && ch[0] == 0 && ch[1] == 1 && ch[2] == 2) {
        /* omp simd: -O2's cheap vectoriser leaves these scalar */
#pragma omp simd reduction(+ : bad)
        for (int i = 0; i < 3 * w; i++)
            bad += !(fabsf(src[i]) <= FLT_MAX);
        if (tm == MCP_TONEMAP_CLAMP) /* unswitched, so that it vectorises */
#pragma omp simd
            for (int i = 0; i < 3 * w; i++)
                dst[i] = src[i] > 0.0f ? (src[i] < 1.0f ? src[i] : 1.0f) : 0.0f;
        else if (tm == MCP_TONEMAP_NONE)
            memcpy(dst, src, (size_t)w * 3 * sizeof *dst);
        else
            for (int i = 0; i < 3 * w; i++)
                dst[i] = mcp__tone(tm, src[i]);
        return bad;
    }
    for (int x = 0; x < w; x++)
        for (int c = 0; c < 3; c++) {
            float v = src[x * img->pixel_stride + ch[c]];
            bad += !isfinite(v);
            dst[x * 3 + c] = mcp__tone(tm, v);
        }
    return bad;
}

int
mcp_perc_error_diffusion(const mcp_image *const *cands, int m, const mcp_image *surrogate,
                         const mcp_perc_options *opt, mcp_perc_result *out)
{
    mcp_perc_options d = mcp_perc_defaults();
    if (!opt) opt = &d;
    memset(out, 0, sizeof *out);
    if (!surrogate) return mcp_error("error-diffusion: needs a surrogate");
    if (mcp__check_run(opt, cands, m, surrogate)) return -1;
    double t0 = mcp__seconds();
    int w = cands[0]->width, h = cands[0]->height, rc = -1, srgb[3];
    int *rgb = mcp_malloc((size_t)m * 3 * sizeof *rgb);
    /* the error pushed down to this row, this row plus it, and the row's errors */
    double *below = mcp_calloc((size_t)w * 3, sizeof *below);
    double *base = mcp_malloc((size_t)w * 3 * sizeof *base);
    double *e = mcp_calloc((size_t)(w + 2) * 3, sizeof *e);
    /* a block of rows prepared in parallel: T(I') [row][x][3] and T(Q_j)
     * [row][j][x][3], each candidate's row contiguous */
    size_t row3 = (size_t)w * 3;
    float *sv = mcp_malloc((size_t)BLOCK * row3 * sizeof *sv);
    float *tv = mcp_malloc((size_t)BLOCK * m * row3 * sizeof *tv);
    int *choice = mcp_malloc((size_t)w * h * sizeof *choice);
    mcp_perc_result r = {0};
    if (!rgb || !below || !base || !e || !sv || !tv || !choice ||
        mcp__check_candidates(cands, m, NULL, rgb) || mcp_rgb_channels(surrogate, srgb))
        goto done;
    mcp_tonemap tm = opt->model.tone_map;
    long n_bad = 0;
    for (int y0 = 0; y0 < h; y0 += BLOCK) {
        int y1 = y0 + BLOCK < h ? y0 + BLOCK : h;
#pragma omp parallel for reduction(+ : n_bad) if ((size_t)w * m >= 4096)
        for (int k = 0; k < (y1 - y0) * (m + 1); k++) {
            int y = y0 + k / (m + 1), j = k % (m + 1) - 1; /* j = -1: the surrogate */
            const mcp_image *img = j < 0 ? surrogate : cands[j];
            const int *ch = j < 0 ? srgb : rgb + 3 * j;
            float *dst = j < 0 ? sv + (size_t)(y - y0) * row3
                               : tv + ((size_t)(y - y0) * m + j) * row3;
            n_bad += tone_row(img, ch, y, tm, dst);
        }
        for (int y = y0; y < y1; y++) {
            const float *srow = sv + (size_t)(y - y0) * row3;
            const float *trow = tv + (size_t)(y - y0) * m * row3;
            int x0 = y % 2 ? w - 1 : 0, dx = y % 2 ? -1 : 1;
            /* what the row above pushed down, added outside the serial chain */
#pragma omp simd
            for (size_t i = 0; i < row3; i++)
                base[i] = srow[i] + below[i];
            /* the serial scan: the 7/16 share for the pixel ahead stays in a0..a2, the
             * shares for the next row wait in e until the row is done */
            double a0 = 0.0, a1 = 0.0, a2 = 0.0; /* scalars: kept in registers */
            for (int i = 0, x = x0; i < w; i++, x += dx) {
                double v0 = base[x * 3] + a0, v1 = base[x * 3 + 1] + a1,
                       v2 = base[x * 3 + 2] + a2;
                /* the nearest candidate, without branches: the choice is data-dependent
                 * and a mispredicted branch per candidate would dominate the scan */
                int best = 0;
                double best_d = INFINITY;
                for (int j = 0; j < m; j++) {
                    const float *t = trow + (size_t)j * row3 + x * 3;
                    double d0 = v0 - t[0], d1 = v1 - t[1], d2 = v2 - t[2];
                    double d = d0 * d0 + d1 * d1 + d2 * d2;
                    int lt = d < best_d;
                    best += (j - best) & -lt;
                    best_d = lt ? d : best_d;
                }
                const float *bt = trow + (size_t)best * row3 + x * 3;
                double *ex = e + (x + 1) * 3;
                ex[0] = v0 - bt[0], ex[1] = v1 - bt[1], ex[2] = v2 - bt[2];
                a0 = ex[0] * (7.0 / 16.0), a1 = ex[1] * (7.0 / 16.0),
                a2 = ex[2] * (7.0 / 16.0);
                choice[(size_t)y * w + x] = best;
            }
            /* the next row receives 1/16 from the pixel behind, 5/16 from the one above
             * and 3/16 from the one ahead, summed in the order the scan made them (e is
             * padded by a zero pixel at each end: shares beyond the image are dropped) */
            const double *eb = e + 3 - 3 * dx, *ec = e + 3, *ea = e + 3 + 3 * dx;
#pragma omp simd
            for (size_t i = 0; i < row3; i++)
                below[i] =
                    eb[i] * (1.0 / 16.0) + ec[i] * (5.0 / 16.0) + ea[i] * (3.0 / 16.0);
        }
    }
    /* the chosen candidates' linear values, in parallel after the scan */
    if (!n_bad && (mcp__pick_image(cands, m, choice, &r.image) ||
                   mcp__index_image(w, h, choice, &r.index)))
        goto done;
    if (n_bad) {
        mcp_error("error-diffusion: the inputs hold %ld non-finite values", n_bad);
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
    free(rgb), free(below), free(base), free(e), free(sv), free(tv), free(choice);
    return rc;
}
