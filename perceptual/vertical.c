/* vertical.c: iterative minimisation in the vertical search space by direct binary
 * search (docs/mathematics.md §4.6; Chizhov et al. 2022 Alg. 1 lines
 * 1-7, Analoui & Allebach 1992).
 *
 * Start from a random candidate per pixel (seeded by (seed, pixel)) or from the
 * candidates' mean, visit the pixels in serpentine order and give each the candidate
 * that lowers E_C most; repeat until a pass changes nothing or T passes have run. The
 * residual r = g * T(O) - h * T(I') makes every candidate O(1) once <a_p, C r> is
 * known (O(|g|) per visit) and an accepted change O(|g|) (internal.h). A pixel that
 * starts at the mean (not a candidate) always takes its best candidate; elsewhere a
 * change must beat rounding (MCP__ACCEPT_RTOL), so passes cannot cycle. */
#include "internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* One visit of pixel (x, y): the best candidate and its dE; returns -1 to keep. */
static int
best_candidate(const mcp__perc_state *s, int x, int y, int m, const float *tp, int cur,
               double *best_de)
{
    size_t p = (size_t)y * s->w + x;
    double corr[3], n2;
    mcp__state_corr_fast(s, x, y, corr, &n2);
    double u = mcp__state_unary(s, p);
    const double *o = s->o + p * 3;
    const float *qi = s->qinit ? s->qinit + p * 3 : NULL;
    double unary_now = 0.0;
    if (u != 0.0)
        for (int c = 0; c < 3; c++)
            unary_now += (o[c] - qi[c]) * (o[c] - qi[c]);
    int best = -1;
    double best_v = cur >= 0 ? 0.0 : INFINITY;
    for (int j = 0; j < m; j++) {
        if (j == cur) continue;
        const float *t = tp + (size_t)j * 3;
        double de = 0.0, mag = 0.0;
        for (int c = 0; c < 3; c++) {
            double d = t[c] - o[c], lin = 2.0 * d * corr[c], quad = d * d * n2;
            de += lin + quad;
            mag += fabs(lin) + quad;
        }
        if (u != 0.0) {
            double un = 0.0;
            for (int c = 0; c < 3; c++) {
                double d = (double)t[c] - qi[c]; /* in double, as everywhere in E */
                un += d * d;
            }
            de += u * (un - unary_now);
            mag += u * (un + unary_now);
        }
        if (de < best_v && (cur < 0 || de < -MCP__ACCEPT_RTOL * mag)) {
            best_v = de;
            best = j;
        }
    }
    *best_de = best_v;
    return best;
}

int
mcp__vertical_iterate(const mcp_perc_options *opt, int w, int h, int m, const float *t,
                      const float *t_surr, const float *t_mean, const int *start,
                      int *choice, mcp_perc_result *res)
{
    size_t n = (size_t)w * h;
    double *o = mcp_malloc(n * 3 * sizeof *o);
    if (!o) return -1;
    for (size_t p = 0; p < n; p++) {
        int j = -1; /* the mean */
        if (start)
            j = start[p];
        else if (opt->init == MCP_PERC_INIT_RANDOM)
            j = (int)(mcp__hash64(opt->seed, p) % (uint64_t)m);
        const float *v = j >= 0 ? t + (p * m + j) * 3 : t_mean + p * 3;
        choice[p] = j;
        o[p * 3] = v[0], o[p * 3 + 1] = v[1], o[p * 3 + 2] = v[2];
    }
    mcp__perc_state s;
    int rc = mcp__state_init(&s, &opt->model, w, h, t_surr, t_mean, o);
    free(o);
    if (rc) return -1;
    /* A visit depends only on r within g's radius of p, which only changes within 2r
     * of p change: pixels with no change that near since their last visit would keep
     * their candidate again, bit for bit, and are skipped. */
    unsigned char *dirty = mcp_malloc(n);
    if (!dirty) {
        mcp__state_free(&s);
        return -1;
    }
    memset(dirty, 1, n);
    int reach = 2 * s.g.r;
    res->energy_initial = s.energy;
    int max_passes = opt->passes > 0 ? opt->passes : 100;
    res->passes = 0;
    res->changes = 0;
    mcp__pass_bar bar;
    mcp__pass_bar_begin(&bar, opt->method, w, h);
    for (int pass = 0; pass < max_passes; pass++) {
        long changes = 0;
        for (int y = 0; y < h; y++) {
            mcp__pass_bar_row(&bar, pass, y);
            int x0 = y % 2 ? w - 1 : 0, dx = y % 2 ? -1 : 1; /* serpentine */
            for (int i = 0, x = x0; i < w; i++, x += dx) {
                size_t p = (size_t)y * w + x;
                if (!dirty[p]) continue;
                dirty[p] = 0;
                double de;
                int j = best_candidate(&s, x, y, m, t + p * m * 3, choice[p], &de);
                if (j < 0) continue;
                const float *v = t + (p * m + j) * 3;
                double nv[3] = {v[0], v[1], v[2]};
                mcp__state_set(&s, x, y, nv, de);
                mcp__mark_dirty(dirty, w, h, x, y, reach);
                choice[p] = j;
                changes++;
            }
        }
        res->passes++;
        res->changes += changes;
        if (changes == 0) break;
    }
    mcp__pass_bar_end(&bar);
    res->energy_final = s.energy;
    mcp__state_free(&s);
    free(dirty);
    return 0;
}

int
mcp_perc_vertical_iterative(const mcp_image *const *cands, int m,
                            const mcp_image *surrogate, const mcp_perc_options *opt,
                            mcp_perc_result *out)
{
    mcp_perc_options d = mcp_perc_defaults();
    if (!opt) opt = &d;
    memset(out, 0, sizeof *out);
    if (!surrogate) return mcp_error("vertical-iterative: needs a surrogate");
    if (mcp__check_run(opt, cands, m, surrogate)) return -1;
    int w = cands[0]->width, h = cands[0]->height, rc = -1;
    size_t n = (size_t)w * h;
    float *t = NULL, *t_surr = NULL, *mean = NULL, *t_mean = NULL;
    int *choice = NULL;
    double t0 = mcp__seconds();
    mcp_perc_result r = {0};
    if (mcp__stack_tone(cands, m, opt->model.tone_map, &t) ||
        mcp__rgb_tone(surrogate, opt->model.tone_map, &t_surr) ||
        mcp__mean_rgb(cands, m, &mean) ||
        mcp__tone_rgb(mean, n, opt->model.tone_map, &t_mean) ||
        !(choice = mcp_malloc(n * sizeof *choice)) ||
        mcp__vertical_iterate(opt, w, h, m, t, t_surr, t_mean, NULL, choice, &r) ||
        mcp__pick_image(cands, m, choice, &r.image) ||
        mcp__index_image(w, h, choice, &r.index)) {
        mcp_perc_result_free(&r);
        goto done;
    }
    r.seconds = mcp__seconds() - t0;
    *out = r;
    rc = 0;
done:
    free(t), free(t_surr), free(mean), free(t_mean), free(choice);
    return rc;
}
