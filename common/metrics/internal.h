/* internal.h: functions of common/metrics/ that other library files and the tests
 * call but that libmcpost.so does not export (hidden visibility; not installed). They
 * were public once; the exported list is docs/library.md's "Exported symbols". */
#ifndef MCP_METRICS_INTERNAL_H
#define MCP_METRICS_INTERNAL_H

#include <stddef.h>

#include <mcpost/flip.h>
#include <mcpost/image.h>
#include <mcpost/tonemap.h>

/* ---- metrics.c ---- */

/* Checks a test/reference pair: same size, R, G, B present, every RGB value finite.
 * Fills the channel indices. */
int mcp_metrics_check_pair(const mcp_image *test, const mcp_image *ref, int rgb_test[3],
                           int rgb_ref[3]);

/* ---- flip.c, flip_stats.c ---- */

/* The pixels per degree that opt selects, in float as FLIP computes it. Fails naming
 * the field when it is not positive and finite. */
int mcp_flip_ppd(const mcp_flip_options *opt, float *ppd);

/* FLIP's weighted percentile (as mcp_flip_stats has it) of n values at p in [0, 1]. */
int mcp_flip_weighted_percentile(const float *values, size_t n, double p, double *out);

/* FLIP's parts, for tests and for other modules: */

/* The 1D filters at a given ppd (FLIP.h setSpatialFilters, setFeatureFilter).
 * spatial: 2 * spatial_radius + 1 taps of y, cx (each sums to 1) and cz1, cz2 (the
 * GaussianSqrt split of the blue-yellow sum of Gaussians: cz1 x cz1 + cz2 x cz2 sums
 * to 1). feature: 2 * feature_radius + 1 taps of the Gaussian g and its first and
 * second derivatives dg, ddg (positive taps sum to 1, negative to -1). */
typedef struct mcp_flip_filters {
    float ppd;
    int spatial_radius;
    float *y, *cx, *cz1, *cz2;
    int feature_radius;
    float *g, *dg, *ddg;
} mcp_flip_filters;

int mcp_flip_filters_new(float ppd, mcp_flip_filters **out);
void mcp_flip_filters_free(mcp_flip_filters *f);

/* cmax = HyAB(Hunt(Lab(green)), Hunt(Lab(blue)))^qc = 41.2760963 (FLIP.h
 * computeMaxDistance, in float). */
float mcp_flip_cmax(void);

/* The larger root x of tm(x) = 0.85 for FLIP's tone curve (FLIP.h computeExposures):
 * 2.1188723 (aces), 3.1277493 (hable), 5.6666667 (reinhard). */
int mcp_flip_exposure_xmax(mcp_tonemap tm, float *xmax);

/* The automatic exposure range of a reference: start = log2(xmax / Ymax),
 * stop = log2(xmax / Ymedian) with Y the Rec. 709 luminance of max(ref, 0), Ymedian
 * element n/2 of the sorted luminances (zeros included) and both clamped to
 * FLT_EPSILON (our departure). */
int mcp_flip_auto_exposures(const mcp_image *ref, mcp_tonemap tm, float *start,
                            float *stop);

#endif
