"""Does SURE see the U-Net's error on fine texture? (docs/fidelity.md, "SURE and the
U-Net on texture"). On the stratified texture fixture, 8 renders of 128 spp (their first
four 32-spp blocks) merged as replicates (the variance from their spread, 7 degrees of
freedom), SURE summed over each 16x16 block against the true squared error of the
denoised image there, for nlm and the U-Net. A report had the U-Net's ratio at 0.26-0.65
(nlm's near 1) on other renders whose replicates were not fully independent; on
independent replicates both are near 1. The true error includes the 16384-spp
reference's own noise, about 6% of it here, so the ratios sit a little below 1."""
import os

import numpy as np
import mcpost
import pytest

from conftest import SOURCE, strat_replicates

STRAT = os.path.join(SOURCE, "samples", "fixtures", "strat", "texture")


def block_ratios(sure, true, size=16):
    h, w = true.shape[:2]
    return np.array([sure[y:y + size, x:x + size].sum() / true[y:y + size, x:x + size].sum()
                     for y in range(0, h - size + 1, size)
                     for x in range(0, w - size + 1, size)])


@pytest.fixture(scope="module")
def merged(tmp_path_factory):
    return strat_replicates(tmp_path_factory.mktemp("sure_texture"), "texture", 4)[0]


@pytest.mark.parametrize("denoiser", ["nlm", "unet"])
def test_sure_per_block_tracks_the_true_error(merged, denoiser):
    ref = mcpost.read_image(os.path.join(STRAT, "texture_reference.exr"))[0][..., :3]
    e = mcpost.estimate(merged, denoiser=denoiser, metric="se")
    true = (e["denoised"].astype(np.float64) - ref) ** 2
    ratios = block_ratios(e["sure"].astype(np.float64), true)
    median = np.median(ratios)
    # measured (4 probes, seed 0): nlm 0.915, unet 0.961 (8 probes: 0.905, 0.951)
    assert 0.8 <= median <= 1.1, f"{denoiser}: median SURE/true per block {median:.3f}"
    # and the U-Net is not the one that SURE misses
    assert np.percentile(ratios, 25) >= 0.7
