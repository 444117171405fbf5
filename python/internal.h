/* internal.h: what the files of the Python module share -- images in and out as numpy
 * arrays, dumps as dicts, mcpost.Error, denoisers from keywords, and long calls
 * without the GIL (docs/python.md). */
#ifndef MCP_PY_INTERNAL_H
#define MCP_PY_INTERNAL_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
/* numpy's C API is a table of pointers that module.c fills (import_array); the other
 * files share it under this name */
#define PY_ARRAY_UNIQUE_SYMBOL mcpost_numpy_api
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#ifndef MCP_PY_MODULE_C
#define NO_IMPORT_ARRAY
#endif
#include <numpy/arrayobject.h>

#include <mcpost/denoiser.h>
#include <mcpost/dump.h>
#include <mcpost/image.h>
#include <mcpost/operations.h>
#include <mcpost/options.h>

/* mcpost.Error, a ValueError: the library's one-line message. */
extern PyObject *mcp_py_error;

/* Raises mcpost.Error with mcp_error_message(); returns NULL. */
PyObject *mcp_py_fail(void);
/* The same as an int, for functions that return 0 or -1. */
int mcp_py_fail_int(void);

/* An image argument: a numpy array (anything np.asarray takes: float32, other float or
 * integer dtypes, nested lists) as an H×W×C or H×W (one channel) view, without a copy
 * when it is already float32 and C-contiguous; or a path (str or os.PathLike) read
 * from the file. img->source is the argument's name, so that the library's messages
 * ("test: pixel (3, 4) is NaN") name it. */
typedef struct mcp_py_image {
    PyArrayObject *array; /* the array viewed (a new reference), or NULL */
    mcp_image *img;       /* the view, or the image read */
} mcp_py_image;

/* channels: 0 any, else the count the argument must have. names (may be NULL) name
 * the channels of an array; 3-channel arrays are R, G, B by default. Returns 0, or -1
 * with a Python exception set: TypeError for a dtype that is not a number,
 * mcpost.Error for a shape. */
int mcp_py_image_get(PyObject *obj, const char *what, int channels,
                     const char *const *names, mcp_py_image *out);
/* The same, None giving img NULL. */
int mcp_py_image_opt(PyObject *obj, const char *what, int channels,
                     const char *const *names, mcp_py_image *out);
void mcp_py_image_release(mcp_py_image *im);

/* A new numpy array for img, taking it over: its pixels become the array's without a
 * copy when it is packed and owns them (freed with the array); otherwise copied. One
 * channel gives H×W, more H×W×C. img is freed on failure. NULL img gives None. */
PyObject *mcp_py_array(mcp_image *img);
/* Channels [first, first + count) of img (not taken over) as a new array. */
PyObject *mcp_py_array_channels(const mcp_image *img, int first, int count);

/* A path argument (str or os.PathLike) as a new bytes object; NULL with TypeError. */
PyObject *mcp_py_path(PyObject *obj, const char *what);

/* ---- dumps (python/dumps.c) ---- */

/* A dump argument: a path (read with detection) or a dict as read_dump returns it
 * (colour required; the arrays are viewed, not copied). */
typedef struct mcp_py_dump {
    mcp_dump *dump;
    mcp_py_image parts[6]; /* color, variance, covariance, albedo, normal, spp_map */
} mcp_py_dump;

int mcp_py_dump_get(PyObject *obj, const char *what, mcp_py_dump *out);
void mcp_py_dump_release(mcp_py_dump *d);
/* A series of dump paths (a sequence of str or os.PathLike, in increasing spp) as
 * the library loads it, one member at a time (fn names the function in errors). -1
 * with the Python error set. */
int mcp_py_series_get(PyObject *list, const char *fn, mcp_series **out);
/* The dict of a dump, taking its images over (the dump is freed). */
PyObject *mcp_py_dump_dict(mcp_dump *dump);
/* The header attributes as a dict, and one attribute from a Python int, float or str
 * (0, or -1 with an exception). */
PyObject *mcp_py_attrs_dict(const mcp_attrs *attrs);
int mcp_py_attrs_set(mcp_attrs *attrs, PyObject *key, PyObject *value);

/* ---- denoisers (python/denoise.c) ---- */

/* A denoiser from a name and a settings dict (may be NULL), the job file's keys:
 * values are numbers, strings, paths or booleans. */
int mcp_py_denoiser(const char *name, PyObject *settings, mcp_denoiser **out);
/* From a keyword argument: a name (str), or a dict with "name" and settings, as the
 * job file's `denoiser:` map; None: "default". */
int mcp_py_denoiser_arg(PyObject *arg, mcp_denoiser **out);

/* ---- options (python/options.c) ---- */

/* Reads kw (may be NULL) through op's table into settings (the defaults first, then
 * op's finish): each keyword that names an option Python takes, its value turned into
 * the command line's text (TypeError for a wrong type; mcpost.Error with the table's
 * message for a bad value; None: the default). The keywords in own (NULL-terminated)
 * are the caller's: their values come back in own_values (borrowed, NULL when absent).
 * Paths the settings borrow are kept alive in the list keep. 0, or -1 with an
 * exception. fn names the function in messages. */
int mcp_py_settings(const mcp_operation *op, const char *fn, PyObject *kw,
                    const char *const *own, PyObject **own_values, void *settings,
                    PyObject *keep);
/* The docstring of op's function fn: "FN(POSITIONAL, *, keyword=default, ..., EXTRAS)
 * -> RETURNS", prose, and a line per keyword from the table; EXTRAS (may be NULL) are
 * the keywords the function reads itself that the table lacks ("maps=False").
 * malloc'd. */
char *mcp_py_doc(const mcp_operation *op, const char *fn, const char *positional,
                 const char *extras, const char *returns, const char *prose);
/* A function's n positional arguments, given by position or by keyword (own_values[i],
 * NULL when not given) into out; a missing or doubled one is a TypeError. */
int mcp_py_positionals(const char *fn, const char *const *names, int n, PyObject *args,
                       PyObject *const *own_values, PyObject **out);

/* ---- numbers ---- */

/* A sequence of up to max floats into out; *n receives the count. */
int mcp_py_doubles(PyObject *seq, const char *what, double *out, int max, int *n);
/* A new 1-D float64 array of n values. */
PyObject *mcp_py_vector(const double *v, int n);
/* Sets d[key] = value and drops the reference to value; -1 when value is NULL. */
int mcp_py_set(PyObject *d, const char *key, PyObject *value);

/* After a call without the GIL: raises KeyboardInterrupt (or what a signal handler
 * raised) when a signal came in meanwhile; returns -1 then. */
int mcp_py_check_signals(void);
/* Inside a call without the GIL, between its steps (a series' members): takes the GIL
 * back to look at the signals that came in (Python's handler only notes them), and
 * releases it again, *thread updated. 1 when a signal raised an exception. */
int mcp_py_signalled(PyThreadState **thread);

/* The method tables of the files (module.c joins them). */
extern PyMethodDef mcp_py_image_methods[];
extern PyMethodDef mcp_py_dump_methods[];
extern PyMethodDef mcp_py_metrics_methods[];
extern PyMethodDef mcp_py_denoise_methods[];
extern PyMethodDef mcp_py_estimate_methods[];
extern PyMethodDef mcp_py_blend_methods[];
extern PyMethodDef mcp_py_perceptual_methods[];
extern PyMethodDef mcp_py_jobs_methods[];
extern PyMethodDef mcp_py_options_methods[];

#endif
