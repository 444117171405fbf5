/* consumer.c: uses the installed library -- an EXR round trip and a PNG written
 * through the plug-in, found beside the installed library. */
#include <mcpost/mcpost.h> /* the umbrella header: every public one */
#include <stdio.h>

int
main(int argc, char **argv)
{
    const char *dir = argc > 1 ? argv[1] : ".";
    char exr[4096], png[4096];
    snprintf(exr, sizeof exr, "%s/consumer.exr", dir);
    snprintf(png, sizeof png, "%s/consumer.png", dir);
    mcp_image *img = NULL, *back = NULL;
    if (mcp_image_new(8, 4, 3, (const char *[]){"R", "G", "B"}, &img)) goto fail;
    img->data[5] = 0.5f;
    if (mcp_image_write(img, exr, NULL) || mcp_image_read(exr, NULL, &back) ||
        /* EXR keeps channels sorted by name: look "B" up, do not assume its place */
        mcp_image_px(back, 1, 0)[mcp_image_channel(back, "B")] != 0.5f ||
        mcp_image_write(img, png, NULL))
        goto fail;
    printf("consumer: ok (plug-in loaded: %d)\n", mcp_oiio_loaded());
    mcp_image_free(back);
    mcp_image_free(img);
    return 0;
fail:
    fprintf(stderr, "consumer: %s\n", mcp_error_message());
    return 1;
}
