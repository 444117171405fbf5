/* metrics.c: how far a test image is from a reference (common/metrics/metrics.h) -- mse,
 * relmse, psnr, pmse, flip (the mean and the map), flip_stats, relse_percentiles,
 * blue_noise, and metrics(), every figure at once in the CLI's JSON layout. The first
 * image is the test image, the second the reference, as everywhere in mcpost. */
#include "internal.h"

#include <mcpost/imageio.h>
#include <mcpost/metrics.h>
#include <mcpost/tonemap.h>

#include <math.h>

/* The two images of every metric; 0 or -1 with an exception. */
static int
get_pair(PyObject *test, PyObject *ref, mcp_py_image *t, mcp_py_image *r)
{
    if (mcp_py_image_get(test, "test", 0, NULL, t)) return -1;
    if (mcp_py_image_get(ref, "ref", 0, NULL, r)) {
        mcp_py_image_release(t);
        return -1;
    }
    return 0;
}

static void
release_pair(mcp_py_image *t, mcp_py_image *r)
{
    mcp_py_image_release(t);
    mcp_py_image_release(r);
}

static PyObject *
py_mse(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"test", "ref", NULL};
    PyObject *a, *b;
    mcp_py_image t, r;
    double v;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "OO:mse", keys, &a, &b) ||
        get_pair(a, b, &t, &r))
        return NULL;
    int rc = mcp_mse(t.img, r.img, &v);
    release_pair(&t, &r);
    return rc ? mcp_py_fail() : PyFloat_FromDouble(v);
}

static PyObject *
py_relmse(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"test", "ref", "eps_rel", NULL};
    PyObject *a, *b;
    double eps = MCP_EPS_REL, v;
    mcp_py_image t, r;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "OO|$d:relmse", keys, &a, &b, &eps) ||
        get_pair(a, b, &t, &r))
        return NULL;
    int rc = mcp_relmse(t.img, r.img, eps, &v);
    release_pair(&t, &r);
    return rc ? mcp_py_fail() : PyFloat_FromDouble(v);
}

static PyObject *
py_psnr(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"test", "ref", NULL};
    PyObject *a, *b;
    double v;
    mcp_py_image t, r;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "OO:psnr", keys, &a, &b) ||
        get_pair(a, b, &t, &r))
        return NULL;
    int rc = mcp_psnr(t.img, r.img, &v);
    release_pair(&t, &r);
    return rc ? mcp_py_fail() : PyFloat_FromDouble(v);
}

/* pMSE's keywords (the CLI's --pmse-* words) into o. */
static int
pmse_options(const char *kernel, double dpi, double distance_in, int filter_reference,
             const char *tone_map, mcp_pmse_options *o)
{
    *o = mcp_pmse_defaults();
    if ((kernel && mcp_pkernel_kind_from_name(kernel, &o->kernel.kind)) ||
        (tone_map && mcp_tonemap_from_name(tone_map, &o->tone_map)))
        return mcp_py_fail_int();
    if (dpi > 0) o->kernel.dpi = dpi;
    if (distance_in > 0) o->kernel.distance_in = distance_in;
    o->filter_reference = filter_reference;
    return 0;
}

static PyObject *
py_pmse(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"test",     "ref",         "kernel",
                           "dpi",      "distance_in", "filter_reference",
                           "tone_map", NULL};
    PyObject *a, *b;
    const char *kernel = NULL, *tone = NULL;
    double dpi = 0, dist = 0, v;
    int filter = 0;
    mcp_pmse_options o;
    mcp_py_image t, r;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "OO|$zddpz:pmse", keys, &a, &b, &kernel,
                                     &dpi, &dist, &filter, &tone) ||
        pmse_options(kernel, dpi, dist, filter, tone, &o) || get_pair(a, b, &t, &r))
        return NULL;
    int rc;
    Py_BEGIN_ALLOW_THREADS rc = mcp_pmse(t.img, r.img, &o, &v);
    Py_END_ALLOW_THREADS release_pair(&t, &r);
    if (mcp_py_check_signals()) return NULL;
    return rc ? mcp_py_fail() : PyFloat_FromDouble(v);
}

/* FLIP's keywords (the CLI's words) into o. */
static int
flip_options(double ppd, double distance_m, double width_m, double width_px,
             const char *tone_mapper, double start, double stop, int num,
             mcp_flip_options *o)
{
    *o = mcp_flip_defaults();
    if (tone_mapper && mcp_tonemap_from_name(tone_mapper, &o->tone_mapper))
        return mcp_py_fail_int();
    o->ppd = ppd;
    if (distance_m > 0) o->distance_m = distance_m;
    if (width_m > 0) o->display_width_m = width_m;
    if (width_px > 0) o->display_width_px = width_px;
    o->start_exposure = start;
    o->stop_exposure = stop;
    o->num_exposures = num;
    return 0;
}

/* A copy of img with its R, G, B channels (by name) decoded from sRGB to linear. */
static int
srgb_decoded(const mcp_image *img, mcp_image **out)
{
    int rgb[3];
    if (mcp_rgb_channels(img, rgb) || mcp_image_copy(img, out)) return -1;
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++) {
            float *p = mcp_image_px(*out, x, y);
            for (int k = 0; k < 3; k++)
                p[rgb[k]] = mcp_srgb_to_linear(p[rgb[k]]);
        }
    return 0;
}

static PyObject *
py_flip(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"test",
                           "ref",
                           "hdr",
                           "ppd",
                           "distance_m",
                           "display_width_m",
                           "display_width_px",
                           "tone_mapper",
                           "start_exposure",
                           "stop_exposure",
                           "num_exposures",
                           "exposure_map",
                           "srgb",
                           NULL};
    PyObject *a, *b;
    int hdr = 0, num = 0, want_exposure = 0, srgb = 0;
    double ppd = 0, dist = 0, wm = 0, wpx = 0, start = NAN, stop = NAN;
    const char *tm = NULL;
    mcp_flip_options o;
    mcp_py_image t, r;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "OO|$pddddzddipp:flip", keys, &a, &b, &hdr,
                                     &ppd, &dist, &wm, &wpx, &tm, &start, &stop, &num,
                                     &want_exposure, &srgb) ||
        flip_options(ppd, dist, wm, wpx, tm, start, stop, num, &o) ||
        get_pair(a, b, &t, &r))
        return NULL;
    if (srgb && hdr) {
        release_pair(&t, &r);
        PyErr_SetString(mcp_py_error,
                        "flip: srgb=True is for LDR-FLIP (HDR input is linear)");
        return NULL;
    }
    /* srgb: the arrays are sRGB-encoded, as NVIDIA's flip takes them (inputsRGB); the
       library's FLIP wants linear colour, so decode copies */
    mcp_image *lin_t = NULL, *lin_r = NULL;
    if (srgb && (srgb_decoded(t.img, &lin_t) || srgb_decoded(r.img, &lin_r))) {
        mcp_image_free(lin_t);
        release_pair(&t, &r);
        return mcp_py_fail();
    }
    const mcp_image *ti = lin_t ? lin_t : t.img, *ri = lin_r ? lin_r : r.img;
    mcp_flip_result res;
    mcp_image *map = NULL, *exposure = NULL;
    int rc;
    Py_BEGIN_ALLOW_THREADS rc =
        hdr ? mcp_flip_hdr(ti, ri, &o, &res, &map, want_exposure ? &exposure : NULL)
            : mcp_flip_ldr(ti, ri, &o, &res, &map);
    Py_END_ALLOW_THREADS mcp_image_free(lin_t);
    mcp_image_free(lin_r);
    release_pair(&t, &r);
    if (mcp_py_check_signals()) {
        mcp_image_free(map);
        mcp_image_free(exposure);
        return NULL;
    }
    if (rc) return mcp_py_fail();
    if (hdr && want_exposure)
        return Py_BuildValue("(dNN)", res.mean, mcp_py_array(map),
                             mcp_py_array(exposure));
    return Py_BuildValue("(dN)", res.mean, mcp_py_array(map));
}

static PyObject *
py_relse_percentiles(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"test", "ref", "percentiles", "eps_rel", NULL};
    PyObject *a, *b, *plist = NULL;
    double eps = MCP_EPS_REL;
    double p[MCP_METRICS_MAX_PERCENTILES] = {0.5, 0.9, 0.99},
           v[MCP_METRICS_MAX_PERCENTILES];
    int n = 3;
    mcp_py_image t, r;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "OO|$Od:relse_percentiles", keys, &a, &b,
                                     &plist, &eps) ||
        (plist &&
         mcp_py_doubles(plist, "percentiles", p, MCP_METRICS_MAX_PERCENTILES, &n)))
        return NULL;
    for (int k = 0; k < n; k++)
        if (!(p[k] >= 0 && p[k] <= 1)) {
            PyErr_Format(mcp_py_error, "percentiles: %g is not in [0, 1]", p[k]);
            return NULL;
        }
    if (get_pair(a, b, &t, &r)) return NULL;
    mcp_image *relse = NULL;
    int rc;
    Py_BEGIN_ALLOW_THREADS rc =
        mcp_relse_map(t.img, r.img, eps, &relse) || mcp_image_percentiles(relse, p, n, v);
    Py_END_ALLOW_THREADS mcp_image_free(relse);
    release_pair(&t, &r);
    return rc ? mcp_py_fail() : mcp_py_vector(v, n);
}

static PyObject *
py_relse_map(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"test", "ref", "eps_rel", NULL};
    PyObject *a, *b;
    double eps = MCP_EPS_REL;
    mcp_py_image t, r;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "OO|$d:relse_map", keys, &a, &b, &eps) ||
        get_pair(a, b, &t, &r))
        return NULL;
    mcp_image *relse = NULL;
    int rc = mcp_relse_map(t.img, r.img, eps, &relse);
    release_pair(&t, &r);
    return rc ? mcp_py_fail() : mcp_py_array(relse);
}

static PyObject *
py_blue_noise(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"test", "ref", "tile_size", "cutoff", "tone_map", NULL};
    PyObject *a, *b;
    mcp_spectra_options o = mcp_spectra_defaults();
    const char *tone = NULL;
    mcp_py_image t, r;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "OO|$idz:blue_noise", keys, &a, &b,
                                     &o.tile_size, &o.cutoff, &tone))
        return NULL;
    if (tone && mcp_tonemap_from_name(tone, &o.tone_map)) return mcp_py_fail();
    if (get_pair(a, b, &t, &r)) return NULL;
    mcp_spectra_result res;
    mcp_image *picture = NULL;
    int rc;
    Py_BEGIN_ALLOW_THREADS rc = mcp_spectra_blue_noise(t.img, r.img, &o, &res, &picture);
    Py_END_ALLOW_THREADS release_pair(&t, &r);
    if (rc) return mcp_py_fail();
    PyObject *d = PyDict_New();
    if (!d || mcp_py_set(d, "low_fraction", PyFloat_FromDouble(res.low_fraction)) ||
        mcp_py_set(d, "white_fraction", PyFloat_FromDouble(res.white_fraction)) ||
        mcp_py_set(d, "energy", PyFloat_FromDouble(res.energy)) ||
        mcp_py_set(d, "tile_size", PyLong_FromLong(res.tile_size)) ||
        mcp_py_set(d, "tiles", Py_BuildValue("(ii)", res.tiles_x, res.tiles_y)) ||
        mcp_py_set(d, "spectrum", mcp_py_array(picture))) {
        Py_XDECREF(d);
        return NULL;
    }
    return d;
}

/* cJSON into Python: numbers become floats, "inf" (how the library writes an infinite
 * figure) float('inf'). */
static PyObject *
from_json(const cJSON *j)
{
    if (cJSON_IsNumber(j)) return PyFloat_FromDouble(j->valuedouble);
    if (cJSON_IsBool(j)) return PyBool_FromLong(cJSON_IsTrue(j));
    if (cJSON_IsString(j))
        return !strcmp(j->valuestring, "inf") ? PyFloat_FromDouble(INFINITY)
                                              : PyUnicode_FromString(j->valuestring);
    if (cJSON_IsArray(j)) {
        PyObject *l = PyList_New(0);
        const cJSON *it;
        cJSON_ArrayForEach(it, j)
        {
            PyObject *v = from_json(it);
            if (!l || !v || PyList_Append(l, v)) {
                Py_XDECREF(v);
                Py_XDECREF(l);
                return NULL;
            }
            Py_DECREF(v);
        }
        return l;
    }
    if (cJSON_IsObject(j)) {
        PyObject *d = PyDict_New();
        const cJSON *it;
        cJSON_ArrayForEach(it, j)
        {
            if (!d || mcp_py_set(d, it->string, from_json(it))) {
                Py_XDECREF(d);
                return NULL;
            }
        }
        return d;
    }
    Py_RETURN_NONE;
}

/* FLIP's statistics of a map (flip.h: NVIDIA's tool's definitions). */
static PyObject *
py_flip_stats(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    static char *keys[] = {"map", NULL};
    PyObject *a;
    mcp_py_image m;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "O:flip_stats", keys, &a) ||
        mcp_py_image_get(a, "map", 1, (const char *const[]){"FLIP"}, &m))
        return NULL;
    size_t n = (size_t)m.img->width * m.img->height, k = 0;
    float *v = PyMem_Malloc(n ? n * sizeof *v : 1);
    if (!v) {
        mcp_py_image_release(&m);
        return PyErr_NoMemory();
    }
    for (int y = 0; y < m.img->height; y++) /* row-major: the order the tool sums in */
        for (int x = 0; x < m.img->width; x++)
            v[k++] = mcp_image_px(m.img, x, y)[0];
    mcp_py_image_release(&m);
    mcp_flip_stats st;
    int rc;
    Py_BEGIN_ALLOW_THREADS rc = mcp_flip_statistics(v, n, &st);
    Py_END_ALLOW_THREADS PyMem_Free(v);
    if (rc) return mcp_py_fail();
    PyObject *counts = PyList_New(MCP_FLIP_HISTOGRAM_BUCKETS),
             *weighted = PyList_New(MCP_FLIP_HISTOGRAM_BUCKETS);
    for (int i = 0; counts && weighted && i < MCP_FLIP_HISTOGRAM_BUCKETS; i++) {
        PyList_SET_ITEM(counts, i, PyLong_FromLongLong(st.histogram[i]));
        PyList_SET_ITEM(weighted, i,
                        PyFloat_FromDouble(mcp_flip_weighted_bucket(&st, i)));
    }
    if (!counts || !weighted) {
        Py_XDECREF(counts);
        Py_XDECREF(weighted);
        return NULL;
    }
    return Py_BuildValue("{s:d,s:d,s:d,s:d,s:d,s:N,s:N}", "weighted_median",
                         st.weighted_median, "weighted_q1", st.weighted_q1, "weighted_q3",
                         st.weighted_q3, "min", st.min, "max", st.max, "histogram",
                         counts, "weighted_histogram", weighted);
}

/* pixels_above=[(map, threshold), ...] into the options. */
static int
above_options(PyObject *list, mcp_metrics_options *o)
{
    PyObject *seq =
        PySequence_Fast(list, "pixels_above: want a list of (map, threshold)");
    if (!seq) return -1;
    for (Py_ssize_t i = 0; i < PySequence_Fast_GET_SIZE(seq); i++) {
        const char *name;
        double t;
        mcp_above_map map;
        if (!PyArg_ParseTuple(PySequence_Fast_GET_ITEM(seq, i), "sd:pixels_above", &name,
                              &t)) {
            Py_DECREF(seq);
            return -1;
        }
        if (mcp_above_map_from_name(name, &map) || mcp_metrics_add_above(o, map, t)) {
            Py_DECREF(seq);
            mcp_py_fail();
            return -1;
        }
    }
    Py_DECREF(seq);
    return 0;
}

static PyObject *
py_metrics(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    /* the keywords are the metrics' table (ops/op_metrics.c); these are read here: the
       two images, maps (return them) and pixels_above */
    static const char *const own[] = {"test", "ref", "maps", "pixels_above", NULL};
    PyObject *vals[4], *pair_args[2], *keep = PyList_New(0);
    mcp_metrics_settings st;
    if (!keep) return NULL;
    int bad =
        mcp_py_settings(mcp_operation_metrics(), "metrics", kw, own, vals, &st, keep) ||
        mcp_py_positionals("metrics", own, 2, args, vals, pair_args);
    Py_DECREF(keep); /* no text of the settings is used below */
    if (bad) return NULL;
    PyObject *a = pair_args[0], *b = pair_args[1], *above = vals[3];
    mcp_metrics_options o = st.o;
    int want_maps = vals[2] ? PyObject_IsTrue(vals[2]) : 0;
    if (want_maps < 0) return NULL;
    if (above && above != Py_None && above_options(above, &o)) return NULL;
    mcp_py_image t, r;
    if (get_pair(a, b, &t, &r)) return NULL;
    mcp_metrics m;
    mcp_metrics_maps maps = {0};
    int rc;
    Py_BEGIN_ALLOW_THREADS rc =
        mcp_metrics_compute(t.img, r.img, &o, &m, want_maps ? &maps : NULL);
    Py_END_ALLOW_THREADS release_pair(&t, &r);
    PyObject *result = NULL;
    cJSON *doc = NULL;
    if (mcp_py_check_signals()) goto done;
    if (rc || !(doc = cJSON_CreateObject()) || mcp_metrics_json(&m, &o, doc)) {
        mcp_py_fail();
        goto done;
    }
    result = from_json(doc);
    if (result && want_maps) {
        PyObject *md = PyDict_New();
        mcp_image **items[] = {&maps.sq_error,          &maps.relse,
                               &maps.flip_ldr,          &maps.flip_hdr,
                               &maps.flip_hdr_exposure, &maps.spectra};
        static const char *const names[] = {
            "sq_error", "relse", "flip_ldr", "flip_hdr", "flip_hdr_exposure", "spectra"};
        for (int i = 0; md && i < 6; i++) {
            mcp_image *img = *items[i];
            *items[i] = NULL;
            if (mcp_py_set(md, names[i], mcp_py_array(img))) Py_CLEAR(md);
        }
        PyObject *pair = md ? Py_BuildValue("(NN)", result, md) : NULL;
        if (!pair) Py_CLEAR(result);
        result = pair;
    }
done:
    cJSON_Delete(doc);
    mcp_metrics_maps_free(&maps);
    return result;
}

#define KW (METH_VARARGS | METH_KEYWORDS)
#define FN(f) (PyCFunction)(void (*)(void))(f)
PyMethodDef mcp_py_metrics_methods[] = {
    {"mse", FN(py_mse), KW, "mse(test, ref) -> float: mean (t - r)^2 over R, G, B"},
    {"relmse", FN(py_relmse), KW,
     "relmse(test, ref, *, eps_rel=0.01) -> float: mean (t - r)^2 / (r^2 + eps_rel)"},
    {"psnr", FN(py_psnr), KW,
     "psnr(test, ref) -> float: PSNR of the displayed images (clamped to [0, 1], sRGB),\n"
     "inf for identical displays"},
    {"pmse", FN(py_pmse), KW,
     "pmse(test, ref, *, kernel='tap3', dpi=300, distance_in=16, "
     "filter_reference=False,\n"
     "     tone_map='clamp') -> float: perceptual MSE (Chizhov et al. 2022)"},
    {"flip", FN(py_flip), KW,
     "flip(test, ref, *, hdr=False, ppd=0, distance_m=0.7, display_width_m=0.7,\n"
     "     display_width_px=3840, tone_mapper='aces', start_exposure=nan,\n"
     "     stop_exposure=nan, num_exposures=0, exposure_map=False, srgb=False)\n"
     "    -> (mean, map)\n\n"
     "LDR-FLIP, or HDR-FLIP with hdr=True, as NVIDIA FLIP v1.6 computes them; the map\n"
     "is H x W. Arrays are linear; for LDR-FLIP srgb=True takes sRGB-encoded ones, as\n"
     "NVIDIA's Python API does (inputsRGB). ppd 0 takes it from the viewing condition;\n"
     "nan exposures are automatic. With hdr and exposure_map=True: (mean, map,\n"
     "exposure map)."},
    {"relse_percentiles", FN(py_relse_percentiles), KW,
     "relse_percentiles(test, ref, *, percentiles=(0.5, 0.9, 0.99), eps_rel=0.01)\n"
     "    -> ndarray: RelSE = (t - r)^2 / (maxc(t)^2 + eps_rel) at each p (nearest "
     "rank)"},
    {"relse_map", FN(py_relse_map), KW,
     "relse_map(test, ref, *, eps_rel=0.01) -> ndarray H x W x 3: RelSE per value"},
    {"blue_noise", FN(py_blue_noise), KW,
     "blue_noise(test, ref, *, tile_size=32, cutoff=0.25, tone_map='clamp') -> dict\n\n"
     "The low-frequency energy fraction of the error (low_fraction; white_fraction is\n"
     "what white noise gives), its energy, and the tiled spectrum picture."},
    {"metrics", FN(py_metrics), KW,
     "Every figure of `mcpost metrics --json`, with its keys and keywords: FLIP's\n"
     "statistics beside each mean, the histogram counts in flip_histogram, and with\n"
     "pixels_above=[('flip_ldr', 0.1), ('relse', 0.5)] the percentage of pixels above\n"
     "each threshold (pixels_above). maps=True returns the maps too: sq_error, relse,\n"
     "flip_ldr, flip_hdr, flip_hdr_exposure, spectra."},
    {"flip_stats", FN(py_flip_stats), KW,
     "flip_stats(map) -> dict: FLIP's statistics of an H x W map as NVIDIA's tool\n"
     "defines them: weighted_median, weighted_q1, weighted_q3 (each pixel weighted by\n"
     "its error), min, max, histogram (100 counts over [0, 1]) and weighted_histogram\n"
     "(count x bucket centre per megapixel, what the tool plots)."},
    {NULL, NULL, 0, NULL}};
