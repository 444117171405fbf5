/* fuzz_pfm.c: the PFM reader (common/io/pfm.c) through mcp_image_read_memory, and
 * through mcp_image_read on the same bytes as a file: both must fail, or give the same
 * image. The input is the whole file. */
#include "fuzz.h"

#include <mcpost/imageio.h>

int
LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    mcp_image *img = NULL;
    int rc = mcp_image_read_memory(data, size, "input.pfm", &img);
    mcp_fuzz_check_error(rc, "pfm read from memory");
    if (size >= 2 && data[0] == 'P' && (data[1] == 'F' || data[1] == 'f'))
        mcp_fuzz_same_as_file(rc, img, data, size, "input.pfm");
    if (rc == 0 && (!img || img->width < 1 || img->height < 1 ||
                    (img->channels != 1 && img->channels != 3)))
        __builtin_trap();
    if (rc != 0 && img)
        __builtin_trap(); /* *out stays NULL on failure (docs/library.md) */
    mcp_image_free(img);
    return 0;
}
