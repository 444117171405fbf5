/* test_progress.c: common/progress.c's text, on a terminal and in a log, written to a
 * memory stream: the bar's lines, nested bars (an inner bar is a sub-count of the outer
 * one's terminal line and silent in a log), a bar abandoned by a failing run, a note
 * while a bar is drawn, and --quiet. */
#include "testing.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../common/core/internal.h"
#include <mcpost/progress.h>

static char *text;
static size_t text_len;
static FILE *out;

static void
capture(int tty)
{
    free(text);
    text = NULL;
    out = open_memstream(&text, &text_len);
    assert_non_null(out);
    mcp__progress_set_output(out, tty);
}

/* What was written, the stream closed; the caller frees nothing (next capture does). */
static const char *
captured(void)
{
    fclose(out);
    mcp__progress_set_output(NULL, 0);
    return text;
}

/* The last state of the line that ends at the newline number `nth` (0-based) or, past
 * the last newline, the line still open: the text after the last '\r' before it, its
 * padding cut. */
static void
line_as_drawn(const char *s, int nth, char *buf, size_t cap)
{
    const char *start = s;
    for (int k = 0; k < nth; k++) {
        start = strchr(start, '\n');
        assert_non_null(start);
        start++;
    }
    const char *end = strchr(start, '\n');
    if (!end) end = start + strlen(start);
    const char *from = start;
    for (const char *c = start; c < end; c++)
        if (*c == '\r') from = c + 1;
    size_t n = (size_t)(end - from);
    while (n > 0 && from[n - 1] == ' ')
        n--;
    assert_true(n < cap);
    memcpy(buf, from, n);
    buf[n] = '\0';
}

static int
count_char(const char *s, char ch)
{
    int n = 0;
    for (; *s; s++)
        n += *s == ch;
    return n;
}

static void
test_terminal_bar(void **state)
{
    (void)state;
    capture(1);
    mcp_progress p;
    mcp_progress_begin(&p, "denoise", 4);
    mcp_progress_update(&p, 1);
    mcp_progress_update(&p, 2);
    mcp_progress_end(&p);
    const char *s = captured();
    /* one line, redrawn at 0, 25, 50 and 100 percent, ended once */
    assert_int_equal(count_char(s, '\n'), 1);
    assert_int_equal(count_char(s, '\r'), 4);
    char line[128];
    line_as_drawn(s, 0, line, sizeof line);
    assert_string_equal(line, "denoise                          "
                              "[########################################] 100%");
    assert_non_null(strstr(s, "[##########..............................]  25%"));
}

static void
test_silent_in_log(void **state)
{
    (void)state;
    capture(0);
    mcp_progress p;
    mcp_progress_begin(&p, "blend", 10);
    for (int i = 1; i <= 10; i++)
        mcp_progress_update(&p, i);
    mcp_progress_end(&p);
    /* a log gets no progress (issue: progress stays silent in logs), a note still */
    mcp_note("blend: done");
    assert_string_equal(captured(), "mcpost: blend: done\n");
}

static void
test_nested_on_terminal(void **state)
{
    (void)state;
    capture(1);
    mcp_progress outer, inner;
    mcp_progress_begin(&outer, "estimate", 2);
    mcp_progress_update(&outer, 1);
    mcp_progress_begin(&inner, "U-Net", 4);
    mcp_progress_update(&inner, 1);
    char line[128];
    const char *partial;
    fflush(out);
    partial = text;
    /* the inner bar is a sub-count at the end of the outer one's line */
    line_as_drawn(partial, 0, line, sizeof line);
    assert_string_equal(line, "estimate             [########........]  50% | U-Net"
                              "                         25%");
    mcp_progress_end(&inner);
    fflush(out);
    /* its end gives the line back to the outer bar, padded over the longer line */
    line_as_drawn(text, 0, line, sizeof line);
    assert_string_equal(line, "estimate                         "
                              "[####################....................]  50%");
    assert_int_equal(count_char(text, '\n'), 0);
    mcp_progress_end(&outer);
    const char *s = captured();
    assert_int_equal(count_char(s, '\n'), 1);
    /* every line drawn is one terminal line wide: no wrap breaks the redraws */
    for (const char *c = strchr(s, '\r'); c; c = strchr(c + 1, '\r')) {
        const char *next = c + 1 + strcspn(c + 1, "\r\n");
        assert_int_equal(next - (c + 1), 80);
    }
}

static void
test_nested_in_log(void **state)
{
    (void)state;
    capture(0);
    mcp_progress outer, inner;
    mcp_progress_begin(&outer, "frames", 2);
    mcp_progress_begin(&inner, "U-Net", 4);
    for (int i = 1; i <= 4; i++)
        mcp_progress_update(&inner, i);
    mcp_progress_end(&inner);
    mcp_progress_update(&outer, 1);
    mcp_progress_update(&outer, 2);
    mcp_progress_end(&outer);
    /* nor nested bars */
    assert_string_equal(captured(), "");
}

static void
test_abandoned_bar(void **state)
{
    (void)state;
    capture(1);
    mcp_progress failed, next;
    mcp_progress_begin(&failed, "nlm", 4);
    mcp_progress_update(&failed, 1);
    mcp__progress_stop(&failed);
    mcp__progress_stop(&failed); /* twice, and on a bar never begun: nothing */
    mcp_progress never;
    memset(&never, 0, sizeof never);
    mcp__progress_stop(&never);
    mcp_progress_begin(&next, "blend", 1);
    mcp_progress_end(&next);
    const char *s = captured();
    char line[128];
    /* the failed bar's line ends where it got (no 100%), and the next bar owns a line
       of its own: it is not drawn as nested in the abandoned one */
    line_as_drawn(s, 0, line, sizeof line);
    assert_string_equal(line, "nlm                              "
                              "[##########..............................]  25%");
    line_as_drawn(s, 1, line, sizeof line);
    assert_string_equal(line, "blend                            "
                              "[########################################] 100%");
    assert_int_equal(count_char(s, '\n'), 2);
}

static void
test_note_during_bar(void **state)
{
    (void)state;
    capture(1);
    mcp_progress p;
    mcp_progress_begin(&p, "frames", 2);
    mcp_progress_update(&p, 1);
    mcp_note("frame %d: done", 7);
    mcp_progress_end(&p);
    const char *s = captured();
    char line[128];
    /* the note on a line of its own, the bar drawn again below it */
    line_as_drawn(s, 0, line, sizeof line);
    assert_string_equal(line, "mcpost: frame 7: done");
    line_as_drawn(s, 1, line, sizeof line);
    assert_string_equal(line, "frames                           "
                              "[########################################] 100%");
    assert_int_equal(count_char(s, '\n'), 2);
}

static void
test_terminal_only(void **state)
{
    (void)state;
    /* one image's bar (an EXR read): nothing in a log ... */
    capture(0);
    mcp_progress p;
    mcp_progress_begin(&p, "reading x.exr", 2);
    mcp_progress_update(&p, 1);
    mcp_progress_end(&p);
    assert_string_equal(captured(), "");
    /* ... a bar on a terminal */
    capture(1);
    mcp_progress_begin(&p, "reading x.exr", 2);
    mcp_progress_end(&p);
    char line[128];
    line_as_drawn(captured(), 0, line, sizeof line);
    assert_string_equal(line, "reading x.exr                    "
                              "[########################################] 100%");
}

static void
test_restart(void **state)
{
    (void)state;
    capture(1);
    mcp_progress p;
    mcp_progress_begin(&p, "vertical-iterative, pass 1", 4);
    mcp_progress_update(&p, 3);
    mcp__progress_restart(&p, "vertical-iterative, pass 2");
    mcp_progress_update(&p, 1);
    fflush(out);
    char line[128];
    /* the same line, the new label, from 0 again */
    line_as_drawn(text, 0, line, sizeof line);
    assert_string_equal(line, "vertical-iterative, pass 2       "
                              "[##########..............................]  25%");
    mcp_progress_end(&p);
    assert_int_equal(count_char(captured(), '\n'), 1);
}

static void
test_quiet(void **state)
{
    (void)state;
    capture(1);
    mcp_progress_set_quiet(1);
    mcp_progress outer, inner;
    mcp_progress_begin(&outer, "frames", 2);
    mcp_progress_begin(&inner, "U-Net", 2);
    mcp_progress_update(&inner, 1);
    mcp_progress_end(&inner);
    mcp_note("a note");
    mcp_progress_end(&outer);
    mcp_progress_set_quiet(0);
    assert_string_equal(captured(), "");
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_terminal_bar),
        cmocka_unit_test(test_silent_in_log),
        cmocka_unit_test(test_nested_on_terminal),
        cmocka_unit_test(test_nested_in_log),
        cmocka_unit_test(test_abandoned_bar),
        cmocka_unit_test(test_note_during_bar),
        cmocka_unit_test(test_terminal_only),
        cmocka_unit_test(test_restart),
        cmocka_unit_test(test_quiet),
    };
    int rc = cmocka_run_group_tests_name("common/progress", tests, NULL, NULL);
    free(text);
    return rc;
}
