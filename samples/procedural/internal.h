/* internal.h: the procedural scene as the renderer and the truth both see it
 * (shared by scene.c, render.c and truth.c; not installed). */
#ifndef MCP_PROCEDURAL_INTERNAL_H
#define MCP_PROCEDURAL_INTERNAL_H

#include "procedural.h"

/* A function a*px + b*py + c of continuous pixel coordinates (px right, py down, pixel
 * (x, y) covers [x, x+1] x [y, y+1]). Planar quantities seen through the pinhole are
 * ratios of two of these, so their level sets are lines on the screen. */
typedef struct mcp__proc_lin {
    double a, b, c;
} mcp__proc_lin;

static inline double
mcp__proc_lin_at(const mcp__proc_lin *l, double px, double py)
{
    return l->a * px + l->b * py + l->c;
}

/* The scene fixed for one image size. */
typedef struct mcp__proc_geom {
    int width, height;
    int strata; /* k of the jittered sampler; 1 for the independent one (the same) */
    double firefly_probability, firefly_value;
    double d0[3], dx[3], dy[3]; /* ray direction d0 + px dx + py dy (not normalised) */
    /* Homogeneous coordinates of where the ray meets the ground (height 0) and the
     * occluder's plane: x = ground_x / w, z = ground_z / w; w > 0 on the screen. */
    mcp__proc_lin w, ground_x, ground_z, occ_x, occ_z;
} mcp__proc_geom;

enum { MCP__PROC_GROUND, MCP__PROC_OCCLUDER };

/* What a camera ray hits: the surface and the world point (x, surface height, z). */
typedef struct mcp__proc_hit {
    int surface;
    double x, z;
} mcp__proc_hit;

/* Random numbers one sample uses after the two for its pixel position. */
#define MCP__PROC_SHADE_DIMS 5

int mcp__proc_geom_init(const mcp_proc_scene *scene, mcp__proc_geom *g);
void mcp__proc_hit_at(const mcp__proc_geom *g, double px, double py, mcp__proc_hit *h);
void mcp__proc_albedo(const mcp__proc_hit *h, double albedo[3]);
/* One sample's radiance at h, given uniforms u in [0,1): light point (2), glossy lobe
 * (2), firefly (1). */
void mcp__proc_shade_sample(const mcp__proc_geom *g, const mcp__proc_hit *h,
                            const double u[MCP__PROC_SHADE_DIMS], double rgb[3]);
/* The first and second moments of mcp__proc_shade_sample over u, in closed form. */
void mcp__proc_shade_moments(const mcp__proc_geom *g, const mcp__proc_hit *h,
                             double mean[3], double m2[3]);
/* 0 when n (a sample count or index, named what) is a whole number of passes of g's
 * sampler; otherwise sets the error and returns -1. The jittered estimate is unbiased
 * only over whole passes (a partial pass leaves cells out). */
int mcp__proc_check_passes(const mcp__proc_geom *g, const char *what, uint64_t n);
/* The lines (in pixel coordinates) crossing the interior of pixel (x, y) across which
 * the moments are discontinuous or kinked. Returns their number, or -1 when there are
 * more than cap (out then holds the first cap). */
int mcp__proc_edges(const mcp__proc_geom *g, int x, int y, mcp__proc_lin *out, int cap);

#endif
