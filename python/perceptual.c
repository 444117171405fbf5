/* perceptual.c: perceptual(candidates, ...) -- perceptual error optimisation of M
 * few-sample renders (perceptual/perceptual.h; Chizhov et al. 2022): the optimised
 * image, the candidate index or the permutation, and the scores of the CLI's JSON
 * (energy; with a reference pMSE, MSE and the low-frequency fraction; the same for the
 * candidates' mean). Keywords are the CLI's flags ('-' as '_'). */
#include "internal.h"

#include <mcpost/imageio.h>
#include <mcpost/perceptual.h>

#include <math.h>
#include <stdlib.h>

/* The candidates: arrays (colour), dicts (a dump's colour, albedo, normal) or paths
 * (read as a dump when they are one, else their R, G, B). */
typedef struct cands {
    int m;
    mcp_py_image *color;          /* views or images read */
    mcp_image **albedo, **normal; /* owned copies, NULL where a candidate has none */
} cands;

static void
cands_free(cands *c)
{
    for (int i = 0; i < c->m; i++) {
        if (c->color) mcp_py_image_release(&c->color[i]);
        if (c->albedo) mcp_image_free(c->albedo[i]);
        if (c->normal) mcp_image_free(c->normal[i]);
    }
    PyMem_Free(c->color);
    PyMem_Free(c->albedo);
    PyMem_Free(c->normal);
}

static int
copy_or_null(const mcp_image *img, mcp_image **out)
{
    *out = NULL;
    return img && mcp_image_copy(img, out) ? mcp_py_fail_int() : 0;
}

static int
get_candidate(PyObject *obj, const char *what, cands *c, int i)
{
    if (PyArray_Check(obj) || PyList_Check(obj) || PyTuple_Check(obj))
        return mcp_py_image_get(obj, what, 3, NULL, &c->color[i]);
    mcp_py_dump d;
    if (!PyDict_Check(obj)) { /* a path: a dump, or a plain image */
        PyObject *path = mcp_py_path(obj, what);
        if (!path) return -1;
        mcp_image *img = NULL;
        mcp_dump *dump = NULL;
        int rc;
        Py_BEGIN_ALLOW_THREADS rc = mcp_image_read(PyBytes_AS_STRING(path), NULL, &img);
        if (!rc && mcp_dump_from_image(img, NULL, &dump)) mcp_error_clear();
        Py_END_ALLOW_THREADS Py_DECREF(path);
        if (rc) return mcp_py_fail_int();
        int idx[3];
        rc = dump ? mcp_image_copy(dump->color, &c->color[i].img) ||
                        copy_or_null(dump->albedo, &c->albedo[i]) ||
                        copy_or_null(dump->normal, &c->normal[i])
                  : mcp_rgb_channels(img, idx) ||
                        mcp_image_copy_channels(img, idx, 3, &c->color[i].img);
        mcp_image_free(img);
        mcp_dump_free(dump);
        return rc ? (PyErr_Occurred() ? -1 : mcp_py_fail_int()) : 0;
    }
    if (mcp_py_dump_get(obj, what, &d)) return -1;
    int rc = mcp_image_copy(d.dump->color, &c->color[i].img) ||
             copy_or_null(d.dump->albedo, &c->albedo[i]) ||
             copy_or_null(d.dump->normal, &c->normal[i]);
    mcp_py_dump_release(&d);
    return rc ? (PyErr_Occurred() ? -1 : mcp_py_fail_int()) : 0;
}

/* The mean of a feature over the candidates, when every one has it. */
static int
feature_mean(mcp_image **parts, int m, mcp_image **out)
{
    *out = NULL;
    for (int i = 0; i < m; i++)
        if (!parts[i]) return 0;
    return mcp_perc_mean((const mcp_image *const *)parts, m, out);
}

static int
add_number(PyObject *d, const char *key, double v)
{
    return mcp_py_set(d, key, isfinite(v) ? PyFloat_FromDouble(v) : Py_NewRef(Py_None));
}

static int
add_scores(PyObject *d, const char *prefix, const mcp_perc_scores *s, int with_ref)
{
    char key[128];
    snprintf(key, sizeof key, "%senergy", prefix);
    if (add_number(d, key, s->energy)) return -1;
    if (!with_ref) return 0;
    snprintf(key, sizeof key, "%spmse", prefix);
    if (add_number(d, key, s->pmse)) return -1;
    snprintf(key, sizeof key, "%smse", prefix);
    if (add_number(d, key, s->mse)) return -1;
    snprintf(key, sizeof key, "%slow_freq_fraction", prefix);
    return add_number(d, key, s->low_freq_fraction);
}

/* A user kernel: separable taps (an odd-length sequence of numbers) or a 2D array. */
static int
user_kernel(PyObject *k, double **taps, mcp_perc_model *model)
{
    PyArrayObject *a = (PyArrayObject *)PyArray_FROMANY(
        k, NPY_FLOAT64, 1, 2, NPY_ARRAY_IN_ARRAY | NPY_ARRAY_FORCECAST);
    if (!a) return -1;
    int nd = PyArray_NDIM(a);
    npy_intp h = nd == 2 ? PyArray_DIM(a, 0) : PyArray_DIM(a, 0);
    npy_intp w = nd == 2 ? PyArray_DIM(a, 1) : PyArray_DIM(a, 0);
    if (h % 2 == 0 || w % 2 == 0 || h > 1025 || w > 1025) {
        PyErr_Format(mcp_py_error,
                     "kernel: needs an odd number of taps per side (got %zd x %zd)",
                     (Py_ssize_t)h, (Py_ssize_t)w);
        Py_DECREF(a);
        return -1;
    }
    const double *v = PyArray_DATA(a);
    double *t = malloc((size_t)w * h * sizeof *t);
    if (!t) {
        Py_DECREF(a);
        PyErr_NoMemory();
        return -1;
    }
    for (npy_intp y = 0; y < h; y++)
        for (npy_intp x = 0; x < w; x++)
            t[y * w + x] = nd == 2 ? v[y * w + x] : v[y] * v[x]; /* outer product */
    Py_DECREF(a);
    *taps = t;
    model->user_kernel = t;
    model->user_kernel_width = (int)w;
    model->user_kernel_height = (int)h;
    return 0;
}

static PyObject *
py_perceptual(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    /* the keywords are perceptual's table (ops/op_perceptual.c); these are read here:
       the candidates, the images and the denoiser, and what takes an array as well as
       a word or a number (surrogate, confidence, kernel) */
    static const char *const own[] = {"candidates", "surrogate", "reference",  "denoiser",
                                      "albedo",     "normal",    "confidence", "kernel",
                                      "mask",       NULL};
    PyObject *vals[9], *list = NULL, *keep = PyList_New(0);
    mcp_perceptual_settings st;
    if (!keep) return NULL;
    int bad = mcp_py_settings(mcp_operation_perceptual(), "perceptual", kw, own, vals,
                              &st, keep) ||
              mcp_py_positionals("perceptual", own, 1, args, vals, &list);
    Py_DECREF(keep); /* no text of the settings is used below */
    if (bad) return NULL;
    mcp_perc_options o = st.opt;
    int spectra_tile = st.spectra_tile;
    PyObject *surr_obj = vals[1], *ref_obj = vals[2] ? vals[2] : Py_None,
             *den_obj = vals[3] ? vals[3] : Py_None,
             *alb_obj = vals[4] ? vals[4] : Py_None,
             *nrm_obj = vals[5] ? vals[5] : Py_None, *conf_obj = vals[6],
             *kernel = vals[7], *mask_obj = vals[8] ? vals[8] : Py_None;
    if (surr_obj == Py_None) surr_obj = NULL; /* None: the default */
    if (conf_obj == Py_None) conf_obj = NULL;
    if (kernel == Py_None) kernel = NULL;
    double *taps = NULL;
    cands c = {0};
    mcp_py_image ref = {0}, surr_in = {0}, conf = {0}, alb = {0}, nrm = {0}, mask = {0};
    mcp_image *albedo = NULL, *normal = NULL, *mean = NULL, *surr_own = NULL,
              *spec = NULL;
    mcp_denoiser *den = NULL;
    mcp_perc_result res = {0};
    PyObject *result = NULL, *fast = NULL;
    if (kernel) {
        if (PyUnicode_Check(kernel)) {
            if (mcp_pkernel_kind_from_name(PyUnicode_AsUTF8(kernel),
                                           &o.model.kernel.kind)) {
                mcp_py_fail();
                goto done;
            }
        } else if (user_kernel(kernel, &taps, &o.model)) {
            goto done;
        }
    }
    if (conf_obj && (PyFloat_Check(conf_obj) || PyLong_Check(conf_obj))) {
        o.model.confidence = PyFloat_AsDouble(conf_obj);
    } else if (conf_obj) {
        if (mcp_py_image_get(conf_obj, "confidence", 1, NULL, &conf)) goto done;
        o.model.confidence_map = conf.img;
    }
    if (mcp_py_image_opt(mask_obj, "mask", 1, NULL, &mask)) goto done;
    o.mask_image = mask.img;
    if (mcp_perc_check(&o)) {
        mcp_py_fail();
        goto done;
    }
    if (!(fast = PySequence_Fast(list, "candidates must be a list of images or dumps")))
        goto done;
    c.m = (int)PySequence_Fast_GET_SIZE(fast);
    if (c.m < 1) {
        PyErr_SetString(mcp_py_error, "perceptual: no candidates given");
        c.m = 0;
        goto done;
    }
    c.color = PyMem_Calloc((size_t)c.m, sizeof *c.color);
    c.albedo = PyMem_Calloc((size_t)c.m, sizeof *c.albedo);
    c.normal = PyMem_Calloc((size_t)c.m, sizeof *c.normal);
    if (!c.color || !c.albedo || !c.normal) {
        PyErr_NoMemory();
        goto done;
    }
    for (int i = 0; i < c.m; i++) {
        char what[40];
        snprintf(what, sizeof what, "candidates[%d]", i);
        if (get_candidate(PySequence_Fast_GET_ITEM(fast, i), what, &c, i)) goto done;
    }
    const mcp_image **cc = PyMem_Calloc((size_t)c.m, sizeof *cc);
    if (!cc) {
        PyErr_NoMemory();
        goto done;
    }
    for (int i = 0; i < c.m; i++)
        cc[i] = c.color[i].img;
    /* the surrogate: "denoise" (the default), "reference", or an image */
    const char *surr_name = surr_obj && PyUnicode_Check(surr_obj)
                                ? PyUnicode_AsUTF8(surr_obj)
                            : surr_obj ? NULL
                                       : "denoise";
    if (mcp_py_image_opt(ref_obj, "reference", 0, NULL, &ref) ||
        mcp_py_image_opt(alb_obj, "albedo", 3, NULL, &alb) ||
        mcp_py_image_opt(nrm_obj, "normal", 3, (const char *const[]){"X", "Y", "Z"},
                         &nrm))
        goto done_cc;
    if (surr_name && strcmp(surr_name, "denoise") && strcmp(surr_name, "reference")) {
        PyErr_Format(mcp_py_error,
                     "surrogate must be 'denoise', 'reference' or an image (got '%s')",
                     surr_name);
        goto done_cc;
    }
    if (!surr_name && mcp_py_image_get(surr_obj, "surrogate", 0, NULL, &surr_in))
        goto done_cc;
    if (surr_name && !strcmp(surr_name, "reference") && !ref.img) {
        PyErr_SetString(mcp_py_error,
                        "perceptual: surrogate 'reference' needs a reference");
        goto done_cc;
    }
    int denoising = surr_name && !strcmp(surr_name, "denoise");
    if (denoising && mcp_py_denoiser_arg(den_obj, &den)) goto done_cc;
    int rc;
    mcp_perc_scores sc, sm;
    Py_BEGIN_ALLOW_THREADS rc =
        mcp_perc_mean(cc, c.m, &mean) ||
        (!alb.img && feature_mean(c.albedo, c.m, &albedo)) ||
        (!nrm.img && feature_mean(c.normal, c.m, &normal)) ||
        (denoising &&
         mcp_perc_surrogate_denoise(cc, c.m, alb.img ? alb.img : albedo,
                                    nrm.img ? nrm.img : normal, den, &surr_own));
    const mcp_image *surr = denoising ? surr_own : surr_in.img ? surr_in.img : ref.img;
    if (!rc) rc = mcp_perc_optimize(cc, c.m, surr, &o, &res);
    if (!rc)
        rc = mcp_perc_score(res.image, surr, mean, ref.img, &o.model, spectra_tile, &sc,
                            &spec) ||
             mcp_perc_score(mean, surr, mean, ref.img, &o.model, spectra_tile, &sm, NULL);
    Py_END_ALLOW_THREADS if (mcp_py_check_signals()) goto done_cc;
    if (rc) {
        mcp_py_fail();
        goto done_cc;
    }
    PyObject *d = PyDict_New();
    mcp_image *image = res.image, *index = res.index, *perm = res.permutation;
    res.image = res.index = res.permutation = NULL;
    int with_ref = ref.img != NULL;
    if (!d ||
        mcp_py_set(d, "method", PyUnicode_FromString(mcp_perc_method_name(o.method))) ||
        mcp_py_set(d, "candidates", PyLong_FromLong(c.m)) ||
        mcp_py_set(d, "image", mcp_py_array(image)) ||
        mcp_py_set(d, "index", mcp_py_array(index)) ||
        mcp_py_set(d, "permutation", mcp_py_array(perm)) ||
        mcp_py_set(d, "surrogate",
                   surr_own
                       ? mcp_py_array(surr_own)
                       : PyUnicode_FromString(surr_in.img ? "image" : "reference")) ||
        mcp_py_set(d, "passes", PyLong_FromLong(res.passes)) ||
        mcp_py_set(d, "changes", PyLong_FromLong(res.changes)) ||
        add_number(d, "seconds", res.seconds) ||
        add_number(d, "energy_initial", res.energy_initial) ||
        add_number(d, "energy_final", res.energy_final) ||
        add_scores(d, "", &sc, with_ref) || add_scores(d, "mean_", &sm, with_ref) ||
        (with_ref && (add_number(d, "pmse_ratio", sc.pmse / sm.pmse) ||
                      add_number(d, "white_fraction", sc.white_fraction))) ||
        mcp_py_set(d, "spectrum", mcp_py_array(spec))) {
        surr_own = spec = NULL; /* taken over (or freed) above */
        Py_XDECREF(d);
        goto done_cc;
    }
    surr_own = spec = NULL;
    result = d;
done_cc:
    PyMem_Free(cc);
done:
    mcp_perc_result_free(&res);
    mcp_image_free(mean), mcp_image_free(albedo), mcp_image_free(normal);
    mcp_image_free(surr_own), mcp_image_free(spec);
    mcp_denoiser_free(den);
    cands_free(&c);
    mcp_py_image_release(&ref), mcp_py_image_release(&surr_in),
        mcp_py_image_release(&conf);
    mcp_py_image_release(&alb), mcp_py_image_release(&nrm), mcp_py_image_release(&mask);
    Py_XDECREF(fast);
    free(taps);
    return result;
}

PyMethodDef mcp_py_perceptual_methods[] = {
    {"perceptual", (PyCFunction)(void (*)(void))py_perceptual,
     METH_VARARGS | METH_KEYWORDS,
     "Perceptual error optimisation (Chizhov et al. 2022) of M candidate renders\n"
     "(arrays, dump dicts or paths): 'image', 'index' (vertical methods) or\n"
     "'permutation' (horizontal), 'surrogate', 'energy' and with a reference 'pmse',\n"
     "'mse', 'low_freq_fraction', the same for the candidates' mean ('mean_*'),\n"
     "'pmse_ratio'. surrogate is 'denoise', 'reference' or an image; confidence a\n"
     "number or an H x W map; kernel 'tap3', 'gaussian', odd taps or a 2D array."},
    {NULL, NULL, 0, NULL}};
