/* alloc.c: allocation that sets the error line when it fails (error.h), and a
 * test-only hook that makes one chosen allocation fail (internal.h), so that a test
 * can walk every failure path of a run in turn (tests/common/test_alloc_failure.c). */
#include <mcpost/error.h>

#include "internal.h"

#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif

void
mcp__unmap_freed_blocks(void)
{
#ifdef __GLIBC__
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
#endif
}

/* The hook: the number of the allocation that fails (-1: none), and how many went
 * through here since it was set. Atomic because OpenMP workers allocate too. Outside
 * the tests this costs one relaxed load per allocation. */
static atomic_long fail_at = -1;
static atomic_long counted;

void
mcp__alloc_fail_after(long n)
{
    atomic_store(&fail_at, -1);
    atomic_store(&counted, 0);
    atomic_store(&fail_at, n);
}

long
mcp__alloc_count(void)
{
    return atomic_load(&counted);
}

static int
injected_failure(void)
{
    long at = atomic_load_explicit(&fail_at, memory_order_relaxed);
    return at >= 0 && atomic_fetch_add(&counted, 1) == at;
}

void *
mcp_malloc(size_t bytes)
{
    void *p = injected_failure() ? NULL : malloc(bytes ? bytes : 1);
    if (!p) mcp_error("out of memory (%zu bytes)", bytes);
    return p;
}

void *
mcp_calloc(size_t count, size_t size)
{
    void *p = injected_failure() ? NULL : calloc(count ? count : 1, size ? size : 1);
    if (!p) mcp_error("out of memory (%zu x %zu bytes)", count, size);
    return p;
}

void *
mcp_realloc(void *p, size_t bytes)
{
    void *q = injected_failure() ? NULL : realloc(p, bytes ? bytes : 1);
    if (!q) mcp_error("out of memory (%zu bytes)", bytes);
    return q;
}

char *
mcp_strdup(const char *s)
{
    size_t n = strlen(s) + 1;
    char *p = mcp_malloc(n);
    if (p) memcpy(p, s, n);
    return p;
}
