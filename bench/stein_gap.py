"""stein_gap.py: does Stein's lemma hold for a denoiser on a stratified scene's own noise?

SURE rests on Cov(x_i, F_i(x)) = (Sigma E[J])_ii, which is exact for Gaussian noise. On a
stratified fixture (samples/fixtures/strat) every 32-spp block of the 8 renders is a
realization of the scene's noise: 256 of them, or 256/G means of G consecutive blocks.
For each, the denoiser's output F and one JVP along a probe eps ~ N(0, Sigma) (Sigma the
per-pixel colour covariance over the realizations: exact up to their number). Printed
per region (all pixels, the darker and the brighter half of the reference):

  Cov/SigmaEJ   the covariance of the noise and the output over the realizations,
                over E[eps_i (J eps)_i]: 1 where Stein's lemma holds
  E[SURE]/MSE   the mean over realizations of (F - x)^2 - Sigma + 2 eps (J eps), over
                the mean of (F - reference)^2 (the reference's noise left in)

--gaussian replaces the render's noise by Gaussian noise of the same covariance around
the reference (the check of the measurement: both ratios 1 up to the realizations'
spread). docs/fidelity.md, "SURE and the U-Net on window", has the figures.

  /usr/bin/python3 bench/stein_gap.py [--scene window] [--denoiser unet] [--group G]
                                      [--gaussian]
Run from the repository root, with the module built (build/python)."""
import argparse

import numpy as np

from strat_fixture import block, features, mcpost, reference


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="window")
    ap.add_argument("--denoiser", default="unet")
    ap.add_argument("--group", type=int, default=1, help="blocks per realization")
    ap.add_argument("--gaussian", action="store_true")
    a = ap.parse_args()
    mcpost.set_quiet(True)
    albedo, normal = features(a.scene)
    ref = reference(a.scene)
    blocks = [[block(a.scene, r, b) for b in range(32)] for r in range(8)]
    X = np.stack([np.mean(render[g:g + a.group], axis=0)
                  for render in blocks for g in range(0, 32, a.group)])
    dev = X - X.mean(axis=0)
    cov = np.einsum("rhwi,rhwj->hwij", dev, dev) / (len(X) - 1)
    jitter = np.trace(cov, axis1=2, axis2=3)[..., None, None] * 1e-6 + 1e-20
    factor = np.linalg.cholesky(cov + np.eye(3) * jitter)
    rng = np.random.default_rng(7)
    if a.gaussian:
        X = ref + np.einsum("hwij,rhwj->rhwi", factor, rng.standard_normal(X.shape))
    var = np.diagonal(cov, axis1=2, axis2=3)
    F = np.empty_like(X)
    eps_jeps = np.zeros_like(ref)
    for r in range(len(X)):
        eps = np.einsum("hwij,hwj->hwi", factor, rng.standard_normal(ref.shape))
        F[r], jt = mcpost.jvp(X[r].astype(np.float32), [eps.astype(np.float32)],
                              albedo=albedo, normal=normal,
                              variance_of_mean=var.astype(np.float32),
                              denoiser=a.denoiser)
        eps_jeps += eps * np.asarray(jt[0], dtype=np.float64)
    eps_jeps /= len(X)
    cov_xf = ((X - X.mean(axis=0)) * (F - F.mean(axis=0))).sum(axis=0) / (len(X) - 1)
    mse = ((F - ref) ** 2).mean(axis=0)
    sure = ((F - X) ** 2).mean(axis=0) - var + 2 * eps_jeps
    brightest = ref.max(axis=2)
    dark = brightest < np.median(brightest)
    noise = "Gaussian noise" if a.gaussian else "its own noise"
    print(f"{a.scene}, {a.denoiser}, {len(X)} realizations of {32 * a.group} spp, {noise}")
    for label, m in (("all", np.ones_like(dark)), ("darker half", dark),
                     ("brighter half", ~dark)):
        print(f"  {label:14s} Cov/SigmaEJ {cov_xf[m].sum() / eps_jeps[m].sum():6.3f}"
              f"   E[SURE]/MSE {sure[m].sum() / mse[m].sum():6.3f}")


if __name__ == "__main__":
    main()
