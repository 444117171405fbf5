// oiio_plugin.cpp: the OpenImageIO plug-in (mcpost_oiio.so), dlopen()ed by imageio.c
// only when a PNG/JPEG/HDR/TIFF file is used, since linking OpenImageIO costs about
// 0.5 s per process start (docs/libraries.md §3). No exception crosses the C ABI.
#include <OpenImageIO/imageio.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

extern "C" {
#include "oiio_internal.h"
}

using namespace OIIO;

static int
fail(char *err, size_t cap, const std::string &msg)
{
    std::string line = msg;
    for (char &ch : line)
        if (ch == '\n') ch = ' ';
    while (!line.empty() && line.back() == ' ')
        line.pop_back();
    std::snprintf(err, cap, "%s", line.c_str());
    return -1;
}

extern "C" __attribute__((visibility("default"))) int
mcp_oiio_plugin_read(const char *path, int *w, int *h, int *c, float **data,
                     char ***names, int *integer_bits, char *err, size_t err_cap)
{
    try {
        auto in = ImageInput::open(path);
        if (!in) return fail(err, err_cap, std::string(path) + ": " + OIIO::geterror());
        const ImageSpec &spec = in->spec();
        if (spec.width < 1 || spec.height < 1 || spec.nchannels < 1 || spec.depth > 1)
            return fail(err, err_cap, std::string(path) + ": unsupported image shape");
        size_t n = (size_t)spec.width * spec.height * spec.nchannels;
        float *pixels = (float *)std::malloc(n * sizeof(float));
        char **nm = (char **)std::calloc((size_t)spec.nchannels, sizeof(char *));
        if (!pixels || !nm) {
            std::free(pixels);
            std::free(nm);
            return fail(err, err_cap, std::string(path) + ": out of memory");
        }
        if (!in->read_image(0, 0, 0, spec.nchannels, TypeDesc::FLOAT, pixels)) {
            std::free(pixels);
            std::free(nm);
            return fail(err, err_cap, std::string(path) + ": " + in->geterror());
        }
        for (int i = 0; i < spec.nchannels; i++)
            nm[i] = strdup(spec.channelnames[i].c_str());
        *w = spec.width;
        *h = spec.height;
        *c = spec.nchannels;
        *data = pixels;
        *names = nm;
        TypeDesc f = spec.format;
        *integer_bits = f.is_floating_point() ? 0 : (int)(f.size() * 8);
        in->close();
        return 0;
    } catch (const std::exception &e) {
        return fail(err, err_cap, std::string(path) + ": " + e.what());
    } catch (...) {
        return fail(err, err_cap, std::string(path) + ": unknown OpenImageIO failure");
    }
}

extern "C" __attribute__((visibility("default"))) int
mcp_oiio_plugin_write(const char *path, int w, int h, int c, const float *data, int bits,
                      char *err, size_t err_cap)
{
    try {
        auto out = ImageOutput::create(path);
        if (!out) return fail(err, err_cap, std::string(path) + ": " + OIIO::geterror());
        ImageSpec spec(w, h, c, bits == 8 ? TypeDesc::UINT8 : TypeDesc::FLOAT);
        if (!out->open(path, spec))
            return fail(err, err_cap, std::string(path) + ": " + out->geterror());
        if (!out->write_image(TypeDesc::FLOAT, data) || !out->close())
            return fail(err, err_cap, std::string(path) + ": " + out->geterror());
        return 0;
    } catch (const std::exception &e) {
        return fail(err, err_cap, std::string(path) + ": " + e.what());
    } catch (...) {
        return fail(err, err_cap, std::string(path) + ": unknown OpenImageIO failure");
    }
}
