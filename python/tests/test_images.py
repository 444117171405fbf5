"""Reading and writing images and dumps, merge, and what crosses the boundary: against
`mcpost info` and `mcpost merge` on the committed renders, and round trips."""
import os

import mcpost
import numpy as np
import pytest

from conftest import CORNELL, assert_close, cli, rgb, series


def test_read_image_matches_info():
    pixels, names, attrs = mcpost.read_image(series("cornell", 16))
    info = cli("info", series("cornell", 16), "--json")
    assert names == [c["name"] for c in info["channels"]]
    assert pixels.shape == (128, 128, len(names)) and pixels.dtype == np.float32
    for c, ch in enumerate(info["channels"]):
        assert_close(pixels[..., c].mean(dtype=np.float64), ch["mean"], rtol=1e-6)
        assert pixels[..., c].max() == np.float32(ch["max"])
    assert attrs["samplesPerPixel"] == 16 and attrs["scene"] == "cornell"


def test_results_own_the_library_pixels_without_a_copy():
    pixels, _, _ = mcpost.read_image(series("cornell", 16))
    # the array's memory is the image the library read, freed with the array
    assert not pixels.flags["OWNDATA"] and type(pixels.base).__name__ == "PyCapsule"
    assert pixels.flags["C_CONTIGUOUS"] and pixels.flags["WRITEABLE"]


@pytest.mark.parametrize("ext", ["exr", "pfm"])
def test_write_read_round_trip(tmp, ext):
    rng = np.random.default_rng(7)
    img = rng.random((5, 9, 3), dtype=np.float32) * 100
    path = tmp / f"x.{ext}"
    mcpost.write_image(path, img)
    back, names, _ = mcpost.read_image(path)
    order = [names.index(c) for c in "RGB"]
    np.testing.assert_array_equal(back[..., order], img)
    assert not any(p.name.startswith("x.") and ".tmp" in p.name for p in tmp.iterdir())


def test_write_channels_attributes_and_half(tmp):
    img = np.arange(4 * 3 * 2, dtype=np.float32).reshape(4, 3, 2) / 7
    path = tmp / "y.exr"
    mcpost.write_image(path, img, channels=["u", "v"], half=True,
                       attributes={"note": "hi", "count": 3, "scale": 0.5})
    back, names, attrs = mcpost.read_image(path)
    assert names == ["u", "v"]
    np.testing.assert_array_equal(back, img.astype(np.float16).astype(np.float32))
    assert attrs["note"] == "hi" and attrs["count"] == 3 and attrs["scale"] == 0.5
    with pytest.raises(mcpost.Error, match="channels: 1 names for 2 channels"):
        mcpost.write_image(path, img, channels=["u"])
    with pytest.raises(mcpost.Error, match="compression"):
        mcpost.write_image(path, img, compression="lzma")
    with pytest.raises(mcpost.Error, match="/no/such/dir"):
        mcpost.write_image("/no/such/dir/z.exr", img)


def test_read_dump_matches_info():
    d = mcpost.read_dump(series("cornell", 16))
    info = cli("info", series("cornell", 16), "--json")
    assert d["convention"] == info["convention"] == "pbrt"
    assert d["spp"] == info["spp"] == 16
    assert d["variance_source"] == info["variance_source"]
    assert (d["albedo"] is not None) == info["albedo"]
    assert d["covariance"] is None and d["spp_map"] is None
    # the file stores per-sample variance: the dump holds the variance of the mean
    pixels, names, _ = mcpost.read_image(series("cornell", 16))
    per_sample = pixels[..., [names.index(f"Variance.{c}") for c in "RGB"]]
    np.testing.assert_allclose(d["variance"], per_sample / 16, rtol=1e-6)
    np.testing.assert_array_equal(d["color"], rgb(series("cornell", 16)))


def test_read_dump_options():
    d = mcpost.read_dump(series("cornell", 16), spp=4, variance="of-mean")
    info = cli("info", series("cornell", 16), "--json", "--spp", 4, "--variance", "of-mean")
    assert d["spp"] == info["spp"] == 4
    pixels, names, _ = mcpost.read_image(series("cornell", 16))
    np.testing.assert_array_equal(
        d["variance"], pixels[..., [names.index(f"Variance.{c}") for c in "RGB"]])
    with pytest.raises(mcpost.Error, match="convention"):
        mcpost.read_dump(series("cornell", 16), convention="povray")


def test_dump_round_trip(tmp):
    d = mcpost.read_dump(series("cornell", 16))
    path = tmp / "d.exr"
    mcpost.write_dump(path, d)
    back = mcpost.read_dump(path)
    assert back["spp"] == 16
    for key in ("color", "variance", "albedo", "normal"):
        np.testing.assert_allclose(back[key], d[key], rtol=1e-6, err_msg=key)
    # a dict made by hand: colour and variance of the mean
    mine = {"color": d["color"], "variance": d["variance"], "spp": 16}
    mcpost.write_dump(path, mine, convention="pbrt")
    assert_close(mcpost.read_dump(path)["variance"], d["variance"], rtol=1e-6)
    with pytest.raises(mcpost.Error, match="needs 'color'"):
        mcpost.write_dump(path, {"variance": d["variance"]})
    with pytest.raises(mcpost.Error, match=r"dump\['albedo'\]: size 128x128 does not match"):
        mcpost.write_dump(path, {"color": d["color"][:64], "albedo": d["albedo"]})


@pytest.mark.parametrize("convention", ["mcpost", "mitsuba", "blender", "pbrt"])
def test_write_dump_matches_convert(tmp, convention):
    cli("convert", series("cornell", 16), tmp / "cli.exr", "--dump", convention,
        json_out=False)
    mcpost.write_dump(tmp / "py.exr", mcpost.read_dump(series("cornell", 16)),
                      convention=convention)
    a, an, aa = mcpost.read_image(tmp / "py.exr")
    b, bn, ba = mcpost.read_image(tmp / "cli.exr")
    assert an == bn and aa == ba
    np.testing.assert_array_equal(a, b)


def test_write_image_matches_convert(tmp):
    pixels, names, attrs = mcpost.read_image(series("cornell", 16))
    cli("convert", series("cornell", 16), tmp / "cli.exr", "--half", json_out=False)
    mcpost.write_image(tmp / "py.exr", pixels, channels=names, attributes=attrs, half=True)
    a, an, _ = mcpost.read_image(tmp / "py.exr")
    b, bn, _ = mcpost.read_image(tmp / "cli.exr")
    assert an == bn
    np.testing.assert_array_equal(a, b)


def test_merge_matches_the_cli(tmp):
    parts = [os.path.join(CORNELL, "realizations", f"cornell_spp0032_r{r}.exr")
             for r in range(4)]
    cli("merge", *parts, "-o", tmp / "m.exr", json_out=False)
    want = mcpost.read_dump(tmp / "m.exr")
    got = mcpost.merge(parts)
    assert got["variance_source"] == want["variance_source"] == "replicates"
    assert got["variance_dof"] == want["variance_dof"] == 3
    assert got["spp"] == want["spp"] == 128
    for key in ("color", "variance", "albedo", "normal"):
        np.testing.assert_array_equal(got[key], want[key], err_msg=key)
    # dicts merge the same as files
    again = mcpost.merge([mcpost.read_dump(p) for p in parts])
    np.testing.assert_array_equal(again["variance"], got["variance"])
    # replicates: the spread of the K means, Σ n_k (X_k - X)² / ((K - 1) N)
    xs = np.stack([mcpost.read_dump(p)["color"].astype(np.float64) for p in parts])
    spread = ((xs - xs.mean(0)) ** 2).sum(0) * 32 / (3 * 128)
    np.testing.assert_allclose(got["variance"], spread, rtol=1e-5, atol=1e-12)
    with pytest.raises(mcpost.Error, match="pool must be >= 0"):
        mcpost.merge(parts, pool=-1)


def test_increment_variance_matches_the_cli_series():
    members = [series("cornell", n) for n in (4, 8, 16, 32)]
    # the probes' SURE, as a single dump's estimate has: a series member's own groups
    # (--sure-groups) are not in one dump
    want = cli("estimate", *members, "--denoiser", "gauss", "--variance-from", "increments",
               "--sure-groups", "0", "--json")
    d, ratio = mcpost.increment_variance(members)
    assert d["variance_source"] == want["variance_source"] == "increments"
    assert d["spp"] == 32 and d["replicates"] == 4 and d["variance_dof"] == 3
    assert_close(ratio, want["variance_ratio"])
    # the series' last member is estimated on exactly this variance
    e = mcpost.estimate(d, denoiser="gauss", taus=[t["tau"] for t in want["taus"]])
    last = want["members"][-1]
    assert_close(e["cdf"], last["cdf"])
    assert_close(e["percentile_error"], last["estimated_percentiles"])
    assert_close(e["expected_mean_error"], last["expected_mean_error"])
    with pytest.raises(mcpost.Error):
        mcpost.increment_variance(members[:1])  # one block: no spread to measure
