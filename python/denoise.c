/* denoise.c: denoisers by name with their settings (the job file's keys), denoise and
 * jvp -- F(colour, albedo?, normal?) and its exact Jacobian-vector products J·t for the
 * built-in denoisers (estimate/denoiser.h). */
#include "internal.h"

#include <stdlib.h>

/* One setting as the "key=value" word of --denoiser-opt. */
static char *
setting_word(PyObject *key, PyObject *value)
{
    const char *k = PyUnicode_Check(key) ? PyUnicode_AsUTF8(key) : NULL;
    if (!k) {
        PyErr_SetString(PyExc_TypeError, "denoiser settings: keys must be str");
        return NULL;
    }
    PyObject *text = NULL;
    if (PyBool_Check(value))
        text = PyUnicode_FromString(value == Py_True ? "true" : "false");
    else if (PyUnicode_Check(value))
        text = Py_NewRef(value);
    else if (PyObject_HasAttrString(value, "__fspath__"))
        text = PyOS_FSPath(value);
    else if (PyLong_Check(value) || PyFloat_Check(value))
        text = PyObject_Repr(value);
    else {
        PyErr_Format(
            PyExc_TypeError,
            "denoiser setting '%s' must be a number, str, path or bool, not %.80s", k,
            Py_TYPE(value)->tp_name);
        return NULL;
    }
    if (!text) return NULL;
    const char *v = PyUnicode_Check(text) ? PyUnicode_AsUTF8(text) : NULL;
    char *word = NULL;
    if (v) {
        size_t n = strlen(k) + strlen(v) + 2;
        if ((word = malloc(n)))
            snprintf(word, n, "%s=%s", k, v);
        else
            PyErr_NoMemory();
    }
    Py_DECREF(text);
    return word;
}

int
mcp_py_denoiser(const char *name, PyObject *settings, mcp_denoiser **out)
{
    *out = NULL;
    Py_ssize_t n = settings ? PyDict_Size(settings) : 0;
    char **words = calloc((size_t)(n ? n : 1), sizeof *words);
    if (!words) {
        PyErr_NoMemory();
        return -1;
    }
    int count = 0, rc = -1;
    PyObject *k, *v;
    Py_ssize_t pos = 0;
    while (settings && PyDict_Next(settings, &pos, &k, &v)) {
        if (PyUnicode_Check(k) && !strcmp(PyUnicode_AsUTF8(k), "name")) continue;
        if (!(words[count] = setting_word(k, v))) goto done;
        count++;
    }
    if (mcp_denoiser_create_from_args(name, (const char *const *)words, count, out))
        mcp_py_fail();
    else
        rc = 0;
done:
    for (int i = 0; i < count; i++)
        free(words[i]);
    free(words);
    return rc;
}

int
mcp_py_denoiser_arg(PyObject *arg, mcp_denoiser **out)
{
    *out = NULL;
    if (!arg || arg == Py_None) return mcp_py_denoiser("default", NULL, out);
    if (PyUnicode_Check(arg)) return mcp_py_denoiser(PyUnicode_AsUTF8(arg), NULL, out);
    if (PyDict_Check(arg)) {
        PyObject *name = PyDict_GetItemString(arg, "name");
        if (!name || !PyUnicode_Check(name)) {
            PyErr_SetString(mcp_py_error, "denoiser: a dict needs 'name' (a str)");
            return -1;
        }
        return mcp_py_denoiser(PyUnicode_AsUTF8(name), arg, out);
    }
    PyErr_Format(PyExc_TypeError,
                 "denoiser must be a name or a dict {'name': ..., settings}, not %.80s",
                 Py_TYPE(arg)->tp_name);
    return -1;
}

/* The input images of denoise and jvp. */
typedef struct {
    mcp_py_image color, albedo, normal, variance;
} inputs;

static int
get_inputs(PyObject *c, PyObject *a, PyObject *n, PyObject *v, inputs *in)
{
    static const char *const rgb[] = {"R", "G", "B"}, *const xyz[] = {"X", "Y", "Z"};
    memset(in, 0, sizeof *in);
    if (mcp_py_image_get(c, "color", 3, rgb, &in->color) ||
        mcp_py_image_opt(a, "albedo", 3, rgb, &in->albedo) ||
        mcp_py_image_opt(n, "normal", 3, xyz, &in->normal) ||
        mcp_py_image_opt(v, "variance", 3, rgb, &in->variance))
        goto fail;
    const mcp_py_image *parts[] = {&in->albedo, &in->normal, &in->variance};
    for (int i = 0; i < 3; i++)
        if (parts[i]->img && !mcp_image_same_size(parts[i]->img, in->color.img)) {
            mcp_py_fail();
            goto fail;
        }
    return 0;
fail:
    mcp_py_image_release(&in->color);
    mcp_py_image_release(&in->albedo);
    mcp_py_image_release(&in->normal);
    mcp_py_image_release(&in->variance);
    return -1;
}

static void
release_inputs(inputs *in)
{
    mcp_py_image_release(&in->color);
    mcp_py_image_release(&in->albedo);
    mcp_py_image_release(&in->normal);
    mcp_py_image_release(&in->variance);
}

/* Positional images, the keywords of denoise's table that Python takes
 * (ops/op_denoise.c: albedo, normal, variance_of_mean, denoiser), variance (the old
 * name of variance_of_mean) and **settings: any other keyword is a setting of the
 * denoiser, checked by its own table when it is made. */
static int
parse_call(const char *fn, PyObject *args, PyObject *kw, int with_tangent,
           PyObject **color, PyObject **tangent, PyObject **albedo, PyObject **normal,
           PyObject **variance, const char **name, PyObject **settings)
{
    static const char *const own[] = {"color",    "tangent",  "albedo",
                                      "normal",   "variance", "variance_of_mean",
                                      "denoiser", NULL};
    PyObject *mine = PyDict_New(), *keep = PyList_New(0), *vals[7], *pos[2];
    mcp_denoise_settings st;
    *settings = PyDict_New();
    if (!*settings || !mine || !keep) goto fail;
    PyObject *k, *v;
    Py_ssize_t at = 0;
    while (kw && PyDict_Next(kw, &at, &k, &v)) {
        int is_own = 0;
        for (int i = 0; own[i]; i++)
            if ((with_tangent || i != 1) && PyUnicode_Check(k) &&
                !strcmp(PyUnicode_AsUTF8(k), own[i]))
                is_own = 1;
        if (PyDict_SetItem(is_own ? mine : *settings, k, v)) goto fail;
    }
    static const char *const positional[] = {"color", "tangent"};
    if (mcp_py_settings(mcp_operation_denoise(), fn, mine, own, vals, &st, keep) ||
        mcp_py_positionals(fn, positional, with_tangent ? 2 : 1, args,
                           (PyObject *const[]){vals[0], vals[1]}, pos))
        goto fail;
    if (vals[4] && vals[5]) {
        PyErr_Format(PyExc_TypeError, "%s(): give variance or variance_of_mean, not both",
                     fn);
        goto fail;
    }
    *color = pos[0];
    if (tangent) *tangent = with_tangent ? pos[1] : NULL;
    *albedo = vals[2] ? vals[2] : Py_None;
    *normal = vals[3] ? vals[3] : Py_None;
    *variance = vals[4] ? vals[4] : vals[5] ? vals[5] : Py_None;
    *name = "default";
    if (vals[6] && vals[6] != Py_None) {
        if (!PyUnicode_Check(vals[6])) {
            PyErr_Format(PyExc_TypeError,
                         "%s(): denoiser must be a str, its settings "
                         "keywords",
                         fn);
            goto fail;
        }
        *name = PyUnicode_AsUTF8(vals[6]);
    }
    Py_DECREF(mine);
    Py_DECREF(keep);
    return 0;
fail:
    Py_XDECREF(mine);
    Py_XDECREF(keep);
    Py_CLEAR(*settings);
    return -1;
}

static PyObject *
py_denoise(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    PyObject *c, *a, *n, *v, *settings;
    const char *name;
    if (parse_call("denoise", args, kw, 0, &c, NULL, &a, &n, &v, &name, &settings))
        return NULL;
    mcp_denoiser *den = NULL;
    inputs in;
    PyObject *result = NULL;
    int rc = mcp_py_denoiser(name, settings, &den);
    Py_DECREF(settings);
    if (rc || get_inputs(c, a, n, v, &in)) {
        mcp_denoiser_free(den);
        return NULL;
    }
    mcp_denoise_input di = {in.color.img, in.albedo.img, in.normal.img, in.variance.img};
    mcp_image *out = NULL;
    Py_BEGIN_ALLOW_THREADS rc = den->apply(den, &di, &out);
    Py_END_ALLOW_THREADS release_inputs(&in);
    mcp_denoiser_free(den);
    if (mcp_py_check_signals())
        mcp_image_free(out);
    else
        result = rc ? mcp_py_fail() : mcp_py_array(out);
    return result;
}

static PyObject *
py_jvp(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    PyObject *c, *t, *a, *n, *v, *settings;
    const char *name;
    if (parse_call("jvp", args, kw, 1, &c, &t, &a, &n, &v, &name, &settings)) return NULL;
    mcp_denoiser *den = NULL;
    inputs in;
    int rc = mcp_py_denoiser(name, settings, &den);
    Py_DECREF(settings);
    if (rc || get_inputs(c, a, n, v, &in)) {
        mcp_denoiser_free(den);
        return NULL;
    }
    /* one tangent (an image) or several (a list of images, or an N x H x W x 3 array) */
    int single = PyUnicode_Check(t) ||
                 (PyArray_Check(t) && PyArray_NDIM((PyArrayObject *)t) <= 3) ||
                 !PySequence_Check(t);
    PyObject *fast =
        single ? NULL : PySequence_Fast(t, "tangent must be an image or a list");
    Py_ssize_t count = single ? 1 : fast ? PySequence_Fast_GET_SIZE(fast) : -1;
    mcp_py_image *tan = count > 0 ? PyMem_Calloc((size_t)count, sizeof *tan) : NULL;
    mcp_denoise_tangent *dt = count > 0 ? PyMem_Calloc((size_t)count, sizeof *dt) : NULL;
    mcp_image **outs = count > 0 ? PyMem_Calloc((size_t)count, sizeof *outs) : NULL;
    mcp_image *primal = NULL;
    PyObject *result = NULL;
    if (count == 0) PyErr_SetString(mcp_py_error, "tangent: an empty list");
    if (!tan || !dt || !outs) {
        if (!PyErr_Occurred()) PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t i = 0; i < count; i++) {
        char what[32];
        snprintf(what, sizeof what, single ? "tangent" : "tangent[%zd]", i);
        if (mcp_py_image_get(single ? t : PySequence_Fast_GET_ITEM(fast, i), what, 3,
                             NULL, &tan[i]))
            goto done;
        if (!mcp_image_same_size(tan[i].img, in.color.img)) {
            mcp_py_fail();
            goto done;
        }
        dt[i].color = tan[i].img;
    }
    mcp_denoise_input di = {in.color.img, in.albedo.img, in.normal.img, in.variance.img};
    Py_BEGIN_ALLOW_THREADS rc = den->jvp(den, &di, dt, (int)count, &primal, outs);
    Py_END_ALLOW_THREADS if (mcp_py_check_signals()) goto done;
    if (rc) {
        mcp_py_fail();
        goto done;
    }
    PyObject *jvps;
    if (single) {
        jvps = mcp_py_array(outs[0]);
        outs[0] = NULL;
    } else {
        jvps = PyList_New(count);
        for (Py_ssize_t i = 0; jvps && i < count; i++) {
            PyObject *arr = mcp_py_array(outs[i]);
            outs[i] = NULL;
            if (!arr)
                Py_CLEAR(jvps);
            else
                PyList_SET_ITEM(jvps, i, arr);
        }
    }
    PyObject *p = mcp_py_array(primal);
    primal = NULL;
    if (jvps && p)
        result = Py_BuildValue("(NN)", p, jvps);
    else
        Py_XDECREF(jvps), Py_XDECREF(p);
done:
    for (Py_ssize_t i = 0; i < count; i++) {
        if (tan) mcp_py_image_release(&tan[i]);
        if (outs) mcp_image_free(outs[i]);
    }
    PyMem_Free(tan);
    PyMem_Free(dt);
    PyMem_Free(outs);
    mcp_image_free(primal);
    Py_XDECREF(fast);
    release_inputs(&in);
    mcp_denoiser_free(den);
    return result;
}

static PyObject *
py_denoisers(PyObject *self, PyObject *unused)
{
    (void)self, (void)unused;
    PyObject *d = PyDict_New();
    for (const mcp_denoiser_kind *const *k = mcp_denoiser_kinds(); d && *k; k++) {
        PyObject *keys = PyList_New(0);
        for (const char *const *key = (*k)->keys; keys && key && *key; key++) {
            PyObject *s = PyUnicode_FromString(*key);
            if (!s || PyList_Append(keys, s)) Py_CLEAR(keys);
            Py_XDECREF(s);
        }
        PyObject *entry =
            keys ? Py_BuildValue("{s:s,s:N}", "summary", (*k)->summary, "settings", keys)
                 : NULL;
        if (mcp_py_set(d, (*k)->name, entry)) Py_CLEAR(d);
    }
    return d;
}

#define KW (METH_VARARGS | METH_KEYWORDS)
#define FN(f) (PyCFunction)(void (*)(void))(f)
PyMethodDef mcp_py_denoise_methods[] = {
    {"denoise", FN(py_denoise), KW,
     "Runs one denoiser (see denoisers()) with its settings, the job file's keys (e.g.\n"
     "denoiser='gauss', sigma=2; denoiser='unet', weights=PATH). 'default' is the U-Net\n"
     "with the shipped weights, or nlm without albedo and normal. variance is\n"
     "variance_of_mean's other name."},
    {"jvp", FN(py_jvp), KW,
     "The denoiser's Jacobian-vector product at the input in the direction of tangent\n"
     "(exact forward mode for the built-in denoisers), in the same pass as F. tangent\n"
     "may be a list of images: then a list of products comes back."},
    {"denoisers", py_denoisers, METH_NOARGS,
     "denoisers() -> dict: every denoiser's summary and settings keys"},
    {NULL, NULL, 0, NULL}};
