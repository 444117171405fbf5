"""jackknife_cov.py: can a render's own blocks say how much of its noise a denoiser keeps?

SURE's divergence term (and the blend's self-influence, docs/blend.md) reads
Cov(n_i, d_i) as v_i E[dd_i/dn_i], Stein's lemma, which fails on a stratified scene's
heavy-tailed noise at low sample counts (bench/stein_gap.py; docs/fidelity.md). A render
made of G blocks carries realizations of that noise itself: the delete-a-group jackknife

    n_(k) = (G n - b_k) / (G - 1),   d_(k) = F(n_(k)) with the variance G / (G - 1) v,
    C_i = (G - 1) / G * sum_k (n_(k),i - mean n_(.),i) (d_(k),i - mean d_(.),i)

estimates Cov(n_i, d_i) under the real noise, at G denoiser applies. For each of a
stratified fixture's 8 renders (its first G blocks of 32 spp; v the 8 renders' spread
at that count, averaged over 5x5 pixels, the same for every render, so that the
denoiser's input is the same in all three), printed as sums over the image over sum v:

  true      the covariance of n and d over the 8 renders
  SURE      (SURE - (d - n)^2 + v) / 2 with 4 probes (the blend's kappa)
  jackknife C above
each as the mean over the renders and the spread (standard deviation) of one render's;
then SURE over the image, (d - n)^2 - v + 2 C with either C, against the true squared
error of d (the 16384-spp reference's own noise left in), the mean over the renders.

  /usr/bin/python3 bench/jackknife_cov.py [--scene stilllife] [--denoiser nlm] [--groups 4]
Run from the repository root, with the module built (build/python)."""
import argparse
import sys

import numpy as np

from strat_fixture import block, features, mcpost, reference

RENDERS = 8


def box5(img):
    """The mean over 5x5 pixels, edges repeated."""
    pad = np.pad(img, ((2, 2), (2, 2), (0, 0)), mode="edge")
    h, w = img.shape[:2]
    return sum(pad[y:y + h, x:x + w] for y in range(5) for x in range(5)) / 25.0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="stilllife")
    ap.add_argument("--denoiser", default="nlm")
    ap.add_argument("--groups", type=int, default=4, help="blocks G of 32 spp (2..32)")
    a = ap.parse_args()
    if not 2 <= a.groups <= 32:
        sys.exit("jackknife_cov.py: --groups must be 2 to 32")
    mcpost.set_quiet(True)
    albedo, normal = features(a.scene)
    G = a.groups
    ref = reference(a.scene)
    blocks = np.array([[block(a.scene, r, b) for b in range(G)] for r in range(RENDERS)])
    n = blocks.mean(axis=1)
    v = box5(n.var(axis=0, ddof=1))

    def denoise(x, var):
        return np.asarray(mcpost.denoise(
            x.astype(np.float32), denoiser=a.denoiser, albedo=albedo, normal=normal,
            variance_of_mean=var.astype(np.float32)), dtype=np.float64)

    d = np.empty_like(n)
    sure_c, jack_c = [], []
    for r in range(RENDERS):
        dump = {"color": n[r].astype(np.float32), "variance": v.astype(np.float32),
                "albedo": albedo, "normal": normal, "spp": 32.0 * G}
        e = mcpost.estimate(dump, denoiser=a.denoiser, metric="se", probes=4)
        d[r] = np.asarray(e["denoised"], dtype=np.float64)
        sure_c.append((np.asarray(e["sure"], dtype=np.float64) - (d[r] - n[r]) ** 2 + v) / 2)
        loo = (G * n[r] - blocks[r]) / (G - 1)
        d_loo = np.array([denoise(x, v * G / (G - 1)) for x in loo])
        jack_c.append((G - 1) / G * ((loo - loo.mean(axis=0)) *
                                     (d_loo - d_loo.mean(axis=0))).sum(axis=0))
    true_c = ((n - n.mean(axis=0)) * (d - d.mean(axis=0))).sum(axis=0) / (RENDERS - 1)
    sv = v.sum()
    mse = ((d - ref) ** 2).sum(axis=(1, 2, 3)).mean()
    resid = ((d - n) ** 2).sum(axis=(1, 2, 3)) - sv
    print(f"{a.scene}, {a.denoiser}, {RENDERS} renders of {G} blocks ({32 * G} spp): "
          "Cov(n, d) summed over the image / sum v")
    print(f"  true       {true_c.sum() / sv:.3f}")
    for name, c in (("SURE", sure_c), ("jackknife", jack_c)):
        per = np.array([x.sum() / sv for x in c])
        print(f"  {name:<10} {per.mean():.3f} (one render's spread {per.std(ddof=1):.3f})")
    for name, c in (("SURE", sure_c), ("jackknife", jack_c)):
        sure = resid + 2 * np.array([x.sum() for x in c])
        print(f"  E[SURE] / MSE with the {name}'s C: {sure.mean() / mse:.3f}")


if __name__ == "__main__":
    main()
