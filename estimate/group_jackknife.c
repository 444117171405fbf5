/* group_jackknife.c: SURE's covariance term measured on a render's own samples
 * (docs/mathematics.md §2.10).
 *
 * SURE's divergence term reads Cov(n_i, d_i) as v_i E[∂d_i/∂n_i] (Stein's lemma),
 * which holds for Gaussian noise. A stratified render's noise at tens of samples is
 * skewed and heavy-tailed, and a denoiser that keeps a pixel's rare bright samples
 * while its slope at the typical value is small keeps more of the noise than its
 * slope says (bench/stein_gap.py). A member of a progressive series is the sum of its
 * increments, which are realisations of that noise: split its I samples into G groups
 * of consecutive checkpoints (group g's sum S_g of m_g samples), leave each out,
 *
 *     n_(g) = (I n - S_g) / (I - m_g),   its variance v I / (I - m_g),
 *     d_(g) = F(n_(g)) with that variance,
 *
 * and weigh the deviations (the delete-a-group jackknife):
 *
 *     C_i = Σ_g w_g (n_(g),i - n_i) (d_(g),i - d̄_i),   V_i = Σ_g w_g (n_(g),i - n_i)²,
 *     w_g = (I - m_g) / (G m_g),   d̄ = Σ_g a_g d_(g),   a_g = (I - m_g) / ((G - 1) I).
 *
 * E[(n_(g) - n)²] = v m_g / (I - m_g) for any noise, so E[V] = v and, for a linear
 * F = J n, E[C] = J v, whatever the group sizes; the a_g-weighted mean of the n_(g) is
 * n itself, so d̄ takes out only the shift that the larger variance gives every d_(g).
 * With equal groups the weights are the textbook (G - 1) / G. SURE then reads
 * (d - n)² - V + 2C: the render's own noise as its probes, so that V's errors and C's
 * cancel as the probes' do. It costs G denoiser applies. */
#include "estimate.h"
#include "internal.h"

#include "../common/dump/internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void
mcp__group_terms_clear(mcp__group_terms *g)
{
    mcp_image_free(g->cov);
    mcp_image_free(g->var);
    memset(g, 0, sizeof *g);
}

/* The last member of each of up to `groups` groups of members 0..i with sample counts
 * spp[0] < ... < spp[i], as near equal as the checkpoints allow (b[G - 1] = i); the
 * number of groups G found (fewer when the checkpoints are too coarse). */
static int
group_ends(const double *spp, int i, int groups, int *b)
{
    int g = 0, prev = -1;
    for (int k = 1; k < groups; k++) {
        double target = spp[i] * k / groups;
        int best = -1;
        for (int j = prev + 1; j < i; j++)
            if (best < 0 || fabs(spp[j] - target) < fabs(spp[best] - target)) best = j;
        if (best < 0) break;
        b[g++] = prev = best;
    }
    b[g++] = i;
    return g;
}

/* The groups' ends for member i from the series' sample counts (member indices when
 * it has none in increasing order); the number of groups, or -1 out of memory. */
static int
plan_groups(const mcp_series *s, int i, int groups, int *b)
{
    double *spp = mcp_calloc((size_t)i + 1, sizeof *spp);
    if (!spp) return -1;
    int known = 1;
    for (int j = 0; j <= i; j++) {
        spp[j] = s->spp ? s->spp[j] : 0;
        known = known && spp[j] > 0 && (j == 0 || spp[j] > spp[j - 1]);
    }
    for (int j = 0; !known && j <= i; j++)
        spp[j] = j + 1.0;
    const int G = group_ends(spp, i, groups, b);
    free(spp);
    return G;
}

/* Accumulates one left-out mean's terms: dn = n_(g) - n and dd = d_(g) - d_(0) (d_(0)
 * the first group's, so that the sums stay at the scale of the noise), into
 * acc = {Σ w dn dd, Σ w dn, Σ a dd, Σ w dn²} (4 images, 3 channels each). */
static void
accumulate(const mcp_image *n, const mcp_image *loo, const mcp_image *d,
           const mcp_image *d0, double w, double a, mcp_image *const acc[4])
{
#pragma omp parallel for schedule(static)
    for (int y = 0; y < n->height; y++)
        for (int x = 0; x < n->width; x++) {
            const float *pn = mcp_image_px(n, x, y), *pl = mcp_image_px(loo, x, y),
                        *pd = mcp_image_px(d, x, y), *p0 = mcp_image_px(d0, x, y);
            float *o[4];
            for (int k = 0; k < 4; k++)
                o[k] = mcp_image_px(acc[k], x, y);
            for (int c = 0; c < 3; c++) {
                const double dn = (double)pl[c] - pn[c], dd = (double)pd[c] - p0[c];
                o[0][c] += (float)(w * dn * dd);
                o[1][c] += (float)(w * dn);
                o[2][c] += (float)(a * dd);
                o[3][c] += (float)(w * dn * dn);
            }
        }
}

int
mcp__series_group_terms(const mcp_series *s, int i, const mcp_dump *member,
                        const mcp_denoiser *den, int groups, mcp__group_terms *out)
{
    memset(out, 0, sizeof *out);
    if (i < 1 || groups < 2 || !mcp__member_can_group(member)) return 0;
    int b[MCP__GROUPS_MAX];
    const int G =
        plan_groups(s, i, groups < MCP__GROUPS_MAX ? groups : MCP__GROUPS_MAX, b);
    /* two groups leave one degree of freedom per value, too few under heavy tails
       (docs/fidelity.md, `bathroom`): at least three unless fewer were asked for */
    if (G < mcp__groups_min(groups)) return G < 0 ? -1 : 0;

    /* one group at a time: its sum from the members at its ends, the member without
       it, denoised, into the sums; the memory is a few images whatever G is */
    const mcp_image *n = member->color, *v = member->var_of_mean;
    const int w = n->width, h = n->height;
    const double I = member->spp;
    mcp_image *loo = NULL, *v_loo = NULL, *d = NULL, *d0 = NULL, *acc[4] = {0};
    mcp_dump *prev = NULL, *end = NULL;
    double before = 0.0; /* the samples up to the group's start */
    int rc = -1;
    if (mcp__image_new(w, h, 3, NULL, "left-out mean", &loo) ||
        mcp__image_new(w, h, 3, NULL, "left-out variance", &v_loo))
        goto done;
    for (int k = 0; k < 4; k++)
        if (mcp__image_new(w, h, 3, NULL, "jackknife sums", &acc[k])) goto done;
    for (int g = 0; g < G; g++) {
        if (g < G - 1 && mcp__series_load_file(s, b[g], 0, &end)) goto done;
        const mcp_dump *e = end ? end : member;
        if (e->spp_map || !(e->spp > before) || (end && !(end->spp < member->spp)) ||
            e->color->width != w || e->color->height != h) {
            rc = 0; /* the ends make no groups: the probes' divergence stands */
            goto done;
        }
        /* n_(g) = (I n - S_g) / (I - m_g), S_g = I_e n_e - I_prev n_prev; its variance */
        const double m = e->spp - before, scale = I / (I - m);
#pragma omp parallel for schedule(static)
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                const float *pn = mcp_image_px(n, x, y), *pv = mcp_image_px(v, x, y),
                            *pe = mcp_image_px(e->color, x, y),
                            *pp = prev ? mcp_image_px(prev->color, x, y) : NULL;
                float *o = mcp_image_px(loo, x, y), *ov = mcp_image_px(v_loo, x, y);
                for (int c = 0; c < 3; c++) {
                    const double sum = e->spp * pe[c] - (pp ? before * pp[c] : 0.0);
                    o[c] = (float)((I * pn[c] - sum) / (I - m));
                    ov[c] = (float)(pv[c] * scale);
                }
            }
        before = e->spp;
        mcp_dump_free(prev);
        prev = end;
        end = NULL;
        mcp_denoise_input in = mcp_denoise_input_of(member);
        in.color = loo;
        in.variance = v_loo;
        if (den->apply(den, &in, &d)) goto done;
        if (d->channels != 3 || d->width != w || d->height != h) {
            mcp_error("the denoiser gave a %dx%d image of %d channels for %dx%d",
                      d->width, d->height, d->channels, w, h);
            goto done;
        }
        if (!d0) d0 = d;
        accumulate(n, loo, d, d0, (I - m) / (G * m), (I - m) / ((G - 1) * I), acc);
        if (d != d0) mcp_image_free(d);
        d = NULL;
    }
    /* C = Σ w dn (d_(g) - d̄) = Σ w dn dd - (Σ a dd)(Σ w dn); V = Σ w dn² */
    double sum_v = 0.0, sum_jv = 0.0;
#pragma omp parallel for schedule(static) reduction(+ : sum_v, sum_jv)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *pv = mcp_image_px(v, x, y), *pb = mcp_image_px(acc[1], x, y),
                        *pa = mcp_image_px(acc[2], x, y),
                        *pw = mcp_image_px(acc[3], x, y);
            float *pc = mcp_image_px(acc[0], x, y);
            for (int c = 0; c < 3; c++) {
                pc[c] = (float)((double)pc[c] - (double)pa[c] * pb[c]);
                sum_v += pv[c];
                sum_jv += pw[c];
            }
        }
    out->cov = acc[0];
    out->var = acc[3];
    acc[0] = acc[3] = NULL;
    out->groups = G;
    out->v_over_v = sum_jv > 0.0 ? sum_v / sum_jv : 0.0;
    rc = 0;
    /* differences far noisier than the members' variances say: not checkpoints of one
       render (independent renders at rising counts), whose differences are no groups
       at all (the series' own rule, mcp_variance_ratio_off) */
    if (mcp_variance_ratio_off(out->v_over_v) && out->v_over_v < 1.0)
        mcp__group_terms_clear(out);
done:
    mcp_image_free(loo);
    mcp_image_free(v_loo);
    mcp_image_free(d);
    mcp_image_free(d0);
    for (int k = 0; k < 4; k++)
        mcp_image_free(acc[k]);
    mcp_dump_free(prev);
    mcp_dump_free(end);
    if (rc) mcp__group_terms_clear(out);
    return rc;
}

int
mcp__group_probe_variance(const mcp_dump *d, const mcp__group_terms *g, mcp_image **cov)
{
    *cov = NULL;
    if (!d->cov_of_mean) return 0;
    if (mcp_image_copy(d->cov_of_mean, cov)) return -1;
    const mcp_image *v = d->var_of_mean;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < v->height; y++)
        for (int x = 0; x < v->width; x++) {
            const float *own = mcp_image_px(v, x, y), *gv = mcp_image_px(g->var, x, y);
            float *cv = mcp_image_px(*cov, x, y);
            double scale[3];
            for (int c = 0; c < 3; c++)
                scale[c] =
                    own[c] > 0.0f && gv[c] > 0.0f ? sqrt((double)gv[c] / own[c]) : 0.0;
            /* RG, RB, GB: the renderer's correlations, at the groups' variances */
            cv[0] = (float)(cv[0] * scale[0] * scale[1]);
            cv[1] = (float)(cv[1] * scale[0] * scale[2]);
            cv[2] = (float)(cv[2] * scale[1] * scale[2]);
        }
    return 0;
}
