/* help_pages.h: the docs pages built into the tool (`mcpost help TOPIC`). The table is
 * generated at build time from the docs pages (docs/TOPIC.md) by cmake/embed_docs.cmake,
 * so an installed mcpost prints the pages of the source it was built from. */
#ifndef MCP_HELP_PAGES_H
#define MCP_HELP_PAGES_H

typedef struct mcp_help_page {
    const char *topic; /* the word after `mcpost help` */
    const char *text;  /* the page's Markdown, NUL-terminated */
} mcp_help_page;

/* Every page, ending in {NULL, NULL}. */
extern const mcp_help_page mcp_help_pages[];

#endif
