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
