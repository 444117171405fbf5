/* jobs.c: job files from Python -- check_job and run_job, with the library's stage
 * table, the one `mcpost run` uses (docs/python.md, docs/jobs.md). */
#include "internal.h"

#include <mcpost/job.h>

#include <stdlib.h>

static PyObject *
py_check_job(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *kwlist[] = {"path", NULL};
    PyObject *path_obj;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "O:check_job", kwlist, &path_obj))
        return NULL;
    PyObject *path = mcp_py_path(path_obj, "path");
    if (!path) return NULL;
    int rc;
    Py_BEGIN_ALLOW_THREADS rc = mcp_job_check(PyBytes_AS_STRING(path), NULL);
    Py_END_ALLOW_THREADS Py_DECREF(path);
    if (rc) return mcp_py_fail();
    Py_RETURN_NONE;
}

static PyObject *
py_run_job(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *kwlist[] = {"path", "output", "quiet", NULL};
    PyObject *path_obj, *output_obj = Py_None;
    int quiet = 1;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "O|Op:run_job", kwlist, &path_obj,
                                     &output_obj, &quiet))
        return NULL;
    PyObject *path = mcp_py_path(path_obj, "path"), *output = NULL;
    if (!path ||
        (output_obj != Py_None && !(output = mcp_py_path(output_obj, "output")))) {
        Py_XDECREF(path);
        return NULL;
    }
    mcp_job_options o = mcp_job_defaults();
    o.output_dir = output ? PyBytes_AS_STRING(output) : NULL;
    o.quiet = quiet;
    char *dir = NULL;
    int *frames = NULL, n_frames = 0, rc;
    Py_BEGIN_ALLOW_THREADS rc =
        mcp_job_run_file(PyBytes_AS_STRING(path), NULL, &o) ||
        mcp_job_frames(PyBytes_AS_STRING(path), &o, &frames, &n_frames, &dir);
    Py_END_ALLOW_THREADS Py_DECREF(path);
    Py_XDECREF(output);
    free(frames);
    PyObject *result = NULL;
    if (!mcp_py_check_signals())
        result = rc ? mcp_py_fail() : PyUnicode_DecodeFSDefault(dir);
    free(dir);
    return result;
}

PyMethodDef mcp_py_jobs_methods[] = {
    {"check_job", (PyCFunction)(void (*)(void))py_check_job, METH_VARARGS | METH_KEYWORDS,
     "check_job(path): validates a job file as `mcpost run --check` does (every stage, "
     "key, input and file) and runs nothing; raises mcpost.Error naming job.yaml:LINE"},
    {"run_job", (PyCFunction)(void (*)(void))py_run_job, METH_VARARGS | METH_KEYWORDS,
     "run_job(path, output=None, quiet=True) -> str: runs a job file as `mcpost run` "
     "does (output overrides its output:) and returns its output folder, which holds "
     "report.json and report.html"},
    {NULL, NULL, 0, NULL}};
