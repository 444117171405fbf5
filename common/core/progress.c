/* progress.c: progress bars on stderr (see progress.h).
 *
 * Bars nest: work that shows a bar (a job's stage, a series, the frames) may call work
 * that shows its own (a U-Net apply, an EXR read). The bars begun and not yet ended
 * form a stack; only the outermost owns a line. On a terminal an inner bar is drawn as
 * a sub-count at the end of the outer one's line ("estimate [###...] 40% | U-Net 23%"),
 * and when it ends the line is the outer bar's again. A log (stderr not a terminal)
 * gets no progress at all, only the notes (docs/conventions.md, "Progress"). */
#define _POSIX_C_SOURCE 200809L
#include <mcpost/progress.h>

#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#include "internal.h"

static int quiet;

/* Where bars go: stderr, a terminal when isatty says so, unless a test has pointed
 * them elsewhere (mcp__progress_set_output). */
static FILE *forced_stream;
static int forced_tty;

static FILE *
stream(void)
{
    return forced_stream ? forced_stream : stderr;
}

/* The bars begun and not ended, outermost first: each one's identity (never
 * dereferenced: a bar abandoned by a failing caller must not be read) and what is
 * drawn of it. Deeper bars than the stack holds are silent. */
enum { MAX_DEPTH = 8, LINE_WIDTH = 80 };
typedef struct active_bar {
    const mcp_progress *bar;
    char label[96];
    int percent;
} active_bar;
static active_bar active[MAX_DEPTH];
static int depth;
/* A terminal line is drawn and not yet ended by a newline. */
static int line_open;

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

void
mcp__progress_set_output(FILE *s, int tty)
{
    forced_stream = s;
    forced_tty = tty;
}

static int
find(const mcp_progress *p)
{
    for (int k = depth - 1; k >= 0; k--)
        if (active[k].bar == p) return k;
    return -1;
}

static void
bar_text(char *out, int width, int percent)
{
    int filled = percent * width / 100;
    memset(out, '#', (size_t)filled);
    memset(out + filled, '.', (size_t)(width - filled));
    out[width] = '\0';
}

/* Redraws the terminal line: the outermost bar, and the innermost of the nested ones
 * as a sub-count. Padded to the line's width so that a longer line drawn before leaves
 * nothing behind. */
static void
draw_line(void)
{
    if (depth == 0) return;
    char line[LINE_WIDTH + 1], bar[41];
    /* nested: 20 + 18 + 5 + 3 + 28 + 5 = 79 columns (the inner label fits "vertical-
       iterative, pass 17") */
    const active_bar *o = &active[0];
    if (depth == 1) {
        bar_text(bar, 40, o->percent);
        snprintf(line, sizeof line, "%-32.32s [%s] %3d%%", o->label, bar, o->percent);
    } else {
        const active_bar *in = &active[depth - 1];
        bar_text(bar, 16, o->percent);
        snprintf(line, sizeof line, "%-20.20s [%s] %3d%% | %-28.28s %3d%%", o->label, bar,
                 o->percent, in->label, in->percent);
    }
    fprintf(stream(), "\r%-*s", LINE_WIDTH, line);
    fflush(stream());
    line_open = 1;
}

static void
end_line(void)
{
    if (!line_open) return;
    fputc('\n', stream());
    fflush(stream());
    line_open = 0;
}

/* Shows bar k of the stack at its new percent: its terminal line is redrawn (a bar in
 * a log is never on the stack). */
static void
show(mcp_progress *p, int k, int percent)
{
    active[k].percent = percent;
    p->last_shown = percent;
    if (!quiet) draw_line();
}

void
mcp_progress_begin(mcp_progress *p, const char *label, long total)
{
    memset(p, 0, sizeof *p);
    snprintf(p->label, sizeof p->label, "%s", label);
    p->total = total > 0 ? total : 1;
    p->tty = forced_stream ? forced_tty : isatty(STDERR_FILENO);
    p->last_shown = -1;
    /* a bar in a log (it would draw nothing), reused without its end, or begun inside
       a parallel region (one thread owns the stack), stays silent */
    int in_parallel = 0;
#ifdef _OPENMP
    in_parallel = omp_in_parallel();
#endif
    if (!p->tty || find(p) >= 0 || in_parallel || depth == MAX_DEPTH) return;
    active_bar *a = &active[depth++];
    a->bar = p;
    snprintf(a->label, sizeof a->label, "%s", label);
    a->percent = 0;
    if (!quiet) show(p, depth - 1, 0);
}

void
mcp__progress_restart(mcp_progress *p, const char *label)
{
    snprintf(p->label, sizeof p->label, "%s", label);
    p->done = 0;
    int k = find(p);
    if (k < 0) return;
    snprintf(active[k].label, sizeof active[k].label, "%s", label);
    show(p, k, 0);
}

void
mcp_progress_update(mcp_progress *p, long done)
{
    p->done = done;
    int k = find(p);
    if (k < 0) return;
    int percent = (int)(100 * (done < p->total ? done : p->total) / p->total);
    if (percent > p->last_shown) show(p, k, percent); /* a redraw per percent */
}

/* Takes bar k and every bar above it off the stack; the outermost ends its terminal
 * line, an inner one gives the line back to the bar below it. */
static void
pop(int k)
{
    depth = k;
    if (quiet) return;
    if (k == 0)
        end_line();
    else if (line_open)
        draw_line();
}

void
mcp_progress_end(mcp_progress *p)
{
    int k = find(p);
    if (k < 0) return;
    if (p->last_shown < 100) show(p, k, 100);
    pop(k);
}

void
mcp__progress_stop(mcp_progress *p)
{
    int k = find(p);
    if (k >= 0) pop(k);
}

void
mcp_note(const char *fmt, ...)
{
    if (quiet) return;
    /* a note while a bar is drawn: on a line of its own, the bar drawn again below */
    int redraw = line_open;
    if (line_open) fprintf(stream(), "\r%-*s\r", LINE_WIDTH, "");
    line_open = 0;
    va_list ap;
    va_start(ap, fmt);
    fputs("mcpost: ", stream());
    vfprintf(stream(), fmt, ap);
    fputc('\n', stream());
    va_end(ap);
    if (redraw) draw_line();
}
