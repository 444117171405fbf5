/* testing.h: what every mcpost test includes -- cmocka, tolerances, scratch files,
 * test images, and running the mcpost executable. */
#ifndef MCP_TESTING_H
#define MCP_TESTING_H

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <mcpost/image.h>

/* |a - b| <= atol + rtol * |b|, with a message naming both values. cmocka 1.1.5 has
 * only an absolute float comparison. */
#define assert_close(a, b, rtol, atol)                                                   \
    mcp_test_assert_close((double)(a), (double)(b), (rtol), (atol), #a, __FILE__,        \
                          __LINE__)
void mcp_test_assert_close(double a, double b, double rtol, double atol, const char *expr,
                           const char *file, int line);

/* Asserts that a call failed (-1) and that the error line contains `needle`. */
#define assert_error_contains(call, needle)                                              \
    mcp_test_assert_error((call), (needle), #call, __FILE__, __LINE__)
void mcp_test_assert_error(int rc, const char *needle, const char *expr, const char *file,
                           int line);

/* A fresh scratch directory for this test binary (MCPOST_TEST_TMP or /tmp); returns
 * "<dir>/<name>" in a static rotating buffer. */
const char *mcp_test_path(const char *name);

/* Images for tests: constant, a ramp (value = x + 10 y + 100 c), a seeded uniform
 * random image in [lo, hi). Channel names are given or C0.. */
mcp_image *mcp_test_constant(int w, int h, int c, float value, const char *const *names);
mcp_image *mcp_test_ramp(int w, int h, int c, const char *const *names);
mcp_image *mcp_test_random(int w, int h, int c, float lo, float hi, uint64_t seed,
                           const char *const *names);

/* Largest absolute difference between two same-shaped images. */
double mcp_test_max_abs_diff(const mcp_image *a, const mcp_image *b);

/* Asserts that two images (or both NULL) hold the same channel names and float bits. */
void mcp_test_assert_same_image(const mcp_image *a, const mcp_image *b);

/* Asserts that two image files hold the same channels (names, order), attributes
 * (names, types, values) and float bits in every value: a streamed command's output
 * against its whole one's (the files' bytes may differ in which zip chunks are raw). */
void mcp_test_assert_same_image_files(const char *a_path, const char *b_path);

/* splitmix64 (common/core/rng_internal.h): a small seeded generator for test data. */
uint64_t mcp_test_rand_u64(uint64_t *state);
double mcp_test_rand_uniform(uint64_t *state);
double mcp_test_rand_normal(uint64_t *state);

/* Runs the mcpost executable with the given argument string through /bin/sh;
 * captures stdout and stderr (each up to cap bytes, NUL-terminated) and returns the
 * exit status (or -1). */
int mcp_test_run_mcpost(const char *args, char *out, size_t out_cap, char *err,
                        size_t err_cap);
/* mcp_test_run_mcpost with the arguments formatted from fmt. Tests define
 *   #define run(...) mcp_test_run_mcpostf(out, sizeof out, err, sizeof err, __VA_ARGS__)
 * over their own out and err buffers. */
int mcp_test_run_mcpostf(char *out, size_t out_cap, char *err, size_t err_cap,
                         const char *fmt, ...) __attribute__((format(printf, 5, 6)));

/* Writes a text file (for job files and corrupt inputs). */
void mcp_test_write_text(const char *path, const char *text);

/* Reads a whole file into a malloc'd NUL-terminated buffer (asserts on failure). */
char *mcp_test_read_text(const char *path);

#endif
