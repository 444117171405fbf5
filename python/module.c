/* module.c: `import mcpost` -- the CPython extension module over libmcpost: its
 * function table (joined from the files, one per subject), mcpost.Error, and the small
 * helpers every file uses (docs/python.md). */
#define MCP_PY_MODULE_C
#include "internal.h"

#include <mcpost/progress.h>

PyObject *mcp_py_error;

PyObject *
mcp_py_fail(void)
{
    const char *msg = mcp_error_message();
    PyErr_SetString(mcp_py_error, *msg ? msg : "failed (no message)");
    return NULL;
}

int
mcp_py_fail_int(void)
{
    mcp_py_fail();
    return -1;
}

PyObject *
mcp_py_path(PyObject *obj, const char *what)
{
    PyObject *bytes = NULL;
    if (!PyUnicode_Check(obj) && !PyBytes_Check(obj) &&
        !PyObject_HasAttrString(obj, "__fspath__")) {
        PyErr_Format(PyExc_TypeError, "%s must be a path (str or os.PathLike), not %.80s",
                     what, Py_TYPE(obj)->tp_name);
        return NULL;
    }
    if (!PyUnicode_FSConverter(obj, &bytes)) return NULL;
    return bytes;
}

int
mcp_py_doubles(PyObject *seq, const char *what, double *out, int max, int *n)
{
    PyObject *fast = PySequence_Fast(seq, "");
    if (!fast) {
        PyErr_Format(PyExc_TypeError, "%s must be a sequence of numbers", what);
        return -1;
    }
    Py_ssize_t count = PySequence_Fast_GET_SIZE(fast);
    if (count < 1 || count > max) {
        Py_DECREF(fast);
        PyErr_Format(mcp_py_error, "%s: needs 1 to %d values (got %zd)", what, max,
                     count);
        return -1;
    }
    for (Py_ssize_t i = 0; i < count; i++) {
        out[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(fast, i));
        if (out[i] == -1.0 && PyErr_Occurred()) {
            Py_DECREF(fast);
            PyErr_Format(PyExc_TypeError, "%s[%zd] is not a number", what, i);
            return -1;
        }
    }
    Py_DECREF(fast);
    *n = (int)count;
    return 0;
}

PyObject *
mcp_py_vector(const double *v, int n)
{
    npy_intp dims[1] = {n};
    PyObject *a = PyArray_SimpleNew(1, dims, NPY_FLOAT64);
    if (a) memcpy(PyArray_DATA((PyArrayObject *)a), v, (size_t)n * sizeof *v);
    return a;
}

int
mcp_py_set(PyObject *d, const char *key, PyObject *value)
{
    if (!value) return -1;
    int rc = PyDict_SetItemString(d, key, value);
    Py_DECREF(value);
    return rc;
}

int
mcp_py_check_signals(void)
{
    return PyErr_CheckSignals() ? -1 : 0;
}

int
mcp_py_signalled(PyThreadState **thread)
{
    PyEval_RestoreThread(*thread);
    const int raised = PyErr_CheckSignals() != 0;
    *thread = PyEval_SaveThread();
    return raised;
}

static PyObject *
py_version(PyObject *self, PyObject *unused)
{
    (void)self, (void)unused;
    return PyUnicode_FromString(MCP_VERSION);
}

static PyObject *
py_set_quiet(PyObject *self, PyObject *arg)
{
    (void)self;
    int quiet = PyObject_IsTrue(arg);
    if (quiet < 0) return NULL;
    mcp_progress_set_quiet(quiet);
    Py_RETURN_NONE;
}

static PyMethodDef own_methods[] = {
    {"version", py_version, METH_NOARGS, "version() -> str: libmcpost's version"},
    {"set_quiet", py_set_quiet, METH_O,
     "set_quiet(quiet): no progress lines or notes on stderr (the CLI's --quiet)"},
    {NULL, NULL, 0, NULL}};

/* Every file's table, joined into one (a module has one). */
static PyMethodDef all_methods[64];

static int
join_tables(void)
{
    PyMethodDef *tables[] = {own_methods,
                             mcp_py_image_methods,
                             mcp_py_dump_methods,
                             mcp_py_metrics_methods,
                             mcp_py_denoise_methods,
                             mcp_py_estimate_methods,
                             mcp_py_blend_methods,
                             mcp_py_perceptual_methods,
                             mcp_py_jobs_methods,
                             mcp_py_options_methods};
    size_t n = 0;
    for (size_t t = 0; t < sizeof tables / sizeof *tables; t++)
        for (PyMethodDef *m = tables[t]; m->ml_name; m++) {
            if (n + 1 >= sizeof all_methods / sizeof *all_methods) return -1;
            all_methods[n++] = *m;
        }
    all_methods[n] = (PyMethodDef){NULL, NULL, 0, NULL};
    /* the functions of operations with a table: their signature and keywords come from
       it (python/options.c), before the prose their file gives */
    static const struct {
        const char *name, *op, *positional, *extras, *returns;
    } ops[] = {
        {"estimate", "estimate", "dump", NULL, "dict"},
        {"blend", "blend", "dumps", NULL, "dict"},
        {"metrics", "metrics", "test, ref", "maps=False, pixels_above=None",
         "dict (or (dict, maps) with maps=True)"},
        {"perceptual", "perceptual", "candidates", "albedo=None, normal=None, mask=None",
         "dict"},
        {"denoise", "denoise", "color", "variance=None, **settings", "ndarray H x W x 3"},
        {"jvp", "denoise", "color, tangent", "variance=None, **settings",
         "(denoised, J·tangent)"}};
    for (size_t i = 0; i < n; i++)
        for (size_t k = 0; k < sizeof ops / sizeof *ops; k++)
            if (!strcmp(all_methods[i].ml_name, ops[k].name)) {
                const mcp_operation *op = mcp_operation_find(ops[k].op);
                char *doc =
                    op ? mcp_py_doc(op, ops[k].name, ops[k].positional, ops[k].extras,
                                    ops[k].returns, all_methods[i].ml_doc)
                       : NULL;
                if (!doc) return -1;
                all_methods[i].ml_doc = doc; /* the module's, for the process */
            }
    return 0;
}

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT,
    "mcpost",
    "mcpost: post-processing of Monte Carlo renderings on numpy arrays.\n\n"
    "Images are float32 arrays H x W x C (H x W for one channel); dumps are dicts as\n"
    "read_dump returns them, or paths. Failures raise mcpost.Error with the library's\n"
    "one-line message. See docs/python.md.",
    -1,
    all_methods,
    NULL,
    NULL,
    NULL,
    NULL};

PyMODINIT_FUNC
PyInit_mcpost(void)
{
    import_array();
    if (join_tables()) {
        PyErr_SetString(PyExc_SystemError, "mcpost: too many functions for the table");
        return NULL;
    }
    PyObject *m = PyModule_Create(&module_def);
    if (!m) return NULL;
    mcp_py_error = PyErr_NewExceptionWithDoc(
        "mcpost.Error",
        "what libmcpost reported: one line naming the file, argument, "
        "channel or field and the value",
        PyExc_ValueError, NULL);
    if (!mcp_py_error || PyModule_AddObjectRef(m, "Error", mcp_py_error) ||
        PyModule_AddStringConstant(m, "__version__", MCP_VERSION)) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
