/* blend.c: blend(dumps, ...) -- converging blends of a progressive render with its
 * denoised images (blend/blend.h; Denisova & Bocchi 2024): per member the blended image
 * and the weights, the figures of the CLI's members table and, with a reference, the
 * errors of every method. The one long call here with a hook: Ctrl-C stops it after the
 * member being blended. */
#include "internal.h"

#include <mcpost/blend.h>

#include <math.h>

/* What the driver hands over per member, copied (its images are borrowed). */
typedef struct member {
    char *source;
    mcp_blend_row row;
    mcp_image *images[MCP_BLEND_N_METHODS];
    mcp_image *weights;
    mcp_blend_method method; /* which image is the blend */
} member;

typedef struct sink {
    member *members;
    int count;
    int all_images;
    PyThreadState *thread; /* the caller's, to take the GIL back for signals */
} sink;

static int
on_point(const mcp_blend_point *p, void *ctx)
{
    sink *s = ctx;
    if (mcp_py_signalled(&s->thread)) return mcp_error("blend: interrupted"); /* Ctrl-C */
    member *m = &s->members[p->index];
    memset(m, 0, sizeof *m);
    m->row = *p->row;
    m->method = p->method;
    if (!(m->source = mcp_strdup(p->source)) || mcp_image_copy(p->weights, &m->weights))
        return -1;
    for (int k = 0; k < MCP_BLEND_N_METHODS; k++)
        if (p->images[k] && (s->all_images || k == (int)p->method) &&
            mcp_image_copy(p->images[k], &m->images[k]))
            return -1;
    s->count = p->index + 1;
    return 0;
}

static void
sink_free(sink *s, int n)
{
    for (int i = 0; s->members && i < n; i++) {
        free(s->members[i].source);
        mcp_image_free(s->members[i].weights);
        for (int k = 0; k < MCP_BLEND_N_METHODS; k++)
            mcp_image_free(s->members[i].images[k]);
    }
    PyMem_Free(s->members);
}

static PyObject *
member_dict(member *m, int has_reference, int has_flip)
{
    PyObject *d = PyDict_New(), *images = NULL, *errors = NULL;
    if (!d || mcp_py_set(d, "source", PyUnicode_DecodeFSDefault(m->source)) ||
        mcp_py_set(d, "spp", PyFloat_FromDouble(m->row.spp)) ||
        mcp_py_set(d, "denoised_spp", PyFloat_FromDouble(m->row.denoised_spp)) ||
        mcp_py_set(d, "mean_var", PyFloat_FromDouble(m->row.mean_var)) ||
        mcp_py_set(d, "mean_sure", PyFloat_FromDouble(m->row.mean_sure)) ||
        mcp_py_set(d, "filtered", PyBool_FromLong(m->row.filtered)) ||
        mcp_py_set(d, "negative_sure",
                   PyUnicode_FromString(m->row.magnitude ? "magnitude" : "zero")) ||
        mcp_py_set(d, "mean_rho", PyFloat_FromDouble(m->row.mean_rho)) ||
        mcp_py_set(d, "safeguard_pulled", PyFloat_FromDouble(m->row.safeguard_pulled)) ||
        mcp_py_set(d, "self_influence", PyFloat_FromDouble(m->row.self_influence)))
        goto fail;
    mcp_image *blend = m->images[m->method], *w = m->weights;
    m->images[m->method] = m->weights = NULL;
    if (mcp_py_set(d, "blend", mcp_py_array(blend)) ||
        mcp_py_set(d, "weights", mcp_py_array(w)))
        goto fail;
    images = PyDict_New();
    if (!images) goto fail;
    for (int k = 0; k < MCP_BLEND_N_METHODS; k++)
        if (m->images[k]) {
            mcp_image *img = m->images[k];
            m->images[k] = NULL;
            if (mcp_py_set(images, mcp_blend_method_name(k), mcp_py_array(img)))
                goto fail;
        }
    if (mcp_py_set(d, "images", images)) goto fail;
    images = NULL;
    if (has_reference) {
        errors = PyDict_New();
        for (int k = 0; errors && k < MCP_BLEND_N_METHODS; k++) {
            const mcp_blend_errors *e = &m->row.err[k];
            PyObject *one =
                has_flip ? Py_BuildValue("{s:d,s:d,s:d}", "mse", e->mse, "relmse",
                                         e->relmse, "flip_hdr", e->flip_hdr)
                         : Py_BuildValue("{s:d,s:d}", "mse", e->mse, "relmse", e->relmse);
            if (mcp_py_set(errors, mcp_blend_method_name(k), one)) goto fail;
        }
        if (mcp_py_set(d, "errors", errors)) goto fail;
        errors = NULL;
    }
    return d;
fail:
    Py_XDECREF(images);
    Py_XDECREF(errors);
    Py_XDECREF(d);
    return NULL;
}

static PyObject *
py_blend(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    /* the keywords are the blend's table (ops/op_blend.c); these are read here: the
       dumps, the reference (an array or a path) and the denoiser */
    static const char *const own[] = {"dumps", "denoiser", "reference", NULL};
    PyObject *vals[3], *list = NULL, *keep = PyList_New(0);
    mcp_blend_settings st;
    if (!keep) return NULL;
    int bad = mcp_py_settings(mcp_operation_blend(), "blend", kw, own, vals, &st, keep);
    Py_DECREF(keep); /* no path of the settings is used below */
    if (bad) return NULL;
    if (!PyArg_UnpackTuple(args, "blend", 0, 1, &list)) return NULL;
    if (list && vals[0]) {
        PyErr_SetString(PyExc_TypeError,
                        "blend() got multiple values for argument 'dumps'");
        return NULL;
    }
    if (!list && !(list = vals[0])) {
        PyErr_SetString(PyExc_TypeError, "blend() missing required argument 'dumps'");
        return NULL;
    }
    PyObject *den_obj = vals[1] ? vals[1] : Py_None,
             *ref_obj = vals[2] ? vals[2] : Py_None;
    mcp_blend_series_options o = st.o;
    mcp_blend_options *b = &o.blend;
    mcp_series_variance vsrc = st.variance_from;
    int all_images = st.all_images;
    /* the members: paths in increasing spp (the driver loads them one at a time) */
    mcp_series *series = NULL;
    mcp_denoiser *den = NULL;
    mcp_py_image ref = {0};
    mcp_blend_series_result *r = NULL;
    sink s = {0};
    PyObject *result = NULL;
    if (mcp_py_series_get(list, "blend", &series)) return NULL;
    const int n = series->count;
    series->variance_from = vsrc;
    if (mcp_py_image_opt(ref_obj, "reference", 0, NULL, &ref) ||
        mcp_py_denoiser_arg(den_obj, &den))
        goto done;
    if (!(s.members = PyMem_Calloc((size_t)n, sizeof *s.members))) {
        PyErr_NoMemory();
        goto done;
    }
    s.all_images = all_images;
    int rc;
    s.thread = PyEval_SaveThread();
    rc = mcp_blend_series(series, den, ref.img, &o, on_point, &s, &r);
    PyEval_RestoreThread(s.thread);
    if (PyErr_Occurred() || mcp_py_check_signals()) goto done;
    if (rc) {
        mcp_py_fail();
        goto done;
    }
    PyObject *members = PyList_New(r->count);
    for (int i = 0; members && i < r->count; i++) {
        s.members[i].row = r->rows[i]; /* the final row (errors filled in) */
        PyObject *m = member_dict(&s.members[i], r->has_reference, r->has_flip);
        if (!m)
            Py_CLEAR(members);
        else
            PyList_SET_ITEM(members, i, m);
    }
    if (members)
        result = Py_BuildValue("{s:N,s:s,s:s,s:O,s:s}", "members", members, "denoiser",
                               den->name, "variance_source",
                               mcp_variance_source_name(r->variance_source),
                               "has_reference", r->has_reference ? Py_True : Py_False,
                               "weights", mcp_blend_weighting_name(b->weights));
done:
    sink_free(&s, n);
    mcp_blend_series_result_free(r);
    mcp_py_image_release(&ref);
    mcp_denoiser_free(den);
    mcp_series_free(series);
    return result;
}

PyMethodDef mcp_py_blend_methods[] = {
    {"blend", (PyCFunction)(void (*)(void))py_blend, METH_VARARGS | METH_KEYWORDS,
     "Blends every member of a progressive render (dump paths in increasing spp) with\n"
     "its denoised image (Denisova & Bocchi 2024). 'members': per member 'blend',\n"
     "'weights', 'spp', 'mean_var', 'mean_sure', 'mean_rho', ..., 'images' (every\n"
     "method's image with all_images) and with a reference 'errors' (mse, relmse,\n"
     "flip_hdr per method). Ctrl-C stops it after the current member."},
    {NULL, NULL, 0, NULL}};
