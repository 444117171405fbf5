/* sampling_map.c: denoising-aware adaptive sampling
 * (docs/mathematics.md §2.6; Firmino 2023 Eqs. 3-5 and §4.1).
 *
 * Per pixel s_p = mean_c Var[F_c] / ((n_p + 1)(F_c² + EPS_REL)), clipped at 0, blurred
 * (Gaussian σ 0.5 in 5x5) and normalised to sum 1. Variants: tone-mapped,
 * Var[T(F)] = T'(F)² Var[F] (J_T v = T'(F) ⊙ J v, so the probe estimate squares to
 * exactly this) over (n_p + 1) without the relative division; MC-SURE, SURE in the
 * numerator with a σ 4, 17x17 blur. Counts for a budget by largest remainders, so
 * they sum exactly to it. */
#define _POSIX_C_SOURCE 200809L /* clock_gettime, strcasecmp */
#include "estimate.h"
#include "internal.h"

#include <mcpost/filter.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

static const char *const kind_names[] = {"variance", "tonemapped", "mc-sure"};
const mcp_wordlist mcp_sampling_kind_words = {"sampling map", kind_names, 3};

int
mcp_sampling_kind_from_name(const char *name, mcp_sampling_kind *out)
{
    return mcp_wordlist_find(&mcp_sampling_kind_words, name, (int *)out);
}

const char *
mcp_sampling_kind_name(mcp_sampling_kind kind)
{
    return (unsigned)kind < 3 ? kind_names[kind] : "unknown";
}

mcp_sampling_options
mcp_sampling_defaults(void)
{
    mcp_sampling_options o;
    memset(&o, 0, sizeof o);
    o.kind = MCP_SAMPLING_VARIANCE;
    o.blur_sigma_px = 0.0; /* per kind */
    o.blur_window = 0;
    o.tone_map = MCP_TONEMAP_ACES;
    return o;
}

static int
same_shape(const char *who, const char *what, const mcp_image *img, const mcp_image *like,
           int channels)
{
    if (!img) return mcp_error("%s: missing %s", who, what);
    if (img->width != like->width || img->height != like->height)
        return mcp_error("%s: %s: size %dx%d does not match %dx%d", who, what, img->width,
                         img->height, like->width, like->height);
    if (img->channels < channels)
        return mcp_error("%s: %s needs %d channels (got %d)", who, what, channels,
                         img->channels);
    return 0;
}

/* Normalises channel 0 of a packed 1-channel image to sum 1 (uniform when the sum is
 * not positive). Sums in double per row, rows in order. */
static int
normalise(mcp_image *img)
{
    int w = img->width, h = img->height;
    double *row = mcp_calloc((size_t)h, sizeof *row), total = 0.0;
    if (!row) return -1;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        double s = 0.0;
        for (int x = 0; x < w; x++)
            s += mcp_image_px(img, x, y)[0];
        row[y] = s;
    }
    for (int y = 0; y < h; y++)
        total += row[y];
    free(row);
    double scale = total > 0.0 && isfinite(total) ? 1.0 / total : 0.0;
    double uniform = 1.0 / ((double)w * h);
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float *p = mcp_image_px(img, x, y);
            p[0] = (float)(scale > 0.0 ? p[0] * scale : uniform);
        }
    return 0;
}

/* The blur of a kind's map, where the options leave it to the kind; -1 on bad
 * options. */
static int
blur_of(const mcp_sampling_options *o, double *sigma, int *window)
{
    if ((unsigned)o->kind > MCP_SAMPLING_MC_SURE)
        return mcp_error("sampling map: unknown kind %d", (int)o->kind);
    *sigma = o->blur_sigma_px > 0.0            ? o->blur_sigma_px
             : o->kind == MCP_SAMPLING_MC_SURE ? 4.0
                                               : 0.5;
    *window = o->blur_window > 0                ? o->blur_window
              : o->kind == MCP_SAMPLING_MC_SURE ? 17
                                                : 5;
    if (!isfinite(*sigma) || *sigma < 0.0)
        return mcp_error("sampling map: blur_sigma_px must be >= 0 (got %g)",
                         o->blur_sigma_px);
    if (*window % 2 == 0 || *window > 1001)
        return mcp_error("sampling map: blur_window must be odd and <= 1001 (got %d)",
                         o->blur_window);
    return 0;
}

int
mcp__sampling_check(const mcp_sampling_options *o)
{
    double sigma = 0.0;
    int window = 0;
    return blur_of(o, &sigma, &window);
}

void
mcp__sampling_weights_rows(const mcp_dump *dump, const mcp_image *denoised,
                           const mcp_image *numerator, const mcp_sampling_options *o,
                           mcp_image *s)
{
    const int w = denoised->width, h = denoised->height;
    const mcp_sampling_kind kind = o->kind;
    const mcp_tonemap tm = o->tone_map;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *f = mcp_image_px(denoised, x, y),
                        *v = mcp_image_px(numerator, x, y);
            double n1 = mcp_dump_spp_at(dump, x, y) + 1.0, sum = 0.0;
            for (int c = 0; c < 3; c++) {
                if (kind == MCP_SAMPLING_TONEMAPPED) {
                    double slope = mcp_tonemap_slope(tm, f[c]);
                    sum += slope * slope * v[c] / n1;
                } else {
                    sum += v[c] / (n1 * ((double)f[c] * f[c] + MCP_EPS_REL));
                }
            }
            double sp = sum / 3.0;
            mcp_image_px(s, x, y)[0] = (float)(sp > 0.0 && isfinite(sp) ? sp : 0.0);
        }
}

int
mcp__sampling_weights_begin(int w, int h, mcp_image **out)
{
    static const char *const name[1] = {"weight"};
    return mcp__image_new(w, h, 1, name, "sampling map", out);
}

int
mcp__sampling_map_finish(mcp_image **weights, const mcp_sampling_options *o)
{
    double sigma = 0.0;
    int window = 0;
    if (blur_of(o, &sigma, &window)) return -1;
    mcp_image *s = *weights;
    if (sigma > 0.0 && window > 1) {
        mcp_image *blurred = NULL;
        if (mcp_gaussian_blur(s, window, sigma, &blurred)) return -1;
        mcp_image_free(s);
        *weights = s = blurred;
    }
    return normalise(s) || mcp_image_set_source(s, "sampling map") ? -1 : 0;
}

int
mcp_sampling_map(const mcp_dump *dump, const mcp_image *denoised,
                 const mcp_image *numerator, const mcp_sampling_options *opt,
                 mcp_image **map)
{
    *map = NULL;
    mcp_sampling_options o = opt ? *opt : mcp_sampling_defaults();
    if (mcp__sampling_check(&o)) return -1;
    if (!dump || !dump->color) return mcp_error("sampling map: missing dump");
    if (same_shape("sampling map", "denoised image", denoised, dump->color, 3) ||
        same_shape("sampling map", "numerator", numerator, dump->color, 3))
        return -1;
    mcp_image *s = NULL;
    if (mcp__sampling_weights_begin(denoised->width, denoised->height, &s)) return -1;
    mcp__sampling_weights_rows(dump, denoised, numerator, &o, s);
    if (mcp__sampling_map_finish(&s, &o)) {
        mcp_image_free(s);
        return -1;
    }
    *map = s;
    return 0;
}

/* ---- integer counts by largest remainders ---- */

typedef struct rem {
    double frac;
    long idx;
} rem;

/* The total order "larger fraction first, then lower index". */
static int
before(const rem *a, const rem *b)
{
    return a->frac > b->frac || (a->frac == b->frac && a->idx < b->idx);
}

static void
swap_rem(rem *a, rem *b)
{
    rem t = *a;
    *a = *b;
    *b = t;
}

/* Moves the k first elements (in `before` order) of v[0..n) to the front
 * (quickselect, median-of-three pivots; deterministic). */
static void
select_first(rem *v, long n, long k)
{
    long lo = 0, hi = n - 1;
    while (lo < hi && k > lo && k <= hi) {
        long mid = lo + (hi - lo) / 2;
        if (before(&v[mid], &v[lo])) swap_rem(&v[mid], &v[lo]);
        if (before(&v[hi], &v[lo])) swap_rem(&v[hi], &v[lo]);
        if (before(&v[hi], &v[mid])) swap_rem(&v[hi], &v[mid]);
        rem pivot = v[mid];
        long i = lo, j = hi;
        while (i <= j) {
            while (before(&v[i], &pivot))
                i++;
            while (before(&pivot, &v[j]))
                j--;
            if (i <= j) {
                swap_rem(&v[i], &v[j]);
                i++;
                j--;
            }
        }
        /* now v[lo..j] come before-or-equal pivot, v[i..hi] after-or-equal */
        if (k <= j + 1)
            hi = j;
        else if (k >= i)
            lo = i;
        else
            break; /* the k-th boundary lies on elements equal to the pivot */
    }
}

int
mcp_sample_counts(const mcp_image *map, int64_t budget, mcp_image **counts)
{
    *counts = NULL;
    if (!map || map->channels < 1) return mcp_error("sample counts: missing map");
    if (budget < 0 || budget > ((int64_t)1 << 52))
        return mcp_error("sample counts: budget must be in [0, 2^52] (got %lld)",
                         (long long)budget);
    int w = map->width, h = map->height;
    long n = (long)w * h;
    double *row = mcp_calloc((size_t)h, sizeof *row), total = 0.0;
    rem *r = mcp_calloc((size_t)n, sizeof *r);
    int64_t *cnt = mcp_calloc((size_t)n, sizeof *cnt);
    long bad = 0;
    int rc = -1;
    if (!row || !r || !cnt) goto done;
#pragma omp parallel for schedule(static) reduction(+ : bad)
    for (int y = 0; y < h; y++) {
        double s = 0.0;
        for (int x = 0; x < w; x++) {
            double v = mcp_image_px(map, x, y)[0];
            if (!(v >= 0.0) || !isfinite(v))
                bad++;
            else
                s += v;
        }
        row[y] = s;
    }
    if (bad) {
        mcp_error("sample counts: %s: %ld weights are negative or not finite",
                  map->source ? map->source : "map", bad);
        goto done;
    }
    for (int y = 0; y < h; y++)
        total += row[y];
    double uniform = total > 0.0 ? 0.0 : 1.0;
    double scale = (double)budget / (total > 0.0 ? total : (double)n);
    int64_t floor_sum = 0;
    for (int y = 0; y < h; y++) /* sequential: floor_sum is exact in int64 */
        for (int x = 0; x < w; x++) {
            long i = (long)y * w + x;
            double q = (uniform > 0.0 ? 1.0 : mcp_image_px(map, x, y)[0]) * scale;
            double f = floor(q);
            cnt[i] = (int64_t)f;
            r[i].frac = q - f;
            r[i].idx = i;
            floor_sum += cnt[i];
        }
    int64_t left = budget - floor_sum;
    /* Rounding of q can make the floors overshoot by a few: take those back from the
     * smallest fractions among non-zero counts. */
    while (left < 0) {
        long best = -1;
        for (long i = 0; i < n; i++)
            if (cnt[i] > 0 && (best < 0 || r[i].frac < r[best].frac)) best = i;
        cnt[best]--;
        r[best].frac = 1.0; /* it is now the first to get one back */
        left++;
    }
    while (left >= n) { /* cannot happen for exact arithmetic (Σ frac < n); kept safe */
        for (long i = 0; i < n; i++)
            cnt[i]++;
        left -= n;
    }
    if (left > 0) {
        select_first(r, n, (long)left);
        for (long j = 0; j < left; j++)
            cnt[r[j].idx]++;
    }
    static const char *const name[1] = {"SampleCount"};
    if (mcp__image_new(w, h, 1, name, "sample counts", counts)) goto done;
    for (long i = 0; i < n; i++) {
        if (cnt[i] > (1 << 24)) {
            mcp_image_free(*counts);
            *counts = NULL;
            mcp_error(
                "sample counts: pixel %ld would get %lld samples, more than a float "
                "holds exactly (2^24)",
                i, (long long)cnt[i]);
            goto done;
        }
        (*counts)->data[i] = (float)cnt[i];
    }
    rc = 0;
done:
    free(row);
    free(r);
    free(cnt);
    return rc;
}

int
mcp_postcorrection_variance(const mcp_image *var_f0, const mcp_image *var_f1,
                            const mcp_image *var_x, const mcp_image *alpha,
                            const mcp_image *rho, mcp_image **out)
{
    *out = NULL;
    if (!var_f0 || !var_f1 || !var_x || !alpha || !rho)
        return mcp_error("post-correction variance: missing input");
    const mcp_image *all[] = {var_f1, var_x, alpha, rho};
    const char *names[] = {"Var[F(x1)]", "Var[x]", "alpha", "rho"};
    for (int i = 0; i < 4; i++)
        if (same_shape("post-correction variance", names[i], all[i], var_f0,
                       i < 2 ? 3 : 1))
            return -1;
    if (var_f0->channels < 3)
        return mcp_error("post-correction variance: Var[F(x0)] needs 3 channels");
    int w = var_f0->width, h = var_f0->height;
    if (mcp__image_new(w, h, 3, NULL, "post-correction variance", out)) return -1;
    mcp_image *o = *out;
    int a3 = alpha->channels >= 3, r3 = rho->channels >= 3;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *v0 = mcp_image_px(var_f0, x, y),
                        *v1 = mcp_image_px(var_f1, x, y), *vx = mcp_image_px(var_x, x, y),
                        *pa = mcp_image_px(alpha, x, y), *pr = mcp_image_px(rho, x, y);
            float *po = mcp_image_px(o, x, y);
            for (int c = 0; c < 3; c++) {
                double a = pa[a3 ? c : 0], r = pr[r3 ? c : 0];
                po[c] = (float)(r * r * (a * a * v0[c] + (1 - a) * (1 - a) * v1[c]) +
                                (1 - r) * (1 - r) * vx[c]);
            }
        }
    return 0;
}
