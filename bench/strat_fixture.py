"""strat_fixture.py: reading a stratified fixture (samples/fixtures/strat/SCENE) for the
bench scripts that measure on it (stein_gap.py, jackknife_cov.py), with the module
built (build/python)."""
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "build", "python"))
import mcpost  # noqa: E402


def folder(scene):
    return os.path.join(ROOT, "samples", "fixtures", "strat", scene)


def rgb(pixels, names):
    """The R, G, B channels of an image that mcpost.read_image returned."""
    return np.ascontiguousarray(pixels[..., [names.index(c) for c in "RGB"]])


def features(scene):
    """(albedo, normal) of the scene's features file, float32."""
    feat, names, _ = mcpost.read_image(os.path.join(folder(scene), f"{scene}_features.exr"))
    albedo = np.ascontiguousarray(feat[..., [names.index("Albedo." + c) for c in "RGB"]])
    normal = np.ascontiguousarray(feat[..., [names.index("N." + c) for c in "XYZ"]])
    return albedo, normal


def reference(scene):
    """The 16384-spp reference, float64."""
    path = os.path.join(folder(scene), f"{scene}_reference.exr")
    return rgb(*mcpost.read_image(path)[:2]).astype(np.float64)


def block(scene, render, index):
    """Block `index` (32 spp) of render `render`, float64."""
    path = os.path.join(folder(scene), "blocks", f"{scene}_r{render}_b{index:02d}.exr")
    return rgb(*mcpost.read_image(path)[:2]).astype(np.float64)
