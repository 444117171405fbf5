/* box_denoiser.h: a linear 3x3 box denoiser for tests -- exact JVP, closed-form SURE --
 * shared by the estimate tests. */
#ifndef MCP_TEST_BOX_DENOISER_H
#define MCP_TEST_BOX_DENOISER_H

#include <mcpost/denoiser.h>

/* A zeroed 3-channel "R,G,B" image (asserts on failure). */
mcp_image *mcp_test_rgb(int w, int h);

/* out = the 3x3 box mean of in, replicate borders (both w x h x 3). */
void mcp_test_box3(const mcp_image *in, mcp_image *out);

/* The box filter as a denoiser: apply is mcp_test_box3, jvp the same on tangents. */
extern const mcp_denoiser mcp_test_box_denoiser;

#endif
