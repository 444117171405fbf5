/* dumps.c: render dumps as dicts -- read_dump (the convention detected, the sample
 * count, the variance of the mean whatever the file stored), write_dump, and merge
 * (K renders of one frame into one dump whose variance comes from their spread). */
#include "internal.h"

#include <mcpost/error.h>
#include <mcpost/imageio.h>

#include <limits.h>

static const char *const part_keys[6] = {"color",  "variance", "covariance",
                                         "albedo", "normal",   "spp_map"};

static mcp_image **
part_slot(mcp_dump *d, int i)
{
    mcp_image **slots[6] = {&d->color,  &d->var_of_mean, &d->cov_of_mean,
                            &d->albedo, &d->normal,      &d->spp_map};
    return slots[i];
}

PyObject *
mcp_py_dump_dict(mcp_dump *dump)
{
    PyObject *d = PyDict_New();
    if (!d) goto fail;
    for (int i = 0; i < 6; i++) {
        mcp_image **slot = part_slot(dump, i);
        mcp_image *img = *slot;
        *slot = NULL; /* the array takes it over */
        if (mcp_py_set(d, part_keys[i], mcp_py_array(img))) goto fail;
    }
    if (mcp_py_set(d, "spp",
                   PyDict_GetItemString(d, "spp_map") != Py_None
                       ? Py_NewRef(Py_None)
                       : PyFloat_FromDouble(dump->spp)) ||
        mcp_py_set(d, "convention",
                   PyUnicode_FromString(mcp_convention_name(dump->convention))) ||
        mcp_py_set(
            d, "variance_source",
            PyUnicode_FromString(mcp_variance_source_name(dump->variance_source))) ||
        mcp_py_set(d, "variance_dof", PyFloat_FromDouble(dump->variance_dof)) ||
        mcp_py_set(d, "replicates", PyLong_FromLong(dump->replicates)) ||
        mcp_py_set(d, "variance_pool", PyFloat_FromDouble(dump->variance_pool)) ||
        mcp_py_set(d, "bad_values", PyLong_FromLong(dump->n_bad_values)) ||
        mcp_py_set(d, "attributes", mcp_py_attrs_dict(&dump->attrs)) ||
        mcp_py_set(d, "source",
                   PyUnicode_DecodeFSDefault(dump->source ? dump->source : "")))
        goto fail;
    mcp_dump_free(dump);
    return d;
fail:
    Py_XDECREF(d);
    mcp_dump_free(dump);
    return NULL;
}

/* A string member of the dict into *out via a name parser; absent or None: untouched. */
static int
dict_name(PyObject *d, const char *key, int (*parse)(const char *, void *), void *out)
{
    PyObject *v = PyDict_GetItemString(d, key);
    if (!v || v == Py_None) return 0;
    const char *s = PyUnicode_Check(v) ? PyUnicode_AsUTF8(v) : NULL;
    if (!s) {
        PyErr_Format(PyExc_TypeError, "dump['%s'] must be a str", key);
        return -1;
    }
    return parse(s, out) ? mcp_py_fail_int() : 0;
}

static int
dict_number(PyObject *d, const char *key, double *out)
{
    PyObject *v = PyDict_GetItemString(d, key);
    if (!v || v == Py_None) return 0;
    *out = PyFloat_AsDouble(v);
    if (*out == -1.0 && PyErr_Occurred()) {
        PyErr_Format(PyExc_TypeError, "dump['%s'] must be a number", key);
        return -1;
    }
    return 0;
}

static int
parse_convention(const char *s, void *o)
{
    return mcp_convention_from_name(s, o);
}
static int
parse_source(const char *s, void *o)
{
    return mcp_variance_source_from_name(s, o);
}

int
mcp_py_dump_get(PyObject *obj, const char *what, mcp_py_dump *out)
{
    memset(out, 0, sizeof *out);
    if (!PyDict_Check(obj)) {
        PyObject *path = mcp_py_path(obj, what);
        if (!path) {
            PyErr_Clear();
            PyErr_Format(PyExc_TypeError,
                         "%s must be a dump: a path or a dict as read_dump returns, not "
                         "%.80s",
                         what, Py_TYPE(obj)->tp_name);
            return -1;
        }
        int rc;
        Py_BEGIN_ALLOW_THREADS rc = mcp_dump_read(PyBytes_AS_STRING(path), &out->dump);
        Py_END_ALLOW_THREADS Py_DECREF(path);
        return rc ? mcp_py_fail_int() : 0;
    }
    mcp_dump *d = out->dump = mcp_calloc(1, sizeof *d);
    if (!d) return mcp_py_fail_int();
    static const char *const rgb[] = {"R", "G", "B"}, *const xyz[] = {"X", "Y", "Z"},
                             *const cov[] = {"RG", "RB", "GB"},
                             *const count[] = {"SampleCount"};
    const char *const *names[6] = {rgb, rgb, cov, rgb, xyz, count};
    const int channels[6] = {3, 3, 3, 3, 3, 1};
    char label[6][64];
    for (int i = 0; i < 6; i++) {
        PyObject *v = PyDict_GetItemString(obj, part_keys[i]);
        snprintf(label[i], sizeof label[i], "%s['%s']", what, part_keys[i]);
        if (i == 0 && (!v || v == Py_None)) {
            PyErr_Format(mcp_py_error, "%s: a dump needs 'color'", what);
            goto fail;
        }
        if (mcp_py_image_opt(v, label[i], channels[i], names[i], &out->parts[i]))
            goto fail;
        /* the dump holds the views; release frees them through mcp_dump_free */
        *part_slot(d, i) = out->parts[i].img;
        if (out->parts[i].img && i > 0 &&
            !mcp_image_same_size(out->parts[i].img, d->color)) {
            mcp_py_fail();
            goto fail;
        }
    }
    d->convention = MCP_CONV_PLAIN;
    d->variance_source = d->var_of_mean ? MCP_VARSRC_OF_MEAN : MCP_VARSRC_NONE;
    d->variance_in_file = MCP_VAR_OF_MEAN;
    double replicates = 0;
    if (dict_name(obj, "convention", parse_convention, &d->convention) ||
        dict_name(obj, "variance_source", parse_source, &d->variance_source) ||
        dict_number(obj, "spp", &d->spp) ||
        dict_number(obj, "variance_dof", &d->variance_dof) ||
        dict_number(obj, "variance_pool", &d->variance_pool) ||
        dict_number(obj, "replicates", &replicates))
        goto fail;
    d->replicates = (int)replicates;
    if (d->spp < 0 || !(d->spp == d->spp)) {
        PyErr_Format(mcp_py_error, "%s['spp'] must be >= 0 (got %g)", what, d->spp);
        goto fail;
    }
    PyObject *attrs = PyDict_GetItemString(obj, "attributes");
    if (attrs && attrs != Py_None) {
        if (!PyDict_Check(attrs)) {
            PyErr_Format(PyExc_TypeError, "%s['attributes'] must be a dict", what);
            goto fail;
        }
        PyObject *k, *v;
        Py_ssize_t pos = 0;
        while (PyDict_Next(attrs, &pos, &k, &v))
            if (mcp_py_attrs_set(&d->attrs, k, v)) goto fail;
    }
    PyObject *src = PyDict_GetItemString(obj, "source");
    const char *s = src && PyUnicode_Check(src) ? PyUnicode_AsUTF8(src) : NULL;
    if (!(d->source = mcp_strdup(s && *s ? s : what))) {
        mcp_py_fail();
        goto fail;
    }
    return 0;
fail:
    mcp_py_dump_release(out);
    return -1;
}

void
mcp_py_dump_release(mcp_py_dump *d)
{
    if (d->dump)
        for (int i = 0; i < 6; i++)
            if (d->parts[i].img && *part_slot(d->dump, i) == d->parts[i].img)
                *part_slot(d->dump, i) = NULL; /* freed below, once */
    mcp_dump_free(d->dump);
    for (int i = 0; i < 6; i++)
        mcp_py_image_release(&d->parts[i]);
    d->dump = NULL;
}

static PyObject *
py_read_dump(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {
        "path",          "spp",         "convention",  "variance",     "bad_values",
        "variance_path", "albedo_path", "normal_path", "spp_map_path", NULL};
    PyObject *path_obj, *paths[4] = {Py_None, Py_None, Py_None, Py_None};
    double spp = 0;
    const char *convention = NULL, *variance = NULL, *bad = NULL;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "O|$dzzzOOOO:read_dump", keys, &path_obj,
                                     &spp, &convention, &variance, &bad, &paths[0],
                                     &paths[1], &paths[2], &paths[3]))
        return NULL;
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    if ((convention && mcp_convention_from_name(convention, &spec.convention)) ||
        (variance && mcp_variance_kind_from_name(variance, &spec.variance)) ||
        (bad && mcp_badval_policy_from_name(bad, &spec.bad_values)))
        return mcp_py_fail();
    if (spp < 0 || spp != spp) {
        PyErr_Format(mcp_py_error, "spp must be > 0 (got %g)", spp);
        return NULL;
    }
    spec.spp = spp;
    PyObject *held[5] = {NULL};
    PyObject *result = NULL;
    static const char *const what[4] = {"variance_path", "albedo_path", "normal_path",
                                        "spp_map_path"};
    const char **fields[4] = {&spec.variance_path, &spec.albedo_path, &spec.normal_path,
                              &spec.spp_map_path};
    if (!(held[0] = mcp_py_path(path_obj, "path"))) goto done;
    spec.path = PyBytes_AS_STRING(held[0]);
    for (int i = 0; i < 4; i++)
        if (paths[i] != Py_None) {
            if (!(held[i + 1] = mcp_py_path(paths[i], what[i]))) goto done;
            *fields[i] = PyBytes_AS_STRING(held[i + 1]);
        }
    mcp_dump *dump = NULL;
    int rc;
    Py_BEGIN_ALLOW_THREADS rc = mcp_dump_load(&spec, &dump);
    Py_END_ALLOW_THREADS result = rc ? mcp_py_fail() : mcp_py_dump_dict(dump);
done:
    for (int i = 0; i < 5; i++)
        Py_XDECREF(held[i]);
    return result;
}

static PyObject *
py_write_dump(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"path", "dump", "convention", "half", NULL};
    PyObject *path_obj, *dump_obj;
    const char *convention = "mcpost";
    int half = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "OO|$sp:write_dump", keys, &path_obj,
                                     &dump_obj, &convention, &half))
        return NULL;
    mcp_convention conv;
    if (mcp_convention_from_name(convention, &conv)) return mcp_py_fail();
    mcp_write_options wo = mcp_write_defaults();
    wo.exr_pixel = half ? MCP_EXR_HALF : MCP_EXR_FLOAT;
    PyObject *path = mcp_py_path(path_obj, "path");
    if (!path) return NULL;
    mcp_py_dump d;
    if (mcp_py_dump_get(dump_obj, "dump", &d)) {
        Py_DECREF(path);
        return NULL;
    }
    int rc;
    Py_BEGIN_ALLOW_THREADS rc =
        mcp_dump_write(d.dump, PyBytes_AS_STRING(path), conv, &wo);
    Py_END_ALLOW_THREADS mcp_py_dump_release(&d);
    Py_DECREF(path);
    if (rc) return mcp_py_fail();
    Py_RETURN_NONE;
}

/* The dumps of a Python sequence (paths or dicts), as the library takes them: parts[i]
 * holds what keeps dumps[i] alive. -1 with the Python error set; either way
 * release_dump_list frees what was made. */
static int
get_dump_list(PyObject *fast, Py_ssize_t n, mcp_py_dump **parts, const mcp_dump ***dumps)
{
    *parts = PyMem_Calloc((size_t)(n ? n : 1), sizeof **parts);
    *dumps = PyMem_Calloc((size_t)(n ? n : 1), sizeof **dumps);
    if (!*parts || !*dumps) {
        PyErr_NoMemory();
        return -1;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        char what[32];
        snprintf(what, sizeof what, "dumps[%zd]", i);
        if (mcp_py_dump_get(PySequence_Fast_GET_ITEM(fast, i), what, &(*parts)[i]))
            return -1;
        (*dumps)[i] = (*parts)[i].dump;
    }
    return 0;
}

int
mcp_py_series_get(PyObject *list, const char *fn, mcp_series **out)
{
    *out = NULL;
    PyObject *fast = PySequence_Fast(list, "dumps must be a list of paths");
    if (!fast) return -1;
    const Py_ssize_t n = PySequence_Fast_GET_SIZE(fast);
    PyObject **held = PyMem_Calloc((size_t)(n ? n : 1), sizeof *held);
    const char **paths = PyMem_Calloc((size_t)(n ? n : 1), sizeof *paths);
    int rc = -1;
    if (!held || !paths) {
        PyErr_NoMemory();
        goto done;
    }
    if (n < 1) {
        PyErr_Format(mcp_py_error, "%s: no dumps given", fn);
        goto done;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        char what[32];
        snprintf(what, sizeof what, "dumps[%zd]", i);
        if (!(held[i] = mcp_py_path(PySequence_Fast_GET_ITEM(fast, i), what))) goto done;
        paths[i] = PyBytes_AS_STRING(held[i]);
    }
    if (n > INT_MAX || mcp_series_from_paths(paths, NULL, (int)n, out)) {
        if (n > INT_MAX) mcp_error("%s: too many dumps", fn);
        mcp_py_fail();
        goto done;
    }
    rc = 0;
done:
    for (Py_ssize_t i = 0; held && i < n; i++)
        Py_XDECREF(held[i]);
    PyMem_Free(held);
    PyMem_Free(paths);
    Py_DECREF(fast);
    return rc;
}

static void
release_dump_list(mcp_py_dump *parts, const mcp_dump **dumps, Py_ssize_t n)
{
    for (Py_ssize_t i = 0; parts && i < n; i++)
        mcp_py_dump_release(&parts[i]);
    PyMem_Free(parts);
    PyMem_Free(dumps);
}

static PyObject *
py_merge(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"dumps", "variance", "pool", NULL};
    PyObject *list;
    const char *variance = "replicates";
    int pool = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "O|$si:merge", keys, &list, &variance,
                                     &pool))
        return NULL;
    mcp_merge_options mo = mcp_merge_defaults();
    if (mcp_merge_variance_from_name(variance, &mo.variance)) return mcp_py_fail();
    if (pool < 0) {
        PyErr_Format(mcp_py_error, "pool must be >= 0 (got %d)", pool);
        return NULL;
    }
    mo.pool_radius = pool;
    PyObject *fast =
        PySequence_Fast(list, "dumps must be a list of dumps (paths or dicts)");
    if (!fast) return NULL;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(fast);
    if (n < 1) {
        Py_DECREF(fast);
        PyErr_SetString(mcp_py_error, "merge: no dumps given");
        return NULL;
    }
    mcp_py_dump *parts = NULL;
    const mcp_dump **dumps = NULL;
    PyObject *result = NULL;
    if (get_dump_list(fast, n, &parts, &dumps)) goto done;
    mcp_dump *merged = NULL;
    int rc;
    Py_BEGIN_ALLOW_THREADS rc = mcp_dump_merge(dumps, (int)n, &mo, &merged);
    Py_END_ALLOW_THREADS result = rc ? mcp_py_fail() : mcp_py_dump_dict(merged);
done:
    release_dump_list(parts, dumps, n);
    Py_DECREF(fast);
    return result;
}

static PyObject *
py_increment_variance(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"dumps", "first_spp", "pool_radius", NULL};
    PyObject *list;
    mcp_increment_options io = {0, 0};
    if (!PyArg_ParseTupleAndKeywords(args, kw, "O|$di:increment_variance", keys, &list,
                                     &io.first_spp, &io.pool_radius))
        return NULL;
    PyObject *fast =
        PySequence_Fast(list, "dumps must be a list of dumps (paths or dicts)");
    if (!fast) return NULL;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(fast);
    mcp_py_dump *parts = NULL;
    const mcp_dump **members = NULL;
    PyObject *result = NULL;
    if (get_dump_list(fast, n, &parts, &members)) goto done;
    mcp_dump *out = NULL;
    double ratio = 0;
    int rc;
    Py_BEGIN_ALLOW_THREADS rc =
        mcp_dump_increment_variance(members, (int)n, &io, &out, &ratio);
    Py_END_ALLOW_THREADS if (rc)
    {
        mcp_py_fail();
        goto done;
    }
    PyObject *d = mcp_py_dump_dict(out);
    result = d ? Py_BuildValue("(Nd)", d, ratio) : NULL;
done:
    release_dump_list(parts, members, n);
    Py_DECREF(fast);
    return result;
}

PyMethodDef mcp_py_dump_methods[] = {
    {"increment_variance", (PyCFunction)(void (*)(void))py_increment_variance,
     METH_VARARGS | METH_KEYWORDS,
     "increment_variance(dumps, *, first_spp=0, pool_radius=0) -> (dump, ratio)\n\n"
     "The last of a progressive render's members (dumps in increasing spp) with its\n"
     "variance of the mean from the spread between the increments before it (right for\n"
     "stratified samplers; docs/variance-sources.md), and ratio: the member's own\n"
     "variance over that spread (0 when not measurable). pool_radius 0 is automatic,\n"
     "< 0 none."},
    {"read_dump", (PyCFunction)(void (*)(void))py_read_dump, METH_VARARGS | METH_KEYWORDS,
     "read_dump(path, *, spp=0, convention=None, variance=None, bad_values=None,\n"
     "          variance_path=None, albedo_path=None, normal_path=None,\n"
     "          spp_map_path=None) -> dict\n\n"
     "A render dump: 'color', 'variance' (of the mean, whatever the file stored),\n"
     "'covariance', 'albedo', 'normal', 'spp_map' (arrays or None), 'spp' (None with a\n"
     "map), 'convention', 'variance_source', 'variance_dof', 'replicates',\n"
     "'variance_pool', 'bad_values', 'attributes', 'source'."},
    {"write_dump", (PyCFunction)(void (*)(void))py_write_dump,
     METH_VARARGS | METH_KEYWORDS,
     "write_dump(path, dump, *, convention='mcpost', half=False)\n\n"
     "Writes a dump (dict or path) as one EXR in a convention (pbrt, mcpost, mitsuba,\n"
     "blender), the variance stored as that convention stores it."},
    {"merge", (PyCFunction)(void (*)(void))py_merge, METH_VARARGS | METH_KEYWORDS,
     "merge(dumps, *, variance='replicates', pool=0) -> dict\n\n"
     "K renders of one frame in one dump: replicates (independent renders: the variance\n"
     "of the mean from their spread, K - 1 degrees of freedom) or pooled (passes of one\n"
     "render); pool R averages the variance over (2R+1)^2 pixels."},
    {NULL, NULL, 0, NULL}};
