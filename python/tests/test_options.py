"""Every operation's option table through Python and the command line: for every
option both take, good and bad values go through mcpost.settings (the keywords, as
mcpost.estimate and mcpost.blend read them) and `mcpost OP --print-settings` (the
flags): both take a value or both refuse it, with the same message (the label aside:
"--tau" against "tau"), and when they take it the settings agree on every option both
take. tests/ops/test_options.c holds the command line and job files to the same."""
import math
import subprocess

import pytest

import mcpost

from conftest import CLI as MCPOST

OPERATIONS = ["estimate", "blend", "metrics", "perceptual"]
COMPARED = ("number", "int", "seed", "whole", "flag", "enum", "list", "wordset")


def both_take(o):
    return "cli" in o["where"] and "python" in o["where"] and o["type"] in COMPARED


def values_for(o):
    """Python values, good and bad, for option o."""
    t, vs = o["type"], []
    if t in ("number", "int"):
        cast = int if t == "int" else float
        if o["has_lo"]:
            vs += [cast(o["lo"]), cast(o["lo"] - 1), cast(o["lo"] + 3)]
        if o["has_hi"]:
            vs += [cast(o["hi"]), cast(o["hi"] + 1), cast(o["hi"] - 3)]
        if o["has_lo"] and o["has_hi"]:
            vs.append(cast(math.floor((o["lo"] + o["hi"]) / 2) + 1))
        if not o["has_lo"] and not o["has_hi"]:
            vs += [cast(37), cast(-2)]
        if t == "number":
            vs += [0.375, 7, float("inf")]
        if o["auto"]:
            vs.append(o["auto"])
    elif t == "seed":
        vs = [0, 12345678901234567, -1]
    elif t == "whole":
        vs = [0, 1048576, 1.5, -2, 4503599627370497]
    elif t == "flag":
        vs = [True, False]
    elif t == "enum":
        vs = o["words"] + [w.upper().replace("_", "-") for w in o["words"]] + ["nope"]
    elif t == "list":
        vs = [[0.25], [0.75, 0.25], [0.25] * (o["max_count"] + 1), [0.25, 2.0], [-1.0]]
    elif t == "wordset":
        w = o["words"]
        vs = [w[0], [w[-1]], list(reversed(w)), ",".join(w).upper(), "none", ["none", w[0]],
              "nope", [w[0], "nope"]]
    return vs


def cli_words(o, v):
    flag = "--" + o["name"].replace("_", "-")
    if o["type"] == "flag":
        return [flag if v else "--no-" + flag[2:]]
    if o["type"] == "list":
        return [flag, ",".join(repr(x) for x in v)]
    if o["type"] == "wordset" and not isinstance(v, str):
        return [flag, ",".join(v)]
    return [flag, v if isinstance(v, str) else repr(v)]


def parse_dump(text):
    return dict(line.split(": ", 1) for line in text.splitlines())


def cli_settings(op, words):
    p = subprocess.run([MCPOST, op, "--print-settings", *words], capture_output=True,
                       text=True)
    return p.returncode, p.stdout, p.stderr.strip()


@pytest.mark.parametrize("op", OPERATIONS)
def test_python_and_the_command_line_read_alike(op):
    compared = 0
    for o in mcpost.options(op):
        if not both_take(o):
            continue
        # blend's --weights is also the U-Net's weights shorthand: a value that is none
        # of its words is the denoiser's on the command line (tests/ops/test_options.c)
        if op == "blend" and o["name"] == "weights":
            words = [w for w in values_for(o) if w.lower().replace("-", "_") in o["words"]]
        else:
            words = values_for(o)
        taken = refused = 0
        for v in words:
            rc, out, err = cli_settings(op, cli_words(o, v))
            try:
                got = mcpost.settings(op, **{o["name"]: v})
            except mcpost.Error as e:
                assert rc != 0, f"{op} {o['name']}={v!r}: Python refuses ({e}), CLI takes it"
                flag = "--" + o["name"].replace("_", "-")
                assert err == "mcpost: " + str(e).replace(o["name"], flag, 1) or \
                    err == "mcpost: " + str(e), f"{op} {o['name']}={v!r}: {err} / {e}"
                refused += 1
            else:
                assert rc == 0, f"{op} {o['name']}={v!r}: Python takes it, CLI: {err}"
                py, cli = parse_dump(got), parse_dump(out)
                common = set(py) & set(cli)
                assert o["name"] in common
                assert {k: py[k] for k in common} == {k: cli[k] for k in common}
                taken += 1
            compared += 1
        assert taken, f"{op} {o['name']}: no value taken"
        if o["type"] not in ("flag",) and not (op == "blend" and o["name"] == "weights"):
            assert refused, f"{op} {o['name']}: no value refused"
    assert compared > 50


@pytest.mark.parametrize("op", OPERATIONS)
def test_defaults_are_the_command_lines(op):
    rc, out, _ = cli_settings(op, [])
    assert rc == 0
    py, cli = parse_dump(mcpost.settings(op)), parse_dump(out)
    common = set(py) & set(cli)
    assert len(common) > 10
    assert {k: py[k] for k in common} == {k: cli[k] for k in common}


def test_wrong_types_and_unknown_keywords():
    with pytest.raises(TypeError, match="unexpected keyword argument 'nope'"):
        mcpost.settings("estimate", nope=1)
    # the command line's spelling is not a keyword, nor an option Python does not take
    with pytest.raises(TypeError, match="unexpected keyword argument 'exit_status'"):
        mcpost.settings("estimate", exit_status=True)
    with pytest.raises(TypeError, match="tau must be a number"):
        mcpost.settings("estimate", tau="0.01")
    with pytest.raises(TypeError, match="metric must be a str"):
        mcpost.settings("estimate", metric=1)
    with pytest.raises(TypeError, match="s2_pool must be an int or 'auto'"):
        mcpost.settings("estimate", s2_pool=1.5)
    with pytest.raises(mcpost.Error, match="no operation called 'nope'"):
        mcpost.settings("nope")


POSITIONAL = {"denoise": ("color",), "jvp": ("color", "tangent")}


@pytest.mark.parametrize("op,fn", [(op, op) for op in OPERATIONS] +
                         [("denoise", "denoise"), ("denoise", "jvp")])
def test_docstrings_list_every_keyword(op, fn):
    doc = getattr(mcpost, fn).__doc__
    head = doc.split("\n\n")[0]
    for name in POSITIONAL.get(fn, ()):
        assert head.startswith(fn + "(" + ", ".join(POSITIONAL[fn]) + ", *"), head
    for o in mcpost.options(op):
        if "python" in o["where"] and o["name"] not in POSITIONAL.get(fn, ()):
            assert o["name"] + "=" in head, o["name"]
            assert "  " + o["name"] + ": " in doc, o["name"]


def test_denoise_takes_the_tables_keywords():
    """denoise's keywords are its table's rows that Python takes (and variance, the old
    name of variance_of_mean): the same image by either name, and both is an error."""
    import numpy as np
    rng = np.random.default_rng(3)
    color = rng.random((16, 16, 3), dtype=np.float32)
    var = np.full((16, 16, 3), 0.01, np.float32)
    a = mcpost.denoise(color, variance=var, denoiser="nlm")
    b = mcpost.denoise(color, variance_of_mean=var, denoiser="nlm")
    assert np.array_equal(a, b)
    with pytest.raises(TypeError, match="variance or variance_of_mean, not both"):
        mcpost.denoise(color, variance=var, variance_of_mean=var, denoiser="nlm")
    with pytest.raises(TypeError, match="missing required argument 'color'"):
        mcpost.denoise(denoiser="nlm")
    # any other keyword is the denoiser's setting, refused by its own table
    with pytest.raises(mcpost.Error, match="sigmaa"):
        mcpost.denoise(color, denoiser="gauss", sigmaa=2)
