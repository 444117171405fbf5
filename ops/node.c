/* node.c: an operation's settings read from a YAML map (<mcpost/options.h>) -- a job
 * stage's settings, and a denoiser's map (which the command line's --denoiser-opt and
 * Python's settings dict become too): every value through mcp_operation_set, a bad one
 * failing at its line. */
#include "internal.h"

#include <stdlib.h>
#include <string.h>

void
mcp__options_node_keys(const mcp_operation *op, const char *const *extras,
                       const char **keys, int cap)
{
    int n = 0;
    for (const mcp_option *o = op->options; o->name && n < cap - 1; o++)
        if (mcp_option_takes(o, MCP_OPT_JOB)) keys[n++] = o->name;
    const mcp_operation *sh = mcp_shared_operation();
    for (const mcp_option *o = sh->options; o->name && n < cap - 1; o++)
        for (unsigned bit = 1; bit <= MCP_SHARED_THREADS; bit <<= 1)
            if ((op->shared & bit) && mcp_shared_option(bit) == o &&
                mcp_option_takes(o, MCP_OPT_JOB))
                keys[n++] = o->name;
    for (const char *const *e = extras; e && *e && n < cap - 1; e++)
        keys[n++] = *e;
    keys[n] = NULL;
}

/* The text of a value node as the table reads it: a scalar's own, or a list's items
 * joined with commas (for MCP_OPT_LIST); *joined is malloc'd when made. */
static int
node_text(const mcp_node *n, const mcp_option *o, const char *key, char **joined,
          const char **text)
{
    *joined = NULL;
    if (n->kind == MCP_NODE_SCALAR) {
        *text = n->value;
        return 0;
    }
    if (n->kind == MCP_NODE_MAP ||
        (o->type != MCP_OPT_LIST && o->type != MCP_OPT_WORDSET)) {
        /* as mcp_node_int and its kin say it */
        static const char *const what[] = {"a number",
                                           "an integer",
                                           "an integer",
                                           "a number",
                                           "true or false",
                                           "a word",
                                           "a list of numbers",
                                           "a string",
                                           "a string",
                                           "a denoiser",
                                           "a string or a list of them",
                                           "a word or a list of words"};
        return mcp_node_error(n, "%s must be %s, not a %s", key, what[o->type],
                              n->kind == MCP_NODE_MAP ? "map" : "list");
    }
    size_t len = 1;
    for (int i = 0; i < n->count; i++) {
        if (n->items[i]->kind != MCP_NODE_SCALAR)
            return mcp_node_error(n->items[i], "%s must be a list of %s", key,
                                  o->type == MCP_OPT_LIST ? "numbers" : "words");
        len += strlen(n->items[i]->value) + 1;
    }
    char *s = mcp_malloc(len);
    if (!s) return -1;
    s[0] = '\0';
    for (int i = 0; i < n->count; i++) {
        if (i) strcat(s, ",");
        strcat(s, n->items[i]->value);
    }
    *joined = s;
    *text = s;
    return 0;
}

int
mcp__options_from_node(const mcp_operation *op, const mcp_node *map,
                       mcp_shared_settings *sh, void *out)
{
    mcp_operation_defaults(op, out);
    if (sh) mcp_operation_defaults(mcp_shared_operation(), sh);
    for (int i = 0; map && map->kind == MCP_NODE_MAP && i < map->count; i++) {
        const char *key = map->keys[i]->value;
        const mcp_operation *target = op;
        void *dst = out;
        const mcp_option *o = mcp_operation_option(op, key);
        if (!o && sh && (o = mcp_operation_option(mcp_shared_operation(), key))) {
            target = mcp_shared_operation();
            dst = sh;
        }
        /* extras (title) are the stage's; the denoiser is read by mcp__stage_denoiser */
        if (!o || !mcp_option_takes(o, MCP_OPT_JOB) || o->type == MCP_OPT_DENOISER)
            continue;
        const mcp_node *v = map->items[i];
        /* a list of inputs (perceptual's candidates) is the stage's to read */
        if (o->type == MCP_OPT_INPUT && v->kind == MCP_NODE_SEQ) continue;
        if (o->type == MCP_OPT_TEXTS && v->kind == MCP_NODE_SEQ) {
            /* each item one value, refused at its own line */
            for (int k = 0; k < v->count; k++) {
                if (v->items[k]->kind != MCP_NODE_SCALAR)
                    return mcp_node_error(v->items[k],
                                          "%s must be a string or a list of "
                                          "them",
                                          key);
                if (mcp_operation_set(target, o, key, v->items[k]->value, dst))
                    return mcp_node_error(v->items[k], "%s", mcp_error_message());
            }
            continue;
        }
        char *joined = NULL;
        const char *text = NULL;
        if (node_text(map->items[i], o, key, &joined, &text)) return -1;
        int rc = mcp_operation_set(target, o, key, text, dst);
        free(joined);
        if (rc) return mcp_node_error(map->items[i], "%s", mcp_error_message());
    }
    if (mcp_operation_finish(op, out))
        return map ? mcp_node_error(map, "%s", mcp_error_message()) : -1;
    return 0;
}
