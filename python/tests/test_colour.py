"""Colour by channel name (docs/python.md, docs/conventions.md "Channel order"; issue 29,
"Red becomes blue"): pure red, green and blue images, with their channels laid out in
many orders, come back from every format as R, G, B and then the other channels. The
truth is the primary itself, built here."""
import mcpost
import numpy as np
import pytest

from conftest import cli

H, W = 4, 5
LAYOUTS = {
    "rgb": ["R", "G", "B"],
    "bgr": ["B", "G", "R"],
    "gbr": ["G", "B", "R"],
    "abgr": ["A", "B", "G", "R"],
    "rgba": ["R", "G", "B", "A"],
    "bgrz": ["B", "G", "R", "Z"],
    "zrgb": ["Z", "R", "G", "B"],
    "abgrz": ["A", "B", "G", "R", "Z"],
}
EXTRA = {"A": 0.5, "Z": 7.0}


def primary(names, p):
    """An H x W image of primary p (0 R, 1 G, 2 B) with its channels in names' order."""
    img = np.empty((H, W, len(names)), np.float32)
    for c, n in enumerate(names):
        img[..., c] = EXTRA[n] if n in EXTRA else float("RGB".index(n) == p)
    return img


def expected(names, p):
    """R, G, B of primary p, then the other channels in their order: names and values."""
    rest = [n for n in names if n not in "RGB"]
    values = [float(k == p) for k in range(3)] + [EXTRA[n] for n in rest]
    return ["R", "G", "B"] + rest, np.array(values, np.float32)


@pytest.mark.parametrize("p", [0, 1, 2])
@pytest.mark.parametrize("layout", LAYOUTS)
def test_exr_comes_back_rgb_first(tmp, layout, p):
    names = LAYOUTS[layout]
    path = tmp / "c.exr"
    mcpost.write_image(path, primary(names, p), channels=names)
    back, back_names, _ = mcpost.read_image(path)
    want_names, want = expected(names, p)
    assert back_names == want_names
    assert (back == want).all()


@pytest.mark.parametrize("p", [0, 1, 2])
@pytest.mark.parametrize("ext", ["png", "pfm", "hdr"])
@pytest.mark.parametrize("layout", ["rgb", "bgr", "gbr"])
def test_nameless_formats_take_colour_by_name(tmp, layout, ext, p):
    names = LAYOUTS[layout]
    path = tmp / f"c.{ext}"
    mcpost.write_image(path, primary(names, p), channels=names, srgb_encode=False)
    back, back_names, _ = mcpost.read_image(path, srgb_decode=False)
    assert back_names == ["R", "G", "B"]
    assert (back == np.eye(3, dtype=np.float32)[p]).all()


@pytest.mark.parametrize("p", [0, 1, 2])
def test_png_keeps_alpha_after_colour(tmp, p):
    names = LAYOUTS["abgr"]
    mcpost.write_image(tmp / "c.png", primary(names, p), channels=names)
    back, back_names, _ = mcpost.read_image(tmp / "c.png", srgb_decode=False)
    assert back_names == ["R", "G", "B", "A"]
    assert (back[..., :3] == np.eye(3, dtype=np.float32)[p]).all()
    assert (back[..., 3] == np.float32(128 / 255)).all()  # 0.5 to 8 bits


@pytest.mark.parametrize("p", [0, 1, 2])
def test_default_write_read_round_trip_is_rgb(tmp, p):
    # an H x W x 3 array is R, G, B: it comes back as written, not as B, G, R
    img = primary(["R", "G", "B"], p)
    mcpost.write_image(tmp / "c.exr", img)
    back, names, _ = mcpost.read_image(tmp / "c.exr")
    assert names == ["R", "G", "B"]
    np.testing.assert_array_equal(back, img)


@pytest.mark.parametrize("p", [0, 1, 2])
def test_functions_on_files_see_rgb(tmp, p):
    # a 3-channel file (stored B, G, R) given by path: the denoiser's input and its
    # result are R, G, B; a Gaussian keeps a constant image as it is
    mcpost.write_image(tmp / "c.exr", primary(["R", "G", "B"], p))
    out = mcpost.denoise(str(tmp / "c.exr"), denoiser="gauss", sigma=1)
    np.testing.assert_allclose(out, np.broadcast_to(np.eye(3)[p], out.shape), atol=1e-6)


@pytest.mark.parametrize("p", [0, 1, 2])
@pytest.mark.parametrize("layout", ["bgr", "abgrz"])
def test_cli_convert_keeps_colour(tmp, layout, p):
    names = LAYOUTS[layout]
    mcpost.write_image(tmp / "c.exr", primary(names, p), channels=names)
    cli("convert", tmp / "c.exr", tmp / "c.png", json_out=False)
    back, back_names, _ = mcpost.read_image(tmp / "c.png", srgb_decode=False)
    assert back_names[:3] == ["R", "G", "B"]
    assert (back[..., :3] == np.eye(3, dtype=np.float32)[p]).all()
