/* scene.c: the analytic scene of the procedural renderer -- geometry, one Monte Carlo
 * sample, and the closed-form moments of that sample at a point (README.md).
 *
 * Every random quantity is chosen so that its expectation over the non-footprint
 * dimensions has a closed form: visibility of a rectangular light past a parallel
 * rectangular occluder (an overlap of rectangles), a Gaussian lobe reflecting a
 * Gaussian-profile emitter (a convolution of Gaussians), and a firefly of fixed value
 * and probability. What is left, the box footprint, is integrated by truth.c. */
#include "internal.h"

#include <math.h>

/* ---- the world: y is up, the camera looks down towards +z ---- */

static const double CAM[3] = {0.0, 2.0, 0.0};
static const double CAM_TARGET[3] = {0.0, 0.0, 3.0};
#define VFOV_TAN 0.36397023426620234 /* tan(20 degrees): 40 degrees vertical view */

/* The occluder: a horizontal sheet; the light: a horizontal rectangle above it. */
#define OCC_H 1.0
#define OCC_X0 (-0.5)
#define OCC_X1 0.3
#define OCC_Z0 2.6
#define OCC_Z1 3.2
#define LIGHT_H 3.0
#define LIGHT_X0 (-1.9)
#define LIGHT_X1 (-0.7)
#define LIGHT_Z0 3.7
#define LIGHT_Z1 4.5
#define FALLOFF_R2 16.0 /* squared radius of the light's smooth falloff */

/* The ground's checkerboard, rotated so that its edges cross pixels at angles. */
#define CHECK_COS 0.86602540378443865 /* 30 degrees */
#define CHECK_SIN 0.5
#define CHECK_CELL 0.4

/* The glossy highlight: a Gaussian-profile emitter at height GLOSS_H seen in the ground
 * through a Gaussian lobe of std. dev. GLOSS_SIGMA (measured where the reflected ray
 * meets the emitter's plane). */
#define GLOSS_H 4.0
#define GLOSS_CX (-1.5)
#define GLOSS_CZ 12.0
#define GLOSS_W 0.7
#define GLOSS_SIGMA 0.8

static const double AMBIENT[3] = {0.14, 0.16, 0.20};
static const double DIRECT[3] = {1.00, 0.93, 0.80};
static const double CHECK_A[3] = {0.75, 0.70, 0.62};
static const double CHECK_B[3] = {0.18, 0.22, 0.30};
static const double OCC_ALB0[3] = {0.85, 0.35, 0.20};
static const double OCC_ALB1[3] = {0.20, 0.50, 0.85};
static const double GLOSS[3] = {2.2, 2.1, 1.9};
static const double FIREFLY_TINT[3] = {1.1, 1.0, 0.8};

/* The sheet's height over the light's: a ray from the ground to the light meets the
 * sheet's plane at this fraction of the way. */
#define SHADOW_A (OCC_H / LIGHT_H)

/* ---- helpers ---- */

static mcp__proc_lin
lin_combo(double s, const mcp__proc_lin *l, double t, const mcp__proc_lin *m)
{
    return (mcp__proc_lin){s * l->a + t * m->a, s * l->b + t * m->b, s * l->c + t * m->c};
}

static void
normalize(double v[3])
{
    double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int k = 0; k < 3; k++)
        v[k] /= n;
}

/* Length of the part of the light's side [l0, l1] hidden by the occluder's side
 * [o0, o1] from a ground point at coordinate g: the occluder side projected from g
 * onto the light's plane is [g + (o0 - g)/A, g + (o1 - g)/A]. Piecewise linear in g. */
static double
hidden(double g, double o0, double o1, double l0, double l1)
{
    double e0 = g + (o0 - g) / SHADOW_A, e1 = g + (o1 - g) / SHADOW_A;
    double len = fmin(l1, e1) - fmax(l0, e0);
    return len > 0.0 ? len : 0.0;
}

/* The fraction of the light visible from ground point (x, z). */
static double
visible_fraction(double x, double z)
{
    double hx = hidden(x, OCC_X0, OCC_X1, LIGHT_X0, LIGHT_X1);
    double hz = hidden(z, OCC_Z0, OCC_Z1, LIGHT_Z0, LIGHT_Z1);
    return 1.0 - hx * hz / ((LIGHT_X1 - LIGHT_X0) * (LIGHT_Z1 - LIGHT_Z0));
}

/* Unshadowed irradiance factor: smooth, evaluated at the point rather than sampled,
 * so that only visibility is random and its expectation is exact. */
static double
falloff(double x, double z)
{
    double cx = 0.5 * (LIGHT_X0 + LIGHT_X1), cz = 0.5 * (LIGHT_Z0 + LIGHT_Z1);
    double d2 = (x - cx) * (x - cx) + (z - cz) * (z - cz);
    return 1.0 / (1.0 + d2 / FALLOFF_R2);
}

/* Where the mirror reflection of the camera ray at ground point (x, z) meets the
 * emitter's plane: the ray from the camera mirrored below the ground, continued. */
static void
mirror_point(double x, double z, double *rx, double *rz)
{
    *rx = x + (x - CAM[0]) * (GLOSS_H / CAM[1]);
    *rz = z + (z - CAM[2]) * (GLOSS_H / CAM[1]);
}

/* E[exp(-|r + sigma g - c|^2 / (2 w2))] for g ~ N(0, I2): a Gaussian of variance w2
 * blurred by one of variance sigma^2. */
static double
blurred_gaussian(double rx, double rz, double w2)
{
    double v = w2 + GLOSS_SIGMA * GLOSS_SIGMA;
    double d2 = (rx - GLOSS_CX) * (rx - GLOSS_CX) + (rz - GLOSS_CZ) * (rz - GLOSS_CZ);
    return (w2 / v) * exp(-d2 / (2.0 * v));
}

static void
occluder_albedo(double x, double albedo[3])
{
    double u = (x - OCC_X0) / (OCC_X1 - OCC_X0);
    for (int c = 0; c < 3; c++)
        albedo[c] = OCC_ALB0[c] + (OCC_ALB1[c] - OCC_ALB0[c]) * u;
}

static void
ground_albedo(double x, double z, double albedo[3])
{
    double p = CHECK_COS * x + CHECK_SIN * z, q = -CHECK_SIN * x + CHECK_COS * z;
    long long i = (long long)floor(p / CHECK_CELL), j = (long long)floor(q / CHECK_CELL);
    const double *alb = ((i + j) & 1) ? CHECK_B : CHECK_A;
    for (int c = 0; c < 3; c++)
        albedo[c] = alb[c];
}

/* Appends the line f = 0 when it crosses the interior of the pixel with corners
 * (px[k], py[k]). */
static int
push_if_crossing(const mcp__proc_lin *f, const double px[4], const double py[4],
                 mcp__proc_lin *out, int n, int cap, int *overflow)
{
    double lo = INFINITY, hi = -INFINITY;
    for (int k = 0; k < 4; k++) {
        double v = mcp__proc_lin_at(f, px[k], py[k]);
        lo = fmin(lo, v);
        hi = fmax(hi, v);
    }
    if (!(lo < 0.0 && hi > 0.0)) return n;
    if (n >= cap) {
        *overflow = 1;
        return n;
    }
    out[n] = *f;
    return n + 1;
}

/* Appends the lines u = k * cell (k integer) crossing the pixel, where u is the
 * ground-plane function (cu * x + su * z). */
static int
push_grid_lines(const mcp__proc_geom *g, double cu, double su, double cell,
                const double px[4], const double py[4], mcp__proc_lin *out, int n,
                int cap, int *overflow)
{
    mcp__proc_lin num = lin_combo(cu, &g->ground_x, su, &g->ground_z);
    double lo = INFINITY, hi = -INFINITY;
    /* A ratio of linear functions with a positive denominator has its extremes over a
     * convex polygon at the corners. */
    for (int k = 0; k < 4; k++) {
        double u =
            mcp__proc_lin_at(&num, px[k], py[k]) / mcp__proc_lin_at(&g->w, px[k], py[k]);
        lo = fmin(lo, u);
        hi = fmax(hi, u);
    }
    for (double k = ceil(lo / cell); k <= floor(hi / cell); k++) {
        mcp__proc_lin f = num;
        f.a -= k * cell * g->w.a;
        f.b -= k * cell * g->w.b;
        f.c -= k * cell * g->w.c;
        n = push_if_crossing(&f, px, py, out, n, cap, overflow);
    }
    return n;
}

/* ---- shared with render.c and truth.c ---- */

int
mcp__proc_geom_init(const mcp_proc_scene *scene, mcp__proc_geom *g)
{
    if (mcp_proc_scene_check(scene)) return -1;
    g->width = scene->width;
    g->height = scene->height;
    g->firefly_probability = scene->firefly_probability;
    g->firefly_value = scene->firefly_value;
    g->strata = scene->sampler == MCP_PROC_SAMPLER_JITTERED ? scene->strata : 1;

    double f[3], r[3] = {1.0, 0.0, 0.0}, u[3];
    for (int k = 0; k < 3; k++)
        f[k] = CAM_TARGET[k] - CAM[k];
    normalize(f);
    /* up = forward x right (right is +x, since the camera does not turn sideways) */
    u[0] = f[1] * r[2] - f[2] * r[1];
    u[1] = f[2] * r[0] - f[0] * r[2];
    u[2] = f[0] * r[1] - f[1] * r[0];
    double ay = VFOV_TAN, ax = VFOV_TAN * scene->width / scene->height;
    for (int k = 0; k < 3; k++) {
        g->d0[k] = f[k] - ax * r[k] + ay * u[k];
        g->dx[k] = 2.0 * ax * r[k] / scene->width;
        g->dy[k] = -2.0 * ay * u[k] / scene->height;
    }
    mcp__proc_lin dxl = {g->dx[0], g->dy[0], g->d0[0]};
    mcp__proc_lin dzl = {g->dx[2], g->dy[2], g->d0[2]};
    g->w = (mcp__proc_lin){-g->dx[1], -g->dy[1], -g->d0[1]};
    /* point = cam + t d with t = (cam_y - h) / w: multiply through by w */
    g->ground_x = lin_combo(CAM[0], &g->w, CAM[1], &dxl);
    g->ground_z = lin_combo(CAM[2], &g->w, CAM[1], &dzl);
    g->occ_x = lin_combo(CAM[0], &g->w, CAM[1] - OCC_H, &dxl);
    g->occ_z = lin_combo(CAM[2], &g->w, CAM[1] - OCC_H, &dzl);
    return 0;
}

void
mcp__proc_hit_at(const mcp__proc_geom *g, double px, double py, mcp__proc_hit *h)
{
    double w = mcp__proc_lin_at(&g->w, px, py);
    double ox = mcp__proc_lin_at(&g->occ_x, px, py) / w;
    double oz = mcp__proc_lin_at(&g->occ_z, px, py) / w;
    if (ox >= OCC_X0 && ox <= OCC_X1 && oz >= OCC_Z0 && oz <= OCC_Z1) {
        *h = (mcp__proc_hit){MCP__PROC_OCCLUDER, ox, oz};
        return;
    }
    h->surface = MCP__PROC_GROUND;
    h->x = mcp__proc_lin_at(&g->ground_x, px, py) / w;
    h->z = mcp__proc_lin_at(&g->ground_z, px, py) / w;
}

void
mcp__proc_albedo(const mcp__proc_hit *h, double albedo[3])
{
    if (h->surface == MCP__PROC_OCCLUDER)
        occluder_albedo(h->x, albedo);
    else
        ground_albedo(h->x, h->z, albedo);
}

void
mcp__proc_shade_sample(const mcp__proc_geom *g, const mcp__proc_hit *h,
                       const double u[MCP__PROC_SHADE_DIMS], double rgb[3])
{
    double alb[3], fall = falloff(h->x, h->z);
    mcp__proc_albedo(h, alb);
    if (h->surface == MCP__PROC_OCCLUDER) {
        /* lit from above with nothing between it and the light */
        for (int c = 0; c < 3; c++)
            rgb[c] = alb[c] * (AMBIENT[c] + DIRECT[c] * fall);
        return;
    }
    /* visibility of a uniform point on the light: does the segment cross the sheet? */
    double lx = LIGHT_X0 + u[0] * (LIGHT_X1 - LIGHT_X0);
    double lz = LIGHT_Z0 + u[1] * (LIGHT_Z1 - LIGHT_Z0);
    double sx = h->x + (lx - h->x) * SHADOW_A, sz = h->z + (lz - h->z) * SHADOW_A;
    double vis = (sx >= OCC_X0 && sx <= OCC_X1 && sz >= OCC_Z0 && sz <= OCC_Z1) ? 0 : 1;
    /* the glossy lobe, drawn by Box-Muller; 1 - u lies in (0, 1], so the log is finite */
    double rx, rz, rad = sqrt(-2.0 * log(1.0 - u[2])), phi = 6.283185307179586 * u[3];
    mirror_point(h->x, h->z, &rx, &rz);
    double qx = rx + GLOSS_SIGMA * rad * cos(phi) - GLOSS_CX;
    double qz = rz + GLOSS_SIGMA * rad * sin(phi) - GLOSS_CZ;
    double le = exp(-(qx * qx + qz * qz) / (2.0 * GLOSS_W * GLOSS_W));
    double ff = u[4] < g->firefly_probability ? g->firefly_value : 0.0;
    for (int c = 0; c < 3; c++)
        rgb[c] = alb[c] * (AMBIENT[c] + DIRECT[c] * fall * vis) + GLOSS[c] * le +
                 FIREFLY_TINT[c] * ff;
}

void
mcp__proc_shade_moments(const mcp__proc_geom *g, const mcp__proc_hit *h, double mean[3],
                        double m2[3])
{
    double alb[3], fall = falloff(h->x, h->z);
    mcp__proc_albedo(h, alb);
    if (h->surface == MCP__PROC_OCCLUDER) {
        for (int c = 0; c < 3; c++) {
            mean[c] = alb[c] * (AMBIENT[c] + DIRECT[c] * fall);
            m2[c] = mean[c] * mean[c];
        }
        return;
    }
    double vis = visible_fraction(h->x, h->z), rx, rz, w2 = GLOSS_W * GLOSS_W;
    mirror_point(h->x, h->z, &rx, &rz);
    /* le^2 is the same Gaussian with half the variance */
    double le = blurred_gaussian(rx, rz, w2), le2 = blurred_gaussian(rx, rz, 0.5 * w2);
    double p = g->firefly_probability, ff = g->firefly_value;
    /* The three random parts use disjoint uniforms, so their variances add. */
    for (int c = 0; c < 3; c++) {
        double d = alb[c] * DIRECT[c] * fall, s = GLOSS[c], f = FIREFLY_TINT[c] * ff;
        mean[c] = alb[c] * AMBIENT[c] + d * vis + s * le + f * p;
        double var =
            d * d * vis * (1.0 - vis) + s * s * (le2 - le * le) + f * f * p * (1.0 - p);
        m2[c] = var + mean[c] * mean[c];
    }
}

int
mcp__proc_edges(const mcp__proc_geom *g, int x, int y, mcp__proc_lin *out, int cap)
{
    const double px[4] = {x, x + 1, x, x + 1}, py[4] = {y, y, y + 1, y + 1};
    int n = 0, overflow = 0;
    /* the occluder's outline */
    const double ox[2] = {OCC_X0, OCC_X1}, oz[2] = {OCC_Z0, OCC_Z1};
    for (int k = 0; k < 2; k++) {
        mcp__proc_lin fx = lin_combo(1.0, &g->occ_x, -ox[k], &g->w);
        mcp__proc_lin fz = lin_combo(1.0, &g->occ_z, -oz[k], &g->w);
        n = push_if_crossing(&fx, px, py, out, n, cap, &overflow);
        n = push_if_crossing(&fz, px, py, out, n, cap, &overflow);
    }
    /* the kinks of the visible fraction: where a projected occluder side passes a
     * light side, g + (o - g)/A = l */
    const double lx[2] = {LIGHT_X0, LIGHT_X1}, lz[2] = {LIGHT_Z0, LIGHT_Z1};
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) {
            double kx = (ox[i] / SHADOW_A - lx[j]) / (1.0 / SHADOW_A - 1.0);
            double kz = (oz[i] / SHADOW_A - lz[j]) / (1.0 / SHADOW_A - 1.0);
            mcp__proc_lin fx = lin_combo(1.0, &g->ground_x, -kx, &g->w);
            mcp__proc_lin fz = lin_combo(1.0, &g->ground_z, -kz, &g->w);
            n = push_if_crossing(&fx, px, py, out, n, cap, &overflow);
            n = push_if_crossing(&fz, px, py, out, n, cap, &overflow);
        }
    /* the checkerboard's two families of edges */
    n = push_grid_lines(g, CHECK_COS, CHECK_SIN, CHECK_CELL, px, py, out, n, cap,
                        &overflow);
    n = push_grid_lines(g, -CHECK_SIN, CHECK_COS, CHECK_CELL, px, py, out, n, cap,
                        &overflow);
    return overflow ? -1 : n;
}

int
mcp__proc_check_passes(const mcp__proc_geom *g, const char *what, uint64_t n)
{
    uint64_t pass = (uint64_t)g->strata * (uint64_t)g->strata;
    if (n % pass == 0) return 0;
    return mcp_error("procedural: the jittered sampler takes whole passes of strata^2 = "
                     "%llu samples; %s must be a multiple of %llu (got %llu)",
                     (unsigned long long)pass, what, (unsigned long long)pass,
                     (unsigned long long)n);
}

/* ---- public ---- */

mcp_proc_scene
mcp_proc_scene_defaults(void)
{
    return (mcp_proc_scene){.width = 64,
                            .height = 64,
                            .firefly_probability = 1e-3,
                            .firefly_value = 100.0,
                            .truth_order = 8,
                            .sampler = MCP_PROC_SAMPLER_INDEPENDENT,
                            .strata = 4};
}

int
mcp_proc_scene_check(const mcp_proc_scene *s)
{
    if (!s) return mcp_error("procedural: no scene");
    if (s->width < 1 || s->width > MCP_MAX_DIM)
        return mcp_error("procedural: width must be in 1..%d (got %d)", MCP_MAX_DIM,
                         s->width);
    if (s->height < 1 || s->height > MCP_MAX_DIM)
        return mcp_error("procedural: height must be in 1..%d (got %d)", MCP_MAX_DIM,
                         s->height);
    if (!(s->firefly_probability >= 0.0 && s->firefly_probability <= 1.0))
        return mcp_error("procedural: firefly_probability must be in [0, 1] (got %g)",
                         s->firefly_probability);
    if (!(s->firefly_value >= 0.0 && isfinite(s->firefly_value)))
        return mcp_error("procedural: firefly_value must be finite and >= 0 (got %g)",
                         s->firefly_value);
    if (s->truth_order < 1 || s->truth_order > 32)
        return mcp_error("procedural: truth_order must be in 1..32 (got %d)",
                         s->truth_order);
    if (s->sampler != MCP_PROC_SAMPLER_INDEPENDENT &&
        s->sampler != MCP_PROC_SAMPLER_JITTERED)
        return mcp_error("procedural: sampler must be MCP_PROC_SAMPLER_INDEPENDENT or "
                         "MCP_PROC_SAMPLER_JITTERED (got %d)",
                         (int)s->sampler);
    /* checked for both samplers, so that switching to jittered cannot fail later; 64
     * (4096 samples per pass) is far more than a stratified render needs */
    if (s->strata < 1 || s->strata > MCP_PROC_MAX_STRATA)
        return mcp_error("procedural: strata must be in 1..%d (got %d)",
                         MCP_PROC_MAX_STRATA, s->strata);
    return 0;
}
