/* fuzz_dump.c: the dump loader (common/dump.c): channel detection, conventions,
 * variance conversion, bad-value checks, and the separate files a dump can come in.
 *
 * The input is up to five files separated by the line "MCPPART\n": the main file,
 * then the variance, albedo, normal and per-pixel spp files (an empty part is a file
 * not given). Each part is an EXR when it starts with EXR's magic number and a PFM
 * otherwise. The first byte of the main file picks the bad-value policy, so both the
 * failing and the replacing paths are searched. */
#include "fuzz.h"

#include <mcpost/dump.h>

#include <string.h>

#define SEPARATOR "MCPPART\n"
#define N_PARTS 5

int
LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const char *const roles[N_PARTS] = {"main", "var", "albedo", "normal", "spp"};
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
        if (!next)
            break;
        at = next + sep;
    }
    if (!part[0] || len[0] == 0)
        return 0;

    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.bad_values = (mcp_badval_policy)(part[0][0] % 2);
    const char **paths[N_PARTS] = {&spec.path, &spec.variance_path, &spec.albedo_path,
                                   &spec.normal_path, &spec.spp_map_path};
    for (int i = 0; i < N_PARTS; i++) {
        if (!part[i] || len[i] == 0)
            continue;
        /* files in memory for now; mcp_image_read_memory (and a dump reader on it)
           replaces them once that reader lands */
        char name[32];
        int exr = len[i] >= 4 && memcmp(part[i], "\x76\x2f\x31\x01", 4) == 0;
        strcpy(name, roles[i]);
        strcat(name, exr ? ".exr" : ".pfm");
        *paths[i] = mcp_fuzz_file(i, name, part[i], len[i]);
    }
    mcp_dump *dump = NULL;
    int rc = mcp_dump_load(&spec, &dump);
    mcp_fuzz_check_error(rc, "dump load");
    if (rc == 0) {
        if (!dump || !dump->color)
            __builtin_trap();
    } else if (dump) {
        __builtin_trap();
    }
    mcp_dump_free(dump);
    return 0;
}
