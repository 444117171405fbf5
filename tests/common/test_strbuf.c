/* test_strbuf.c: common/core/strbuf.c, the growing string behind reports, plots, CSV
 * tables, shell lines and settings dumps. Its text is checked byte for byte against
 * the same text made with snprintf into a fixed buffer (the truth), across many
 * growths; a failed allocation must stick (later appends do nothing, take gives NULL
 * and frees) and a file read whole must come back byte for byte. */
#include "testing.h"

#include "../../common/core/internal.h"

#include <mcpost/error.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* put, str, printf and reserve mixed, 3000 rounds (about 100 kB, so the buffer
 * doubles many times from its first 256 bytes), against snprintf. */
static void
test_matches_snprintf(void **state)
{
    (void)state;
    static char truth[1 << 17];
    size_t tl = 0;
    mcp__strbuf b = {0};
    for (int i = 0; i < 3000; i++) {
        switch (i % 4) {
        case 0:
            assert_int_equal(mcp__strbuf_put(&b, "abcdef", (size_t)(i % 7)), 0);
            tl +=
                (size_t)snprintf(truth + tl, sizeof truth - tl, "%.*s", i % 7, "abcdef");
            break;
        case 1:
            assert_int_equal(mcp__strbuf_str(&b, "|x|"), 0);
            tl += (size_t)snprintf(truth + tl, sizeof truth - tl, "|x|");
            break;
        case 2:
            assert_int_equal(mcp__strbuf_printf(&b, "%d:%.3f;%s", i, i / 7.0, "q"), 0);
            tl += (size_t)snprintf(truth + tl, sizeof truth - tl, "%d:%.3f;%s", i,
                                   i / 7.0, "q");
            break;
        default: {
            char *at = mcp__strbuf_reserve(&b, 3);
            assert_non_null(at);
            memcpy(at, "RRR", 3);
            b.len += 3;
            b.s[b.len] = '\0';
            tl += (size_t)snprintf(truth + tl, sizeof truth - tl, "RRR");
        }
        }
        assert_int_equal(b.len, tl);
        assert_true(b.cap > b.len);
    }
    /* one piece longer than the buffer holds at once */
    static char wide[5000];
    memset(wide, 'w', sizeof wide - 1);
    assert_int_equal(mcp__strbuf_printf(&b, "<%s>", wide), 0);
    tl += (size_t)snprintf(truth + tl, sizeof truth - tl, "<%s>", wide);
    assert_int_equal(b.len, tl);
    assert_int_equal(strlen(b.s), tl);
    char *s = mcp__strbuf_take(&b);
    assert_string_equal(s, truth);
    assert_null(b.s);
    assert_int_equal(b.len, 0);
    free(s);
}

/* Nothing added: take gives an empty string, not NULL. */
static void
test_take_empty(void **state)
{
    (void)state;
    mcp__strbuf b = {0};
    char *s = mcp__strbuf_take(&b);
    assert_non_null(s);
    assert_string_equal(s, "");
    free(s);
}

/* The n-th allocation fails (common/core/alloc.c's hook): that call and every later one
 * return -1, the text stays as it was, take frees it and gives NULL. */
static void
test_failure_sticks(void **state)
{
    (void)state;
    for (long n = 0; n < 3; n++) {
        mcp__strbuf b = {0};
        mcp__alloc_fail_after(n);
        int failed_at = -1;
        for (int i = 0; i < 100 && failed_at < 0; i++)
            if (mcp__strbuf_printf(&b, "%0100d", i)) failed_at = i;
        mcp__alloc_fail_after(-1);
        assert_true(failed_at >= 0);
        assert_true(b.failed);
        size_t len = b.len;
        assert_int_equal(mcp__strbuf_str(&b, "more"), -1);
        assert_null(mcp__strbuf_reserve(&b, 1));
        assert_int_equal(b.len, len);
        assert_int_equal(len, (size_t)failed_at * 100);
        assert_null(mcp__strbuf_take(&b));
        assert_null(b.s);
    }
}

/* A file of 300 001 bytes (more than one read's 64 KiB), NULs included, read after
 * what the buffer already held. */
static void
test_read_file(void **state)
{
    (void)state;
    const size_t n = 300001;
    unsigned char *data = malloc(n);
    assert_non_null(data);
    for (size_t i = 0; i < n; i++)
        data[i] = (unsigned char)(i * 2654435761u >> 13);
    const char *path = mcp_test_path("strbuf.bin");
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(data, 1, n, f), n);
    fclose(f);

    mcp__strbuf b = {0};
    assert_int_equal(mcp__strbuf_str(&b, "head:"), 0);
    f = fopen(path, "rb");
    assert_non_null(f);
    assert_int_equal(mcp__strbuf_read_file(&b, f), 0);
    fclose(f);
    assert_int_equal(b.len, 5 + n);
    assert_memory_equal(b.s, "head:", 5);
    assert_memory_equal(b.s + 5, data, n);
    assert_int_equal(b.s[b.len], '\0');
    mcp__strbuf_free(&b);
    assert_null(b.s);
    free(data);
}

/* Markup text: the four characters XML and HTML reserve in text and attributes as
 * entities, everything else as it is, NULL as nothing. */
static void
test_markup_text(void **state)
{
    (void)state;
    mcp__strbuf b = {0};
    assert_int_equal(mcp__strbuf_markup_text(&b, "a<b & \"c\"> 'd'"), 0);
    assert_int_equal(mcp__strbuf_markup_text(&b, NULL), 0);
    assert_string_equal(b.s, "a&lt;b &amp; &quot;c&quot;&gt; 'd'");
    mcp__strbuf_free(&b);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_matches_snprintf), cmocka_unit_test(test_take_empty),
        cmocka_unit_test(test_failure_sticks),   cmocka_unit_test(test_read_file),
        cmocka_unit_test(test_markup_text),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
