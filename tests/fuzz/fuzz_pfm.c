/* fuzz_pfm.c: the PFM reader (common/pfm.c) through mcp_image_read.
 * The input is the whole file. */
#include "fuzz.h"

#include <mcpost/imageio.h>

int
LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    /* a file in memory for now; mcp_image_read_memory(data, size, "input.pfm", &img)
       replaces it once that reader lands */
    const char *path = mcp_fuzz_file(0, "input.pfm", data, size);
    mcp_image *img = NULL;
    int rc = mcp_image_read(path, NULL, &img);
    mcp_fuzz_check_error(rc, "pfm read");
    if (rc == 0 && (!img || img->width < 1 || img->height < 1 ||
                    (img->channels != 1 && img->channels != 3)))
        __builtin_trap();
    if (rc != 0 && img)
        __builtin_trap(); /* *out stays NULL on failure (STYLE 6) */
    mcp_image_free(img);
    return 0;
}
