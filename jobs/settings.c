/* settings.c: reading a stage's settings -- an enum key by its from_name function, and
 * an error the library found put at the line of the key it came from. */
#include "internal.h"

int
mcp__at_line(const mcp_node *settings, const char *key)
{
    const mcp_node *n = mcp_node_get(settings, key);
    return n ? mcp_node_error(n, "%s", mcp_error_message()) : -1;
}

int
mcp__opt_enum(const mcp_node *settings, const char *key, int (*parse)(const char *, void *),
              void *out)
{
    const char *s = NULL;
    if (mcp_node_opt_string(settings, key, &s))
        return -1;
    if (s && parse(s, out))
        return mcp__at_line(settings, key);
    return 0;
}
