/* yaml.h: job files as trees of nodes that remember their line (YAML, read with
 * libyaml; JSON parses too). The job runner (job.h) reads its files with it, and the
 * denoisers (denoiser.h) and the operations' options read their settings from its
 * nodes, so that every error names "FILE:LINE". */
#ifndef MCP_YAML_H
#define MCP_YAML_H

#include <mcpost/error.h>

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum { MCP_NODE_SCALAR, MCP_NODE_SEQ, MCP_NODE_MAP } mcp_node_kind;

typedef struct mcp_node {
    mcp_node_kind kind;
    int line, column;        /* 1-based position in the file */
    const char *file;        /* the file's path (shared, owned by the root) */
    char *value;             /* MCP_NODE_SCALAR: the text */
    int quoted;              /* scalar was quoted (so "1" is a string) */
    int count;               /* SEQ: items; MAP: pairs */
    struct mcp_node **items; /* SEQ items, or MAP values */
    struct mcp_node **keys;  /* MAP keys (scalar nodes) */
} mcp_node;

MCP_API int mcp_yaml_parse_file(const char *path, mcp_node **out);
MCP_API int mcp_yaml_parse_string(const char *text, const char *label, mcp_node **out);
MCP_API void mcp_node_free(mcp_node *root);

/* The value under key in a map, or NULL (also when node is not a map). */
MCP_API const mcp_node *mcp_node_get(const mcp_node *map, const char *key);

/* Fails with "FILE:LINE: unknown key 'K' in WHAT (known: a, b, c)" when the map has a
 * key not in allowed (NULL-terminated). Also fails when node is not a map. */
MCP_API int mcp_node_check_keys(const mcp_node *map, const char *const *allowed,
                                const char *what);

/* Typed reads of a scalar, each failing with "FILE:LINE: KEY must be ... (got 'V')".
 * `key` is only for the message. */
MCP_API int mcp_node_int(const mcp_node *n, const char *key, int *out);
MCP_API int mcp_node_double(const mcp_node *n, const char *key, double *out);
MCP_API int mcp_node_bool(const mcp_node *n, const char *key, int *out);
MCP_API int mcp_node_string(const mcp_node *n, const char *key, const char **out);

/* Optional keys in a map: leave *out unchanged when absent; fail on a wrong type. */
MCP_API int mcp_node_opt_int(const mcp_node *map, const char *key, int *out);
MCP_API int mcp_node_opt_double(const mcp_node *map, const char *key, double *out);
MCP_API int mcp_node_opt_bool(const mcp_node *map, const char *key, int *out);
MCP_API int mcp_node_opt_string(const mcp_node *map, const char *key, const char **out);
/* A list of numbers (a scalar counts as a list of one); *out is malloc'd. */
MCP_API int mcp_node_opt_doubles(const mcp_node *map, const char *key, double **out,
                                 int *count);
/* The same, required: fails with "FILE:LINE: missing key 'K' in WHAT". */
MCP_API int mcp_node_require(const mcp_node *map, const char *key, const char *what,
                             const mcp_node **out);

/* "FILE:LINE: " + message, as an error; returns -1. */
MCP_API int mcp_node_error(const mcp_node *n, const char *fmt, ...) MCP_PRINTF(2, 3);

#ifdef __cplusplus
}
#endif
#endif
