"""blend against `mcpost blend -o DIR` (the blended images, weights and final errors)
and perceptual against `mcpost perceptual --json -o DIR` (the optimised image, the
candidate index and the scores), on the committed renders."""
import json

import mcpost
import numpy as np
import pytest

from conftest import assert_close, cli, reference, rgb, series, single

MEMBERS = [series("cornell", n) for n in (1, 2, 4)]


def test_blend_matches_the_cli(tmp):
    # HDR-FLIP of six images per member is most of the time here; flip() has its test
    cli("blend", *MEMBERS, "--denoiser", "gauss", "--ref", reference("cornell"), "-o", tmp,
        "--quiet", "--no-flip", json_out=False)
    want = json.load(open(tmp / "blend.json"))
    got = mcpost.blend(MEMBERS, denoiser="gauss", reference=reference("cornell"), flip=False)
    assert got["has_reference"] and len(got["members"]) == 3
    for m, f in zip(got["members"], want["files"]):
        assert m["spp"] == f["spp"] and m["source"] == f["source"]
        np.testing.assert_array_equal(m["blend"], rgb(tmp / f["files"]["blend"]))
        np.testing.assert_array_equal(m["weights"], rgb(tmp / f["files"]["weights"]))
    last = got["members"][-1]["errors"]
    for method, errors in want["final"].items():
        if method == "spp":
            continue
        for k, v in errors.items():
            assert_close(last[method][k], v, err_msg=f"{method} {k}")


def test_blend_options_and_errors(tmp):
    got = mcpost.blend(MEMBERS[:2], denoiser="gauss", all_images=True, fit="last_two",
                       flip=False)
    images = got["members"][1]["images"]
    # the blend is the James-Stein combiner's (the default weights); curves beside it
    assert got["weights"] == "james_stein"
    assert set(images) == {"noisy", "denoised", "easy", "curves"}
    curves = mcpost.blend(MEMBERS[:2], denoiser="gauss", all_images=True, fit="last_two",
                          flip=False, weights="curves")
    assert curves["weights"] == "curves"
    assert set(curves["members"][1]["images"]) == {"noisy", "denoised", "easy", "james_stein"}
    np.testing.assert_array_equal(curves["members"][1]["images"]["james_stein"],
                                  got["members"][1]["blend"])
    np.testing.assert_array_equal(curves["members"][1]["blend"], images["curves"])
    with pytest.raises(mcpost.Error, match="unknown blend weights 'mean'"):
        mcpost.blend(MEMBERS, weights="mean")
    np.testing.assert_array_equal(images["noisy"], rgb(MEMBERS[1]))
    assert "errors" not in got["members"][1]
    with pytest.raises(mcpost.Error, match="fit"):
        mcpost.blend(MEMBERS, fit="sideways")
    with pytest.raises(mcpost.Error, match="no dumps given"):
        mcpost.blend([])
    with pytest.raises(mcpost.Error, match="missing.exr"):
        mcpost.blend([series("cornell", 1), "missing.exr"], denoiser="gauss")


def test_blend_self_influence_is_the_denoisers():
    """Each member's self_influence (blend.md "Self-influence") against its truth for the
    linear gauss denoiser: sum v K_ii / sum v, K_ii the blur's response at an impulse
    (impulses 13 px apart, beyond the kernel's radius of 6, so that 169 blurs give every
    pixel). The one probe's noise in it is sqrt(sum v^2 / 2) / sum v per channel."""
    members = [series("texture", n) for n in (32, 64, 128)]
    got = mcpost.blend(members, denoiser="gauss", flip=False)
    h, w = rgb(members[0]).shape[:2]
    k_ii = np.zeros((h, w))
    for oy in range(13):
        for ox in range(13):
            impulse = np.zeros((h, w, 3), np.float32)
            impulse[oy::13, ox::13, :] = 1
            k_ii[oy::13, ox::13] = mcpost.denoise(impulse, denoiser="gauss")[oy::13, ox::13, 0]
    # a blur of sigma 2 keeps 1 / (2 pi sigma^2) of an impulse away from the borders
    assert abs(k_ii[h // 2, w // 2] - 1 / (8 * np.pi)) < 0.002
    for path, m in zip(members, got["members"]):
        v = mcpost.read_dump(path)["variance"].astype(np.float64)
        truth = np.mean([(v[..., c] * k_ii).sum() / v[..., c].sum() for c in range(3)])
        sd = np.sqrt(sum(((v[..., c] ** 2).sum() / 2) / v[..., c].sum() ** 2
                         for c in range(3))) / 3
        assert abs(m["self_influence"] - truth) < 4 * sd + 0.002, (path, m["self_influence"],
                                                                  truth, sd)


CANDIDATES = [single("cornell", i) for i in range(4)]


@pytest.mark.parametrize("method", ["vertical-iterative", "error-diffusion", "horizontal"])
def test_perceptual_matches_the_cli(tmp, method):
    want = cli("perceptual", "--method", method, "--surrogate", "reference", "--ref",
               reference("cornell"), "-o", tmp, "--json", "--no-cache", *CANDIDATES)
    got = mcpost.perceptual(CANDIDATES, method=method, surrogate="reference",
                            reference=reference("cornell"), cache=False)
    np.testing.assert_array_equal(got["image"], rgb(tmp / f"{method}.exr"))
    if got["index"] is not None:
        index, _, _ = mcpost.read_image(tmp / f"{method}_index.exr")
        np.testing.assert_array_equal(got["index"], index)
    else:
        perm, names, _ = mcpost.read_image(tmp / f"{method}_permutation.exr")
        np.testing.assert_array_equal(got["permutation"],
                                      perm[..., [names.index("X"), names.index("Y")]])
    for key in ("energy", "pmse", "mse", "low_freq_fraction", "mean_energy", "mean_pmse",
                "pmse_ratio", "passes", "changes"):
        assert_close(got[key], want[key], err_msg=key)


def test_perceptual_from_arrays_and_errors():
    arrays = [rgb(p) for p in CANDIDATES]
    ref = rgb(reference("cornell"))
    a = mcpost.perceptual(arrays, surrogate=ref, reference=ref)
    b = mcpost.perceptual(CANDIDATES, surrogate="reference", reference=ref)
    np.testing.assert_array_equal(a["image"], b["image"])
    # every pixel takes one of the candidates' values
    pick = np.take_along_axis(np.stack(arrays), a["index"].astype(int)[None, ..., None],
                              axis=0)[0]
    np.testing.assert_array_equal(a["image"], pick)
    with pytest.raises(mcpost.Error, match="surrogate 'reference' needs a reference"):
        mcpost.perceptual(arrays, surrogate="reference")
    with pytest.raises(mcpost.Error, match="method"):
        mcpost.perceptual(arrays, surrogate=ref, method="best")
    with pytest.raises(mcpost.Error, match=r"candidates\[1\]: needs 3 channels"):
        mcpost.perceptual([arrays[0], arrays[1][..., :1]], surrogate=ref)
    with pytest.raises(mcpost.Error, match="kernel"):
        mcpost.perceptual(arrays, surrogate=ref, kernel=[0.25, 0.75])
