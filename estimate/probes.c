/* probes.c: random probes for SURE and the JVP variance (docs/mathematics.md §2.2, §2.5;
 * Firmino 2024 §3.3, Firmino 2023 Eq. 2, Li 2017 for the joint colour-feature draw).
 *
 * Gaussian probes ε ~ N(0, Σ̂_p) per pixel. §2.2 asks for a draw through the 3x3
 * block's eigen-decomposition with negative eigenvalues clamped to 0, because Σ̂ may
 * not be positive semi-definite. Where Σ̂_p is positive definite its Cholesky factor
 * gives the same distribution N(0, Σ̂_p) at a fraction of the cost, so we try Cholesky
 * first and take the eigen route (Jacobi, clamped) only where it fails. A dump with
 * only the diagonal needs neither: ε_c = σ_c z_c.
 *
 * Rademacher probes v_p = L_p r_p with L_p L_pᵀ = Σ̂_p (the same factor) and r_p
 * independent ±1; with a diagonal Σ̂ this is v_c = ±σ_c.
 *
 * Each pixel owns a counter-based stream (splitmix64) keyed by (seed, kind, probe k,
 * pixel index), so probes do not depend on the thread count or on the other pixels. */
#include "estimate.h"
#include "internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#define MAX_DIM 9 /* colour + albedo + normal */

enum { STREAM_GAUSS = 1, STREAM_RADEMACHER = 2 };

/* ---- random numbers ---- */

/* The streams of (seed, stream, k) share this key; a pixel's stream starts at
 * mcp__mix64(key ^ index). */
static uint64_t
streams_key(uint64_t seed, uint64_t stream, uint64_t k)
{
    return mcp__mix64(mcp__mix64(seed + MCP__SPLITMIX64_GAMMA) ^
                      (stream * 0xd1b54a32d192ed03ULL + k));
}

void
mcp__rng_init(mcp__rng *r, uint64_t seed, uint64_t stream, uint64_t k, uint64_t index)
{
    r->state = mcp__mix64(streams_key(seed, stream, k) ^ index);
    r->spare = 0.0;
    r->has_spare = 0;
}

uint64_t
mcp__rng_u64(mcp__rng *r)
{
    return mcp__splitmix64_next(&r->state);
}

/* Box-Muller in float (probes are stored in float anyway) with its own logarithm,
 * sine and cosine: libm's are calls that no loop vectorises, and they were a fifth of
 * a gauss estimate's CPU (three normals per pixel and probe). On the arguments that
 * Box-Muller gives them they are within a few float roundings of the true functions
 * (tests/estimate/test_sure.c measures it against libm's double ones), which keeps
 * N(0, 1) to float precision; as plain arithmetic, not contracted into multiply-adds
 * (gcc's default in ISO C; clang's pragma below), they give the same bits in the
 * row loop's vector clones as in mcp__rng_normal. */
#ifdef __clang__
#pragma clang fp contract(off)
#endif

/* ln u for u in (0, 1]: u = m 2^e with m in [sqrt(1/2), sqrt(2)), ln m = 2 atanh(s),
 * s = (m - 1) / (m + 1), |s| <= 0.172, as its series to s^9 (the next term is 2e-9 of
 * it); e ln 2 in two parts, the first exact for the |e| <= 25 that u has. */
static inline __attribute__((always_inline)) float
log_unit(float u)
{
    uint32_t b;
    memcpy(&b, &u, sizeof b);
    int e = (int)(b >> 23) - 127;
    const uint32_t mb = (b & 0x7fffffu) | 0x3f800000u;
    float m;
    memcpy(&m, &mb, sizeof m);
    const int big = m > 1.41421356f;
    m = big ? 0.5f * m : m;
    e += big;
    const float f = m - 1.0f, s = f / (2.0f + f), z = s * s;
    const float series =
        1.0f + z * (1.0f / 3 + z * (1.0f / 5 + z * (1.0f / 7 + z * (1.0f / 9))));
    const float ef = (float)e;
    return ef * 6.93145752e-1f + (ef * 1.42860677e-6f + 2.0f * s * series);
}

/* sin and cos of 2 pi u for u in [0, 1) with 24 bits: 4 u = q + r exactly (q the
 * nearest integer, |r| <= 1/2), a = r pi / 2, their Taylor series on |a| <= pi / 4
 * to a^9 and a^10 (the next terms are below 2e-9), then the quadrant q. */
static inline __attribute__((always_inline)) void
sincos_turn(float u, float *sin_out, float *cos_out)
{
    const float t = 4.0f * u;
    const int q = (int)(t + 0.5f);
    const float a = (t - (float)q) * 1.57079637f, a2 = a * a;
    const float s =
        a +
        a * a2 *
            (-1.0f / 6 + a2 * (1.0f / 120 + a2 * (-1.0f / 5040 + a2 * (1.0f / 362880))));
    const float c =
        1.0f + a2 * (-0.5f + a2 * (1.0f / 24 +
                                   a2 * (-1.0f / 720 +
                                         a2 * (1.0f / 40320 + a2 * (-1.0f / 3628800)))));
    /* quadrant k: (sin, cos) = (s, c), (c, -s), (-s, -c), (-c, s); as selects, which
       every compiler vectorises (a chain of them became a switch) */
    const int k = q & 3, swap = k & 1;
    const float ss = swap ? c : s, cc = swap ? s : c;
    *sin_out = k & 2 ? -ss : ss;
    *cos_out = (k + 1) & 2 ? -cc : cc;
}

/* Two normals from one 64-bit draw: both uniforms from it, u1 in (0, 1] so that the
 * logarithm is finite. */
static inline __attribute__((always_inline)) void
box_muller(uint64_t bits, float *z0, float *z1)
{
    const float u1 = (float)(int32_t)((bits >> 40) + 1) * 0x1.0p-24f;
    const float u2 = (float)(int32_t)((bits >> 16) & 0xffffff) * 0x1.0p-24f;
    const float rad = sqrtf(-2.0f * log_unit(u1));
    float s, c;
    sincos_turn(u2, &s, &c);
    *z0 = rad * c;
    *z1 = rad * s;
}

double
mcp__rng_normal(mcp__rng *r)
{
    if (r->has_spare) {
        r->has_spare = 0;
        return r->spare;
    }
    float z0, z1;
    box_muller(mcp__rng_u64(r), &z0, &z1);
    r->spare = z1;
    r->has_spare = 1;
    return z0;
}

float
mcp__log_unit(float u)
{
    return log_unit(u);
}

void
mcp__sincos_turn(float u, float *s, float *c)
{
    sincos_turn(u, s, c);
}

#if defined(__GNUC__) && defined(__x86_64__)
#define NORMALS_KERNEL __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define NORMALS_KERNEL
#endif

/* The three normals that mcp__rng_normal draws first from each of the streams (seed,
 * stream, k, index0 + x) for x in [0, n), into z[3 x + c]: a row of a diagonal probe
 * at once, in vectors. */
NORMALS_KERNEL static void
normals_row(uint64_t seed, uint64_t stream, uint64_t k, uint64_t index0, int n, float *z)
{
    const uint64_t key = streams_key(seed, stream, k);
#pragma omp simd
    for (int x = 0; x < n; x++) {
        uint64_t state = mcp__mix64(key ^ (index0 + (uint64_t)x));
        float a, b, c, unused;
        box_muller(mcp__splitmix64_next(&state), &a, &b);
        box_muller(mcp__splitmix64_next(&state), &c, &unused);
        z[3 * x] = a, z[3 * x + 1] = b, z[3 * x + 2] = c;
    }
}

/* ---- small symmetric matrices (row-major n x n, n <= MAX_DIM) ---- */

/* Cholesky a = L Lᵀ (L lower, row-major). Returns 0, or -1 when a pivot is not
 * positive (a not positive definite): the caller then uses eigen_factor. */
static int
cholesky(const double *a, int n, double *l)
{
    memset(l, 0, sizeof(double) * (size_t)(n * n));
    for (int j = 0; j < n; j++) {
        double d = a[j * n + j];
        for (int k = 0; k < j; k++)
            d -= l[j * n + k] * l[j * n + k];
        if (!(d > 0.0)) return -1;
        d = sqrt(d);
        l[j * n + j] = d;
        for (int i = j + 1; i < n; i++) {
            double s = a[i * n + j];
            for (int k = 0; k < j; k++)
                s -= l[i * n + k] * l[j * n + k];
            l[i * n + j] = s / d;
        }
    }
    return 0;
}

/* Cyclic Jacobi: a = V diag(w) Vᵀ, columns of v the eigenvectors. */
static void
jacobi_eigen(const double *a_in, int n, double *w, double *v)
{
    double a[MAX_DIM * MAX_DIM];
    memcpy(a, a_in, sizeof(double) * (size_t)(n * n));
    for (int i = 0; i < n * n; i++)
        v[i] = 0.0;
    for (int i = 0; i < n; i++)
        v[i * n + i] = 1.0;
    for (int sweep = 0; sweep < 50; sweep++) {
        double off = 0.0, diag = 0.0;
        for (int i = 0; i < n; i++) {
            diag += a[i * n + i] * a[i * n + i];
            for (int j = i + 1; j < n; j++)
                off += a[i * n + j] * a[i * n + j];
        }
        if (off <= 1e-30 * diag || off == 0.0) break;
        for (int p = 0; p < n; p++)
            for (int q = p + 1; q < n; q++) {
                double apq = a[p * n + q];
                if (apq == 0.0) continue;
                double theta = (a[q * n + q] - a[p * n + p]) / (2.0 * apq);
                double t =
                    (theta >= 0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1));
                double c = 1.0 / sqrt(t * t + 1), s = t * c;
                for (int k = 0; k < n; k++) { /* columns p, q */
                    double akp = a[k * n + p], akq = a[k * n + q];
                    a[k * n + p] = c * akp - s * akq;
                    a[k * n + q] = s * akp + c * akq;
                }
                for (int k = 0; k < n; k++) { /* rows p, q */
                    double apk = a[p * n + k], aqk = a[q * n + k];
                    a[p * n + k] = c * apk - s * aqk;
                    a[q * n + k] = s * apk + c * aqk;
                }
                for (int k = 0; k < n; k++) {
                    double vkp = v[k * n + p], vkq = v[k * n + q];
                    v[k * n + p] = c * vkp - s * vkq;
                    v[k * n + q] = s * vkp + c * vkq;
                }
            }
    }
    for (int i = 0; i < n; i++)
        w[i] = a[i * n + i];
}

/* A factor f with f fᵀ = a with negative eigenvalues clamped to 0: Cholesky where a
 * is positive definite, else V sqrt(max(Λ, 0)). */
static void
psd_factor(const double *a, int n, double *f)
{
    if (cholesky(a, n, f) == 0) return;
    double w[MAX_DIM], v[MAX_DIM * MAX_DIM];
    jacobi_eigen(a, n, w, v);
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++)
            f[i * n + j] = v[i * n + j] * sqrt(w[j] > 0.0 ? w[j] : 0.0);
}

/* The pseudo-inverse of a symmetric 3x3 (eigenvalues <= 1e-12 max |λ| dropped). */
static void
pinv3(const double *a, double *p)
{
    double w[3], v[9], wmax = 0.0;
    jacobi_eigen(a, 3, w, v);
    for (int i = 0; i < 3; i++)
        wmax = fmax(wmax, fabs(w[i]));
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double s = 0.0;
            for (int k = 0; k < 3; k++)
                if (w[k] > 1e-12 * wmax) s += v[i * 3 + k] * v[j * 3 + k] / w[k];
            p[i * 3 + j] = s;
        }
}

/* ---- the per-pixel covariance ---- */

/* The colour covariance of the mean at (x, y): 3x3 row-major. */
static void
color_cov(const mcp_dump *d, int x, int y, double *c)
{
    const float *v = mcp_image_px(d->var_of_mean, x, y);
    memset(c, 0, 9 * sizeof *c);
    for (int i = 0; i < 3; i++)
        c[i * 3 + i] = v[i];
    if (d->cov_of_mean) {
        const float *o = mcp_image_px(d->cov_of_mean, x, y); /* RG, RB, GB */
        c[1] = c[3] = o[0];
        c[2] = c[6] = o[1];
        c[5] = c[7] = o[2];
    }
}

/* Which feature blocks take part in a joint draw. */
typedef struct joint_plan {
    const mcp_image *cross[2]; /* colour-albedo, colour-normal (9 channels) or NULL */
    const mcp_image *var[2];   /* feature variances or NULL */
    int n_features;            /* 0, 1 or 2 blocks in use */
    int use[2];
} joint_plan;

static int
check_image(const char *what, const mcp_image *img, const mcp_dump *d, int channels)
{
    if (img->width != d->color->width || img->height != d->color->height)
        return mcp_error("probe: %s: size %dx%d does not match %s (%dx%d)", what,
                         img->width, img->height, d->source ? d->source : "the dump",
                         d->color->width, d->color->height);
    if (img->channels != channels)
        return mcp_error("probe: %s: needs %d channels (got %d)", what, channels,
                         img->channels);
    return 0;
}

static int
plan_joint(const mcp_dump *d, const mcp_feature_covariance *f, joint_plan *plan)
{
    memset(plan, 0, sizeof *plan);
    if (!f) return 0;
    const mcp_image *feature[2] = {d->albedo, d->normal};
    const mcp_image *cross[2] = {f->color_albedo, f->color_normal};
    const mcp_image *var[2] = {f->albedo_var, f->normal_var};
    const char *names[2] = {"albedo", "normal"};
    for (int b = 0; b < 2; b++) {
        if (!cross[b]) continue;
        char what[64];
        snprintf(what, sizeof what, "colour-%s covariance", names[b]);
        if (!feature[b])
            return mcp_error("probe: %s given but %s has no %s", what,
                             d->source ? d->source : "the dump", names[b]);
        if (check_image(what, cross[b], d, 9)) return -1;
        if (var[b]) {
            snprintf(what, sizeof what, "%s variance", names[b]);
            if (check_image(what, var[b], d, 3)) return -1;
        }
        plan->use[b] = 1;
        plan->cross[b] = cross[b];
        plan->var[b] = var[b];
        plan->n_features++;
    }
    return 0;
}

/* One pixel's joint draw: e[0..2] colour, then 3 per feature block in use. */
static void
draw_joint(const mcp_dump *d, const joint_plan *plan, int x, int y, mcp__rng *r,
           double *e)
{
    int n = 3 + 3 * plan->n_features;
    double c[MAX_DIM * MAX_DIM] = {0}, cxx[9];
    color_cov(d, x, y, cxx);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            c[i * n + j] = cxx[i * 3 + j];
    int all_var = 1, off = 3;
    for (int b = 0; b < 2; b++) {
        if (!plan->use[b]) continue;
        const float *cr = mcp_image_px(plan->cross[b], x, y);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                c[i * n + off + j] = c[(off + j) * n + i] = cr[i * 3 + j];
        if (plan->var[b]) {
            const float *v = mcp_image_px(plan->var[b], x, y);
            for (int j = 0; j < 3; j++)
                c[(off + j) * n + off + j] = v[j];
        } else {
            all_var = 0;
        }
        off += 3;
    }
    double z[MAX_DIM];
    if (all_var) {
        /* the whole joint covariance is known: draw from it (clamped) */
        double f[MAX_DIM * MAX_DIM];
        psd_factor(c, n, f);
        for (int i = 0; i < n; i++)
            z[i] = mcp__rng_normal(r);
        for (int i = 0; i < n; i++) {
            double s = 0.0;
            for (int j = 0; j < n; j++)
                s += f[i * n + j] * z[j];
            e[i] = s;
        }
        return;
    }
    /* Feature variances missing: ε_y = Σ_yx Σ_xx⁺ ε_x has exactly the given
     * cross-covariance with ε_x (the only part SURE's expectation uses) and the
     * smallest feature covariance that keeps the joint matrix PSD. */
    double f[9], pinv[9];
    psd_factor(cxx, 3, f);
    for (int i = 0; i < 3; i++)
        z[i] = mcp__rng_normal(r);
    for (int i = 0; i < 3; i++)
        e[i] = f[i * 3 + 0] * z[0] + f[i * 3 + 1] * z[1] + f[i * 3 + 2] * z[2];
    pinv3(cxx, pinv);
    double w[3]; /* Σ_xx⁺ ε_x */
    for (int i = 0; i < 3; i++)
        w[i] = pinv[i * 3 + 0] * e[0] + pinv[i * 3 + 1] * e[1] + pinv[i * 3 + 2] * e[2];
    for (int k = 3; k < n; k++) /* row k of Σ_yx is column k of c's top rows */
        e[k] = c[0 * n + k] * w[0] + c[1 * n + k] * w[1] + c[2 * n + k] * w[2];
}

static int
check_dump(const char *who, const mcp_dump *d)
{
    if (!d || !d->color) return mcp_error("%s: missing dump", who);
    if (!d->var_of_mean)
        return mcp_error("%s: %s has no variance%s", who,
                         d->source ? d->source : "the dump",
                         mcp__no_variance_hint(d, " (SURE and the variance estimate need "
                                                  "the variance of the pixel means)"));
    if (d->color->channels != 3 || d->var_of_mean->channels != 3)
        return mcp_error("%s: %s: colour and variance need 3 channels", who,
                         d->source ? d->source : "the dump");
    return 0;
}

int
mcp__check_dump(const char *who, const mcp_dump *dump)
{
    return check_dump(who, dump);
}

void
mcp_probe_clear(mcp_probe *p)
{
    if (!p) return;
    mcp_image_free(p->color);
    mcp_image_free(p->albedo);
    mcp_image_free(p->normal);
    p->color = p->albedo = p->normal = NULL;
}

int
mcp_probe_gaussian(const mcp_dump *dump, const mcp_feature_covariance *features,
                   uint64_t seed, int k, mcp_probe *out)
{
    return mcp__probe_gaussian_rows(dump, 0, features, seed, k, out);
}

int
mcp__probe_gaussian_rows(const mcp_dump *dump, int row0,
                         const mcp_feature_covariance *features, uint64_t seed, int k,
                         mcp_probe *out)
{
    memset(out, 0, sizeof *out);
    joint_plan plan;
    if (check_dump("probe", dump) || plan_joint(dump, features, &plan)) return -1;
    if (k < 0) return mcp_error("probe: index must be >= 0 (got %d)", k);
    if (row0 < 0) return mcp_error("probe: first row must be >= 0 (got %d)", row0);
    int w = dump->color->width, h = dump->color->height;
    const char *xyz[3] = {"X", "Y", "Z"};
    if (mcp__image_new(w, h, 3, NULL, "probe", &out->color) ||
        (plan.use[0] && mcp__image_new(w, h, 3, NULL, "probe albedo", &out->albedo)) ||
        (plan.use[1] && mcp__image_new(w, h, 3, xyz, "probe normal", &out->normal))) {
        mcp_probe_clear(out);
        return -1;
    }
    int joint = plan.n_features > 0, cov = dump->cov_of_mean != NULL;
    float *rows = NULL; /* the diagonal's normals, 3 w per thread */
#ifdef _OPENMP
    const int threads = omp_get_max_threads();
#else
    const int threads = 1;
#endif
    if (!joint && !cov && !(rows = mcp_malloc((size_t)threads * 3 * w * sizeof(float)))) {
        mcp_probe_clear(out);
        return -1;
    }
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        if (rows) { /* the common case: per value sigma z, the row's normals at once */
#ifdef _OPENMP
            float *z = rows + (size_t)omp_get_thread_num() * 3 * w;
#else
            float *z = rows;
#endif
            normals_row(seed, STREAM_GAUSS, (uint64_t)k, ((uint64_t)row0 + y) * w, w, z);
            for (int x = 0; x < w; x++) {
                const float *var = mcp_image_px(dump->var_of_mean, x, y);
                float *e = mcp_image_px(out->color, x, y);
                for (int c = 0; c < 3; c++)
                    e[c] = (float)(sqrt(var[c] > 0.0f ? (double)var[c] : 0.0) *
                                   (double)z[3 * x + c]);
            }
            continue;
        }
        for (int x = 0; x < w; x++) {
            mcp__rng r;
            mcp__rng_init(&r, seed, STREAM_GAUSS, (uint64_t)k,
                          ((uint64_t)row0 + y) * w + x);
            float *e = mcp_image_px(out->color, x, y);
            double v[MAX_DIM];
            if (joint) {
                draw_joint(dump, &plan, x, y, &r, v);
                int off = 3;
                for (int b = 0; b < 2; b++) {
                    if (!plan.use[b]) continue;
                    float *o = mcp_image_px(b == 0 ? out->albedo : out->normal, x, y);
                    for (int c = 0; c < 3; c++)
                        o[c] = (float)v[off + c];
                    off += 3;
                }
            } else { /* the colour's covariance */
                double c3[9], f[9], z[3];
                color_cov(dump, x, y, c3);
                psd_factor(c3, 3, f);
                for (int c = 0; c < 3; c++)
                    z[c] = mcp__rng_normal(&r);
                for (int c = 0; c < 3; c++)
                    v[c] =
                        f[c * 3 + 0] * z[0] + f[c * 3 + 1] * z[1] + f[c * 3 + 2] * z[2];
            }
            for (int c = 0; c < 3; c++)
                e[c] = (float)v[c];
        }
    }
    free(rows);
    return 0;
}

int
mcp_probe_rademacher(const mcp_dump *dump, uint64_t seed, int k, mcp_image **out)
{
    return mcp__probe_rademacher_rows(dump, 0, seed, k, out);
}

int
mcp__probe_rademacher_rows(const mcp_dump *dump, int row0, uint64_t seed, int k,
                           mcp_image **out)
{
    *out = NULL;
    if (check_dump("probe", dump)) return -1;
    if (k < 0) return mcp_error("probe: index must be >= 0 (got %d)", k);
    if (row0 < 0) return mcp_error("probe: first row must be >= 0 (got %d)", row0);
    int w = dump->color->width, h = dump->color->height;
    if (mcp__image_new(w, h, 3, NULL, "rademacher probe", out)) return -1;
    int cov = dump->cov_of_mean != NULL;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        for (int x = 0; x < w; x++) {
            mcp__rng r;
            mcp__rng_init(&r, seed, STREAM_RADEMACHER, (uint64_t)k,
                          ((uint64_t)row0 + y) * w + x);
            uint64_t bits = mcp__rng_u64(&r);
            double s[3];
            for (int c = 0; c < 3; c++)
                s[c] = (bits >> c) & 1 ? 1.0 : -1.0;
            float *v = mcp_image_px(*out, x, y);
            if (cov) {
                double c3[9], f[9];
                color_cov(dump, x, y, c3);
                psd_factor(c3, 3, f);
                for (int c = 0; c < 3; c++)
                    v[c] = (float)(f[c * 3 + 0] * s[0] + f[c * 3 + 1] * s[1] +
                                   f[c * 3 + 2] * s[2]);
            } else {
                const float *var = mcp_image_px(dump->var_of_mean, x, y);
                for (int c = 0; c < 3; c++)
                    v[c] = (float)(s[c] * sqrt(var[c] > 0.0f ? (double)var[c] : 0.0));
            }
        }
    }
    return 0;
}
