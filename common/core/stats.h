/* stats.h: per-channel statistics of an image (what `mcpost info` prints). */
#ifndef MCP_STATS_H
#define MCP_STATS_H

#include <mcpost/image.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct mcp_channel_stats {
    double min, max, mean; /* over finite values; 0 when there are none */
    long n_nan, n_inf, n_negative, n_finite;
} mcp_channel_stats;

/* Statistics of channel c. Sums in double per row, rows added in order, so the
 * result does not depend on the thread count. */
MCP_API int mcp_channel_stats_compute(const mcp_image *img, int c,
                                      mcp_channel_stats *out);

/* Pools the first 3 channels over a (2 radius + 1)² window clipped at the borders, in
 * place: with a shape (3 channels, same size) each value becomes
 * shape_i Σ_W values / Σ_W shape -- a ratio estimate that keeps the shape's pattern
 * and takes its level from the whole window -- or, without one (or where Σ_W shape
 * is 0), the window mean. Sums in double over a summed-area table. Used for
 * few-degree-of-freedom variance estimates (docs "Variance sources"). */
MCP_API int mcp_pool_window(mcp_image *values, const mcp_image *shape, int radius);

#ifdef __cplusplus
}
#endif
#endif
