"""The metrics against `mcpost metrics --json` on the committed renders (the same
numbers) and against numpy where the formula is simple (MSE, relMSE)."""
import math

import mcpost
import numpy as np
import pytest

from conftest import assert_close, cli, reference, rgb, series


@pytest.fixture(scope="module")
def pair():
    return rgb(series("cornell", 16)), rgb(reference("cornell"))


@pytest.fixture(scope="module")
def cli_metrics():
    return cli("metrics", series("cornell", 16), reference("cornell"), "--json")


def test_mse_and_relmse_match_numpy(pair):
    t, r = (a.astype(np.float64) for a in pair)
    assert_close(mcpost.mse(*pair), np.mean((t - r) ** 2), rtol=1e-12)
    assert_close(mcpost.relmse(*pair), np.mean((t - r) ** 2 / (r ** 2 + 1e-2)), rtol=1e-12)
    assert_close(mcpost.relmse(*pair, eps_rel=0.5), np.mean((t - r) ** 2 / (r ** 2 + 0.5)),
                 rtol=1e-12)


def test_single_metrics_match_the_cli(pair, cli_metrics):
    m = cli_metrics
    assert_close(mcpost.mse(*pair), m["mse"])
    assert_close(mcpost.relmse(*pair), m["relmse"])
    assert_close(mcpost.psnr(*pair), m["psnr"])
    assert_close(mcpost.pmse(*pair), m["pmse"])
    assert_close(mcpost.relse_percentiles(*pair), m["relse_percentiles"]["value"])
    assert_close(mcpost.blue_noise(*pair)["low_fraction"], m["blue_noise"]["low_fraction"])
    ldr, ldr_map = mcpost.flip(*pair)
    hdr, hdr_map = mcpost.flip(*pair, hdr=True)
    assert_close(ldr, m["flip_ldr"]["mean"])
    assert_close(hdr, m["flip_hdr"]["mean"])
    assert ldr_map.shape == hdr_map.shape == (128, 128) and ldr_map.dtype == np.float32
    # the map's mean is the FLIP value (FLIP sums in float, row-major: 1e-6 apart)
    assert_close(ldr_map.mean(dtype=np.float64), ldr, rtol=1e-5)


def test_paths_give_the_same_numbers(cli_metrics):
    assert_close(mcpost.mse(series("cornell", 16), reference("cornell")), cli_metrics["mse"])


def test_metrics_is_the_cli_json(pair, cli_metrics, tmp):
    got, maps = mcpost.metrics(*pair, maps=True)
    for key in ("test", "reference", "width", "height"):
        cli_metrics.pop(key)
    assert got.keys() == cli_metrics.keys()
    for key, want in cli_metrics.items():
        if isinstance(want, dict):
            for k, v in want.items():
                if isinstance(v, (int, float, list)):
                    assert_close(got[key][k], v)
                else:
                    assert got[key][k] == v
        else:
            assert_close(got[key], want)
    # the maps are the files the CLI writes with -o
    cli("metrics", series("cornell", 16), reference("cornell"), "-o", tmp, json_out=False)
    for name in ("flip_ldr", "flip_hdr"):
        want, _, _ = mcpost.read_image(tmp / f"{name}.exr")
        np.testing.assert_array_equal(maps[name], want)
    for name in ("relse", "sq_error"):  # stored B, G, R, read back R, G, B (by name)
        want, names, _ = mcpost.read_image(tmp / f"{name}.exr")
        assert names == ["R", "G", "B"]
        np.testing.assert_array_equal(maps[name], want)
    np.testing.assert_array_equal(mcpost.relse_map(*pair), maps["relse"])


def test_metrics_options_follow_the_cli_words(pair):
    want = cli("metrics", series("cornell", 16), reference("cornell"), "--json",
               "--percentiles", "0.25,0.75", "--eps-rel", "0.1", "--flip", "hdr",
               "--tone-mapper", "reinhard", "--pmse-kernel", "gaussian",
               "--pmse-filter-reference", "--no-spectra")
    got = mcpost.metrics(*pair, percentiles=[0.25, 0.75], eps_rel=0.1, flip="hdr",
                         tone_mapper="reinhard", pmse_kernel="gaussian",
                         pmse_filter_reference=True, spectra=False)
    assert "flip_ldr" not in got and "blue_noise" not in got
    assert_close(got["relse_percentiles"]["value"], want["relse_percentiles"]["value"])
    assert_close(got["flip_hdr"]["mean"], want["flip_hdr"]["mean"])
    assert_close(got["pmse"], want["pmse"])
    assert_close(got["relmse"], want["relmse"])


def test_identical_images_have_infinite_psnr(pair):
    assert math.isinf(mcpost.psnr(pair[1], pair[1]))
    assert mcpost.metrics(pair[1], pair[1], flip="none", spectra=False)["psnr"] == math.inf


def test_other_dtypes_are_converted(pair):
    t, r = pair
    assert mcpost.mse(t.astype(np.float64), r) == mcpost.mse(t, r)
    # a non-contiguous view is copied once, with the same result
    wide = np.concatenate([t, t], axis=2)[..., :3]
    assert not wide.flags["C_CONTIGUOUS"]
    assert mcpost.mse(wide, r) == mcpost.mse(t, r)
    assert mcpost.mse(np.zeros((2, 2, 3), np.int32), np.ones((2, 2, 3), np.uint8)) == 1.0


def test_bad_inputs_raise_clear_errors(pair):
    t, r = pair
    with pytest.raises(mcpost.Error, match=r"^test: size 128x128 does not match ref \(128x64\)"):
        mcpost.mse(t, r[:64])
    with pytest.raises(mcpost.Error, match="needs an H x W x C or H x W array"):
        mcpost.mse(t.ravel(), r)
    with pytest.raises(TypeError, match="test must hold real numbers"):
        mcpost.mse(t.astype(np.complex64), r)
    with pytest.raises(TypeError, match="ref must hold real numbers"):
        mcpost.mse(t, np.full((128, 128, 3), "x"))
    bad = t.copy()
    bad[5, 7, 1] = np.nan
    with pytest.raises(mcpost.Error, match=r"test: non-finite value nan at pixel \(7, 5\) channel G"):
        mcpost.mse(bad, r)
    with pytest.raises(mcpost.Error, match="ref"):
        mcpost.flip(t, np.where(np.isnan(bad), np.inf, r))
    with pytest.raises(mcpost.Error, match="unknown"):
        mcpost.pmse(t, r, tone_map="sepia")
    with pytest.raises(mcpost.Error, match="percentiles"):
        mcpost.relse_percentiles(t, r, percentiles=[1.5])
    with pytest.raises(mcpost.Error, match="no-such.exr"):
        mcpost.mse("no-such.exr", r)
    with pytest.raises(TypeError):
        mcpost.mse(t, r, eps_rel=1)  # mse takes no eps_rel


def test_flip_takes_srgb_encoded_arrays():
    # srgb=True: the arrays are sRGB-encoded (NVIDIA's inputsRGB); decoding them by the
    # sRGB formula (an independent numpy one here) and passing linear gives the same
    rng = np.random.default_rng(3)
    a = rng.random((24, 32, 3), dtype=np.float32)
    b = np.clip(a + 0.1 * rng.standard_normal(a.shape).astype(np.float32), 0, 1)

    def decode(c):
        c = c.astype(np.float64)
        return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)

    got, got_map = mcpost.flip(a, b, srgb=True)
    want, want_map = mcpost.flip(decode(a), decode(b))
    assert abs(got - want) <= 1e-6
    np.testing.assert_allclose(got_map, want_map, atol=1e-5)
    assert abs(mcpost.flip(a, b)[0] - got) > 1e-3  # the keyword matters
    with pytest.raises(mcpost.Error, match="srgb=True is for LDR-FLIP"):
        mcpost.flip(a, b, hdr=True, srgb=True)


def tool_weighted_percentile(values, p):
    """NVIDIA's tool's weighted percentile (pooling.h), written with numpy: the first
    sorted value at which the float32 running sum exceeds p times the float32 total
    summed in row-major order (numpy's cumsum is sequential)."""
    flat = values.ravel().astype(np.float32)
    total = np.cumsum(flat, dtype=np.float32)[-1]
    running = np.cumsum(np.sort(flat), dtype=np.float32)
    hit = np.nonzero(running > np.float32(p) * total)[0]
    return float(np.sort(flat)[hit[0]]) if hit.size else 0.0


def test_flip_stats_are_the_tools(pair):
    _, fmap = mcpost.flip(*pair)
    st = mcpost.flip_stats(fmap)
    for key, p in (("weighted_median", 0.5), ("weighted_q1", 0.25), ("weighted_q3", 0.75)):
        assert st[key] == tool_weighted_percentile(fmap, p)
    assert st["min"] == fmap.min() and st["max"] == fmap.max()
    # buckets of width 0.01f, the index divided in double as the tool does
    idx = np.minimum((fmap.astype(np.float64) / np.float64(np.float32(0.01))).astype(int), 99)
    np.testing.assert_array_equal(st["histogram"], np.bincount(idx.ravel(), minlength=100))
    n = fmap.size
    assert_close(st["weighted_histogram"],
                 [c * (i + 0.5) * 0.01 / (n / 2 ** 20) for i, c in enumerate(st["histogram"])],
                 rtol=1e-12)
    # metrics() carries the same numbers
    m = mcpost.metrics(*pair, flip="ldr", spectra=False)
    assert m["flip_ldr"]["weighted_median"] == st["weighted_median"]
    assert m["flip_histogram"]["flip_ldr"] == st["histogram"]


def test_flip_stats_closed_form():
    # uniform errors weighted by themselves: density 2v, median sqrt(1/2), quartiles
    # sqrt(1/4) and sqrt(3/4), within the grid's 1/n and float sums' ~1e-5
    n = 256 * 256
    v = ((np.arange(n) + 0.5) / n).astype(np.float32)
    np.random.default_rng(3).shuffle(v)
    st = mcpost.flip_stats(v.reshape(256, 256))
    assert_close(st["weighted_median"], math.sqrt(0.5), atol=1e-4)
    assert_close(st["weighted_q1"], 0.5, atol=1e-4)
    assert_close(st["weighted_q3"], math.sqrt(0.75), atol=1e-4)


def test_pixels_above_counts_the_maps(pair):
    m, maps = mcpost.metrics(*pair, spectra=False, maps=True,
                             pixels_above=[("flip_ldr", 0.2), ("relse", 0.05)])
    got = {a["map"]: a["percent"] for a in m["pixels_above"]}
    assert got["flip_ldr"] == 100 * np.count_nonzero(maps["flip_ldr"] > np.float32(0.2)) / maps["flip_ldr"].size
    relse = maps["relse"]
    assert got["relse"] == 100 * np.count_nonzero((relse > 0.05).any(axis=2)) / relse.shape[0] / relse.shape[1]
    with pytest.raises(mcpost.Error, match="unknown per-pixel map 'flip'"):
        mcpost.metrics(*pair, pixels_above=[("flip", 0.1)])
