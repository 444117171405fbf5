/* fuzz_exr.c: the OpenEXR reader (common/io/exr.c, on OpenEXR Core) through
 * mcp_image_read_memory, and through mcp_image_read on the same bytes as a file: both
 * must fail, or give the same image. The input is the whole file. */
#include "fuzz.h"

#include <mcpost/imageio.h>

int
LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    mcp_image *img = NULL;
    int rc = mcp_image_read_memory(data, size, "input.exr", &img);
    mcp_fuzz_check_error(rc, "exr read from memory");
    if (size >= 4 && data[0] == 0x76 && data[1] == 0x2f && data[2] == 0x31 &&
        data[3] == 0x01) /* an EXR by its magic: the file reader must agree */
        mcp_fuzz_same_as_file(rc, img, data, size, "input.exr");
    if (rc == 0) {
        if (!img || img->width < 1 || img->height < 1 || img->channels < 1)
            __builtin_trap();
        /* every pixel was written: reading them all is what ASan and MSan-like
           checks need to see */
        volatile float sink = 0;
        for (int y = 0; y < img->height; y++)
            for (int c = 0; c < img->channels; c++)
                sink += mcp_image_px(img, img->width - 1, y)[c];
        (void)sink;
    } else if (img) {
        __builtin_trap();
    }
    mcp_image_free(img);
    return 0;
}
