/* denoiser_settings.h: denoisers from YAML settings text, for the estimate tests. */
#ifndef MCP_TEST_DENOISER_SETTINGS_H
#define MCP_TEST_DENOISER_SETTINGS_H

#include <mcpost/denoiser.h>

/* The denoiser of settings text (a name or a flow map), read as file "job.yaml";
 * fails the test on error. */
mcp_denoiser *mcp_test_denoiser(const char *yaml);

/* Asserts that creating from the settings text fails with an error containing needle,
 * leaving the output NULL. */
void mcp_test_denoiser_fails(const char *yaml, const char *needle);

#endif
