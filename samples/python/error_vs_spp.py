#!/usr/bin/env python3
"""error_vs_spp.py: walks a progressive render and plots the error mcpost estimates
(SURE, without the reference) beside the true one (with it) against samples per pixel.

    python3 samples/python/error_vs_spp.py [--scene cornell] [--spp 1,2,4,...]
                                           [--denoiser NAME] [-o error_vs_spp.png]

For each member of samples/fixtures/SCENE/series it runs mcpost.estimate with the
reference, and plots the mean relative squared error of the denoised image (estimated:
the model's mean s²(λ + 1); true: against the reference) and the 99th percentile of the
per-value error (estimated from the error distribution; true: nearest rank), and marks
where the estimate says to stop (F(τ) >= p). It prints the numbers as a table too.
Needs build/python on PYTHONPATH (./setup.sh build does that) and python3-matplotlib."""
import argparse
import os
import sys

import matplotlib

matplotlib.use("Agg")  # files only: no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import mcpost  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
FIXTURES = os.path.join(HERE, "..", "fixtures")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="cornell", help="cornell or texture [cornell]")
    ap.add_argument("--spp", default="2,4,8,16,32,64,128,256,512,1024",
                    help="the members to walk [2,4,...,1024]; at 1 spp a render has no "
                    "variance, so nothing to estimate from")
    ap.add_argument("--denoiser", default="default",
                    help="the denoiser, as the CLI's --denoiser [default: the U-Net]")
    ap.add_argument("--tau", type=float, default=0.01, help="the error threshold [0.01]")
    ap.add_argument("-o", "--output", default="error_vs_spp.png", help="the figure")
    args = ap.parse_args(argv)

    scene_dir = os.path.join(FIXTURES, args.scene)
    reference = os.path.join(scene_dir, f"{args.scene}_reference.exr")
    spps = [int(s) for s in args.spp.split(",")]
    rows = []
    print(f"{'spp':>6} {'est mean':>10} {'true mean':>10} {'est p99':>10} {'true p99':>10}"
          f" {'F(tau)':>8} stop")
    for spp in spps:
        dump = os.path.join(scene_dir, "series", f"{args.scene}_spp{spp:04d}.exr")
        e = mcpost.estimate(dump, denoiser=args.denoiser, reference=reference,
                            tau=args.tau, percentiles=[0.99])
        true_mean = float(mcpost.true_error(e["denoised"], reference).mean(dtype=np.float64))
        row = (spp, e["expected_mean_error"], true_mean, e["percentile_error"][0],
               e["true_percentiles"][0], e["cdf_at_tau"], e["stop"])
        print(f"{spp:6d} {row[1]:10.4g} {row[2]:10.4g} {row[3]:10.4g} {row[4]:10.4g}"
              f" {row[5]:8.4f} {'yes' if row[6] else 'no'}"
              f"{'  (no variance: not plotted)' if e['no_variance'] else ''}")
        if not e["no_variance"]:
            rows.append(row)

    spp = np.array([r[0] for r in rows], dtype=float)
    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=120)
    ax.loglog(spp, [r[1] for r in rows], "o-", color="C0", label="mean RelSE, estimated")
    ax.loglog(spp, [r[2] for r in rows], "o--", color="C0", mfc="none",
              label="mean RelSE, true")
    ax.loglog(spp, [r[3] for r in rows], "s-", color="C1", label="99th percentile, estimated")
    ax.loglog(spp, [r[4] for r in rows], "s--", color="C1", mfc="none",
              label="99th percentile, true")
    ax.axhline(args.tau, color="grey", lw=0.8, ls=":", label=f"τ = {args.tau:g}")
    stops = [r[0] for r in rows if r[6]]
    if stops:
        ax.axvline(stops[0], color="C2", lw=0.8, label=f"estimate stops at {stops[0]} spp")
    ax.set_xlabel("samples per pixel")
    ax.set_ylabel("relative squared error of the denoised image")
    ax.set_title(f"{args.scene}: estimated and true error ({e['denoiser']})")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.output)
    print(f"figure written to {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
