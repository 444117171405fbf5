/* internal.h: the operation tables of ops/ for the list in operations.c, and the
 * reader of a YAML map through a table, for job stages and denoisers (not installed). */
#ifndef MCP_OPS_INTERNAL_H
#define MCP_OPS_INTERNAL_H

#include <mcpost/yaml.h>
#include <mcpost/operations.h>

extern const mcp_operation mcp__op_estimate;
extern const mcp_operation mcp__op_blend;
extern const mcp_operation mcp__op_adaptive;
extern const mcp_operation mcp__op_info;
extern const mcp_operation mcp__op_merge;
extern const mcp_operation mcp__op_denoise;
extern const mcp_operation mcp__op_convert;
extern const mcp_operation mcp__op_metrics;
extern const mcp_operation mcp__op_compare;
extern const mcp_operation mcp__op_perceptual;
/* collect's gates (cli/cmd_collect.c; settings: mcp_metrics_settings): the command
 * line's only, so not in operations.c's list */
extern const mcp_operation mcp__op_collect;

/* metrics' and compare's FLIPs, "ldr,hdr" (op_metrics.c) */
extern const mcp_wordlist mcp__flip_kind_words;

/* ---- node.c ---- */

/* The keys of a map read through op's table: every option a job takes (and the shared
 * ones op takes, e.g. output), then extras (NULL-terminated, may be NULL), into
 * keys[cap] (NULL-terminated). */
void mcp__options_node_keys(const mcp_operation *op, const char *const *extras,
                            const char **keys, int cap);
/* A map (a stage's settings, a denoiser's) read through op's table into out (op's
 * settings struct, set to the defaults first) and sh (may be NULL; the shared output:),
 * in the file's order: a bad value fails at its line with the table's message
 * ("job.yaml:7: estimate: tau must be > 0 (got -1)"), and op's finish (the library's
 * check) at the map's line. Keys that are not op's options (title, a denoiser's name)
 * and the denoiser are left to the caller. */
int mcp__options_from_node(const mcp_operation *op, const mcp_node *map,
                           mcp_shared_settings *sh, void *out);
/* Room for a map's keys (mcp__options_node_keys). */
#define MCP__OPTION_KEYS_MAX 64

/* ---- not exported by libmcpost.so (docs/library.md, "Exported symbols") ---- */

/* The value of o in settings as text, as mcp_operation_set reads it back ("0.01",
 * "true", "relse", "0.5,0.9"; NULL text "~"): into buf, truncated to cap. */
void mcp_option_format(const mcp_option *o, const void *settings, char *buf, size_t cap);

#endif
