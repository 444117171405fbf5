/* truth.c: the exact expectation and per-sample variance of every pixel of the
 * procedural scene, by deterministic quadrature (README.md, "Ground truth").
 *
 * scene.c gives the moments of one sample at a point in closed form; what remains is
 * their integral over the pixel's box footprint. The integrand jumps or kinks only
 * along lines on the screen (occluder outline, checker edges, penumbra boundaries), so
 * the pixel square is cut along those lines into convex pieces on which it is smooth
 * (analytic), and each piece is integrated with a collapsed tensor Gauss-Legendre rule
 * per triangle of its fan. The error then falls exponentially with the order: 8 points
 * per side give about 1e-12 (tests/samples/test_procedural.c compares orders).
 *
 * The variance of the pixel mean under the jittered sampler needs the moments of each
 * cell of the k x k grid instead of the whole pixel's. The camera maps continuous
 * pixel coordinates to rays independently of the image size (only the scale of the
 * coordinates changes), so cell (i, j) of pixel (x, y) is pixel (k x + i, k y + j)
 * of the same scene k times finer (up to the rounding of the ray directions, ~1e-16),
 * and the cutting and quadrature serve unchanged. */
#include "internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

/* A pixel's pieces have at most 4 + (number of lines) vertices; pixels of reasonable
 * images are crossed by a handful of lines (dozens only when a pixel covers much of
 * the scene). */
#define MAX_LINES 60
#define MAX_VERTS (4 + MAX_LINES)

typedef struct {
    int n;
    double x[MAX_VERTS], y[MAX_VERTS];
} poly;

typedef struct {
    poly *a, *b; /* the current pieces and the next generation */
    int cap;
} scratch;

/* Gauss-Legendre nodes and weights on [0, 1], by Newton's method on P_n. */
static void
gauss_legendre(int n, double *node, double *weight)
{
    for (int i = 0; i < (n + 1) / 2; i++) {
        double z = cos(3.141592653589793 * (i + 0.75) / (n + 0.5)), dp = 1.0;
        for (int it = 0; it < 100; it++) {
            double p0 = 1.0, p1 = 0.0;
            for (int k = 1; k <= n; k++) {
                double p2 = p1;
                p1 = p0;
                p0 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p2) / k;
            }
            dp = n * (z * p0 - p1) / (z * z - 1.0);
            double dz = p0 / dp;
            z -= dz;
            if (fabs(dz) < 1e-16) break;
        }
        double w = 2.0 / ((1.0 - z * z) * dp * dp);
        node[i] = 0.5 * (1.0 - z);
        node[n - 1 - i] = 0.5 * (1.0 + z);
        weight[i] = weight[n - 1 - i] = 0.5 * w;
    }
}

/* Cuts p along f = 0 into *neg (f <= 0) and *pos (f >= 0); returns 0 when the line
 * misses p's interior (nothing is written). */
static int
split(const poly *p, const mcp__proc_lin *f, poly *neg, poly *pos)
{
    double v[MAX_VERTS];
    int has_neg = 0, has_pos = 0;
    for (int i = 0; i < p->n; i++) {
        v[i] = mcp__proc_lin_at(f, p->x[i], p->y[i]);
        has_neg |= v[i] < 0.0;
        has_pos |= v[i] > 0.0;
    }
    if (!has_neg || !has_pos) return 0;
    neg->n = pos->n = 0;
    for (int i = 0; i < p->n; i++) {
        int j = (i + 1) % p->n;
        if (v[i] <= 0.0) neg->x[neg->n] = p->x[i], neg->y[neg->n++] = p->y[i];
        if (v[i] >= 0.0) pos->x[pos->n] = p->x[i], pos->y[pos->n++] = p->y[i];
        if ((v[i] < 0.0 && v[j] > 0.0) || (v[i] > 0.0 && v[j] < 0.0)) {
            double t = v[i] / (v[i] - v[j]);
            double x = p->x[i] + t * (p->x[j] - p->x[i]);
            double y = p->y[i] + t * (p->y[j] - p->y[i]);
            neg->x[neg->n] = pos->x[pos->n] = x;
            neg->y[neg->n++] = y;
            pos->y[pos->n++] = y;
        }
    }
    return 1;
}

static int
reserve(scratch *s, int n)
{
    if (n <= s->cap) return 0;
    int cap = s->cap ? s->cap : 16;
    while (cap < n)
        cap *= 2;
    poly *a = realloc(s->a, (size_t)cap * sizeof *a);
    if (!a) return -1;
    s->a = a;
    poly *b = realloc(s->b, (size_t)cap * sizeof *b);
    if (!b) return -1;
    s->b = b;
    s->cap = cap;
    return 0;
}

/* Adds the integrals of the moments over triangle (p0, p1, p2). The collapsed map
 * p0 + u (p1 - p0) + u v (p2 - p1) has Jacobian 2 area u. */
static void
integrate_triangle(const mcp__proc_geom *g, const double *p0, const double *p1,
                   const double *p2, int n, const double *node, const double *weight,
                   double mean[3], double m2[3])
{
    double e1x = p1[0] - p0[0], e1y = p1[1] - p0[1];
    double e2x = p2[0] - p1[0], e2y = p2[1] - p1[1];
    double jac = fabs(e1x * e2y - e1y * e2x);
    if (jac == 0.0) return;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            double u = node[i], v = node[j], w = weight[i] * weight[j] * jac * u;
            double px = p0[0] + u * e1x + u * v * e2x, py = p0[1] + u * e1y + u * v * e2y;
            mcp__proc_hit h;
            double pm[3], pm2[3];
            mcp__proc_hit_at(g, px, py, &h);
            mcp__proc_shade_moments(g, &h, pm, pm2);
            for (int c = 0; c < 3; c++) {
                mean[c] += w * pm[c];
                m2[c] += w * pm2[c];
            }
        }
}

/* The moments of pixel (x, y); -1 when too many lines cross it or memory runs out. */
static int
truth_pixel(const mcp__proc_geom *g, int x, int y, int order, const double *node,
            const double *weight, scratch *s, double mean[3], double m2[3])
{
    mcp__proc_lin lines[MAX_LINES];
    int nl = mcp__proc_edges(g, x, y, lines, MAX_LINES), np = 1;
    if (nl < 0 || reserve(s, 4)) return -1;
    s->a[0] = (poly){4, {x, x + 1, x + 1, x}, {y, y, y + 1, y + 1}};
    for (int l = 0; l < nl; l++) {
        if (reserve(s, 2 * np)) return -1;
        int nn = 0;
        for (int i = 0; i < np; i++)
            if (split(&s->a[i], &lines[l], &s->b[nn], &s->b[nn + 1]))
                nn += 2;
            else
                s->b[nn++] = s->a[i];
        poly *t = s->a;
        s->a = s->b;
        s->b = t;
        np = nn;
    }
    for (int c = 0; c < 3; c++)
        mean[c] = m2[c] = 0.0;
    for (int i = 0; i < np; i++) {
        const poly *p = &s->a[i];
        for (int k = 1; k + 1 < p->n; k++) {
            double p0[2] = {p->x[0], p->y[0]}, p1[2] = {p->x[k], p->y[k]};
            double p2[2] = {p->x[k + 1], p->y[k + 1]};
            integrate_triangle(g, p0, p1, p2, order, node, weight, mean, m2);
        }
    }
    return 0;
}

/* ---- public ---- */

int
mcp_proc_truth_pixel(const mcp_proc_scene *scene, int x, int y, double mean[3],
                     double var[3])
{
    mcp__proc_geom g;
    double node[32], weight[32], m2[3];
    scratch s = {0};
    if (mcp__proc_geom_init(scene, &g)) return -1;
    if (x < 0 || x >= g.width || y < 0 || y >= g.height)
        return mcp_error("procedural truth: pixel (%d, %d) outside the %dx%d image", x, y,
                         g.width, g.height);
    gauss_legendre(scene->truth_order, node, weight);
    int rc = truth_pixel(&g, x, y, scene->truth_order, node, weight, &s, mean, m2);
    free(s.a);
    free(s.b);
    if (rc)
        return mcp_error("procedural truth: pixel (%d, %d) is crossed by more than %d "
                         "edges (or memory ran out); use a larger image",
                         x, y, MAX_LINES);
    for (int c = 0; c < 3; c++)
        var[c] = fmax(0.0, m2[c] - mean[c] * mean[c]);
    return 0;
}

/* The variance of the mean of `passes` jittered passes at pixel (x, y), from the k^2
 * cells of fine, the k-times-finer scene: the samples are independent, one per cell
 * per pass, so the variance is (1 / passes) sum_cells var_cell / k^4. With k = 1 this
 * is the per-sample variance / passes, the independent sampler's. */
static int
var_of_mean_pixel(const mcp__proc_geom *fine, int k, int passes, int x, int y, int order,
                  const double *node, const double *weight, scratch *s, double out[3])
{
    double sum[3] = {0.0, 0.0, 0.0};
    for (int j = 0; j < k; j++)
        for (int i = 0; i < k; i++) {
            double m[3], m2[3];
            if (truth_pixel(fine, k * x + i, k * y + j, order, node, weight, s, m, m2))
                return -1;
            for (int c = 0; c < 3; c++)
                sum[c] += fmax(0.0, m2[c] - m[c] * m[c]);
        }
    double scale = (double)k * k * k * k * passes;
    for (int c = 0; c < 3; c++)
        out[c] = sum[c] / scale;
    return 0;
}

/* The k-times-finer scene whose pixels are the cells of the jittered sampler (k = 1
 * for the independent sampler: the scene itself), and the number of passes in spp. */
static int
fine_geom(const mcp_proc_scene *scene, int spp, mcp__proc_geom *fine, int *k, int *passes)
{
    mcp__proc_geom g;
    if (mcp__proc_geom_init(scene, &g)) return -1;
    if (spp < 1) return mcp_error("procedural: spp must be >= 1 (got %d)", spp);
    if (mcp__proc_check_passes(&g, "spp", (uint64_t)spp)) return -1;
    *k = g.strata;
    *passes = spp / (g.strata * g.strata);
    if ((long)scene->width * *k > MCP_MAX_DIM || (long)scene->height * *k > MCP_MAX_DIM)
        return mcp_error("procedural truth: the cells of %d strata of a %dx%d image "
                         "would be pixels of a %ldx%ld one, more than %d a side",
                         *k, scene->width, scene->height, (long)scene->width * *k,
                         (long)scene->height * *k, MCP_MAX_DIM);
    mcp_proc_scene f = *scene;
    f.width *= *k;
    f.height *= *k;
    f.sampler = MCP_PROC_SAMPLER_INDEPENDENT;
    return mcp__proc_geom_init(&f, fine);
}

int
mcp_proc_truth(const mcp_proc_scene *scene, mcp_image **mean, mcp_image **var)
{
    static const char *const rgb[3] = {"R", "G", "B"};
    mcp__proc_geom g;
    double node[32], weight[32];
    *mean = NULL;
    if (var) *var = NULL;
    if (mcp__proc_geom_init(scene, &g)) return -1;
    int order = scene->truth_order;
    gauss_legendre(order, node, weight);
    mcp_image *m = NULL, *v = NULL;
    if (mcp_image_new(g.width, g.height, 3, rgb, &m) ||
        mcp_image_set_source(m, "procedural truth") ||
        mcp_image_new(g.width, g.height, 3, rgb, &v) ||
        mcp_image_set_source(v, "procedural truth variance"))
        goto fail;

    long failed = 0, fail_index = -1;
#pragma omp parallel reduction(+ : failed)
    {
        scratch s = {0};
#pragma omp for schedule(dynamic)
        for (int y = 0; y < g.height; y++)
            for (int x = 0; x < g.width; x++) {
                double pm[3], pm2[3];
                if (truth_pixel(&g, x, y, order, node, weight, &s, pm, pm2)) {
                    failed++;
#pragma omp critical(mcp_proc_truth_fail)
                    if (fail_index < 0 || (long)y * g.width + x < fail_index)
                        fail_index = (long)y * g.width + x;
                    continue;
                }
                float *pmo = mcp_image_px(m, x, y), *pvo = mcp_image_px(v, x, y);
                for (int c = 0; c < 3; c++) {
                    pmo[c] = (float)pm[c];
                    pvo[c] = (float)fmax(0.0, pm2[c] - pm[c] * pm[c]);
                }
            }
        free(s.a);
        free(s.b);
    }
    if (failed) {
        mcp_error("procedural truth: pixel (%ld, %ld) is crossed by more than %d edges "
                  "(or memory ran out); use a larger image",
                  fail_index % g.width, fail_index / g.width, MAX_LINES);
        goto fail;
    }
    *mean = m;
    if (var)
        *var = v;
    else
        mcp_image_free(v);
    return 0;
fail:
    mcp_image_free(m);
    mcp_image_free(v);
    return -1;
}

int
mcp_proc_truth_pixel_var_of_mean(const mcp_proc_scene *scene, int x, int y, int spp,
                                 double var_of_mean[3])
{
    mcp__proc_geom fine;
    double node[32], weight[32];
    int k = 0, passes = 0; /* set by fine_geom; gcc -O3 cannot see that */
    scratch s = {0};
    if (fine_geom(scene, spp, &fine, &k, &passes)) return -1;
    if (x < 0 || x >= scene->width || y < 0 || y >= scene->height)
        return mcp_error("procedural truth: pixel (%d, %d) outside the %dx%d image", x, y,
                         scene->width, scene->height);
    gauss_legendre(scene->truth_order, node, weight);
    int rc = var_of_mean_pixel(&fine, k, passes, x, y, scene->truth_order, node, weight,
                               &s, var_of_mean);
    free(s.a);
    free(s.b);
    if (rc)
        return mcp_error("procedural truth: a cell of pixel (%d, %d) is crossed by more "
                         "than %d edges (or memory ran out); use a larger image",
                         x, y, MAX_LINES);
    return 0;
}

int
mcp_proc_truth_var_of_mean(const mcp_proc_scene *scene, int spp, mcp_image **var_of_mean)
{
    static const char *const rgb[3] = {"R", "G", "B"};
    mcp__proc_geom fine;
    double node[32], weight[32];
    int k, passes;
    char label[96];
    mcp_image *v = NULL;
    *var_of_mean = NULL;
    if (fine_geom(scene, spp, &fine, &k, &passes)) return -1;
    int order = scene->truth_order, w = scene->width, h = scene->height;
    gauss_legendre(order, node, weight);
    if (scene->sampler == MCP_PROC_SAMPLER_JITTERED)
        snprintf(label, sizeof label,
                 "procedural truth variance of the mean (%d spp, "
                 "jittered %dx%d)",
                 spp, k, k);
    else
        snprintf(label, sizeof label, "procedural truth variance of the mean (%d spp)",
                 spp);
    if (mcp_image_new(w, h, 3, rgb, &v) || mcp_image_set_source(v, label)) goto fail;

    long failed = 0, fail_index = -1;
#pragma omp parallel reduction(+ : failed)
    {
        scratch s = {0};
#pragma omp for schedule(dynamic)
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                double vm[3];
                if (var_of_mean_pixel(&fine, k, passes, x, y, order, node, weight, &s,
                                      vm)) {
                    failed++;
#pragma omp critical(mcp_proc_truth_var_fail)
                    if (fail_index < 0 || (long)y * w + x < fail_index)
                        fail_index = (long)y * w + x;
                    continue;
                }
                float *out = mcp_image_px(v, x, y);
                for (int c = 0; c < 3; c++)
                    out[c] = (float)vm[c];
            }
        free(s.a);
        free(s.b);
    }
    if (failed) {
        mcp_error("procedural truth: a cell of pixel (%ld, %ld) is crossed by more than "
                  "%d edges (or memory ran out); use a larger image",
                  fail_index % w, fail_index / w, MAX_LINES);
        goto fail;
    }
    *var_of_mean = v;
    return 0;
fail:
    mcp_image_free(v);
    return -1;
}
