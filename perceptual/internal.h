/* internal.h: what the perceptual module's files share -- the kernel g as a 2D array,
 * pixel footprints under replicate borders, tone-mapped pixel buffers, and the
 * incremental energy state of direct binary search (docs/mathematics.md §4.6).
 * Not installed. */
#ifndef MCP_PERCEPTUAL_INTERNAL_H
#define MCP_PERCEPTUAL_INTERNAL_H

#include <mcpost/perceptual.h>
#include <mcpost/progress.h>

#include <omp.h>
#include <stddef.h>
#include <stdint.h>

#include "../common/core/rng_internal.h"

/* ---- the kernel g ---- */

/* g as a full (2r+1)^2 array: g(dx, dy) at taps[(dy + r) * side + dx + r]. The
 * filtered image is the convolution (g * X)(q) = sum_k g(k) X(clamp(q - k)). */
typedef struct mcp__pkern {
    int r, side;
    double *taps;
    double l1; /* |g|_1 */
} mcp__pkern;

int mcp__pkern_build(const mcp_perc_model *model, mcp__pkern *out);
void mcp__pkern_free(mcp__pkern *k);

/* Footprints: with replicate borders, pixel p enters (g * X)(q) with the weight
 * a_p(q) = sum_k g(k) [clamp(q - k) = p], which is g(q - p) away from the borders and
 * differs within r of them. a_p depends only on the distances of p to the four
 * borders capped at r, so there are at most (2r+1)^2 different ones; they are tabled
 * per class. a_p(p + d) for |d| <= r lives at fp[cls][(dy + r) * side + dx + r], 0
 * where p + d lies outside the image. */
typedef struct mcp__footprints {
    int w, h, r, side;
    int nx, ny;    /* classes along x and y */
    int *cx, *cy;  /* class of each column and row */
    int ix, iy;    /* the interior class (-1: none, tiny images) */
    double *fp;    /* [ny][nx][side * side] */
    double *norm2; /* [ny][nx] sum_q a_p(q)^2 */
} mcp__footprints;

int mcp__footprints_build(const mcp__pkern *g, int w, int h, mcp__footprints *out);
void mcp__footprints_free(mcp__footprints *f);

static inline const double *
mcp__footprint(const mcp__footprints *f, int x, int y)
{
    return f->fp + ((size_t)f->cy[y] * f->nx + f->cx[x]) * (size_t)f->side * f->side;
}

static inline int
mcp__footprint_interior(const mcp__footprints *f, int x, int y)
{
    return f->cx[x] == f->ix && f->cy[y] == f->iy;
}

/* ---- inputs ---- */

/* T(x) inline for the common maps; the others go through tonemap.h (same values). */
static inline float
mcp__tone(mcp_tonemap tm, float x)
{
    if (tm == MCP_TONEMAP_NONE) return x;
    if (tm == MCP_TONEMAP_CLAMP)
        return x > 0.0f ? (x < 1.0f ? x : 1.0f) : 0.0f; /* NaN -> 0, as tonemap.c */
    return mcp_tonemap_value(tm, x);
}

/* Checks the candidates (m >= 1, RGB, all the same size, also as the surrogate when
 * given) and fills their RGB channel indices (rgb[3 * j + c]) when rgb is not NULL. */
int mcp__check_candidates(const mcp_image *const *cands, int m,
                          const mcp_image *surrogate, int *rgb);

/* T of an image's R, G, B, packed [n][3]; fails naming the file and pixel on a
 * non-finite value. *out is malloc'd. */
int mcp__rgb_tone(const mcp_image *img, mcp_tonemap tm, float **out);

/* T of every candidate, packed pixel-major [n][m][3]. */
int mcp__stack_tone(const mcp_image *const *cands, int m, mcp_tonemap tm, float **out);

/* The candidates' mean per pixel, [n][3] linear (in double, stored as float). */
int mcp__mean_rgb(const mcp_image *const *cands, int m, float **out);

/* A packed copy of an image's R, G, B, named so. */
int mcp__rgb_image(const mcp_image *img, mcp_image **out);

/* A new R, G, B image from packed [n][3] values. */
int mcp__image_from_rgb(int w, int h, const float *rgb, mcp_image **out);

/* Confidence per pixel [n] from the model (NULL when it is the scalar), checked to lie
 * in [0, 1]. */
int mcp__confidence_map(const mcp_perc_model *model, int w, int h, float **out);

/* A 64-bit hash of (seed, i): splitmix64's finaliser (common/core/rng_internal.h; random
 * streams per pixel, so results never depend on the thread count). */
static inline uint64_t
mcp__hash64(uint64_t seed, uint64_t i)
{
    return mcp__mix64(seed ^ (MCP__SPLITMIX64_GAMMA * (i + 1)));
}

static inline double
mcp__seconds(void)
{
    return omp_get_wtime();
}

/* ---- the incremental energy (direct binary search) ---- */

/* E_C(O) with the residual r = g * T(O) - h * T(I') kept up to date:
 *   E_C = sum_p u_p |o_p - qinit_p|^2 + sum_q C_q |r_q|^2,  u_p = (1 - C_p) |g|_1^2.
 * Changing o_p by D changes E_C by
 *   sum_c [2 D_c <a_p, C r_c> + D_c^2 <a_p, C a_p>] + u_p (|o_p + D - qi|^2 - |o_p -
 * qi|^2) (§4.6: 2D (g * r)_p + D^2 |g|^2 for C = 1 away from the borders): O(1) per
 * candidate once <a_p, C r> is known (O(|g|)), and an accepted change updates r in
 * O(|g|). All sums are in double. */
typedef struct mcp__perc_state {
    int w, h;
    mcp__pkern g;
    mcp__footprints fp;
    double *target; /* h * T(I'), [n][3] */
    double *resid;  /* g * o - target, [n][3] */
    double *o;      /* T(O), [n][3] */
    float *qinit;   /* T(Q_init), [n][3]; NULL when C = 1 everywhere */
    float *cmap;    /* C per pixel [n]; NULL: the scalar c */
    double c;       /* scalar C */
    double unary;   /* |g|_1^2 */
    double energy;  /* E_C, updated incrementally */
} mcp__perc_state;

/* Sets the state up for O = o_init ([n][3], T-space, copied), against the tone-mapped
 * surrogate t_surr and T(Q_init) t_qinit (may be NULL when C = 1 everywhere; copied).
 * The energy is computed in full. */
int mcp__state_init(mcp__perc_state *s, const mcp_perc_model *model, int w, int h,
                    const float *t_surr, const float *t_qinit, const double *o_init);
void mcp__state_free(mcp__perc_state *s);

/* E_C recomputed from scratch from s->o (direct convolution, double sums per row). */
double mcp__state_energy_full(const mcp__perc_state *s);

/* <a_p, C r_c> for c = 0..2 and <a_p, C a_p> at pixel p = (x, y). */
void mcp__state_corr(const mcp__perc_state *s, int x, int y, double corr[3], double *n2);

/* The change of E_C if o_p became o_new (p = y * w + x), not applied. */
double mcp__state_delta(const mcp__perc_state *s, int x, int y, const double o_new[3]);

/* Sets o_p = o_new, updating r and the energy by dE (as returned by
 * mcp__state_delta). */
void mcp__state_set(mcp__perc_state *s, int x, int y, const double o_new[3], double dE);

/* <a_i, C a_j> for pixels i = (xi, yi) and j = (xj, yj) within 2r of each other. */
double mcp__state_cross(const mcp__perc_state *s, int xi, int yi, int xj, int yj);

/* mcp__state_corr with the common case inline: away from the borders, with a scalar
 * C, the footprint is g itself and no bounds need checking. */
static inline void
mcp__state_corr_fast(const mcp__perc_state *s, int x, int y, double corr[3], double *n2)
{
    if (s->cmap || !mcp__footprint_interior(&s->fp, x, y)) {
        mcp__state_corr(s, x, y, corr, n2);
        return;
    }
    int r = s->g.r, side = s->g.side, w = s->w;
    const double *g = s->g.taps, *base = s->resid + ((size_t)(y - r) * w + (x - r)) * 3;
    double c0 = 0.0, c1 = 0.0, c2 = 0.0;
    for (int ky = 0; ky < side; ky++) {
        const double *row = base + (size_t)ky * w * 3;
        for (int kx = 0; kx < side; kx++) {
            double k = g[ky * side + kx];
            c0 += k * row[kx * 3], c1 += k * row[kx * 3 + 1], c2 += k * row[kx * 3 + 2];
        }
    }
    corr[0] = s->c * c0, corr[1] = s->c * c1, corr[2] = s->c * c2;
    *n2 = s->c * s->fp.norm2[(size_t)s->fp.iy * s->fp.nx + s->fp.ix];
}

/* Marks the pixels within `radius` of (x, y) (a byte per pixel). */
static inline void
mcp__mark_dirty(unsigned char *dirty, int w, int h, int x, int y, int radius)
{
    int x0 = x - radius < 0 ? 0 : x - radius, x1 = x + radius >= w ? w - 1 : x + radius;
    int y0 = y - radius < 0 ? 0 : y - radius, y1 = y + radius >= h ? h - 1 : y + radius;
    for (int yy = y0; yy <= y1; yy++)
        for (int xx = x0; xx <= x1; xx++)
            dirty[(size_t)yy * w + xx] = 1;
}

/* Unary weight u_p. */
static inline double
mcp__state_unary(const mcp__perc_state *s, size_t p)
{
    if (!s->qinit) return 0.0;
    return (1.0 - (s->cmap ? (double)s->cmap[p] : s->c)) * s->unary;
}

/* The change of E_C if pixels i and j exchanged their values, not applied. */
double mcp__state_swap_delta(const mcp__perc_state *s, int xi, int yi, int xj, int yj);

/* The comparison threshold: a change is accepted only when it lowers E_C by more than
 * rounding could explain (1e-12 of the magnitude of the terms that make it up). */
#define MCP__ACCEPT_RTOL 1e-12

/* ---- shared by the methods ---- */

/* T of packed linear [n][3] values into a new float buffer. */
int mcp__tone_rgb(const float *rgb, size_t n, mcp_tonemap tm, float **out);

/* T of row y of img's channels ch (R, G, B) into dst[x][3]; returns the count of
 * non-finite values. */
long mcp__tone_row(const mcp_image *img, const int ch[3], int y, mcp_tonemap tm,
                   float *dst);

/* A one-channel image "index" holding choice[n]. */
int mcp__index_image(int w, int h, const int *choice, mcp_image **out);

/* R, G, B of candidate choice[p] at every pixel p. */
int mcp__pick_image(const mcp_image *const *cands, int m, const int *choice,
                    mcp_image **out);

/* The iterative minimisation over a stack t ([n][m][3], T-space); choice[n] receives
 * the chosen candidate per pixel. start (may be NULL: opt->init decides) gives the
 * starting candidate per pixel, -1 meaning t_mean there. Fills passes, changes and the
 * energies of res. */
int mcp__vertical_iterate(const mcp_perc_options *opt, int w, int h, int m,
                          const float *t, const float *t_surr, const float *t_mean,
                          const int *start, int *choice, mcp_perc_result *res);

/* Validates opt and the candidates (and surrogate, when given). */
int mcp__check_run(const mcp_perc_options *opt, const mcp_image *const *cands, int m,
                   const mcp_image *surrogate);

/* The threshold mask of opt: opt->mask_image (checked, *owned = NULL) or the
 * generated blue-noise mask (*owned = it; free it after use). */
int mcp__mask(const mcp_perc_options *opt, const mcp_image **mask, mcp_image **owned);

/* The blue-noise threshold B at pixel (x, y) of a tiled mask. */
static inline float
mcp__mask_at(const mcp_image *mask, int x, int y)
{
    return mcp_image_px(mask, x % mask->width, y % mask->height)[0];
}

/* ---- not exported by libmcpost.so (docs/library.md, "Exported symbols") ---- */

int mcp_perc_method_from_name(const char *name, mcp_perc_method *out);
/* 1 for the horizontal methods (their result is a permutation to re-render). */
int mcp_perc_method_is_horizontal(mcp_perc_method method);
int mcp_perc_init_from_name(const char *name, mcp_perc_init *out);
const char *mcp_perc_init_name(mcp_perc_init init);

/* The methods one by one (opt->method is ignored); mcp_perc_optimize picks one. */
int mcp_perc_vertical_iterative(const mcp_image *const *cands, int m,
                                const mcp_image *surrogate, const mcp_perc_options *opt,
                                mcp_perc_result *out);
int mcp_perc_power_set(const mcp_image *const *cands, int m, const mcp_image *surrogate,
                       const mcp_perc_options *opt, mcp_perc_result *out);
int mcp_perc_error_diffusion(const mcp_image *const *cands, int m,
                             const mcp_image *surrogate, const mcp_perc_options *opt,
                             mcp_perc_result *out);
int mcp_perc_dither(const mcp_image *const *cands, int m, const mcp_image *surrogate,
                    const mcp_perc_options *opt, mcp_perc_result *out);
int mcp_perc_histogram(const mcp_image *const *cands, int m, const mcp_perc_options *opt,
                       mcp_perc_result *out);
/* Horizontal: one estimate q per pixel. */
int mcp_perc_horizontal(const mcp_image *q, const mcp_image *surrogate,
                        const mcp_perc_options *opt, mcp_perc_result *out);
int mcp_perc_permutation(const mcp_image *q, const mcp_perc_options *opt,
                         mcp_perc_result *out);

/* Applies a permutation map (channels X, Y) to an image: out(p) = img(map(p)). */
int mcp_perc_permute(const mcp_image *img, const mcp_image *map, mcp_image **out);

/* ---- progress of the passes (pass_progress.c) ---- */

/* A bar over the rows of each pass, the pass in its label ("power-set, pass 3"), on a
 * terminal for a megapixel or more; begin, a row at a time (row y of pass k, from 0),
 * end. */
typedef struct mcp__pass_bar {
    mcp_progress bar;
    int shown, pass;
    mcp_perc_method method;
} mcp__pass_bar;
void mcp__pass_bar_begin(mcp__pass_bar *b, mcp_perc_method method, int w, int h);
void mcp__pass_bar_row(mcp__pass_bar *b, int pass, int y);
void mcp__pass_bar_end(mcp__pass_bar *b);

#endif
