/* operations.c: the list of operations with an option table, found by name. */
#include "internal.h"

#include <string.h>

static const mcp_operation *const list[] = {&mcp__op_estimate,
                                            &mcp__op_blend,
                                            &mcp__op_adaptive,
                                            &mcp__op_info,
                                            &mcp__op_merge,
                                            &mcp__op_denoise,
                                            &mcp__op_convert,
                                            &mcp__op_metrics,
                                            &mcp__op_compare,
                                            &mcp__op_perceptual,
                                            NULL};

const mcp_operation *const *
mcp_operations(void)
{
    return list;
}

const mcp_operation *
mcp_operation_find(const char *name)
{
    for (const mcp_operation *const *op = list; name && *op; op++)
        if (!strcmp((*op)->name, name)) return *op;
    return NULL;
}
