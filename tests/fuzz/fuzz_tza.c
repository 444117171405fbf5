/* fuzz_tza.c: the .tza weight loader (estimate/tza.c) and the U-Net's checks of the
 * tensors it finds there (mcp__unet_from_tza: names, shapes, channel counts), both on
 * the bytes in memory. The input is the whole archive. */
#include "fuzz.h"

#include "../../estimate/unet_internal.h"

int
LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    mcp__tza *tza = NULL;
    int rc = mcp__tza_parse(data, size, "fuzz.tza", &tza);
    mcp_fuzz_check_error(rc, "tza parse");
    if (rc != 0) {
        if (tza) __builtin_trap();
        return 0;
    }
    mcp__unet *net = NULL;
    rc = mcp__unet_from_tza(tza, "fuzz.tza", &net);
    mcp_fuzz_check_error(rc, "unet from tza");
    if (rc != 0 && net) __builtin_trap();
    mcp__unet_free(net);
    mcp__tza_free(tza);
    return 0;
}
