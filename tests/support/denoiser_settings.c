/* denoiser_settings.c: see denoiser_settings.h. */
#include "denoiser_settings.h"
#include "testing.h"

mcp_denoiser *
mcp_test_denoiser(const char *yaml)
{
    mcp_node *node = NULL;
    mcp_denoiser *d = NULL;
    if (mcp_yaml_parse_string(yaml, "job.yaml", &node) ||
        mcp_denoiser_create(node, NULL, &d))
        fail_msg("%s: %s", yaml, mcp_error_message());
    mcp_node_free(node);
    return d;
}

void
mcp_test_denoiser_fails(const char *yaml, const char *needle)
{
    mcp_node *node = NULL;
    mcp_denoiser *d = (mcp_denoiser *)&d; /* must come back NULL */
    if (mcp_yaml_parse_string(yaml, "job.yaml", &node))
        fail_msg("%s: %s", yaml, mcp_error_message());
    assert_error_contains(mcp_denoiser_create(node, NULL, &d), needle);
    assert_null(d);
    mcp_node_free(node);
}
