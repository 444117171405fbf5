/* arrays.c: images between numpy and libmcpost. Arrays come in as views when they are
 * float32 and C-contiguous (else they are converted once, numbers only), and results go
 * out as arrays that own the library's pixels, so neither direction copies where the
 * layout allows. */
#include "internal.h"

#include <mcpost/imageio.h>

static const char *const rgb_names[] = {"R", "G", "B"};
static const char *const rgba_names[] = {"R", "G", "B", "A"};

int
mcp_py_image_get(PyObject *obj, const char *what, int channels, const char *const *names,
                 mcp_py_image *out)
{
    out->array = NULL;
    out->img = NULL;
    if (PyUnicode_Check(obj) || PyObject_HasAttrString(obj, "__fspath__")) {
        PyObject *path = mcp_py_path(obj, what);
        if (!path) return -1;
        int rc;
        Py_BEGIN_ALLOW_THREADS rc =
            mcp_image_read(PyBytes_AS_STRING(path), NULL, &out->img);
        Py_END_ALLOW_THREADS Py_DECREF(path);
        if (rc) return mcp_py_fail_int();
        if (channels && out->img->channels != channels) {
            PyErr_Format(mcp_py_error, "%s: %s has %d channels (needs %d)", what,
                         out->img->source, out->img->channels, channels);
            mcp_py_image_release(out);
            return -1;
        }
        return 0;
    }
    /* numbers only: a string, object or complex array has no float32 meaning */
    PyObject *probe = PyArray_FROM_O(obj); /* the array itself when obj is one */
    if (!probe) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be an image array (H x W x C), not %.80s",
                     what, Py_TYPE(obj)->tp_name);
        return -1;
    }
    PyArray_Descr *dt = PyArray_DESCR((PyArrayObject *)probe);
    if (dt->kind != 'f' && dt->kind != 'i' && dt->kind != 'u' && dt->kind != 'b') {
        PyErr_Format(PyExc_TypeError,
                     "%s must hold real numbers (float32 preferred), not %S", what,
                     (PyObject *)dt);
        Py_DECREF(probe);
        return -1;
    }
    PyArrayObject *a = (PyArrayObject *)PyArray_FROMANY(
        probe, NPY_FLOAT32, 0, 0, NPY_ARRAY_IN_ARRAY | NPY_ARRAY_FORCECAST);
    Py_DECREF(probe);
    if (!a) return -1;
    int nd = PyArray_NDIM(a);
    npy_intp *dims = PyArray_DIMS(a);
    if (nd != 2 && nd != 3) {
        PyErr_Format(mcp_py_error,
                     "%s: needs an H x W x C or H x W array (got %d dimensions)", what,
                     nd);
        Py_DECREF(a);
        return -1;
    }
    npy_intp h = dims[0], w = dims[1], c = nd == 3 ? dims[2] : 1;
    if (channels && c != channels) {
        PyErr_Format(mcp_py_error,
                     "%s: needs %d channels (got an array of shape %zd x %zd x %zd)",
                     what, channels, (Py_ssize_t)h, (Py_ssize_t)w, (Py_ssize_t)c);
        Py_DECREF(a);
        return -1;
    }
    if (h < 1 || w < 1 || c < 1 || h > MCP_MAX_DIM || w > MCP_MAX_DIM || c > 4096) {
        PyErr_Format(mcp_py_error, "%s: bad image shape %zd x %zd x %zd", what,
                     (Py_ssize_t)h, (Py_ssize_t)w, (Py_ssize_t)c);
        Py_DECREF(a);
        return -1;
    }
    if (!names) names = c == 3 ? rgb_names : c == 4 ? rgba_names : NULL;
    if (mcp_image_wrap((float *)PyArray_DATA(a), (int)w, (int)h, (int)c, (ptrdiff_t)c,
                       (ptrdiff_t)(w * c), names, what, &out->img)) {
        Py_DECREF(a);
        return mcp_py_fail_int();
    }
    out->array = a;
    return 0;
}

int
mcp_py_image_opt(PyObject *obj, const char *what, int channels, const char *const *names,
                 mcp_py_image *out)
{
    out->array = NULL;
    out->img = NULL;
    if (!obj || obj == Py_None) return 0;
    return mcp_py_image_get(obj, what, channels, names, out);
}

void
mcp_py_image_release(mcp_py_image *im)
{
    mcp_image_free(im->img);
    Py_XDECREF(im->array);
    im->img = NULL;
    im->array = NULL;
}

/* The capsule that frees an image whose pixels an array took over. */
static void
free_image_capsule(PyObject *capsule)
{
    mcp_image_free(PyCapsule_GetPointer(capsule, "mcpost.image"));
}

PyObject *
mcp_py_array(mcp_image *img)
{
    if (!img) Py_RETURN_NONE;
    npy_intp dims[3] = {img->height, img->width, img->channels};
    int nd = img->channels == 1 ? 2 : 3;
    if (!mcp_image_is_packed(img) || !img->owns_data) {
        PyObject *a = mcp_py_array_channels(img, 0, img->channels);
        mcp_image_free(img);
        return a;
    }
    PyObject *a = PyArray_SimpleNewFromData(nd, dims, NPY_FLOAT32, img->data);
    if (!a) {
        mcp_image_free(img);
        return NULL;
    }
    PyObject *cap = PyCapsule_New(img, "mcpost.image", free_image_capsule);
    if (!cap) {
        Py_DECREF(a);
        mcp_image_free(img);
        return NULL;
    }
    if (PyArray_SetBaseObject((PyArrayObject *)a, cap)) { /* steals cap */
        Py_DECREF(a);
        return NULL;
    }
    return a;
}

PyObject *
mcp_py_array_channels(const mcp_image *img, int first, int count)
{
    npy_intp dims[3] = {img->height, img->width, count};
    PyObject *a = PyArray_SimpleNew(count == 1 ? 2 : 3, dims, NPY_FLOAT32);
    if (!a) return NULL;
    float *dst = PyArray_DATA((PyArrayObject *)a);
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++)
            memcpy(dst + ((size_t)y * img->width + x) * count,
                   mcp_image_px(img, x, y) + first, (size_t)count * sizeof(float));
    return a;
}
