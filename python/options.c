/* options.c: keyword arguments read through an operation's table (<mcpost/options.h>),
 * and the docstrings written from it. A keyword's value becomes the text the command
 * line would give (repr of a number, "true"/"false", the word, "a,b,c") and goes
 * through mcp_operation_set, so Python accepts and refuses what the CLI and job files
 * do, with the same messages (docs/python.md). */
#include "internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* str(value) or repr(value) as a new bytes-free C string in buf; -1 with an exception */
static int
text_of(PyObject *v, int use_repr, char *buf, size_t cap)
{
    PyObject *s = use_repr ? PyObject_Repr(v) : PyObject_Str(v);
    if (!s) return -1;
    const char *u = PyUnicode_AsUTF8(s);
    if (!u) {
        Py_DECREF(s);
        return -1;
    }
    snprintf(buf, cap, "%s", u);
    Py_DECREF(s);
    return 0;
}

static int
is_number(PyObject *v)
{
    return !PyBool_Check(v) && (PyLong_Check(v) || PyFloat_Check(v));
}

static int
type_error(const char *fn, const char *key, const char *want)
{
    PyErr_Format(PyExc_TypeError, "%s(): %s must be %s", fn, key, want);
    return -1;
}

/* The text of one keyword's value, into buf (or *held for a path: the bytes object,
 * kept alive by the caller while the settings borrow it). */
static int
value_text(const char *fn, const mcp_option *o, PyObject *v, char *buf, size_t cap,
           PyObject **held, const char **text)
{
    *text = buf;
    switch (o->type) {
    case MCP_OPT_NUMBER:
        if (o->auto_word && PyUnicode_Check(v)) return text_of(v, 0, buf, cap);
        if (!is_number(v))
            return type_error(fn, o->name,
                              o->auto_word ? "a number or 'auto'" : "a number");
        return text_of(v, 1, buf, cap);
    case MCP_OPT_INT:
        if (o->auto_word && PyUnicode_Check(v)) return text_of(v, 0, buf, cap);
        if (PyBool_Check(v) || !PyLong_Check(v))
            return type_error(fn, o->name, o->auto_word ? "an int or 'auto'" : "an int");
        return text_of(v, 0, buf, cap);
    case MCP_OPT_SEED:
        if (PyBool_Check(v) || !PyLong_Check(v)) return type_error(fn, o->name, "an int");
        return text_of(v, 0, buf, cap);
    case MCP_OPT_WHOLE:
        if (!is_number(v)) return type_error(fn, o->name, "a number");
        return text_of(v, 1, buf, cap);
    case MCP_OPT_FLAG: {
        if (!PyBool_Check(v) && !PyLong_Check(v))
            return type_error(fn, o->name, "True or False");
        int t = PyObject_IsTrue(v);
        if (t < 0) return -1;
        snprintf(buf, cap, "%s", t ? "true" : "false");
        return 0;
    }
    case MCP_OPT_ENUM:
        if (!PyUnicode_Check(v)) return type_error(fn, o->name, "a str");
        return text_of(v, 0, buf, cap);
    case MCP_OPT_LIST: {
        if (is_number(v)) return text_of(v, 1, buf, cap);
        PyObject *fast = PySequence_Fast(v, "");
        if (!fast) {
            PyErr_Clear();
            return type_error(fn, o->name, "a number or a sequence of numbers");
        }
        size_t n = 0;
        buf[0] = '\0';
        for (Py_ssize_t i = 0; i < PySequence_Fast_GET_SIZE(fast); i++) {
            PyObject *x = PySequence_Fast_GET_ITEM(fast, i);
            char one[64];
            if (!is_number(x)) {
                Py_DECREF(fast);
                return type_error(fn, o->name, "a sequence of numbers");
            }
            if (text_of(x, 1, one, sizeof one)) {
                Py_DECREF(fast);
                return -1;
            }
            n += (size_t)snprintf(buf + n, n < cap ? cap - n : 0, "%s%s", i ? "," : "",
                                  one);
        }
        Py_DECREF(fast);
        return 0;
    }
    case MCP_OPT_TEXT:
    case MCP_OPT_INPUT: {
        PyObject *b = mcp_py_path(v, o->name);
        if (!b) return -1;
        *held = b;
        *text = PyBytes_AS_STRING(b);
        return 0;
    }
    case MCP_OPT_WORDSET: {
        if (PyUnicode_Check(v)) return text_of(v, 0, buf, cap);
        PyObject *fast = PySequence_Fast(v, "");
        if (!fast) {
            PyErr_Clear();
            return type_error(fn, o->name, "a str or a sequence of str");
        }
        size_t n = 0;
        buf[0] = '\0';
        for (Py_ssize_t i = 0; i < PySequence_Fast_GET_SIZE(fast); i++) {
            PyObject *x = PySequence_Fast_GET_ITEM(fast, i);
            const char *w = PyUnicode_Check(x) ? PyUnicode_AsUTF8(x) : NULL;
            if (!w) {
                Py_DECREF(fast);
                return PyErr_Occurred() ? -1
                                        : type_error(fn, o->name, "a sequence of str");
            }
            n +=
                (size_t)snprintf(buf + n, n < cap ? cap - n : 0, "%s%s", i ? "," : "", w);
        }
        Py_DECREF(fast);
        return 0;
    }
    case MCP_OPT_TEXTS: /* one str here; a sequence is taken item by item */
        if (!PyUnicode_Check(v))
            return type_error(fn, o->name, "a str or a sequence of str");
        *text = PyUnicode_AsUTF8(v);
        return *text ? 0 : -1;
    case MCP_OPT_DENOISER:
        break;
    }
    return type_error(fn, o->name, "read by the function itself");
}

int
mcp_py_settings(const mcp_operation *op, const char *fn, PyObject *kw,
                const char *const *own, PyObject **own_values, void *settings,
                PyObject *keep)
{
    mcp_operation_defaults(op, settings);
    for (int k = 0; own && own[k]; k++)
        own_values[k] = NULL;
    PyObject *key, *value;
    Py_ssize_t pos = 0;
    while (kw && PyDict_Next(kw, &pos, &key, &value)) {
        const char *name = PyUnicode_AsUTF8(key);
        if (!name) return -1;
        int mine = 0;
        for (int k = 0; own && own[k] && !mine; k++)
            if (!strcmp(own[k], name)) {
                own_values[k] = value;
                mine = 1;
            }
        if (mine) continue;
        const mcp_option *o = mcp_operation_option(op, name);
        /* the table's spelling only: '-' is not a Python name */
        if (!o || strcmp(o->name, name) || !mcp_option_takes(o, MCP_OPT_PY)) {
            PyErr_Format(PyExc_TypeError, "%s() got an unexpected keyword argument '%s'",
                         fn, name);
            return -1;
        }
        if (value == Py_None) continue; /* None: the default */
        if (o->type == MCP_OPT_TEXTS && !PyUnicode_Check(value)) {
            PyObject *fast = PySequence_Fast(value, "");
            if (!fast) {
                PyErr_Clear();
                return type_error(fn, name, "a str or a sequence of str");
            }
            /* the items are borrowed by the settings: kept alive with them */
            int rc = PyList_Append(keep, fast);
            Py_DECREF(fast);
            for (Py_ssize_t i = 0; !rc && i < PySequence_Fast_GET_SIZE(fast); i++) {
                PyObject *x = PySequence_Fast_GET_ITEM(fast, i);
                const char *t = PyUnicode_Check(x) ? PyUnicode_AsUTF8(x) : NULL;
                if (!t)
                    return PyErr_Occurred() ? -1
                                            : type_error(fn, name, "a sequence of str");
                if (mcp_operation_set(op, o, name, t, settings)) return mcp_py_fail_int();
            }
            if (rc) return -1;
            continue;
        }
        char buf[2048];
        PyObject *held = NULL;
        const char *text = NULL;
        if (value_text(fn, o, value, buf, sizeof buf, &held, &text)) return -1;
        if (held) {
            int rc = PyList_Append(keep, held);
            Py_DECREF(held);
            if (rc) return -1;
        }
        if (mcp_operation_set(op, o, name, text, settings)) return mcp_py_fail_int();
    }
    return mcp_operation_finish(op, settings) ? mcp_py_fail_int() : 0;
}

/* ---- docstrings ---- */

/* How the default reads in Python: 'relse', 0.01, True, (0.5, 0.9), None. */
static void
python_default(const mcp_option *o, char *buf, size_t cap)
{
    const char *def = o->def;
    char *end = NULL;
    if (o->type == MCP_OPT_INPUT || !def) {
        snprintf(buf, cap, "None");
    } else if (o->type == MCP_OPT_TEXT || o->type == MCP_OPT_TEXTS) {
        /* a number as a number (confidence=1), a word as a str (surrogate='denoise') */
        (void)strtod(def, &end);
        snprintf(buf, cap, end != def && !*end ? "%s" : "'%s'", def);
    } else if (o->type == MCP_OPT_ENUM || o->type == MCP_OPT_DENOISER ||
               o->type == MCP_OPT_WORDSET ||
               ((o->type == MCP_OPT_INT || o->type == MCP_OPT_NUMBER) && o->auto_word &&
                !strcmp(def, o->auto_word))) {
        snprintf(buf, cap, "'%s'", def);
    } else if (o->type == MCP_OPT_FLAG) {
        snprintf(buf, cap, "%s", strcmp(def, "true") ? "False" : "True");
    } else if (o->type == MCP_OPT_LIST) {
        size_t n = (size_t)snprintf(buf, cap, "(");
        for (const char *p = def; *p && n + 2 < cap; p++) {
            buf[n++] = *p;
            if (*p == ',') buf[n++] = ' ';
        }
        snprintf(buf + n, cap - n, ")");
    } else {
        snprintf(buf, cap, "%s", def);
    }
}

int
mcp_py_positionals(const char *fn, const char *const *names, int n, PyObject *args,
                   PyObject *const *own_values, PyObject **out)
{
    Py_ssize_t given = PyTuple_GET_SIZE(args);
    if (given > n) {
        PyErr_Format(PyExc_TypeError,
                     "%s() takes %d positional arguments but %zd were given", fn, n,
                     given);
        return -1;
    }
    for (int i = 0; i < n; i++) {
        out[i] = i < given ? PyTuple_GET_ITEM(args, i) : own_values[i];
        if (i < given && own_values[i]) {
            PyErr_Format(PyExc_TypeError, "%s() got multiple values for argument '%s'",
                         fn, names[i]);
            return -1;
        }
        if (!out[i]) {
            PyErr_Format(PyExc_TypeError, "%s() missing required argument '%s'", fn,
                         names[i]);
            return -1;
        }
    }
    return 0;
}

/* 1 when name is one of the words of "a, b, c" */
static int
in_list(const char *list, const char *name)
{
    size_t len = strlen(name);
    for (const char *p = list; (p = strstr(p, name)); p += len)
        if ((p == list || p[-1] == ' ') && (p[len] == ',' || p[len] == '\0')) return 1;
    return 0;
}

char *
mcp_py_doc(const mcp_operation *op, const char *fn, const char *positional,
           const char *extras, const char *returns, const char *prose)
{
    size_t cap = 16384, n = 0, line = 0;
    char *doc = malloc(cap);
    if (!doc) return NULL;
    n += (size_t)snprintf(doc, cap, "%s(%s, *", fn, positional);
    line = n;
    for (const mcp_option *o = op->options; o->name && n < cap; o++) {
        if (!mcp_option_takes(o, MCP_OPT_PY) || in_list(positional, o->name)) continue;
        char def[128], item[256];
        python_default(o, def, sizeof def);
        int len = snprintf(item, sizeof item, ", %s=%s", o->name, def);
        if (line + (size_t)len > 84) { /* wrap under the opening parenthesis */
            n += (size_t)snprintf(doc + n, cap - n, ",\n%*s", (int)strlen(fn) + 1, "");
            line = strlen(fn) + 1;
            n += (size_t)snprintf(doc + n, cap - n, "%s", item + 2);
            line += (size_t)len - 2;
        } else {
            n += (size_t)snprintf(doc + n, cap - n, "%s", item);
            line += (size_t)len;
        }
    }
    if (extras && n < cap) {
        if (line + strlen(extras) + 2 > 84)
            n += (size_t)snprintf(doc + n, cap - n, ",\n%*s%s", (int)strlen(fn) + 1, "",
                                  extras);
        else
            n += (size_t)snprintf(doc + n, cap - n, ", %s", extras);
    }
    if (n < cap)
        n += (size_t)snprintf(doc + n, cap - n, ") -> %s\n\n%s\n\nKeywords:\n", returns,
                              prose);
    for (const mcp_option *o = op->options; o->name && n < cap; o++) {
        if (!mcp_option_takes(o, MCP_OPT_PY) || in_list(positional, o->name)) continue;
        n += (size_t)snprintf(doc + n, cap - n, "  %s: %s", o->name, o->doc);
        if ((o->type == MCP_OPT_ENUM || o->type == MCP_OPT_WORDSET) && n < cap) {
            char words[256];
            mcp_wordlist_join(o->words, ", ", words, sizeof words);
            n += (size_t)snprintf(doc + n, cap - n, " (%s)", words);
        }
        if (n < cap) n += (size_t)snprintf(doc + n, cap - n, "\n");
    }
    return doc;
}

/* mcpost.settings(operation, **keywords) -> str: the settings as the keywords give
 * them, as `mcpost OPERATION --print-settings` prints them (the denoiser and inputs
 * are the functions' own and left out). */
static PyObject *
py_settings(PyObject *self, PyObject *args, PyObject *kw)
{
    (void)self;
    const char *name;
    if (!PyArg_ParseTuple(args, "s:settings", &name)) return NULL;
    const mcp_operation *op = mcp_operation_find(name);
    if (!op) {
        PyErr_Format(mcp_py_error, "no operation called '%s'", name);
        return NULL;
    }
    const char *own[64];
    PyObject *own_values[64];
    int n = 0;
    for (const mcp_option *o = op->options; o->name && n < 63; o++)
        if (o->type == MCP_OPT_INPUT || o->type == MCP_OPT_DENOISER) own[n++] = o->name;
    own[n] = NULL;
    void *settings = PyMem_Calloc(1, op->size);
    PyObject *keep = PyList_New(0), *result = NULL;
    if (!settings || !keep) {
        PyErr_NoMemory();
    } else if (!mcp_py_settings(op, "settings", kw, own, own_values, settings, keep)) {
        char *text = mcp_operation_dump(op, settings, MCP_OPT_PY);
        result = text ? PyUnicode_FromString(text) : mcp_py_fail();
        free(text);
    }
    Py_XDECREF(keep);
    PyMem_Free(settings);
    return result;
}

/* mcpost.options(operation) -> list of dicts: the table's rows, as the docs list them */
static PyObject *
py_options(PyObject *self, PyObject *args)
{
    (void)self;
    static const char *const types[] = {"number", "int",      "seed",  "whole",
                                        "flag",   "enum",     "list",  "text",
                                        "input",  "denoiser", "texts", "wordset"};
    const char *name;
    if (!PyArg_ParseTuple(args, "s:options", &name)) return NULL;
    const mcp_operation *op = mcp_operation_find(name);
    if (!op) {
        PyErr_Format(mcp_py_error, "no operation called '%s'", name);
        return NULL;
    }
    PyObject *list = PyList_New(0);
    for (const mcp_option *o = op->options; list && o->name; o++) {
        PyObject *words = Py_NewRef(Py_None), *where = PyList_New(0);
        if (o->type == MCP_OPT_ENUM || o->type == MCP_OPT_WORDSET) {
            Py_DECREF(words);
            words = PyList_New(0);
            for (int i = 0; words && i < o->words->count; i++) {
                PyObject *w = PyUnicode_FromString(o->words->words[i]);
                if (!w || PyList_Append(words, w)) Py_CLEAR(words);
                Py_XDECREF(w);
            }
        }
        static const char *const fronts[] = {"cli", "job", "python"};
        for (int k = 0; where && k < 3; k++)
            if (mcp_option_takes(o, 1u << k)) {
                PyObject *w = PyUnicode_FromString(fronts[k]);
                if (!w || PyList_Append(where, w)) Py_CLEAR(where);
                Py_XDECREF(w);
            }
        PyObject *d =
            words && where
                ? Py_BuildValue("{s:s,s:s,s:N,s:z,s:s,s:N,s:d,s:d,s:O,s:O,s:i,s:z}",
                                "name", o->name, "type", types[o->type], "where", where,
                                "default", o->def, "doc", o->doc, "words", words, "lo",
                                o->lo, "hi", o->hi, "has_lo",
                                (o->bounds & MCP_OPT_LO) ? Py_True : Py_False, "has_hi",
                                (o->bounds & MCP_OPT_HI) ? Py_True : Py_False,
                                "max_count", o->max_count, "auto", o->auto_word)
                : NULL;
        if (!d) {
            Py_XDECREF(words);
            Py_XDECREF(where);
            Py_CLEAR(list);
        } else {
            if (PyList_Append(list, d)) Py_CLEAR(list);
            Py_DECREF(d);
        }
    }
    return list;
}

PyMethodDef mcp_py_options_methods[] = {
    {"options", py_options, METH_VARARGS,
     "options(operation) -> list of dicts: the option table of operation ('estimate',\n"
     "'blend'): each option's name, type, where it is taken ('cli', 'job', 'python'),\n"
     "default, doc, words (an enum's) and range"},
    {"settings", (PyCFunction)(void (*)(void))py_settings, METH_VARARGS | METH_KEYWORDS,
     "settings(operation, **keywords) -> str: the settings of operation ('estimate',\n"
     "'blend') as these keywords give them, one 'name: value' a line, as\n"
     "`mcpost OPERATION --print-settings` prints them for the same flags"},
    {NULL, NULL, 0, NULL}};
