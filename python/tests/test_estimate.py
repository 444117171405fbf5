"""estimate against `mcpost estimate --json -o DIR` on a committed render: the decision,
F(τ), the percentile curve, the distribution, the true percentiles, and the maps the CLI
writes, value for value."""
import mcpost
import numpy as np
import pytest

from conftest import assert_close, cli, reference, rgb, series

ARGS = ["--denoiser", "nlm", "--probes", "2", "--seed", "5", "--budget", "16384",
        "--tau", "0.02"]


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    out = tmp_path_factory.mktemp("estimate")
    want = cli("estimate", series("cornell", 32), *ARGS, "--ref", reference("cornell"),
               "--json", "-o", out)
    got = mcpost.estimate(series("cornell", 32), denoiser="nlm", probes=2, seed=5,
                          budget=16384, tau=0.02, reference=reference("cornell"),
                          taus=[0.02, 0.05, 1e9])
    return got, want, out


def test_the_decision_and_curve_match_the_cli(both):
    got, want, _ = both
    assert got["stop"] == want["stop"]
    assert_close(got["cdf_at_tau"], want["cdf_at_tau"])
    assert got["tau"] == want["tau"] and got["p"] == want["p"]
    assert_close(got["percentile_error"], [p["error"] for p in want["percentiles"]])
    assert_close(got["percentiles"], [p["p"] for p in want["percentiles"]])
    assert_close(got["true_percentiles"], want["true_percentiles"])
    assert got["blocks"] == want["blocks"]
    assert_close(got["expected_mean_error"], want["expected_mean_error"])
    assert_close(got["mean_lambda"], want["distribution"]["mean_lambda"])
    assert_close(got["mean_s2"], want["distribution"]["mean_s2"])
    assert got["variance_source"] == want["variance_source"]
    # F at the taus asked for: the first is F(tau), F never falls, and reaches 1
    assert got["cdf"][0] == got["cdf_at_tau"]
    assert got["cdf"][0] <= got["cdf"][1] <= got["cdf"][2] == pytest.approx(1.0)


def test_the_maps_match_the_cli_files(both):
    got, _, out = both
    for key, name in [("denoised", "denoised"), ("sure", "sure"), ("sure_rel", "sure_rel"),
                      ("variance", "variance"), ("variance_rel", "variance_rel"),
                      ("blocks_sure_rel", "blocks_sure_rel")]:
        np.testing.assert_array_equal(got[key], rgb(out / f"{name}.exr"), err_msg=key)
    for key in ("sampling_map", "sample_counts"):
        want, _, _ = mcpost.read_image(out / f"{key}.exr")
        np.testing.assert_array_equal(got[key], want, err_msg=key)
    assert got["sample_counts"].sum(dtype=np.float64) == 16384
    dist, names, _ = mcpost.read_image(out / "distribution.exr")
    assert names == ["lambda.R", "lambda.G", "lambda.B"]
    np.testing.assert_array_equal(got["lambda"], dist)
    # the distribution's s² is Var[F]^r: the file is variance_rel.exr
    np.testing.assert_array_equal(got["s2"], rgb(out / "variance_rel.exr"))
    labels = got["block_labels"]
    assert labels.shape == (128, 128) and labels.max() == got["blocks"] - 1


def test_a_dump_dict_gives_the_same_estimate(both):
    got, _, _ = both
    again = mcpost.estimate(mcpost.read_dump(series("cornell", 32)), denoiser="nlm",
                            probes=2, seed=5, tau=0.02)
    assert again["cdf_at_tau"] == got["cdf_at_tau"]
    np.testing.assert_array_equal(again["sure"], got["sure"])


def test_true_error_matches_the_truth_of_estimate(both):
    got, _, _ = both
    err = mcpost.true_error(got["denoised"], reference("cornell"))
    f = got["denoised"].astype(np.float64)
    r = rgb(reference("cornell")).astype(np.float64)
    want = (f - r) ** 2 / (f.max(axis=2, keepdims=True) ** 2 + 1e-2)
    np.testing.assert_allclose(err, want, rtol=1e-5)


def test_estimate_options_and_errors():
    d = mcpost.read_dump(series("cornell", 8))
    want = cli("estimate", series("cornell", 8), "--denoiser", "gauss", "--metric", "se",
               "--variance-probes", "rademacher", "--s2-pool", "auto", "--tile", "32",
               "--json")
    got = mcpost.estimate(d, denoiser="gauss", metric="se", variance_probes="rademacher",
                          s2_pool="auto", tile=32)
    assert_close(got["cdf_at_tau"], want["cdf_at_tau"])
    assert got["blocks"] == want["blocks"] and got["s2_pool"] == want["s2_pool"]
    with pytest.raises(mcpost.Error, match="tau must be > 0"):
        mcpost.estimate(d, tau=-1, denoiser="gauss")
    with pytest.raises(mcpost.Error, match="unknown metric 'mse'"):
        mcpost.estimate(d, metric="mse", denoiser="gauss")
    with pytest.raises(mcpost.Error, match="budget must be a whole number"):
        mcpost.estimate(d, budget=1.5, denoiser="gauss")
    with pytest.raises(TypeError, match="dump must be a dump"):
        mcpost.estimate(3, denoiser="gauss")


# ---- a progressive render: estimate([paths...]) as `mcpost estimate DUMP DUMP...` ----

STRAT = "samples/fixtures/strat/texture"


def strat_series():
    import glob
    import os
    from conftest import SOURCE
    paths = sorted(glob.glob(os.path.join(SOURCE, STRAT, "series", "*.exr")))
    assert len(paths) == 6  # 32 .. 1024 spp, one stratified render's checkpoints
    return paths, os.path.join(SOURCE, STRAT, "texture_reference.exr")


def test_a_series_matches_the_cli_and_the_truth():
    paths, ref = strat_series()
    got = mcpost.estimate(paths, denoiser="nlm", reference=ref, taus=[0.05, 0.02])
    want = cli("estimate", *paths, "--denoiser", "nlm", "--ref", ref, "--taus",
               "0.05,0.02", "--json")
    assert got["first_spp"] == [t["first_spp"] for t in want["taus"]]
    assert got["true_first_spp"] == [t["true_first_spp"] for t in want["taus"]]
    assert got["variance_source"] == want["variance_source"] == "increments"
    for g, w in zip(got["members"], want["members"]):
        assert g["spp"] == w["spp"]
        assert_close(g["cdf"], w["cdf"])
        assert g["stop"] == w["stop"] and g["held"] == w["held"]
        assert g["sure_groups"] == w["sure_groups"]
        assert g["probes_from_groups"] == w["probes_from_groups"]
        assert_close(g["true_cdf"], w["true_cdf"])
    # against the truth (the 23552-spp reference): both stops agree
    # (docs/fidelity.md's rule), and the groups measure SURE from the third member on
    assert got["agree"] == [True, True] and got["agreement_rate"] == 1.0
    assert [m["sure_groups"] > 0 for m in got["members"]] == [False, False] + [True] * 4
    # Variance/n of this stratified render is twice what its increments show
    assert 1.8 < got["variance_ratio"] < 2.2
    assert got["stop"] == all(got["members"][-1]["stop"])


def test_a_series_takes_the_cli_options():
    paths, _ = strat_series()
    # the renderer's per-sample variance kept on purpose: from the third member the
    # probes come from the groups' variance, which it overstates (docs/fidelity.md)
    kept = mcpost.estimate(paths, denoiser="nlm", variance_from="file", taus=[0.02])
    assert kept["variance_source"] == "per-sample"
    assert [m["probes_from_groups"] for m in kept["members"]] == [False] * 2 + [True] * 4
    # no groups: the probes' divergence everywhere, and no member held
    plain = mcpost.estimate(paths, denoiser="nlm", sure_groups=0, taus=[0.02])
    assert all(m["sure_groups"] == 0 and not m["held"] for m in plain["members"])
    want = cli("estimate", *paths, "--denoiser", "nlm", "--sure-groups", "0", "--taus",
               "0.02", "--json")
    assert_close([m["cdf"][0] for m in plain["members"]],
                 [m["cdf"][0] for m in want["members"]])
    with pytest.raises(mcpost.Error, match="estimate: no dumps given"):
        mcpost.estimate([], denoiser="nlm")
    with pytest.raises(TypeError, match=r"dumps\[1\]"):
        mcpost.estimate([paths[0], 3], denoiser="nlm")
    with pytest.raises(mcpost.Error, match="no_such.exr"):
        mcpost.estimate([paths[0], "no_such.exr"], denoiser="nlm")
