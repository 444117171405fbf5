/* internal.h: the operation tables of ops/, for the list in operations.c (not
 * installed). */
#ifndef MCP_OPS_INTERNAL_H
#define MCP_OPS_INTERNAL_H

#include "operations.h"

extern const mcp_operation mcp__op_estimate;
extern const mcp_operation mcp__op_blend;

#endif
