/* images.c: read_image and write_image -- any format libmcpost reads (EXR, PFM, and
 * PNG, JPEG, HDR, TIFF through the OpenImageIO plug-in), every channel and the header
 * attributes. */
#include "internal.h"

#include <mcpost/imageio.h>

PyObject *
mcp_py_attrs_dict(const mcp_attrs *attrs)
{
    PyObject *d = PyDict_New();
    for (int i = 0; d && i < attrs->count; i++) {
        const mcp_attr *a = &attrs->items[i];
        PyObject *v = a->type == MCP_ATTR_INT      ? PyLong_FromLongLong(a->i)
                      : a->type == MCP_ATTR_STRING ? PyUnicode_DecodeFSDefault(a->s)
                                                   : PyFloat_FromDouble(a->f);
        if (mcp_py_set(d, a->name, v)) {
            Py_DECREF(d);
            return NULL;
        }
    }
    return d;
}

static PyObject *
py_read_image(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"path", "srgb_decode", NULL};
    PyObject *path_obj;
    int srgb = 1;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "O|$p:read_image", keys, &path_obj, &srgb))
        return NULL;
    PyObject *path = mcp_py_path(path_obj, "path");
    if (!path) return NULL;
    mcp_read_options ro = mcp_read_defaults();
    ro.srgb_decode = srgb;
    mcp_image *img = NULL;
    int rc;
    Py_BEGIN_ALLOW_THREADS rc = mcp_image_read(PyBytes_AS_STRING(path), &ro, &img);
    Py_END_ALLOW_THREADS Py_DECREF(path);
    if (rc) return mcp_py_fail();
    PyObject *names = PyList_New(img->channels);
    for (int c = 0; names && c < img->channels; c++)
        PyList_SET_ITEM(names, c, PyUnicode_FromString(img->names[c]));
    PyObject *attrs = mcp_py_attrs_dict(&img->attrs);
    PyObject *pixels = mcp_py_array(img); /* takes img over */
    if (!names || !attrs || !pixels) {
        Py_XDECREF(names), Py_XDECREF(attrs), Py_XDECREF(pixels);
        return NULL;
    }
    return Py_BuildValue("(NNN)", pixels, names, attrs);
}

int
mcp_py_attrs_set(mcp_attrs *attrs, PyObject *key, PyObject *value)
{
    const char *name = PyUnicode_Check(key) ? PyUnicode_AsUTF8(key) : NULL;
    if (!name) {
        PyErr_SetString(PyExc_TypeError, "attributes: names must be str");
        return -1;
    }
    int rc;
    if (PyBool_Check(value) || PyLong_Check(value)) {
        long long v = PyLong_AsLongLong(value);
        if (v == -1 && PyErr_Occurred()) return -1;
        rc = mcp_attrs_set_int(attrs, name, v);
    } else if (PyFloat_Check(value)) {
        rc = mcp_attrs_set_double(attrs, name, PyFloat_AS_DOUBLE(value));
    } else if (PyUnicode_Check(value)) {
        const char *s = PyUnicode_AsUTF8(value);
        if (!s) return -1;
        rc = mcp_attrs_set_string(attrs, name, s);
    } else {
        PyErr_Format(PyExc_TypeError,
                     "attributes['%s'] must be int, float or str, not %.80s", name,
                     Py_TYPE(value)->tp_name);
        return -1;
    }
    return rc ? mcp_py_fail_int() : 0;
}

static PyObject *
py_write_image(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"path", "pixels",      "channels",    "attributes",
                           "half", "compression", "srgb_encode", NULL};
    PyObject *path_obj, *pixels, *channels = Py_None, *attributes = Py_None;
    int half = 0, srgb = 1;
    const char *compression = "zip";
    if (!PyArg_ParseTupleAndKeywords(args, kw, "OO|$OOpsp:write_image", keys, &path_obj,
                                     &pixels, &channels, &attributes, &half, &compression,
                                     &srgb))
        return NULL;
    mcp_write_options wo = mcp_write_defaults();
    wo.exr_pixel = half ? MCP_EXR_HALF : MCP_EXR_FLOAT;
    wo.srgb_encode = srgb;
    if (mcp_exr_compression_from_name(compression, &wo.compression)) return mcp_py_fail();
    PyObject *path = mcp_py_path(path_obj, "path");
    if (!path) return NULL;
    mcp_py_image im = {0};
    PyObject *result = NULL;
    if (mcp_py_image_get(pixels, "pixels", 0, NULL, &im)) goto done;
    if (channels != Py_None) {
        PyObject *fast = PySequence_Fast(channels, "channels must be a list of names");
        if (!fast) goto done;
        Py_ssize_t n = PySequence_Fast_GET_SIZE(fast);
        if (n != im.img->channels) {
            PyErr_Format(mcp_py_error, "channels: %zd names for %d channels", n,
                         im.img->channels);
            Py_DECREF(fast);
            goto done;
        }
        for (Py_ssize_t c = 0; c < n; c++) {
            PyObject *item = PySequence_Fast_GET_ITEM(fast, c);
            const char *name = PyUnicode_Check(item) ? PyUnicode_AsUTF8(item) : NULL;
            if (!name) {
                PyErr_SetString(PyExc_TypeError, "channels: names must be str");
                Py_DECREF(fast);
                goto done;
            }
            if (mcp_image_set_channel_name(im.img, (int)c, name)) {
                Py_DECREF(fast);
                mcp_py_fail();
                goto done;
            }
        }
        Py_DECREF(fast);
    }
    if (attributes != Py_None) {
        if (!PyDict_Check(attributes)) {
            PyErr_SetString(PyExc_TypeError, "attributes must be a dict");
            goto done;
        }
        PyObject *k, *v;
        Py_ssize_t pos = 0;
        while (PyDict_Next(attributes, &pos, &k, &v))
            if (mcp_py_attrs_set(&im.img->attrs, k, v)) goto done;
    }
    int rc;
    Py_BEGIN_ALLOW_THREADS rc = mcp_image_write(im.img, PyBytes_AS_STRING(path), &wo);
    Py_END_ALLOW_THREADS if (rc)
    {
        mcp_py_fail();
        goto done;
    }
    result = Py_NewRef(Py_None);
done:
    mcp_py_image_release(&im);
    Py_DECREF(path);
    return result;
}

PyMethodDef mcp_py_image_methods[] = {
    {"read_image", (PyCFunction)(void (*)(void))py_read_image,
     METH_VARARGS | METH_KEYWORDS,
     "read_image(path, *, srgb_decode=True) -> (pixels, channels, attributes)\n\n"
     "Every channel of an EXR, PFM, PNG, JPEG, HDR or TIFF file as float32 H x W x C\n"
     "(H x W for one channel), the channel names and the header attributes. Colour\n"
     "comes first, as R, G, B taken by name (an EXR lists B, G, R), then the other\n"
     "channels. 8-bit files are sRGB-decoded to linear unless srgb_decode is False."},
    {"write_image", (PyCFunction)(void (*)(void))py_write_image,
     METH_VARARGS | METH_KEYWORDS,
     "write_image(path, pixels, *, channels=None, attributes=None, half=False,\n"
     "            compression='zip', srgb_encode=True)\n\n"
     "Writes an image in the format the extension names (to a temporary name, then\n"
     "renamed). channels names them (default R,G,B for 3, R,G,B,A for 4, else C0...);\n"
     "PNG, PFM and HDR take R, G, B by name, wherever they stand."},
    {NULL, NULL, 0, NULL}};
