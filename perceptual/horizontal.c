/* horizontal.c: iterative minimisation in the horizontal search space -- pixel swaps
 * (docs/mathematics.md §4.9; Chizhov et al. 2022 Sec. 4.2, Alg. 2, Eq. 10b).
 *
 * One estimate Q per pixel; the search space is permutations pi, pixel p showing
 * Q(pi(p)) (and, once re-rendered, using pi(p)'s random seed). Energy
 *   E_d(pi) = E_C(pi(Q)) + |g|_1^2 sum_p d(p, pi(p)),
 * d = 0 when pi(p) lies within the travel limit r of p (max norm, so r = 1 is the 3x3
 * neighbourhood the paper likens to a 3x3 tile) and infinity beyond: swaps that would
 * carry a pixel further are never taken. Greedy: visit the pixels in serpentine order
 * and apply the swap within the (2R+1)^2 window that lowers E_d most; [T = 10] passes
 * or until one swaps nothing. A swap moves two pixels at once, so its dE has a cross
 * term <a_i, C a_j> (the kernel's autocorrelation away from the borders). E_C is the
 * model of model.c with Q_init = Q. */
#include "internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

int
mcp_perc_permute(const mcp_image *img, const mcp_image *map, mcp_image **out)
{
    int xy[2];
    *out = NULL;
    if (!mcp_image_same_size(map, img) ||
        mcp_image_channels(map, (const char *const[]){"X", "Y"}, 2, xy))
        return -1;
    int w = img->width, h = img->height;
    const char *src = map->source ? map->source : "permutation";
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *m = mcp_image_px(map, x, y);
            float sx = m[xy[0]], sy = m[xy[1]];
            if (!(sx >= 0.0f && sx < (float)w && sy >= 0.0f && sy < (float)h) ||
                sx != floorf(sx) || sy != floorf(sy))
                return mcp_error(
                    "%s: pixel %d, %d names source (%g, %g), not a pixel of the "
                    "%dx%d image",
                    src, x, y, sx, sy, w, h);
        }
    if (mcp_image_new(w, h, img->channels, (const char *const *)img->names, out))
        return -1;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *m = mcp_image_px(map, x, y);
            const float *s = mcp_image_px(img, (int)m[xy[0]], (int)m[xy[1]]);
            float *d = mcp_image_px(*out, x, y);
            for (int c = 0; c < img->channels; c++)
                d[c] = s[c];
        }
    return 0;
}

static int
cheb(int ax, int ay, int bx, int by)
{
    int dx = abs(ax - bx), dy = abs(ay - by);
    return dx > dy ? dx : dy;
}

typedef struct {
    const mcp__perc_state *s;
    double
        *auto_c; /* C <a_i, a_j> for interior i, j = i + d, |d| <= R; NULL with a map */
    int R;
} swapper;

static double
cross(const swapper *sw, int xi, int yi, int xj, int yj)
{
    const mcp__perc_state *s = sw->s;
    if (sw->auto_c && mcp__footprint_interior(&s->fp, xi, yi) &&
        mcp__footprint_interior(&s->fp, xj, yj))
        return sw->auto_c[(yj - yi + sw->R) * (2 * sw->R + 1) + xj - xi + sw->R];
    return mcp__state_cross(s, xi, yi, xj, yj);
}

/* dE of swapping i and j given <a_i, C r> (ci) and <a_i, C a_i> (ni); *mag receives
 * the size of the terms that make it up (for the acceptance threshold). */
static double
swap_delta(const swapper *sw, int xi, int yi, const double ci[3], double ni, int xj,
           int yj, double *mag)
{
    const mcp__perc_state *s = sw->s;
    size_t i = (size_t)yi * s->w + xi, j = (size_t)yj * s->w + xj;
    double cj[3], nj;
    mcp__state_corr(s, xj, yj, cj, &nj);
    double x = cross(sw, xi, yi, xj, yj), curv = ni + nj - 2.0 * x, de = 0.0, mg = 0.0;
    const double *oi = s->o + i * 3, *oj = s->o + j * 3;
    for (int c = 0; c < 3; c++) {
        double d = oj[c] - oi[c], lin = 2.0 * d * (ci[c] - cj[c]);
        de += lin + d * d * curv;
        mg += fabs(lin) + d * d * (ni + nj + 2.0 * fabs(x));
    }
    double ui = mcp__state_unary(s, i), uj = mcp__state_unary(s, j);
    if (ui != 0.0 || uj != 0.0)
        for (int c = 0; c < 3; c++) {
            double qi = s->qinit[i * 3 + c], qj = s->qinit[j * 3 + c];
            double a = ui * (oj[c] - qi) * (oj[c] - qi),
                   b = ui * (oi[c] - qi) * (oi[c] - qi);
            double e = uj * (oi[c] - qj) * (oi[c] - qj),
                   f = uj * (oj[c] - qj) * (oj[c] - qj);
            de += a - b + e - f;
            mg += a + b + e + f;
        }
    *mag = mg;
    return de;
}

int
mcp_perc_horizontal(const mcp_image *q, const mcp_image *surrogate,
                    const mcp_perc_options *opt, mcp_perc_result *out)
{
    static const char *const xy_names[] = {"X", "Y"};
    mcp_perc_options d = mcp_perc_defaults();
    if (!opt) opt = &d;
    memset(out, 0, sizeof *out);
    const mcp_image *qs[1] = {q};
    if (!surrogate) return mcp_error("horizontal: needs a surrogate");
    if (mcp__check_run(opt, qs, 1, surrogate)) return -1;
    double t0 = mcp__seconds();
    int w = q->width, h = q->height, R = opt->radius, travel = opt->travel, rc = -1;
    size_t n = (size_t)w * h;
    float *t_q = NULL, *t_surr = NULL;
    double *o = NULL;
    int *src = NULL;
    swapper sw = {.R = R};
    mcp__perc_state s;
    int have_state = 0;
    mcp_perc_result r = {0};
    if (mcp__rgb_tone(q, opt->model.tone_map, &t_q) ||
        mcp__rgb_tone(surrogate, opt->model.tone_map, &t_surr) ||
        !(o = mcp_malloc(n * 3 * sizeof *o)) || !(src = mcp_malloc(n * sizeof *src)))
        goto done;
    for (size_t i = 0; i < n * 3; i++)
        o[i] = t_q[i];
    if (mcp__state_init(&s, &opt->model, w, h, t_surr, t_q, o)) goto done;
    have_state = 1;
    if (!s.cmap) { /* the kernel's autocorrelation, for pairs away from the borders */
        int side = s.g.side, gr = s.g.r, win = 2 * R + 1;
        if (!(sw.auto_c = mcp_calloc((size_t)win * win, sizeof *sw.auto_c))) goto done;
        for (int dy = -R; dy <= R; dy++)
            for (int dx = -R; dx <= R; dx++) {
                double a = 0.0; /* sum_u g(u) g(u - d) */
                for (int uy = -gr; uy <= gr; uy++)
                    for (int ux = -gr; ux <= gr; ux++) {
                        int vx = ux - dx, vy = uy - dy;
                        if (abs(vx) <= gr && abs(vy) <= gr)
                            a += s.g.taps[(uy + gr) * side + ux + gr] *
                                 s.g.taps[(vy + gr) * side + vx + gr];
                    }
                sw.auto_c[(dy + R) * win + dx + R] = s.c * a;
            }
    }
    sw.s = &s;
    for (size_t p = 0; p < n; p++)
        src[p] = (int)p;
    r.energy_initial = s.energy;
    int max_passes = opt->passes > 0 ? opt->passes : 10;
    mcp__pass_bar bar;
    mcp__pass_bar_begin(&bar, opt->method, w, h);
    for (int pass = 0; pass < max_passes; pass++) {
        long swaps = 0;
        for (int y = 0; y < h; y++) {
            mcp__pass_bar_row(&bar, pass, y);
            int x0 = y % 2 ? w - 1 : 0, step = y % 2 ? -1 : 1; /* serpentine */
            for (int k = 0, x = x0; k < w; k++, x += step) {
                size_t i = (size_t)y * w + x;
                int si = src[i], six = si % w, siy = si / w, bx = -1, by = -1;
                double ci[3], ni, best = 0.0;
                mcp__state_corr(&s, x, y, ci, &ni);
                for (int yj = y - R; yj <= y + R; yj++)
                    for (int xj = x - R; xj <= x + R; xj++) {
                        if (xj < 0 || yj < 0 || xj >= w || yj >= h ||
                            (xj == x && yj == y))
                            continue;
                        int sj = src[(size_t)yj * w + xj];
                        if (cheb(x, y, sj % w, sj / w) > travel ||
                            cheb(xj, yj, six, siy) > travel)
                            continue; /* d = infinity: out of the travel limit */
                        double mag, de = swap_delta(&sw, x, y, ci, ni, xj, yj, &mag);
                        if (de < best && de < -MCP__ACCEPT_RTOL * mag)
                            best = de, bx = xj, by = yj;
                    }
                if (bx < 0) continue;
                size_t j = (size_t)by * w + bx;
                double oi[3], oj[3];
                memcpy(oi, s.o + i * 3, sizeof oi);
                memcpy(oj, s.o + j * 3, sizeof oj);
                mcp__state_set(&s, x, y, oj,
                               best); /* the energy moves by the swap's dE */
                mcp__state_set(&s, bx, by, oi, 0.0);
                int t = src[i];
                src[i] = src[j], src[j] = t;
                swaps++;
            }
        }
        r.passes++;
        r.changes += swaps;
        if (swaps == 0) break;
    }
    mcp__pass_bar_end(&bar);
    r.energy_final = s.energy;
    if (mcp_image_new(w, h, 2, xy_names, &r.permutation)) goto done;
    for (size_t p = 0; p < n; p++) {
        r.permutation->data[p * 2] = (float)(src[p] % w);
        r.permutation->data[p * 2 + 1] = (float)(src[p] / w);
    }
    mcp_image *q_rgb = NULL;
    int bad =
        mcp__rgb_image(q, &q_rgb) || mcp_perc_permute(q_rgb, r.permutation, &r.image);
    mcp_image_free(q_rgb);
    if (bad) goto done;
    r.seconds = mcp__seconds() - t0;
    *out = r;
    memset(&r, 0, sizeof r);
    rc = 0;
done:
    mcp_perc_result_free(&r);
    if (have_state) mcp__state_free(&s);
    free(t_q), free(t_surr), free(o), free(src), free(sw.auto_c);
    return rc;
}
