/* fuzz_dump.c: the dump loader (common/dump/dump.c): channel detection, conventions,
 * variance conversion, bad-value checks, and the separate files a dump can come in.
 *
 * The input is up to five files separated by the line "MCPPART\n": the main file,
 * then the variance, albedo, normal and per-pixel spp files (an empty part is a file
 * not given), all read from memory (mcp_dump_read_memory), which tells EXR from PFM
 * by the first bytes: no file is written. The first byte of the main file picks the
 * bad-value policy, so both the failing and the replacing paths are searched. */
#include "fuzz.h"

#include <mcpost/dump.h>

#include <string.h>

#define SEPARATOR "MCPPART\n"
#define N_PARTS 5

int
LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const uint8_t *part[N_PARTS] = {0};
    size_t len[N_PARTS] = {0};
    const size_t sep = sizeof SEPARATOR - 1;
    const uint8_t *at = data, *end = data + size;
    for (int i = 0; i < N_PARTS && at <= end; i++) {
        const uint8_t *next = NULL;
        for (const uint8_t *p = at; i < N_PARTS - 1 && (size_t)(end - p) >= sep; p++)
            if (memcmp(p, SEPARATOR, sep) == 0) {
                next = p;
                break;
            }
        part[i] = at;
        len[i] = next ? (size_t)(next - at) : (size_t)(end - at);
        if (!next) break;
        at = next + sep;
    }
    if (!part[0] || len[0] == 0) return 0;

    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.bad_values = (mcp_badval_policy)(part[0][0] % 2);
    /* every part from memory (mcp_dump_read_memory), named by its role */
    mcp_dump_buffers parts = {0};
    mcp_dump_buffer *bufs[N_PARTS] = {&parts.main, &parts.variance, &parts.albedo,
                                      &parts.normal, &parts.spp_map};
    for (int i = 0; i < N_PARTS; i++)
        if (part[i] && len[i] > 0) *bufs[i] = (mcp_dump_buffer){part[i], len[i]};
    mcp_dump *dump = NULL;
    int rc = mcp_dump_read_memory(&spec, &parts, &dump);
    mcp_fuzz_check_error(rc, "dump load");
    if (rc == 0) {
        if (!dump || !dump->color) __builtin_trap();
    } else if (dump) {
        __builtin_trap();
    }
    mcp_dump_free(dump);
    return 0;
}
