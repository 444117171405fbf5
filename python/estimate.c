/* estimate.c: estimate(dump, ...) -- how wrong the denoised render still is and whether
 * to stop (estimate/estimate.h; docs/mathematics.md §2): the error maps, the blocks, the
 * distribution's λ and s², F(τ) and the decision F(τ) >= p, the estimated percentile
 * curve, the sampling map and, with a reference, the true percentiles beside it. The
 * keywords are the estimate's table (ops/op_estimate.c), as the CLI's flags ('-' as
 * '_') and the job stage's keys; the docstring's signature comes from it (module.c). */
#include "internal.h"

#include <mcpost/estimate.h>

#include <math.h>
#include <stdlib.h>

/* Takes an image out of a slot into d[key] (None when it is NULL). */
static int
take(PyObject *d, const char *key, mcp_image **slot)
{
    mcp_image *img = *slot;
    *slot = NULL;
    return mcp_py_set(d, key, mcp_py_array(img));
}

/* The result dict; takes the estimate's images over. */
static PyObject *
result_dict(mcp_estimate *e, const mcp_estimate_options *o, const double *taus,
            int n_taus, const double *truth, const char *denoiser)
{
    PyObject *d = PyDict_New();
    mcp_image *dist = NULL, *block_mean = NULL;
    int32_t *label = NULL;
    if (!d) return NULL;
    /* the distribution and the block-averaged SURE, before the maps are taken */
    if (mcp_error_dist_image(e->dist, &dist) ||
        mcp_blocks_mean_image(e->blocks, e->maps.sure_rel, &block_mean) ||
        mcp_blocks_label(e->blocks, &label)) {
        mcp_py_fail();
        goto fail;
    }
    double cdf[MCP_ESTIMATE_MAX_TAUS];
    for (int j = 0; j < n_taus; j++)
        if (isnan(cdf[j] = mcp_error_cdf(e->dist, taus[j]))) {
            mcp_py_fail();
            goto fail;
        }
    double lambda = 0, s2 = 0, n = (double)e->blocks->width * e->blocks->height * 3;
    for (int i = 0; i < e->blocks->count; i++) {
        const mcp_block *k = &e->blocks->items[i];
        for (int c = 0; c < 3; c++) {
            lambda += mcp_error_dist_lambda(e->dist, i, c) * k->w * k->h;
            s2 += k->var_sum[c];
        }
    }
    npy_intp dims[2] = {e->blocks->height, e->blocks->width};
    PyObject *labels = PyArray_SimpleNew(2, dims, NPY_INT32);
    if (labels)
        memcpy(PyArray_DATA((PyArrayObject *)labels), label,
               (size_t)dims[0] * dims[1] * sizeof *label);
    if (mcp_py_set(d, "denoiser", PyUnicode_FromString(denoiser)) ||
        mcp_py_set(d, "metric",
                   PyUnicode_FromString(mcp_error_metric_name(o->sure.metric))) ||
        mcp_py_set(d, "tau", PyFloat_FromDouble(e->tau)) ||
        mcp_py_set(d, "p", PyFloat_FromDouble(e->p)) ||
        mcp_py_set(d, "cdf_at_tau", PyFloat_FromDouble(e->cdf_at_tau)) ||
        mcp_py_set(d, "stop", PyBool_FromLong(e->stop)) ||
        mcp_py_set(d, "no_variance", PyBool_FromLong(e->no_variance)) ||
        mcp_py_set(d, "taus", mcp_py_vector(taus, n_taus)) ||
        mcp_py_set(d, "cdf", mcp_py_vector(cdf, n_taus)) ||
        mcp_py_set(d, "percentiles", mcp_py_vector(e->percentiles, e->n_percentiles)) ||
        mcp_py_set(d, "percentile_error",
                   mcp_py_vector(e->percentile_tau, e->n_percentiles)) ||
        mcp_py_set(d, "true_percentiles",
                   truth ? mcp_py_vector(truth, e->n_percentiles) : Py_NewRef(Py_None)) ||
        mcp_py_set(d, "blocks", PyLong_FromLong(e->blocks->count)) ||
        mcp_py_set(d, "block_labels", labels) ||
        mcp_py_set(d, "expected_mean_error",
                   PyFloat_FromDouble(mcp_error_dist_mean(e->dist))) ||
        mcp_py_set(d, "mean_lambda", PyFloat_FromDouble(lambda / n)) ||
        mcp_py_set(d, "mean_s2", PyFloat_FromDouble(s2 / n)) ||
        mcp_py_set(d, "lambda", mcp_py_array_channels(dist, 0, 3)) ||
        mcp_py_set(d, "s2", mcp_py_array_channels(dist, 3, 3)) ||
        mcp_py_set(d, "variance_source",
                   PyUnicode_FromString(mcp_variance_source_name(e->variance_source))) ||
        mcp_py_set(d, "variance_dof", PyFloat_FromDouble(e->variance_dof)) ||
        mcp_py_set(d, "s2_pool", PyLong_FromLong(e->s2_pool)) ||
        mcp_py_set(d, "probe_floor", PyLong_FromLong(e->probe_floor)) ||
        mcp_py_set(d, "probes", PyLong_FromLong(e->probes)) ||
        mcp_py_set(d, "time_ms",
                   Py_BuildValue("{s:d,s:d,s:d,s:d,s:d,s:d}", "denoise_and_jvp",
                                 e->ms_denoise, "sure_and_variance", e->ms_error_terms,
                                 "block_averaging", e->ms_blocks, "stopping",
                                 e->ms_stopping, "percentiles", e->ms_percentiles,
                                 "sampling_map", e->ms_sampling)) ||
        take(d, "blocks_sure_rel", &block_mean) ||
        take(d, "denoised", &e->maps.denoised) || take(d, "sure", &e->maps.sure) ||
        take(d, "sure_rel", &e->maps.sure_rel) || take(d, "variance", &e->maps.var) ||
        take(d, "variance_rel", &e->maps.var_rel) ||
        take(d, "sigma_rel", &e->maps.sigma_rel) ||
        take(d, "denominator", &e->maps.denominator) ||
        take(d, "sampling_map", &e->sampling_map) ||
        take(d, "sample_counts", &e->sample_counts))
        goto fail;
    free(label);
    mcp_image_free(dist);
    return d;
fail:
    free(label);
    mcp_image_free(dist);
    mcp_image_free(block_mean);
    Py_DECREF(d);
    return NULL;
}

/* A function's one positional argument, given by position or by keyword (own_value). */
static int
positional(const char *fn, const char *name, PyObject *args, PyObject *own_value,
           PyObject **out)
{
    PyObject *given = NULL;
    if (!PyArg_UnpackTuple(args, fn, 0, 1, &given)) return -1;
    if (given && own_value) {
        PyErr_Format(PyExc_TypeError, "%s() got multiple values for argument '%s'", fn,
                     name);
        return -1;
    }
    if (!given && !(given = own_value)) {
        PyErr_Format(PyExc_TypeError, "%s() missing required argument '%s'", fn, name);
        return -1;
    }
    *out = given;
    return 0;
}

/* ---- a series: the CLI's `mcpost estimate DUMP DUMP...` ---- */

/* Between members: Python's Ctrl-C ends the series. ctx: the released thread state. */
static int
on_member(int done, int total, void *ctx)
{
    (void)done, (void)total;
    return mcp_py_signalled(ctx) ? mcp_error("estimate: interrupted") : 0;
}

/* spp per tau, None where the series never reaches it */
static PyObject *
spp_list(const double *spp, int n)
{
    PyObject *l = PyList_New(n);
    for (int j = 0; l && j < n; j++) {
        PyObject *v = spp[j] > 0 ? PyFloat_FromDouble(spp[j]) : Py_NewRef(Py_None);
        if (!v) Py_CLEAR(l);
        if (l) PyList_SET_ITEM(l, j, v);
    }
    return l;
}

static PyObject *
bool_list(const int *b, int n)
{
    PyObject *l = PyList_New(n);
    for (int j = 0; l && j < n; j++)
        PyList_SET_ITEM(l, j, PyBool_FromLong(b[j]));
    return l;
}

/* One member as estimate.json's member (jobs/estimate_output.c), with the single
 * estimate's names for the percentile curve. */
static PyObject *
member_dict(const mcp_series_estimate *s, const mcp_series_point *pt)
{
    PyObject *d = PyDict_New();
    if (!d) return NULL;
    int bad =
        mcp_py_set(d, "spp", PyFloat_FromDouble(pt->spp)) ||
        mcp_py_set(d, "cdf", mcp_py_vector(pt->cdf, s->n_taus)) ||
        mcp_py_set(d, "stop", bool_list(pt->stop, s->n_taus)) ||
        mcp_py_set(d, "held", PyBool_FromLong(pt->held)) ||
        mcp_py_set(d, "sure_groups", PyLong_FromLong(pt->sure_groups)) ||
        mcp_py_set(d, "probes_from_groups", PyBool_FromLong(pt->probes_from_groups)) ||
        mcp_py_set(d, "percentile_error",
                   mcp_py_vector(pt->est_percentile, s->n_percentiles)) ||
        mcp_py_set(d, "expected_mean_error", PyFloat_FromDouble(pt->est_mean_error));
    if (!bad && s->has_reference)
        bad = mcp_py_set(d, "true_cdf", mcp_py_vector(pt->true_cdf, s->n_taus)) ||
              mcp_py_set(d, "true_stop", bool_list(pt->true_stop, s->n_taus)) ||
              mcp_py_set(d, "true_percentiles",
                         mcp_py_vector(pt->true_percentile, s->n_percentiles)) ||
              mcp_py_set(d, "true_mean_error", PyFloat_FromDouble(pt->true_mean_error));
    if (bad) Py_CLEAR(d);
    return d;
}

static PyObject *
series_dict(const mcp_series_estimate *s, const mcp_estimate_options *o,
            const char *denoiser)
{
    PyObject *d = PyDict_New(), *members = PyList_New(s->count);
    int stop = 1;
    for (int i = 0; members && i < s->count; i++) {
        PyObject *m = member_dict(s, &s->points[i]);
        if (!m) Py_CLEAR(members);
        if (members) PyList_SET_ITEM(members, i, m);
    }
    for (int j = 0; j < s->n_taus; j++)
        stop = stop && s->points[s->count - 1].stop[j];
    if (!d || !members) {
        Py_XDECREF(d);
        Py_XDECREF(members);
        return NULL;
    }
    int bad =
        mcp_py_set(d, "members", members) ||
        mcp_py_set(d, "denoiser", PyUnicode_FromString(denoiser)) ||
        mcp_py_set(d, "metric",
                   PyUnicode_FromString(mcp_error_metric_name(o->sure.metric))) ||
        mcp_py_set(d, "p", PyFloat_FromDouble(s->p)) ||
        mcp_py_set(d, "taus", mcp_py_vector(s->taus, s->n_taus)) ||
        mcp_py_set(d, "percentiles", mcp_py_vector(s->percentiles, s->n_percentiles)) ||
        mcp_py_set(d, "first_spp", spp_list(s->first_spp, s->n_taus)) ||
        mcp_py_set(d, "stop", PyBool_FromLong(stop)) ||
        mcp_py_set(d, "variance_source",
                   PyUnicode_FromString(mcp_variance_source_name(s->variance_source))) ||
        mcp_py_set(d, "variance_ratio", PyFloat_FromDouble(s->variance_ratio)) ||
        mcp_py_set(d, "has_reference", PyBool_FromLong(s->has_reference));
    if (!bad && s->has_reference) {
        int agree = 0;
        for (int j = 0; j < s->n_taus; j++)
            agree += s->agree[j];
        bad = mcp_py_set(d, "true_first_spp", spp_list(s->true_first_spp, s->n_taus)) ||
              mcp_py_set(d, "agree", bool_list(s->agree, s->n_taus)) ||
              mcp_py_set(d, "agreement_rate",
                         PyFloat_FromDouble((double)agree / s->n_taus));
    }
    if (bad) Py_CLEAR(d);
    return d;
}

/* estimate([paths...]): every member of a progressive render (the dumps' paths in
 * increasing spp, loaded one at a time), as `mcpost estimate DUMP...` runs them: the
 * variance chosen per member (variance_from), SURE from the render's own groups, and
 * with a reference the true stops beside the estimated ones. */
static PyObject *
estimate_series(PyObject *list, PyObject *den_obj, PyObject *ref_obj,
                const mcp_estimate_settings *st)
{
    mcp_series *series = NULL;
    mcp_denoiser *den = NULL;
    mcp_py_image ref = {0};
    mcp_series_estimate *s = NULL;
    PyObject *result = NULL;
    if (mcp_py_series_get(list, "estimate", &series)) return NULL;
    series->spec.convention = st->convention;
    series->spec.variance = st->variance;
    series->variance_from = st->variance_from;
    if (mcp_py_image_opt(ref_obj, "reference", 0, NULL, &ref) ||
        mcp_py_denoiser_arg(den_obj, &den))
        goto done;
    PyThreadState *thread = PyEval_SaveThread();
    int rc =
        mcp_estimate_series_each(series, den, &st->so, ref.img, on_member, &thread, &s);
    PyEval_RestoreThread(thread);
    if (PyErr_Occurred() || mcp_py_check_signals()) goto done;
    if (rc) {
        mcp_py_fail();
        goto done;
    }
    result = series_dict(s, &st->so.est, den->name);
done:
    mcp_series_estimate_free(s);
    mcp_py_image_release(&ref);
    mcp_denoiser_free(den);
    mcp_series_free(series);
    return result;
}

static PyObject *
py_estimate(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    /* the keywords are the estimate's table (ops/op_estimate.c); these three are read
       here: the dump and the reference (arrays or paths) and the denoiser */
    static const char *const own[] = {"dump", "denoiser", "reference", NULL};
    PyObject *vals[3], *dump_obj = NULL, *keep = PyList_New(0);
    mcp_estimate_settings st;
    if (!keep) return NULL;
    if (mcp_py_settings(mcp_operation_estimate(), "estimate", kw, own, vals, &st, keep) ||
        positional("estimate", "dump", args, vals[0], &dump_obj)) {
        Py_DECREF(keep);
        return NULL;
    }
    Py_DECREF(keep); /* no path of the settings is used below */
    PyObject *den_obj = vals[1] ? vals[1] : Py_None,
             *ref_obj = vals[2] ? vals[2] : Py_None;
    /* a list or tuple of paths: a progressive render */
    if (PyList_Check(dump_obj) || PyTuple_Check(dump_obj))
        return estimate_series(dump_obj, den_obj, ref_obj, &st);
    mcp_estimate_options o = st.so.est;
    /* one dump: F at the taus given, else at tau */
    const mcp_operation *op = mcp_operation_estimate();
    int n_taus = 1;
    double taus[MCP_ESTIMATE_MAX_TAUS] = {o.tau};
    if (mcp_operation_given(op, mcp_operation_option(op, "taus"), &st)) {
        n_taus = st.so.n_taus;
        memcpy(taus, st.so.taus, (size_t)n_taus * sizeof *taus);
    }
    mcp_py_dump dump;
    mcp_py_image ref = {0};
    mcp_denoiser *den = NULL;
    if (mcp_py_dump_get(dump_obj, "dump", &dump)) return NULL;
    PyObject *result = NULL;
    mcp_estimate *e = NULL;
    mcp_image *err = NULL;
    if (mcp_py_image_opt(ref_obj, "reference", 0, NULL, &ref) ||
        mcp_py_denoiser_arg(den_obj, &den))
        goto done;
    double truth[MCP_ESTIMATE_MAX_PERCENTILES];
    int rc;
    Py_BEGIN_ALLOW_THREADS rc = mcp_estimate_compute(dump.dump, den, &o, &e);
    if (!rc && ref.img)
        rc = mcp_true_error(e->maps.denoised, ref.img, o.sure.metric, o.sure.ppd, &err) ||
             mcp_true_percentiles(err, e->percentiles, e->n_percentiles, truth);
    Py_END_ALLOW_THREADS if (mcp_py_check_signals()) goto done;
    if (rc) {
        mcp_py_fail();
        goto done;
    }
    result = result_dict(e, &o, taus, n_taus, ref.img ? truth : NULL, den->name);
done:
    mcp_image_free(err);
    mcp_estimate_free(e);
    mcp_denoiser_free(den);
    mcp_py_image_release(&ref);
    mcp_py_dump_release(&dump);
    return result;
}

static PyObject *
py_true_error(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"denoised", "reference", "metric", "ppd", NULL};
    PyObject *a, *b;
    const char *metric = NULL;
    double ppd = 0;
    mcp_error_metric m = MCP_METRIC_RELSE;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "OO|$zd:true_error", keys, &a, &b, &metric,
                                     &ppd))
        return NULL;
    if (metric && mcp_error_metric_from_name(metric, &m)) return mcp_py_fail();
    mcp_py_image f, r;
    if (mcp_py_image_get(a, "denoised", 0, NULL, &f)) return NULL;
    if (mcp_py_image_get(b, "reference", 0, NULL, &r)) {
        mcp_py_image_release(&f);
        return NULL;
    }
    mcp_image *err = NULL;
    int rc;
    Py_BEGIN_ALLOW_THREADS rc = mcp_true_error(f.img, r.img, m, ppd, &err);
    Py_END_ALLOW_THREADS mcp_py_image_release(&f);
    mcp_py_image_release(&r);
    return rc ? mcp_py_fail() : mcp_py_array(err);
}

#define KW (METH_VARARGS | METH_KEYWORDS)
#define FN(f) (PyCFunction)(void (*)(void))(f)
PyMethodDef mcp_py_estimate_methods[] = {
    {"estimate", FN(py_estimate), KW,
     "The error estimate of the denoised dump (SURE, Firmino et al. 2024) and the stop\n"
     "decision F(tau) >= p: maps ('denoised', 'sure', 'sure_rel', 'variance',\n"
     "'variance_rel', 'sigma_rel', 'denominator', 'blocks_sure_rel', 'sampling_map',\n"
     "'sample_counts'), the distribution ('lambda', 's2', 'block_labels', 'blocks',\n"
     "'mean_lambda', 'mean_s2', 'expected_mean_error'), 'cdf_at_tau', 'stop', 'cdf'\n"
     "(F at each of taus), 'percentile_error' at 'percentiles', and with a reference\n"
     "'true_percentiles'. dump is a path or a dict; denoiser a name or a dict with\n"
     "'name' and its settings.\n\n"
     "A list of dump paths in increasing spp is a progressive render, as `mcpost\n"
     "estimate DUMP DUMP...` runs it: 'members' (per member 'spp', 'cdf' and 'stop'\n"
     "per tau, 'held', 'sure_groups', 'probes_from_groups', 'percentile_error',\n"
     "'expected_mean_error'; with a reference 'true_cdf', 'true_stop',\n"
     "'true_percentiles', 'true_mean_error'), 'first_spp' per tau (None: never),\n"
     "'stop' (the last member, every tau), 'variance_source', 'variance_ratio'; with a\n"
     "reference 'true_first_spp', 'agree', 'agreement_rate'. Ctrl-C stops it after\n"
     "the current member."},
    {"true_error", FN(py_true_error), KW,
     "true_error(denoised, reference, *, metric='relse', ppd=0) -> ndarray H x W x 3:\n"
     "the true per-value error in the metric (docs/mathematics.md section 2.9)"},
    {NULL, NULL, 0, NULL}};
