/* stats.h: per-channel statistics of an image (what `mcpost info` prints). */
#ifndef MCP_STATS_H
#define MCP_STATS_H

#include <mcpost/image.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct mcp_channel_stats {
    double min, max, mean;  /* over finite values; 0 when there are none */
    long n_nan, n_inf, n_negative, n_finite;
} mcp_channel_stats;

/* Statistics of channel c. Sums in double per row, rows added in order, so the
 * result does not depend on the thread count. */
MCP_API int mcp_channel_stats_compute(const mcp_image *img, int c, mcp_channel_stats *out);

#ifdef __cplusplus
}
#endif
#endif
