/* progress.h: progress of long-running work on stderr -- a bar on a terminal; nothing
 * in a log (stderr not a terminal) or when quiet. Call from one thread (the caller of a
 * parallel loop), e.g. once per finished row block. */
#ifndef MCP_PROGRESS_H
#define MCP_PROGRESS_H

#include <mcpost/error.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct mcp_progress {
    char label[96];
    long total, done;
    int last_shown; /* percent last printed */
    int tty;
} mcp_progress;

/* Process-wide switch (the CLI's --quiet and job option `quiet`). */
MCP_API void mcp_progress_set_quiet(int quiet);
MCP_API int mcp_progress_quiet(void);

MCP_API void mcp_progress_begin(mcp_progress *p, const char *label, long total);
MCP_API void mcp_progress_update(mcp_progress *p, long done);
MCP_API void mcp_progress_end(mcp_progress *p);

/* One line of news on stderr ("mcpost: ..."), unless quiet. */
MCP_API void mcp_note(const char *fmt, ...) MCP_PRINTF(1, 2);

#ifdef __cplusplus
}
#endif
#endif
