/* settings.c: reading a stage's settings -- an enum key by its from_name function, and
 * an error the library found put at the line of the key it came from. */
#include "internal.h"

#include <ctype.h>
#include <string.h>

int
mcp__at_line(const mcp_node *settings, const char *key)
{
    const mcp_node *n = mcp_node_get(settings, key);
    if (!n)
        return -1;
    /* an error from inside the key's value (a denoiser's unknown setting) already
       names its own line: "job.yaml:6: job.yaml:6: ..." would say it twice */
    const char *msg = mcp_error_message();
    size_t len = strlen(n->file);
    if (strncmp(msg, n->file, len) == 0 && msg[len] == ':' && isdigit((unsigned char)msg[len + 1]))
        return -1;
    return mcp_node_error(n, "%s", msg);
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
