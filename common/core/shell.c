/* shell.c: the commands mcpost runs (an adaptive loop's render command, an external
 * denoiser), with its own programs reachable by name. A job's render command says
 * `mcpost-procedural ...`, not a path into a build tree: the folder that holds the
 * mcpost executable goes at the end of the child's PATH (never this process's, which
 * a library must not change), as git finds its own helpers. */
#define _XOPEN_SOURCE 700 /* realpath */
#include "internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

/* The folder of mcpost's programs: the first of the code's bin/ (the code is the
 * shared library in <libdir>), the code's own folder (the code is an executable, or
 * the build tree's library beside it), the build tree and the install folder that
 * holds an executable `mcpost`. */
static int
programs_dir(char *buf, size_t cap)
{
    char code[4096], from_lib[4200] = "";
    if (mcp__code_dir(code, sizeof code) == 0)
        snprintf(from_lib, sizeof from_lib, "%s/%s", code, MCP_BIN_FROM_LIB);
    else
        code[0] = '\0';
    const char *dirs[] = {from_lib, code, MCP_BIN_BUILD_DIR, MCP_BIN_INSTALL_DIR};
    for (size_t i = 0; i < sizeof dirs / sizeof *dirs; i++) {
        char exe[4300];
        if (!*dirs[i] ||
            (size_t)snprintf(exe, sizeof exe, "%s/mcpost", dirs[i]) >= sizeof exe)
            continue;
        /* absolute: a relative entry would move with a command's own cd */
        char *real = access(exe, X_OK) == 0 ? realpath(dirs[i], NULL) : NULL;
        int fits = real && (size_t)snprintf(buf, cap, "%s", real) < cap;
        free(real);
        if (fits) return 0;
    }
    buf[0] = '\0';
    return -1;
}

/* Appends text[0..n) to b, single-quoted for /bin/sh when quote is set ('\'' for
 * each quote inside). */
static int
append(mcp__strbuf *b, const char *text, size_t n, int quote)
{
    char *o = mcp__strbuf_reserve(b, quote ? 4 * n + 2 : n);
    if (!o) return -1;
    if (quote) *o++ = '\'';
    for (size_t i = 0; i < n; i++) {
        if (quote && text[i] == '\'') {
            memcpy(o, "'\\''", 4);
            o += 4;
        } else
            *o++ = text[i];
    }
    if (quote) *o++ = '\'';
    *o = '\0';
    b->len = (size_t)(o - b->s);
    return 0;
}

int
mcp__shell_fill(const char *tmpl, int n, const char *const *names,
                const char *const *values, unsigned quoted, char **out)
{
    mcp__strbuf s = {0};
    int rc = 0;
    for (const char *p = tmpl; *p && !rc;) {
        int k = -1;
        for (int i = 0; i < n && k < 0; i++)
            if (!strncmp(p, names[i], strlen(names[i]))) k = i;
        rc = k < 0 ? append(&s, p, 1, 0)
                   : append(&s, values[k], strlen(values[k]), (quoted >> k) & 1);
        p += k < 0 ? 1 : strlen(names[k]);
    }
    *out = mcp__strbuf_take(&s);
    return *out ? 0 : -1;
}

int
mcp__shell(const char *command)
{
    char dir[4096];
    fflush(NULL); /* the child shares stdout and stderr */
    if (programs_dir(dir, sizeof dir) != 0) return system(command);
    /* PATH="${PATH:+$PATH:}"'DIR'; export PATH; COMMAND */
    static const char head[] = "PATH=\"${PATH:+$PATH:}\"", tail[] = "; export PATH; ";
    mcp__strbuf line = {0};
    append(&line, head, strlen(head), 0);
    append(&line, dir, strlen(dir), 1);
    append(&line, tail, strlen(tail), 0);
    append(&line, command, strlen(command), 0);
    int status = line.failed ? -1 : system(line.s);
    mcp__strbuf_free(&line);
    return status;
}

int
mcp__shell_check(int status, const char *what, const char *command)
{
    if (status == -1) return mcp_error("%s '%s': cannot start /bin/sh", what, command);
    if (WIFSIGNALED(status))
        return mcp_error("%s '%s' was killed by signal %d", what, command,
                         WTERMSIG(status));
    if (!WIFEXITED(status)) return mcp_error("%s '%s' failed", what, command);
    int code = WEXITSTATUS(status);
    if (code == 127) { /* the shell's "not found" */
        char dir[4096];
        int found = programs_dir(dir, sizeof dir) == 0;
        return mcp_error("%s '%s' failed (exit status 127: a program not found; looked "
                         "on the PATH%s%s)",
                         what, command, found ? ", then in " : "", found ? dir : "");
    }
    if (code != 0)
        return mcp_error("%s '%s' failed (exit status %d)", what, command, code);
    return 0;
}
