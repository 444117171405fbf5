/* testing.c: shared test helpers (see testing.h). */
#include "testing.h"

#include "../../common/core/rng_internal.h"

#include <mcpost/imageio.h>

#include <stdarg.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

void
mcp_test_assert_close(double a, double b, double rtol, double atol, const char *expr,
                      const char *file, int line)
{
    double tol = atol + rtol * fabs(b);
    if (!(fabs(a - b) <= tol)) {
        print_error("%s = %.10g, expected %.10g (tolerance %.3g)\n", expr, a, b, tol);
        _fail(file, line);
    }
}

void
mcp_test_assert_error(int rc, const char *needle, const char *expr, const char *file,
                      int line)
{
    if (rc != -1) {
        print_error("%s returned %d, expected -1\n", expr, rc);
        _fail(file, line);
    }
    if (!strstr(mcp_error_message(), needle)) {
        print_error("%s: error \"%s\" does not contain \"%s\"\n", expr,
                    mcp_error_message(), needle);
        _fail(file, line);
    }
}

static void
make_dirs(const char *path)
{
    char buf[4096];
    snprintf(buf, sizeof buf, "%s", path);
    for (char *p = buf + 1; *p; p++)
        if (*p == '/') {
            *p = '\0';
            mkdir(buf, 0777);
            *p = '/';
        }
    mkdir(buf, 0777);
}

const char *
mcp_test_path(const char *name)
{
    static char bufs[8][4096];
    static int next;
    static char dir[4000];
    if (!dir[0]) {
        const char *env = getenv("MCPOST_TEST_TMP");
        if (env && *env)
            snprintf(dir, sizeof dir, "%s", env);
        else
            snprintf(dir, sizeof dir, "/tmp/mcpost-test-%d", (int)getpid());
        make_dirs(dir);
    }
    char *b = bufs[next++ % 8];
    snprintf(b, 4096, "%s/%s", dir, name);
    return b;
}

static mcp_image *
new_or_fail(int w, int h, int c, const char *const *names)
{
    mcp_image *img = NULL;
    if (mcp_image_new(w, h, c, names, &img))
        fail_msg("mcp_image_new: %s", mcp_error_message());
    return img;
}

mcp_image *
mcp_test_constant(int w, int h, int c, float value, const char *const *names)
{
    mcp_image *img = new_or_fail(w, h, c, names);
    for (size_t i = 0; i < (size_t)w * h * c; i++)
        img->data[i] = value;
    return img;
}

mcp_image *
mcp_test_ramp(int w, int h, int c, const char *const *names)
{
    mcp_image *img = new_or_fail(w, h, c, names);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int k = 0; k < c; k++)
                mcp_image_px(img, x, y)[k] = (float)(x + 10 * y + 100 * k);
    return img;
}

mcp_image *
mcp_test_random(int w, int h, int c, float lo, float hi, uint64_t seed,
                const char *const *names)
{
    mcp_image *img = new_or_fail(w, h, c, names);
    for (size_t i = 0; i < (size_t)w * h * c; i++)
        img->data[i] = lo + (hi - lo) * (float)mcp_test_rand_uniform(&seed);
    return img;
}

double
mcp_test_max_abs_diff(const mcp_image *a, const mcp_image *b)
{
    assert_int_equal(a->width, b->width);
    assert_int_equal(a->height, b->height);
    assert_int_equal(a->channels, b->channels);
    double m = 0;
    for (int y = 0; y < a->height; y++)
        for (int x = 0; x < a->width; x++)
            for (int c = 0; c < a->channels; c++) {
                double d =
                    fabs((double)mcp_image_px(a, x, y)[c] - mcp_image_px(b, x, y)[c]);
                if (d > m || d != d) m = d != d ? INFINITY : d;
            }
    return m;
}

uint64_t
mcp_test_rand_u64(uint64_t *state)
{
    return mcp__splitmix64_next(state);
}

double
mcp_test_rand_uniform(uint64_t *state)
{
    return (double)(mcp_test_rand_u64(state) >> 11) * 0x1.0p-53;
}

double
mcp_test_rand_normal(uint64_t *state)
{
    double u1 = mcp_test_rand_uniform(state), u2 = mcp_test_rand_uniform(state);
    return sqrt(-2.0 * log(u1 + 1e-300)) * cos(6.283185307179586 * u2);
}

static void
slurp(const char *path, char *buf, size_t cap)
{
    if (!buf || !cap) return;
    buf[0] = '\0';
    FILE *f = fopen(path, "rb");
    if (!f) return;
    size_t n = fread(buf, 1, cap - 1, f);
    buf[n] = '\0';
    fclose(f);
}

int
mcp_test_run_mcpost(const char *args, char *out, size_t out_cap, char *err,
                    size_t err_cap)
{
    char out_path[4200], err_path[4200], cmd[16384];
    snprintf(out_path, sizeof out_path, "%s", mcp_test_path("run.stdout"));
    snprintf(err_path, sizeof err_path, "%s", mcp_test_path("run.stderr"));
    snprintf(cmd, sizeof cmd, "'%s' %s >'%s' 2>'%s' </dev/null", MCP_TEST_MCPOST, args,
             out_path, err_path);
    int status = system(cmd);
    slurp(out_path, out, out_cap);
    slurp(err_path, err, err_cap);
    if (status == -1 || !WIFEXITED(status)) return -1;
    return WEXITSTATUS(status);
}

void
mcp_test_write_text(const char *path, const char *text)
{
    FILE *f = fopen(path, "wb");
    if (!f) fail_msg("cannot write %s: %s", path, strerror(errno));
    fputs(text, f);
    fclose(f);
}

char *
mcp_test_read_text(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f) fail_msg("cannot read %s: %s", path, strerror(errno));
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *buf = malloc((size_t)n + 1);
    assert_non_null(buf);
    assert_int_equal(fread(buf, 1, (size_t)n, f), (size_t)n);
    buf[n] = '\0';
    fclose(f);
    return buf;
}

int
mcp_test_run_mcpostf(char *out, size_t out_cap, char *err, size_t err_cap,
                     const char *fmt, ...)
{
    char args[8192];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(args, sizeof args, fmt, ap);
    va_end(ap);
    return mcp_test_run_mcpost(args, out, out_cap, err, err_cap);
}

void
mcp_test_assert_same_image(const mcp_image *a, const mcp_image *b)
{
    if (!a || !b) {
        assert_true(a == b);
        return;
    }
    assert_int_equal(a->width, b->width);
    assert_int_equal(a->height, b->height);
    assert_int_equal(a->channels, b->channels);
    for (int c = 0; c < a->channels; c++)
        assert_string_equal(a->names[c], b->names[c]);
    for (int y = 0; y < a->height; y++)
        for (int x = 0; x < a->width; x++)
            assert_memory_equal(mcp_image_px(a, x, y), mcp_image_px(b, x, y),
                                (size_t)a->channels * sizeof(float));
}

void
mcp_test_assert_same_image_files(const char *a_path, const char *b_path)
{
    mcp_image *a = NULL, *b = NULL;
    assert_int_equal(mcp_image_read(a_path, NULL, &a), 0);
    assert_int_equal(mcp_image_read(b_path, NULL, &b), 0);
    mcp_test_assert_same_image(a, b);
    assert_int_equal(a->attrs.count, b->attrs.count);
    for (int i = 0; i < a->attrs.count; i++) {
        const mcp_attr *p = &a->attrs.items[i], *q = &b->attrs.items[i];
        assert_string_equal(p->name, q->name);
        assert_int_equal(p->type, q->type);
        if (p->type == MCP_ATTR_STRING)
            assert_string_equal(p->s, q->s);
        else if (p->type == MCP_ATTR_INT)
            assert_true(p->i == q->i);
        else
            assert_memory_equal(&p->f, &q->f, sizeof p->f);
    }
    mcp_image_free(a);
    mcp_image_free(b);
}
