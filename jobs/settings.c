/* settings.c: reading a stage's settings -- an error the library found put at the line
 * of the key it came from (the values themselves are read through the operation table,
 * ops/node.c). */
#include "internal.h"

#include <ctype.h>
#include <string.h>

int
mcp__at_line(const mcp_node *settings, const char *key)
{
    const mcp_node *n = mcp_node_get(settings, key);
    if (!n) return -1;
    /* an error from inside the key's value (a denoiser's unknown setting) already
       names its own line: "job.yaml:6: job.yaml:6: ..." would say it twice */
    const char *msg = mcp_error_message();
    size_t len = strlen(n->file);
    if (strncmp(msg, n->file, len) == 0 && msg[len] == ':' &&
        isdigit((unsigned char)msg[len + 1]))
        return -1;
    return mcp_node_error(n, "%s", msg);
}
