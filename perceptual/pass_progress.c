/* pass_progress.c: the progress of the methods that sweep the image in passes until a
 * pass changes nothing (vertical-iterative, power-set's search, horizontal's swaps):
 * how many passes is not known beforehand, so the bar runs over the rows of each pass
 * and its label names the pass, "power-set, pass 3" (docs/conventions.md, "Progress").
 * On a terminal only, for a megapixel or more: 4 candidates of 4K take 5 s. */
#include "../common/core/internal.h" /* progress on a terminal */
#include "internal.h"

#include <stdio.h>

void
mcp__pass_bar_begin(mcp__pass_bar *b, mcp_perc_method method, int w, int h)
{
    b->shown = (double)w * h >= 1048576.0 && !mcp_progress_quiet();
    b->pass = 0;
    b->method = method;
    if (!b->shown) return;
    char label[64];
    snprintf(label, sizeof label, "%s, pass 1", mcp_perc_method_name(method));
    mcp_progress_begin(&b->bar, label, h);
}

void
mcp__pass_bar_row(mcp__pass_bar *b, int pass, int y)
{
    if (!b->shown) return;
    if (pass != b->pass) {
        char label[64];
        snprintf(label, sizeof label, "%s, pass %d", mcp_perc_method_name(b->method),
                 pass + 1);
        mcp__progress_restart(&b->bar, label);
        b->pass = pass;
    }
    mcp_progress_update(&b->bar, y);
}

void
mcp__pass_bar_end(mcp__pass_bar *b)
{
    if (b->shown) mcp_progress_end(&b->bar);
}
