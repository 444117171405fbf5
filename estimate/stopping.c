/* stopping.c: the error distribution of a denoised image and the stopping criterion
 * (docs/mathematics.md §2.8; Firmino 2024 Eqs. 3, 14-16).
 *
 * The scaled error of value i is modelled as s_i² (Z + √λ_i)², Z ~ N(0, 1): a scaled
 * noncentral χ² with one degree of freedom, whose CDF is closed-form,
 *     F_i(τ) = Φ(√(τ/s_i²) - √λ_i) - Φ(-√(τ/s_i²) - √λ_i),
 * with s_i² = Var^r_i and λ_i from the block sums (Eq. 14). The image CDF F(τ) is the
 * mean over values; stop when F(τ) >= p; percentiles solve F(τ) = p in log τ on
 * compressed copies of the distribution (below). Sums run in double per row, rows in
 * order. */
#include "estimate.h"
#include "internal.h"

#include <math.h>
#include <omp.h>
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

/* g[j] = F_j for n values v[j] = s_j² with sqrt(λ) l[j]; v = 0 gives 1 (the error is
 * 0, below every τ > 0), whatever λ: the formula alone, with s² clamped to 1e-37, would
 * give 0 for τ < λ / 9e36, a λ that a block without variance reaches (SURE / 1e-6:
 * docs/mathematics.md, "Quiet blocks are not cut"), and the percentile search asks
 * about τ that small. On x86-64
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
        const float f = 1.0f - q_low - upper_tail(a + l[j]);
        const int32_t keep = -(int32_t)(b > 0); /* a select without a branch: 1.0f */
        g[j] = i2f((f2i(f) & keep) | (0x3f800000 & ~keep));
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
mcp__error_dist_image(const mcp_error_dist *d, int with_s2, mcp_image **out)
{
    *out = NULL;
    if (!d) return mcp_error("error distribution: missing");
    static const char *const names[6] = {"lambda.R", "lambda.G", "lambda.B",
                                         "s2.R",     "s2.G",     "s2.B"};
    const mcp_blocks *b = d->blocks;
    if (mcp__image_new(b->width, b->height, with_s2 ? 6 : 3, names, "error distribution",
                       out))
        return -1;
    mcp_image *img = *out;
    /* a block's pixels are its own: the blocks fill the image in any order */
#pragma omp parallel for schedule(dynamic, 1)
    for (int i = 0; i < b->count; i++) {
        const mcp_block *k = &b->items[i];
        float l[3];
        for (int c = 0; c < 3; c++)
            l[c] = (float)mcp_error_dist_lambda(d, i, c);
        for (int y = k->y; y < k->y + k->h; y++)
            for (int x = k->x; x < k->x + k->w; x++) {
                float *o = mcp_image_px(img, x, y);
                memcpy(o, l, sizeof l);
                if (with_s2) memcpy(o + 3, mcp_image_px(d->var_rel, x, y), sizeof l);
            }
    }
    return 0;
}

int
mcp_error_dist_image(const mcp_error_dist *d, mcp_image **out)
{
    return mcp__error_dist_image(d, 1, out);
}

double
mcp_error_cdf(const mcp_error_dist *d, double tau)
{
    if (!d || d->n_values == 0) return 1.0;
    if (!(tau > 0.0)) return 0.0;
    const mcp_blocks *b = d->blocks;
    const mcp_image *var = d->var_rel;
    double *block_sum = mcp_malloc(((size_t)b->count + 1) * sizeof *block_sum);
    if (!block_sum) return NAN; /* the error line is set */
    float root_tau = (float)sqrt(tau);
    int failed = 0, n_max = 3 * d->max_w;
    int packed = var->pixel_stride == 3;
#pragma omp parallel reduction(+ : failed)
    {
        float *lpat = mcp_malloc((size_t)(n_max + 1) * sizeof *lpat);
        float *g = mcp_malloc((size_t)(n_max + 1) * sizeof *g);
        float *row = packed ? NULL : mcp_malloc((size_t)(n_max + 1) * sizeof *row);
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
    if (failed) {
        mcp_error("error CDF: out of memory");
        return NAN;
    }
    double f = total / (double)d->n_values;
    if (isnan(f)) mcp_error("error CDF at tau %g is not a number", tau);
    return f;
}

int
mcp_error_should_stop(const mcp_error_dist *d, double tau, double p, double *cdf)
{
    double f = mcp_error_cdf(d, tau);
    if (cdf) *cdf = f;
    return isnan(f) ? -1 : f >= p;
}

/* ---- percentiles ----
 *
 * A percentile needs F at some 20 values of τ, and each exact F is a pass over every
 * value (6 million for a 1080p image). F_i depends on a value only through s_i² and its
 * block's λ, so the search runs on compressed copies instead: per block and channel, the
 * s² values grouped by their float's exponent and top mantissa bits, each group standing
 * at the geometric centre of its bin with its count. F_i is a function of τ / s_i², so
 * where a bin spans at most a factor e^2h in s² the compressed F lies between F(τ e^-h)
 * and F(τ e^h), and the percentile it gives is within a factor e^±h of the exact one.
 * Two levels: coarse bins (64 per octave, h = 7.8e-3; tens of thousands of bins for a
 * 1080p image) find each percentile from a shared grid of τ, and fine bins (1024 per
 * octave, h = 4.9e-4) refine it inside the coarse answer's ±(h_coarse + h_fine): a few
 * evaluations instead of 20 over every value. The result is within 6e-4 of the exact
 * root (h_fine and the search's 1e-4); the API promises 1e-3. Sums run over fixed chunks
 * in order, so the result does not depend on the thread count. */

#define FINE_SHIFT 13   /* 23 mantissa bits - 10 kept: 1024 bins per octave */
#define COARSE_SHIFT 17 /* 6 kept: 64 per octave */
#define FINE_KEYS (1 << (31 - FINE_SHIFT))
#define BIN_CHUNK 4096 /* bins per parallel task */
#define GRID 48        /* coarse τ grid points between the bracket's ends */
#define RUN 256        /* bins per run that may be saturated as a whole */
/* F_i is 1.0f once a - l >= SAT_Z: fold_cdf's tails are then below 1e-9, under half
 * of float's last step below 1 (2^-25), so 1 - Q - Q rounds to exactly 1 */
#define SAT_Z 6.5

/* The fine bin of s² >= 0 (-0 included): its float's bits without the sign, shifted. */
static inline int
fine_key(float s2)
{
    return (f2i(s2) & 0x7fffffff) >> FINE_SHIFT;
}

/* The half-width in log s² of the widest bin at a shift (its first mantissa step). */
static double
bin_half_width(int shift)
{
    return 0.5 * log1p(ldexp(1.0, shift - 23));
}

typedef struct {
    float *s2, *l, *count; /* per bin: representative s², √λ, number of values */
    long n;
    /* per run of RUN bins: the τ from which each of its F_i is 1.0f (run_sat), and its
       count (run_count); set by bin_set_runs */
    double *run_sat, *run_count;
} bin_set;

typedef struct {
    bin_set fine, coarse;
    double top, s2_min; /* every F_i is 1 above top; the smallest bin edge > 0 */
    double n_values;
} binned_dist;

static void
bin_set_free(bin_set *b)
{
    free(b->s2);
    free(b->l);
    free(b->count);
    free(b->run_sat);
    free(b->run_count);
    memset(b, 0, sizeof *b);
}

static int
bin_set_alloc(bin_set *b, long n)
{
    memset(b, 0, sizeof *b);
    b->s2 = mcp_malloc((size_t)(n + 1) * sizeof *b->s2);
    b->l = mcp_malloc((size_t)(n + 1) * sizeof *b->l);
    b->count = mcp_malloc((size_t)(n + 1) * sizeof *b->count);
    return b->s2 && b->l && b->count ? 0 : -1;
}

static void
bin_push(bin_set *b, int key, int shift, float l, uint32_t count)
{
    double b0 = i2f(key << shift), b1 = i2f((key + 1) << shift);
    b->s2[b->n] = (float)sqrt(b0 * b1); /* the bin of 0 and denormals stands at 0 */
    b->l[b->n] = l;
    b->count[b->n] = (float)count;
    b->n++;
}

/* One thread's bins: the blocks it binned, one after the other, in chunks of
 * CHUNK_BINS bins or of one block's (bin_set_join puts them in block order). A few
 * dozen bytes a block where each block had arrays of its own: at a block per pixel
 * (Alg. 1 on a render whose variance is understated) those took 300 bytes a pixel.
 * Chunks, not one array grown as needed: a grown array is new memory each time, whose
 * first touch is slow on some machines (docs/benchmarks.md, "Renders without variance,
 * and 8K"), where a chunk takes memory the heap holds. */
#define CHUNK_BINS (1L << 18)

typedef struct {
    bin_set bins;
    long cap;
} bin_chunk;

typedef struct {
    bin_chunk *items;
    int n, cap;
} bin_chunks;

typedef struct {
    bin_chunks fine, coarse;
    double top, s2_min;
} bin_arena;

typedef struct {
    int arena;                    /* the thread whose arena holds the block's bins */
    int fine_chunk, coarse_chunk; /* the chunks, and where the bins start in them */
    long fine0, coarse0;
    int fine_n, coarse_n;
} block_bins;

/* The chunk that takes `more` bins next (its index in *chunk), or NULL when out of
 * memory. */
static bin_set *
chunk_room(bin_chunks *c, long more, int *chunk)
{
    if (c->n && c->items[c->n - 1].bins.n + more <= c->items[c->n - 1].cap) {
        *chunk = c->n - 1;
        return &c->items[c->n - 1].bins;
    }
    if (c->n == c->cap) {
        const int cap = c->cap ? 2 * c->cap : 8;
        bin_chunk *grown = mcp_realloc(c->items, (size_t)cap * sizeof *grown);
        if (!grown) return NULL;
        c->items = grown;
        c->cap = cap;
    }
    bin_chunk *k = &c->items[c->n];
    k->cap = more > CHUNK_BINS ? more : CHUNK_BINS;
    if (bin_set_alloc(&k->bins, k->cap)) {
        bin_set_free(&k->bins);
        return NULL;
    }
    *chunk = c->n++;
    return &k->bins;
}

static void
chunks_free(bin_chunks *c)
{
    for (int i = 0; i < c->n; i++)
        bin_set_free(&c->items[i].bins);
    free(c->items);
    memset(c, 0, sizeof *c);
}

/* Bins block i's values per channel into the arena (fine and coarse), with hist[3]
 * zeroed tables of HIST_COUNTS counts (left zeroed): FINE_KEYS fine counts, then the
 * coarse ones, which the scan uses to step over empty runs of fine keys (a block's values
 * span tens of octaves, 1024 fine keys each, most of them empty). */
#define MERGE (COARSE_SHIFT - FINE_SHIFT) /* fine keys per coarse one: 1 << MERGE */
#define HIST_COUNTS (FINE_KEYS + (FINE_KEYS >> MERGE))
static int
bin_block(const mcp_error_dist *d, int i, uint32_t *hist[3], bin_arena *a, block_bins *at)
{
    const mcp_block *k = &d->blocks->items[i];
    int lo[3] = {FINE_KEYS, FINE_KEYS, FINE_KEYS}, hi[3] = {-1, -1, -1};
    for (int y = k->y; y < k->y + k->h; y++)
        for (int x = k->x; x < k->x + k->w; x++) {
            const float *v = mcp_image_px(d->var_rel, x, y);
            for (int c = 0; c < 3; c++) {
                int key = fine_key(v[c]);
                hist[c][key]++;
                hist[c][FINE_KEYS + (key >> MERGE)]++;
                lo[c] = key < lo[c] ? key : lo[c];
                hi[c] = key > hi[c] ? key : hi[c];
            }
        }
    long cap = 0, values = (long)k->w * k->h;
    for (int c = 0; c < 3; c++)
        cap += hi[c] - lo[c] + 1 < values ? hi[c] - lo[c] + 1 : values;
    bin_set *to_fine = chunk_room(&a->fine, cap, &at->fine_chunk),
            *to_coarse = to_fine ? chunk_room(&a->coarse, cap, &at->coarse_chunk) : NULL;
    const int failed = !to_coarse;
    at->fine0 = to_fine ? to_fine->n : 0;
    at->coarse0 = to_coarse ? to_coarse->n : 0;
    for (int c = 0; c < 3; c++) {
        float l = d->sqrt_lambda[3 * i + c];
        double r = l + TAIL_Z + 1.0;
        uint32_t *coarse = hist[c] + FINE_KEYS;
        for (int ck = lo[c] >> MERGE; ck <= hi[c] >> MERGE; ck++) {
            const uint32_t coarse_count = coarse[ck];
            if (!coarse_count) continue;
            coarse[ck] = 0;
            for (int key = ck << MERGE; key < (ck + 1) << MERGE; key++) {
                const uint32_t n = hist[c][key];
                if (!n) continue;
                hist[c][key] = 0;
                if (failed) continue; /* the tables are left zeroed all the same */
                bin_push(to_fine, key, FINE_SHIFT, l, n);
                double b0 = i2f(key << FINE_SHIFT), b1 = i2f((key + 1) << FINE_SHIFT);
                if (b0 > 0.0) { /* the bin of 0 (and denormals) has F = 1 at every τ */
                    a->top = fmax(a->top, b1 * r * r);
                    a->s2_min = fmin(a->s2_min, b0);
                }
            }
            if (!failed) bin_push(to_coarse, ck, COARSE_SHIFT, l, coarse_count);
        }
    }
    at->fine_n = failed ? 0 : (int)(to_fine->n - at->fine0);
    at->coarse_n = failed ? 0 : (int)(to_coarse->n - at->coarse0);
    return failed ? -1 : 0;
}

/* The blocks' bins in block order, from the arenas, whose chunks are freed as soon as
 * they are copied: a thread binned its blocks in increasing order, each into its last
 * chunk or a new one, so once a block of an arena lies in chunk j no later block reads
 * that arena's chunks below j. The percentiles peaked with the bins held twice: at 8K
 * this took 90 MB off the streamed estimate's peak (docs/benchmarks.md, "The estimate
 * in bands"). */
static int
bin_set_join(bin_arena *arenas, int n_arenas, const block_bins *at, int n, int coarse,
             bin_set *out)
{
    long total = 0;
    for (int i = 0; i < n; i++)
        total += coarse ? at[i].coarse_n : at[i].fine_n;
    int *freed_below = mcp_calloc((size_t)n_arenas, sizeof *freed_below);
    if (!freed_below || bin_set_alloc(out, total)) {
        free(freed_below);
        return -1;
    }
    for (int i = 0; i < n; i++) {
        const int t = at[i].arena, chunk = coarse ? at[i].coarse_chunk : at[i].fine_chunk;
        bin_chunks *chunks = coarse ? &arenas[t].coarse : &arenas[t].fine;
        for (; freed_below[t] < chunk; freed_below[t]++)
            bin_set_free(&chunks->items[freed_below[t]].bins);
        const bin_set *b = &chunks->items[chunk].bins;
        const long from = coarse ? at[i].coarse0 : at[i].fine0;
        const int count = coarse ? at[i].coarse_n : at[i].fine_n;
        memcpy(out->s2 + out->n, b->s2 + from, (size_t)count * sizeof *b->s2);
        memcpy(out->l + out->n, b->l + from, (size_t)count * sizeof *b->l);
        memcpy(out->count + out->n, b->count + from, (size_t)count * sizeof *b->count);
        out->n += count;
    }
    free(freed_below);
    for (int t = 0; t < n_arenas; t++)
        chunks_free(coarse ? &arenas[t].coarse : &arenas[t].fine);
    return 0;
}

/* The runs' saturation points and counts. A bin's F_i is 1.0f (fold_cdf) for τ >=
 * s² (√λ + SAT_Z)² (1 + 1e-5: a's float rounding), so a run whose every bin is past
 * that point adds its count exactly, without an erfc: at the percentiles' τ that is
 * most bins, as the blocks' quiet values sit far below it. The sum of whole counts is
 * exact in double whatever the order, so the skip gives the bits of the full
 * evaluation. */
static int
bin_set_runs(bin_set *b)
{
    const long runs = (b->n + RUN - 1) / RUN;
    b->run_sat = mcp_malloc((size_t)(runs + 1) * sizeof *b->run_sat);
    b->run_count = mcp_malloc((size_t)(runs + 1) * sizeof *b->run_count);
    if (!b->run_sat || !b->run_count) return -1;
#pragma omp parallel for schedule(static)
    for (long r = 0; r < runs; r++) {
        double sat = 0.0, count = 0.0;
        for (long j = r * RUN; j < b->n && j < (r + 1) * RUN; j++) {
            const double z = (double)b->l[j] + SAT_Z;
            sat = fmax(sat, (double)b->s2[j] * z * z * (1.0 + 1e-5));
            count += b->count[j];
        }
        b->run_sat[r] = sat;
        b->run_count[r] = count;
    }
    return 0;
}

static void
binned_free(binned_dist *bd)
{
    bin_set_free(&bd->fine);
    bin_set_free(&bd->coarse);
}

static int
binned_new(const mcp_error_dist *d, binned_dist *bd)
{
    memset(bd, 0, sizeof *bd);
    const mcp_blocks *b = d->blocks;
    bd->n_values = (double)d->n_values;
    bd->top = 0.0;
    bd->s2_min = INFINITY;
    const int n_arenas = omp_get_max_threads();
    bin_arena *arenas = mcp_calloc((size_t)n_arenas, sizeof *arenas);
    block_bins *at = mcp_calloc((size_t)b->count + 1, sizeof *at);
    if (!arenas || !at) {
        free(arenas);
        free(at);
        return mcp_error("out of memory (error percentiles)");
    }
    int failed = 0;
#pragma omp parallel num_threads(n_arenas) reduction(+ : failed)
    {
        const int t = omp_get_thread_num();
        bin_arena *a = &arenas[t];
        a->top = 0.0;
        a->s2_min = INFINITY;
        uint32_t *hist[3];
        for (int c = 0; c < 3; c++)
            hist[c] = mcp_calloc(HIST_COUNTS, sizeof *hist[c]);
        int ok = hist[0] && hist[1] && hist[2];
        failed += !ok;
#pragma omp for schedule(dynamic, 1)
        for (int i = 0; i < b->count; i++) {
            at[i].arena = t;
            if (ok) failed += bin_block(d, i, hist, a, &at[i]) != 0;
        }
        for (int c = 0; c < 3; c++)
            free(hist[c]);
    }
    if (!failed) {
        failed = bin_set_join(arenas, n_arenas, at, b->count, 0, &bd->fine) ||
                 bin_set_join(arenas, n_arenas, at, b->count, 1, &bd->coarse) ||
                 bin_set_runs(&bd->fine) || bin_set_runs(&bd->coarse);
        for (int t = 0; t < n_arenas; t++) {
            bd->top = fmax(bd->top, arenas[t].top);
            bd->s2_min = fmin(bd->s2_min, arenas[t].s2_min);
        }
    }
    for (int t = 0; t < n_arenas; t++) {
        chunks_free(&arenas[t].fine);
        chunks_free(&arenas[t].coarse);
    }
    free(arenas);
    free(at);
    if (failed) {
        binned_free(bd);
        return mcp_error("out of memory (error percentiles)");
    }
    return 0;
}

/* f[t] = F(tau[t]) of a compressed distribution for t < m: the bins' F_i weighted by
 * their counts, summed in double per chunk and over chunks in order. All m in one
 * parallel pass, because a parallel region costs more than a small evaluation where
 * threads wait for a busy machine's scheduler. -1 when out of memory. */
static int
bin_set_cdf(const bin_set *b, double n_values, int m, const double *tau, double *f)
{
    long n_chunks = (b->n + BIN_CHUNK - 1) / BIN_CHUNK;
    double *chunk_sum = mcp_malloc((size_t)(n_chunks * m + 1) * sizeof *chunk_sum);
    if (!chunk_sum) return -1;
#pragma omp parallel if (n_chunks * m > 4)
    {
        float g[RUN];
#pragma omp for schedule(dynamic, 1) collapse(2)
        for (long q = 0; q < n_chunks; q++)
            for (int t = 0; t < m; t++) {
                long j0 = q * BIN_CHUNK;
                int n = (int)(b->n - j0 < BIN_CHUNK ? b->n - j0 : BIN_CHUNK);
                double sum = 0.0;
                for (int r0 = 0; tau[t] > 0.0 && r0 < n; r0 += RUN) {
                    const long r = (j0 + r0) / RUN;
                    const int rn = n - r0 < RUN ? n - r0 : RUN;
                    if (tau[t] >= b->run_sat[r]) { /* every F_i of the run is 1 */
                        sum += b->run_count[r];
                        continue;
                    }
                    fold_cdf(b->s2 + j0 + r0, b->l + j0 + r0, g, rn, (float)sqrt(tau[t]));
                    const float *cnt = b->count + j0 + r0;
                    double part = 0.0;
                    /* reassociated in vector lanes: the same bits for a given build */
#pragma omp simd reduction(+ : part)
                    for (int j = 0; j < rn; j++)
                        part += (double)cnt[j] * g[j];
                    sum += part;
                }
                chunk_sum[q * m + t] = sum;
            }
    }
    for (int t = 0; t < m; t++) {
        double total = 0.0;
        for (long q = 0; q < n_chunks; q++)
            total += chunk_sum[q * m + t];
        f[t] = total / n_values;
    }
    free(chunk_sum);
    return 0;
}

/* One percentile's search: its bracket [e^a, e^b] in log τ with F - p at both ends. */
typedef struct {
    double p, a, b, ra, rb, width; /* width: the bracket three steps ago */
    int side, steps;
} search;

static void
search_start(search *s, double p, double lo, double hi, double f_lo, double f_hi)
{
    *s = (search){p, log(lo), log(hi), f_lo - p, f_hi - p, log(hi / lo), 0, 0};
}

/* The τ with F(τ) = p for every search (F(lo) < p <= F(hi)), all in step: false
 * position in log τ with the Illinois step (the stale end's residual halved) and a
 * bisection step whenever three steps have not halved a bracket; each ends at its hi
 * once hi / lo < 1 + 1e-4. */
static int
solve_log(const bin_set *bins, double n_values, search *s, int m, double *out)
{
    double x[MCP_ESTIMATE_MAX_PERCENTILES], f[MCP_ESTIMATE_MAX_PERCENTILES];
    int open[MCP_ESTIMATE_MAX_PERCENTILES];
    for (;;) {
        int n = 0;
        for (int k = 0; k < m; k++) {
            search *e = &s[k];
            if (e->b - e->a <= PERCENTILE_RTOL) continue;
            double t = e->a - e->ra * (e->b - e->a) / (e->rb - e->ra);
            if (++e->steps % 3 == 0) {
                if (e->b - e->a > 0.5 * e->width) t = 0.5 * (e->a + e->b);
                e->width = e->b - e->a;
            }
            double margin = 0.25 * PERCENTILE_RTOL; /* strictly inside */
            x[n] = exp(fmin(fmax(t, e->a + margin), e->b - margin));
            open[n++] = k;
        }
        if (n == 0) break;
        if (bin_set_cdf(bins, n_values, n, x, f)) return -1;
        for (int i = 0; i < n; i++) {
            search *e = &s[open[i]];
            double r = f[i] - e->p;
            if (r >= 0.0) {
                e->b = log(x[i]);
                e->rb = r;
                if (e->side == 1) e->ra *= 0.5;
                e->side = 1;
            } else {
                e->a = log(x[i]);
                e->ra = r;
                if (e->side == -1) e->rb *= 0.5;
                e->side = -1;
            }
        }
    }
    for (int k = 0; k < m; k++)
        out[k] = exp(s[k].b);
    return 0;
}

/* The percentiles on the fine bins from the coarse answers tc: each root lies within
 * e^±(h_coarse + h_fine) of its coarse one (both bound the exact root's distance); a
 * bracket is widened should rounding put the root outside it. */
static int
refine(const binned_dist *bd, const double *p, const double *tc, int m, double *out)
{
    search s[MCP_ESTIMATE_MAX_PERCENTILES];
    double t[2 * MCP_ESTIMATE_MAX_PERCENTILES], f[2 * MCP_ESTIMATE_MAX_PERCENTILES];
    double h =
        bin_half_width(COARSE_SHIFT) + bin_half_width(FINE_SHIFT) + 2 * PERCENTILE_RTOL;
    const bin_set *fine = &bd->fine;
    /* first a bracket of ±3e-4: the coarse answer is far closer than its bound, since
     * a bin's values spread on both sides of its centre */
    double first = 3e-4;
    for (int k = 0; k < m; k++) {
        t[2 * k] = tc[k] * exp(-first);
        t[2 * k + 1] = tc[k] * exp(first);
    }
    if (bin_set_cdf(fine, bd->n_values, 2 * m, t, f)) return -1;
    for (int k = 0; k < m; k++) {
        double lo = t[2 * k], hi = t[2 * k + 1], f_lo = f[2 * k], f_hi = f[2 * k + 1];
        for (double w = h; !(f_lo < p[k] && f_hi >= p[k]) && w < 1e3 * h; w *= 4) {
            double ends[2] = {tc[k] * exp(-w), tc[k] * exp(w)}, fe[2];
            if (bin_set_cdf(fine, bd->n_values, 2, ends, fe)) return -1;
            lo = ends[0], hi = ends[1], f_lo = fe[0], f_hi = fe[1];
        }
        if (f_lo < p[k] && f_hi >= p[k])
            search_start(&s[k], p[k], lo, hi, f_lo, f_hi);
        else /* not bracketed (rounding at p near 0 or 1): the coarse answer stands */
            search_start(&s[k], p[k], tc[k], tc[k], 0.0, 0.0);
    }
    return solve_log(fine, bd->n_values, s, m, out);
}

int
mcp_error_percentiles(const mcp_error_dist *d, const double *p, int n, double *tau)
{
    if (!d) return mcp_error("error percentiles: missing distribution");
    if (n < 0 || n > MCP_ESTIMATE_MAX_PERCENTILES)
        return mcp_error("error percentiles: at most %d (got %d)",
                         MCP_ESTIMATE_MAX_PERCENTILES, n);
    for (int k = 0; k < n; k++)
        if (!(p[k] >= 0.0 && p[k] < 1.0))
            return mcp_error("error percentiles: p must be in [0, 1) (got %g)", p[k]);
    binned_dist bd;
    if (binned_new(d, &bd)) return -1;
    /* the bracket: above top every F_i is 1 (to double precision); below bottom
     * every F_i with s_i > 0 is < 1e-4 */
    double top = bd.top, bottom = bd.s2_min * 1e-8;
    int rc = -1;
    if (top == 0.0 || !isfinite(bottom)) { /* every s_i is 0: no error */
        for (int k = 0; k < n; k++)
            tau[k] = 0.0;
        rc = 0;
        goto done;
    }
    /* the coarse F on a grid shared by the percentiles, then each one's cell */
    double grid_tau[GRID + 1], grid_f[GRID + 1], tc[MCP_ESTIMATE_MAX_PERCENTILES];
    const bin_set *cs = &bd.coarse;
    for (int g = 0; g <= GRID; g++)
        grid_tau[g] = g == GRID ? top : bottom * pow(top / bottom, (double)g / GRID);
    if (bin_set_cdf(cs, bd.n_values, GRID + 1, grid_tau, grid_f)) goto done;
    search s[MCP_ESTIMATE_MAX_PERCENTILES];
    int which[MCP_ESTIMATE_MAX_PERCENTILES], m = 0;
    for (int k = 0; k < n; k++) {
        int g = 0;
        while (g <= GRID && !(grid_f[g] >= p[k]))
            g++;
        if (g > GRID) { /* only by rounding, for p near 1 */
            tau[k] = INFINITY;
            continue;
        }
        double lo = bottom, hi = grid_tau[g], f_lo = grid_f[g], f_hi = grid_f[g];
        if (g > 0) {
            lo = grid_tau[g - 1];
            f_lo = grid_f[g - 1];
        }
        for (int tries = 0; tries < 8 && f_lo >= p[k]; tries++) { /* F >= p at bottom */
            hi = lo;
            f_hi = f_lo;
            lo *= 1e-4;
            if (bin_set_cdf(cs, bd.n_values, 1, &lo, &f_lo)) goto done;
        }
        if (f_lo >= p[k]) { /* reached below any scale that matters */
            tau[k] = 0.0;
            continue;
        }
        search_start(&s[m], p[k], lo, hi, f_lo, f_hi);
        which[m++] = k;
    }
    double pm[MCP_ESTIMATE_MAX_PERCENTILES], fine[MCP_ESTIMATE_MAX_PERCENTILES];
    for (int i = 0; i < m; i++)
        pm[i] = p[which[i]];
    if (solve_log(cs, bd.n_values, s, m, tc) || refine(&bd, pm, tc, m, fine)) goto done;
    for (int i = 0; i < m; i++)
        tau[which[i]] = fine[i];
    rc = 0;
done:
    binned_free(&bd);
    return rc ? mcp_error("out of memory (error percentiles)") : 0;
}
