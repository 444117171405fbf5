/* progress.c: progress bars and plain progress lines on stderr (see progress.h). */
#define _POSIX_C_SOURCE 200809L
#include <mcpost/progress.h>

#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

static int quiet;

void
mcp_progress_set_quiet(int q)
{
    quiet = q;
}

int
mcp_progress_quiet(void)
{
    return quiet;
}

static void
show(mcp_progress *p, int percent)
{
    if (p->tty) {
        char bar[41];
        int filled = percent * 40 / 100;
        memset(bar, '#', (size_t)filled);
        memset(bar + filled, '.', (size_t)(40 - filled));
        bar[40] = '\0';
        fprintf(stderr, "\r%-32.32s [%s] %3d%%", p->label, bar, percent);
    } else {
        fprintf(stderr, "%s: %d%%\n", p->label, percent);
    }
    fflush(stderr);
    p->last_shown = percent;
}

void
mcp_progress_begin(mcp_progress *p, const char *label, long total)
{
    memset(p, 0, sizeof *p);
    snprintf(p->label, sizeof p->label, "%s", label);
    p->total = total > 0 ? total : 1;
    p->tty = isatty(STDERR_FILENO);
    p->last_shown = -1;
    if (!quiet && p->tty) show(p, 0);
}

void
mcp_progress_update(mcp_progress *p, long done)
{
    p->done = done;
    if (quiet) return;
    int percent = (int)(100 * (done < p->total ? done : p->total) / p->total);
    /* a terminal redraws each percent; a log gets a line per quarter */
    int step = p->tty ? 1 : 25;
    if (percent / step > p->last_shown / step || (p->last_shown < 0 && percent >= step))
        show(p, percent);
}

void
mcp_progress_end(mcp_progress *p)
{
    if (quiet) return;
    if (p->last_shown < 100) show(p, 100);
    if (p->tty) fputc('\n', stderr);
}

void
mcp_note(const char *fmt, ...)
{
    if (quiet) return;
    va_list ap;
    va_start(ap, fmt);
    fputs("mcpost: ", stderr);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
}
