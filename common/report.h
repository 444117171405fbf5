/* report.h: what a run found, for people and for programs.
 *
 * A report is a JSON document (report.json: every figure) plus a self-contained HTML
 * page (report.html) built from the same content: sections, each with tables, images
 * and plots. Stages add one section each. */
#ifndef MCP_REPORT_H
#define MCP_REPORT_H

#include <cjson/cJSON.h>
#include <mcpost/error.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct mcp_report mcp_report;

MCP_API int mcp_report_new(const char *title, mcp_report **out);
MCP_API void mcp_report_free(mcp_report *r);

/* The whole JSON document: {"title": ..., "sections": [...]}. */
MCP_API cJSON *mcp_report_json(mcp_report *r);

/* Appends a section {"title": title, "stage": stage} and returns it (owned by the
 * report); stages put their figures into it as JSON members. NULL on failure. */
MCP_API cJSON *mcp_report_section(mcp_report *r, const char *stage, const char *title);

/* Adds an image (a file path relative to the report's folder) to a section's
 * "images" list. */
MCP_API int mcp_report_add_image(cJSON *section, const char *rel_path,
                                 const char *caption);

/* Writes report.json and report.html into dir (atomically). */
MCP_API int mcp_report_write(mcp_report *r, const char *dir);

#ifdef __cplusplus
}
#endif
#endif
