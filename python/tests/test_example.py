"""samples/python/error_vs_spp.py runs, writes its figure, and prints the numbers that
mcpost.estimate gives."""
import os
import subprocess
import sys

import mcpost
import numpy as np

from conftest import SOURCE, reference, series


def test_the_example_plots_estimate_and_truth(tmp):
    script = os.path.join(SOURCE, "samples", "python", "error_vs_spp.py")
    fig = tmp / "fig.png"
    out = subprocess.run([sys.executable, script, "--spp", "1,8,32", "--denoiser", "gauss",
                          "-o", str(fig)], check=True, capture_output=True, text=True).stdout
    assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and fig.stat().st_size > 10000
    lines = out.splitlines()
    assert "no variance: not plotted" in lines[1]  # 1 spp
    for line, spp in zip(lines[2:4], (8, 32)):
        cols = line.split()
        e = mcpost.estimate(series("cornell", spp), denoiser="gauss",
                            reference=reference("cornell"), percentiles=[0.99])
        true_mean = mcpost.true_error(e["denoised"], reference("cornell")).mean(
            dtype=np.float64)
        want = [spp, e["expected_mean_error"], true_mean, e["percentile_error"][0],
                e["true_percentiles"][0], e["cdf_at_tau"]]
        np.testing.assert_allclose([float(c) for c in cols[:6]], want, rtol=1e-3)
    assert lines[-1] == f"figure written to {fig}"
