/* stopping.c: the error distribution of a denoised image and the stopping criterion
 * (SPEC "Error distribution and stopping"; Firmino 2024 Eqs. 3, 14-16).
 *
 * The scaled error of value i is modelled as s_i² (Z + √λ_i)², Z ~ N(0, 1): a scaled
 * noncentral χ² with one degree of freedom, whose CDF is closed-form,
 *     F_i(τ) = Φ(√(τ/s_i²) - √λ_i) - Φ(-√(τ/s_i²) - √λ_i),
 * with s_i² = Var^r_i and λ_i from the block sums (Eq. 14). The image CDF F(τ) is the
 * mean over values; stop when F(τ) >= p; percentiles solve F(τ) = p by bisection in
 * log τ. Sums run in double per row, rows in order. */
#include "estimate.h"
#include "internal.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define SQRT1_2 0.70710678118654752440
/* Beyond this many standard deviations a normal tail is below 1e-16 of the body, so
 * F_i is 1 (or the tail term 0) to double precision: skip the erfc. */
#define TAIL_Z 8.3
/* Bisection stops when hi / lo < 1 + this. */
#define PERCENTILE_RTOL 1e-4

/* F for Z + l with |Z + l| <= a, a >= 0, l >= 0, in the form that keeps precision in
 * both tails: 1 - Q(a - l) - Q(a + l) above the mode, Φ(a - l) - Q(a + l) below it
 * (Q the upper normal tail, 0.5 erfc(z/√2)). */
static inline double
folded_cdf(double a, double l)
{
    double hi = a + l; /* Q(hi): the lower tail Φ(-a - l) */
    double q_hi = hi > TAIL_Z ? 0.0 : 0.5 * erfc(hi * SQRT1_2);
    double d = a - l;
    if (d > TAIL_Z) return 1.0 - q_hi;
    if (d >= 0.0) return 1.0 - 0.5 * erfc(d * SQRT1_2) - q_hi;
    return 0.5 * erfc(-d * SQRT1_2) - q_hi;
}

double
mcp_ncx2_cdf(double x, double lambda)
{
    if (!(x > 0.0)) return 0.0;
    if (isinf(x)) return 1.0;
    double f = folded_cdf(sqrt(x), sqrt(lambda > 0.0 ? lambda : 0.0));
    return f < 0.0 ? 0.0 : f > 1.0 ? 1.0 : f;
}

/* ---- the image CDF, vectorised ----
 *
 * F_i = 1 - Q(a - l) - Q(a + l) with Q the upper normal tail (Q(-z) = 1 - Q(z)),
 * a = sqrt(τ / s²), l = sqrt(λ). Q by Abramowitz & Stegun 26.2.17 (|error| < 7.5e-8)
 * with its own exp and 1/sqrt, written so that the compiler vectorises the loop
 * (no branches, no libm calls, integer tricks for the clamps), in float. */

static inline int32_t
f2i(float f)
{
    int32_t i;
    memcpy(&i, &f, sizeof i);
    return i;
}

static inline float
i2f(int32_t i)
{
    float f;
    memcpy(&f, &i, sizeof f);
    return f;
}

/* e^x for x in [-72, 0]: Cody-Waite reduction, degree-6 Taylor (error < 2e-7). */
static inline float
exp_neg(float x)
{
    int32_t k = (int32_t)(x * 1.44269504f - 0.5f); /* rounds x log2(e) for x <= 0 */
    float kf = (float)k;
    float r = x - kf * 0.693145752f - kf * 1.42860677e-6f;
    float p =
        1.0f +
        r * (1.0f +
             r * (0.5f + r * (1.0f / 6 +
                              r * (1.0f / 24 + r * (1.0f / 120 + r * (1.0f / 720))))));
    return p * i2f((k + 127) << 23);
}

/* Q(z) for z >= 0 (z may be +inf): clamped at 12, where Q < 2e-33. */
static inline float
upper_tail(float z)
{
    int32_t b = f2i(z), m = 0x41400000; /* 12.0f: non-negative floats order as ints */
    z = i2f(b < m ? b : m);
    float t = 1.0f / (1.0f + 0.2316419f * z);
    float poly = t * (0.319381530f +
                      t * (-0.356563782f +
                           t * (1.781477937f + t * (-1.821255978f + t * 1.330274429f))));
    return 0.398942280f * exp_neg(-0.5f * z * z) * poly;
}

/* 1 / sqrt(v) for v > 0: bit-level first guess and three Newton steps. */
static inline float
rsqrt(float v)
{
    float y = i2f(0x5f3759df - (f2i(v) >> 1)), h = 0.5f * v;
    y = y * (1.5f - h * y * y);
    y = y * (1.5f - h * y * y);
    return y * (1.5f - h * y * y);
}

/* g[j] = F_j for n values v[j] = s_j² with sqrt(λ) l[j]; v = 0 gives 1. On x86-64
 * GCC also builds an AVX2 + FMA copy, picked at load time where the CPU has it, and
 * may fuse multiply-adds here (-std=c11 turns contraction off elsewhere). */
#if defined(__GNUC__) && defined(__x86_64__) && !defined(__clang__)
__attribute__((target_clones("arch=x86-64-v3", "default"), optimize("fp-contract=fast")))
#endif
static void
fold_cdf(const float *restrict v, const float *restrict l, float *restrict g, int n,
         float root_tau)
{
#pragma omp simd
    for (int j = 0; j < n; j++) {
        int32_t b = f2i(v[j]), tiny = 0x02081cea; /* 1e-37: s² = 0 becomes a = 3e18 */
        float a = root_tau * rsqrt(i2f(b > tiny ? b : tiny));
        float d = a - l[j];
        float qd = upper_tail(fabsf(d));
        float q_low = 0.5f - copysignf(0.5f - qd, d); /* Q(d) for either sign */
        g[j] = 1.0f - q_low - upper_tail(a + l[j]);
    }
}

/* The sum of n floats in double, through 8 float lanes. */
static double
sum_floats(const float *g, int n)
{
    float acc[8] = {0};
    int j = 0;
    for (; j + 8 <= n; j += 8)
        for (int k = 0; k < 8; k++)
            acc[k] += g[j + k];
    double s = 0.0;
    for (int k = 0; k < 8; k++)
        s += acc[k];
    for (; j < n; j++)
        s += g[j];
    return s;
}

/* ---- the distribution ---- */

struct mcp_error_dist {
    const mcp_blocks *blocks; /* borrowed */
    const mcp_image *var_rel; /* borrowed */
    float *sqrt_lambda;       /* 3 per block */
    long n_values;
    int max_w; /* the widest block */
};

void
mcp_error_dist_free(mcp_error_dist *d)
{
    if (!d) return;
    free(d->sqrt_lambda);
    free(d);
}

int
mcp_error_distribution(mcp_blocks *blocks, const mcp_image *var_rel, mcp_error_dist **out)
{
    *out = NULL;
    if (!blocks || !var_rel || var_rel->channels < 3)
        return mcp_error("error distribution: missing blocks or a 3-channel variance");
    if (var_rel->width != blocks->width || var_rel->height != blocks->height)
        return mcp_error("error distribution: the variance is %dx%d but the blocks cover "
                         "%dx%d",
                         var_rel->width, var_rel->height, blocks->width, blocks->height);
    mcp_error_dist *d = mcp_calloc(1, sizeof *d);
    if (!d) return -1;
    d->blocks = blocks;
    d->var_rel = var_rel;
    d->n_values = (long)blocks->width * blocks->height * 3;
    d->sqrt_lambda = mcp_calloc((size_t)blocks->count * 3 + 1, sizeof *d->sqrt_lambda);
    if (!d->sqrt_lambda) {
        mcp_error_dist_free(d);
        return -1;
    }
    long bad = 0;
    int packed = var_rel->pixel_stride == 3;
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : bad)
    for (int i = 0; i < blocks->count; i++) {
        mcp_block *k = &blocks->items[i];
        double sum[3] = {0, 0, 0};
        int negative = 0;
        for (int y = k->y; y < k->y + k->h; y++) {
            int x = 0;
            if (packed) { /* 4 pixels at a time in 12 lanes (vectorised), then folded */
                const float *v = mcp_image_px(var_rel, k->x, y);
                double lane[12] = {0};
                float low = 0.0f;
                for (; x + 4 <= k->w; x += 4)
                    for (int i = 0; i < 12; i++) {
                        lane[i] += v[3 * x + i];
                        low = v[3 * x + i] < low ? v[3 * x + i] : low;
                    }
                for (int i = 0; i < 12; i++)
                    sum[i % 3] += lane[i];
                negative |= low < 0.0f;
            }
            for (; x < k->w; x++) {
                const float *v = mcp_image_px(var_rel, k->x + x, y);
                negative |= (v[0] < 0.0f) | (v[1] < 0.0f) | (v[2] < 0.0f);
                sum[0] += v[0];
                sum[1] += v[1];
                sum[2] += v[2];
            }
        }
        bad += negative || !isfinite(sum[0] + sum[1] + sum[2]);
        for (int c = 0; c < 3; c++) {
            k->var_sum[c] = sum[c];
            double lambda = fmax(k->sure_sum[c] / (sum[c] + 1e-6), 1.0) - 1.0;
            d->sqrt_lambda[3 * i + c] = (float)sqrt(lambda);
        }
    }
    for (int i = 0; i < blocks->count; i++)
        d->max_w = blocks->items[i].w > d->max_w ? blocks->items[i].w : d->max_w;
    if (bad) {
        mcp_error_dist_free(d);
        return mcp_error("error distribution: %ld blocks have negative or non-finite "
                         "variance values",
                         bad);
    }
    *out = d;
    return 0;
}

double
mcp_error_dist_lambda(const mcp_error_dist *d, int block, int c)
{
    double sl = d->sqrt_lambda[3 * block + c];
    return sl * sl;
}

double
mcp_error_dist_mean(const mcp_error_dist *d)
{
    double s = 0.0;
    for (int i = 0; i < d->blocks->count; i++)
        for (int c = 0; c < 3; c++)
            s += d->blocks->items[i].var_sum[c] * (mcp_error_dist_lambda(d, i, c) + 1.0);
    return d->n_values ? s / (double)d->n_values : 0.0;
}

int
mcp_error_dist_image(const mcp_error_dist *d, mcp_image **out)
{
    *out = NULL;
    if (!d) return mcp_error("error distribution: missing");
    static const char *const names[6] = {"lambda.R", "lambda.G", "lambda.B",
                                         "s2.R",     "s2.G",     "s2.B"};
    const mcp_blocks *b = d->blocks;
    if (mcp__image_new(b->width, b->height, 6, names, "error distribution", out))
        return -1;
    for (int i = 0; i < b->count; i++) {
        const mcp_block *k = &b->items[i];
        for (int y = k->y; y < k->y + k->h; y++)
            for (int x = k->x; x < k->x + k->w; x++) {
                float *o = mcp_image_px(*out, x, y);
                const float *v = mcp_image_px(d->var_rel, x, y);
                for (int c = 0; c < 3; c++) {
                    o[c] = (float)mcp_error_dist_lambda(d, i, c);
                    o[3 + c] = v[c];
                }
            }
    }
    return 0;
}

double
mcp_error_cdf(const mcp_error_dist *d, double tau)
{
    if (!d || d->n_values == 0) return 1.0;
    if (!(tau > 0.0)) return 0.0;
    const mcp_blocks *b = d->blocks;
    const mcp_image *var = d->var_rel;
    double *block_sum = malloc(((size_t)b->count + 1) * sizeof *block_sum);
    if (!block_sum) return NAN;
    float root_tau = (float)sqrt(tau);
    int failed = 0, n_max = 3 * d->max_w;
    int packed = var->pixel_stride == 3;
#pragma omp parallel reduction(+ : failed)
    {
        float *lpat = malloc((size_t)(n_max + 1) * sizeof *lpat);
        float *g = malloc((size_t)(n_max + 1) * sizeof *g);
        float *row = packed ? NULL : malloc((size_t)(n_max + 1) * sizeof *row);
        if (!lpat || !g || (!packed && !row)) failed++;
#pragma omp for schedule(dynamic, 1)
        for (int i = 0; i < b->count; i++) {
            if (!lpat || !g || (!packed && !row)) continue;
            const mcp_block *k = &b->items[i];
            int n = 3 * k->w;
            for (int j = 0; j < n; j++)
                lpat[j] = d->sqrt_lambda[3 * i + j % 3];
            double s = 0.0;
            for (int y = k->y; y < k->y + k->h; y++) {
                const float *v = mcp_image_px(var, k->x, y);
                if (!packed) {
                    for (int x = 0; x < k->w; x++)
                        for (int c = 0; c < 3; c++)
                            row[3 * x + c] = mcp_image_px(var, k->x + x, y)[c];
                    v = row;
                }
                fold_cdf(v, lpat, g, n, root_tau);
                s += sum_floats(g, n);
            }
            block_sum[i] = s;
        }
        free(lpat);
        free(g);
        free(row);
    }
    double total = 0.0;
    for (int i = 0; i < b->count; i++)
        total += block_sum[i];
    free(block_sum);
    return failed ? NAN : total / (double)d->n_values;
}

int
mcp_error_should_stop(const mcp_error_dist *d, double tau, double p, double *cdf)
{
    double f = mcp_error_cdf(d, tau);
    if (cdf) *cdf = f;
    return f >= p;
}

int
mcp_error_percentiles(const mcp_error_dist *d, const double *p, int n, double *tau)
{
    if (!d) return mcp_error("error percentiles: missing distribution");
    for (int k = 0; k < n; k++)
        if (!(p[k] >= 0.0 && p[k] < 1.0))
            return mcp_error("error percentiles: p must be in [0, 1) (got %g)", p[k]);
    /* the bracket: above top every F_i is 1 (to double precision); below bottom
     * every F_i with s_i > 0 is < 1e-4 */
    double top = 0.0, s2_min = INFINITY;
    const mcp_blocks *b = d->blocks;
    for (int i = 0; i < b->count; i++) {
        const mcp_block *k = &b->items[i];
        for (int y = k->y; y < k->y + k->h; y++)
            for (int x = k->x; x < k->x + k->w; x++) {
                const float *v = mcp_image_px(d->var_rel, x, y);
                for (int c = 0; c < 3; c++) {
                    double r = d->sqrt_lambda[3 * i + c] + TAIL_Z + 1.0;
                    top = fmax(top, v[c] * r * r);
                    if (v[c] > 0.0f) s2_min = fmin(s2_min, v[c]);
                }
            }
    }
    double bottom = s2_min * 1e-8;
    for (int k = 0; k < n; k++) {
        if (top == 0.0 || !isfinite(bottom)) { /* every s_i is 0: no error */
            tau[k] = 0.0;
            continue;
        }
        double lo = bottom, hi = top;
        int tries = 0;
        while (mcp_error_cdf(d, lo) >= p[k] && tries++ < 8)
            lo *= 1e-4;
        if (mcp_error_cdf(d, lo) >= p[k]) { /* reached below any scale that matters */
            tau[k] = 0.0;
            continue;
        }
        if (!(mcp_error_cdf(d, hi) >= p[k])) { /* only by rounding, for p near 1 */
            tau[k] = INFINITY;
            continue;
        }
        while (log(hi / lo) > PERCENTILE_RTOL) {
            double mid = sqrt(lo * hi);
            if (mcp_error_cdf(d, mid) >= p[k])
                hi = mid;
            else
                lo = mid;
        }
        tau[k] = hi;
    }
    return 0;
}
