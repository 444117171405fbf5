"""denoise and jvp against `mcpost denoise` (with --tangent) on a committed render: the
same images, value for value; and the JVP of a linear denoiser against its own output."""
import mcpost
import numpy as np
import pytest

from conftest import cli, rgb, series


@pytest.fixture(scope="module")
def dump():
    return mcpost.read_dump(series("texture", 16))


@pytest.mark.parametrize("name,opts", [("gauss", {"sigma": 1.5}), ("nlm", {}),
                                       ("unet", {})])
def test_denoise_matches_the_cli(tmp, dump, name, opts):
    out = tmp / "den.exr"
    args = [f"--denoiser-opt={k}={v}" for k, v in opts.items()]
    cli("denoise", series("texture", 16), "--denoiser", name, *args, "-o", out,
        json_out=False)
    got = mcpost.denoise(dump["color"], albedo=dump["albedo"], normal=dump["normal"],
                         variance=dump["variance"], denoiser=name, **opts)
    assert got.shape == (128, 128, 3) and got.dtype == np.float32
    np.testing.assert_array_equal(got, rgb(out))


def test_jvp_matches_the_cli(tmp, dump):
    rng = np.random.default_rng(3)
    tangent = rng.standard_normal((128, 128, 3)).astype(np.float32)
    mcpost.write_image(tmp / "t.exr", tangent)
    cli("denoise", series("texture", 16), "--denoiser", "nlm", "-o", tmp / "f.exr",
        "--tangent", tmp / "t.exr", "--tangent-out", tmp / "jt.exr", json_out=False)
    f, jt = mcpost.jvp(dump["color"], tangent, albedo=dump["albedo"], normal=dump["normal"],
                       variance=dump["variance"], denoiser="nlm")
    np.testing.assert_array_equal(f, rgb(tmp / "f.exr"))
    np.testing.assert_array_equal(jt, rgb(tmp / "jt.exr"))
    # several tangents in one pass give the same products
    f2, many = mcpost.jvp(dump["color"], [tangent, 2 * tangent], albedo=dump["albedo"],
                          normal=dump["normal"], variance=dump["variance"], denoiser="nlm")
    np.testing.assert_array_equal(f2, f)
    np.testing.assert_array_equal(many[0], jt)
    np.testing.assert_allclose(many[1], 2 * jt, rtol=1e-5, atol=1e-6)


def test_jvp_of_a_linear_denoiser_is_the_denoiser(dump):
    # the Gaussian blur is linear: J t = F(t) exactly (up to float rounding)
    t = np.random.default_rng(5).random((128, 128, 3), dtype=np.float32)
    _, jt = mcpost.jvp(dump["color"], t, denoiser="gauss", sigma=2)
    np.testing.assert_allclose(jt, mcpost.denoise(t, denoiser="gauss", sigma=2),
                               rtol=1e-5, atol=1e-6)


def test_denoiser_settings_and_errors(dump):
    assert set(mcpost.denoisers()) >= {"gauss", "nlm", "unet", "default"}
    assert "sigma" in mcpost.denoisers()["gauss"]["settings"]
    # a dict is the job file's denoiser map
    a = mcpost.denoise(dump["color"], denoiser="gauss", sigma=3)
    b = mcpost.estimate(dump, denoiser={"name": "gauss", "sigma": 3})["denoised"]
    np.testing.assert_array_equal(a, b)
    with pytest.raises(mcpost.Error, match="sigmaa"):
        mcpost.denoise(dump["color"], denoiser="gauss", sigmaa=3)
    with pytest.raises(mcpost.Error, match="unknown denoiser 'blur'"):
        mcpost.denoise(dump["color"], denoiser="blur")
    with pytest.raises(mcpost.Error, match="color: needs 3 channels"):
        mcpost.denoise(dump["color"][..., :2], denoiser="gauss")
    with pytest.raises(mcpost.Error, match="albedo: size 64x128 does not match color"):
        mcpost.denoise(dump["color"], albedo=dump["albedo"][:, :64], denoiser="nlm")
    with pytest.raises(TypeError, match="denoiser setting 'sigma'"):
        mcpost.denoise(dump["color"], denoiser="gauss", sigma=[1, 2])


def test_default_denoiser_takes_the_unets_settings():
    # `default` has no settings of its own: given some, it is the U-Net with them, as
    # `mcpost denoise --input-scale` (no --denoiser) is
    d = mcpost.read_dump(series("cornell", 16))
    kw = dict(albedo=d["albedo"], normal=d["normal"], input_scale=0.5)
    np.testing.assert_array_equal(mcpost.denoise(d["color"], **kw),
                                  mcpost.denoise(d["color"], denoiser="unet", **kw))
