"""Shared fixtures of the Python module's tests: the CLI built beside the module (its
output is the truth the module must reproduce), the committed renders and a scratch
folder. ctest sets the paths (python/CMakeLists.txt)."""
import json
import os
import subprocess

import numpy as np
import mcpost
import pytest

SOURCE = os.environ.get("MCPOST_TEST_SOURCE_DIR",
                        os.path.join(os.path.dirname(__file__), "..", ".."))
CLI = os.environ.get("MCPOST_TEST_MCPOST", os.path.join(SOURCE, "build", "mcpost"))
CORNELL = os.path.join(SOURCE, "samples", "fixtures", "cornell")
TEXTURE = os.path.join(SOURCE, "samples", "fixtures", "texture")


def series(scene, spp):
    return os.path.join(SOURCE, "samples", "fixtures", scene, "series",
                        f"{scene}_spp{spp:04d}.exr")


def single(scene, i):
    return os.path.join(SOURCE, "samples", "fixtures", scene, "singles",
                        f"{scene}_single{i:02d}.exr")


def reference(scene):
    return os.path.join(SOURCE, "samples", "fixtures", scene, f"{scene}_reference.exr")


def cli(*args, json_out=True):
    """Runs `mcpost ARGS` quietly; its stdout parsed as JSON (or as text)."""
    out = subprocess.run([CLI, *map(str, args)], check=True, capture_output=True,
                         text=True).stdout
    return json.loads(out) if json_out else out


@pytest.fixture
def tmp(tmp_path):
    return tmp_path


def assert_close(a, b, rtol=1e-12, atol=0.0, err_msg=""):
    """Figures the module and the CLI computed with the same library code: equal up to
    the 17 significant digits the JSON keeps."""
    np.testing.assert_allclose(a, b, rtol=rtol, atol=atol, err_msg=err_msg)


def rgb(path):
    """The R, G, B channels of a file, by name, as float32 H x W x 3."""
    pixels, names, _ = mcpost.read_image(path)
    return np.ascontiguousarray(pixels[..., [names.index(c) for c in "RGB"]])


def strat_replicates(tmp, scene, blocks):
    """The stratified fixture `scene` (samples/fixtures/strat) as 8 independent renders
    merged as replicates: each render the merge of its first `blocks` 32-spp blocks
    (render 0 carrying its per-sample variance, whose blocks pool exactly; the others
    means only, passes of one render too), or its first block alone; albedo and normal
    from the scene's features. Returns the merged dump's path and the dump."""
    strat = os.path.join(SOURCE, "samples", "fixtures", "strat", scene)
    feat, names, _ = mcpost.read_image(os.path.join(strat, f"{scene}_features.exr"))
    albedo = feat[..., [names.index(c) for c in ("Albedo.R", "Albedo.G", "Albedo.B")]]
    normal = feat[..., [names.index(c) for c in ("N.X", "N.Y", "N.Z")]]
    paths = []
    for r in range(8):
        files = [os.path.join(strat, "blocks", f"{scene}_r{r}_b{b:02d}.exr")
                 for b in range(blocks)]
        render = (dict(mcpost.read_dump(files[0])) if blocks == 1 else
                  dict(mcpost.merge(files, variance="pooled" if r == 0 else "replicates")))
        render["albedo"], render["normal"] = albedo, normal
        paths.append(str(tmp / f"r{r}.exr"))
        mcpost.write_dump(paths[-1], render)
    dump = dict(mcpost.merge(paths, variance="replicates"))
    assert dump["variance_source"] == "replicates" and dump["variance_dof"] == 7
    dump["albedo"], dump["normal"] = albedo, normal
    path = str(tmp / "merged.exr")
    mcpost.write_dump(path, dump)
    return path, dump
