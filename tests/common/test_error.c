/* test_error.c: the error line (common/core/error.c) -- one line whatever the names in
 * it hold, prefixes, and the allocation helpers' messages. */
#include "testing.h"

#include <mcpost/error.h>

#include <string.h>

/* Regression (fuzz_dump, fuzz_tza): a channel or tensor name with a newline in it
 * made a two-line message; control characters are shown as '?'. */
static void
test_message_stays_one_line(void **state)
{
    (void)state;
    assert_int_equal(mcp_error("f.exr: no channel '%s'", "R\nG\r\tB\x7f"), -1);
    assert_string_equal(mcp_error_message(), "f.exr: no channel 'R?G??B?'");
    assert_int_equal(mcp_error_prefix("job.yaml:%d: %s", 3, "a\nb: "), -1);
    assert_string_equal(mcp_error_message(),
                        "job.yaml:3: a?b: f.exr: no channel 'R?G??B?'");
    /* UTF-8 names are left alone */
    mcp_error("f.exr: no channel '%s'", "\xc3\xa9t\xc3\xa9");
    assert_string_equal(mcp_error_message(), "f.exr: no channel '\xc3\xa9t\xc3\xa9'");
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_message_stays_one_line),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
