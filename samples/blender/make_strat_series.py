"""make_strat_series.py: a progressive series from a stratified fixture's blocks.

A renderer's user has a progressive render with checkpoints, not blocks. This
writes that form of replicate 0 of one scene of samples/fixtures/strat: at
n = 32, 64, 128, 256, 512, 1024 spp, the running mean of its first n/32 blocks
(R, G, B), the per-sample variance of all n samples combined exactly from the
blocks' means and within-block variances (Variance.R/G/B, S/(n-1), as pbrt-v4
writes it), the scene's features (Albedo.*, N.*) and int samplesPerPixel, in
<scene>/series/<scene>_spp%04d.exr (HALF, ZIP). No rendering: numpy only.

  /usr/bin/python3 samples/blender/make_strat_series.py samples/fixtures/strat texture
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import exr_min  # noqa: E402

BLOCK = 32


def main(root, scene):
    d = os.path.join(root, scene)
    feats, _ = exr_min.read(os.path.join(d, scene + '_features.exr'))
    os.makedirs(os.path.join(d, 'series'), exist_ok=True)
    total = m2 = None
    count = 0
    for b in range(32):
        ch, _ = exr_min.read(os.path.join(d, 'blocks', '%s_r0_b%02d.exr' % (scene, b)))
        mean = np.stack([ch[c].astype(np.float64) for c in 'RGB'])
        var = np.stack([ch['Variance.' + c].astype(np.float64) for c in 'RGB'])
        if total is None:
            total, m2, count = mean * BLOCK, var * (BLOCK - 1), BLOCK
        else:
            # Chan et al.: sums of squared deviations of two groups combined exactly
            delta = mean - total / count
            m2 = m2 + var * (BLOCK - 1) + delta ** 2 * count * BLOCK / (count + BLOCK)
            total, count = total + mean * BLOCK, count + BLOCK
        if count not in (32, 64, 128, 256, 512, 1024):
            continue
        out = {c: (total[i] / count).astype(np.float32) for i, c in enumerate('RGB')}
        for i, c in enumerate('RGB'):
            out['Variance.' + c] = (m2[i] / (count - 1)).astype(np.float32)
        for k, v in feats.items():
            out[k] = v
        path = os.path.join(d, 'series', '%s_spp%04d.exr' % (scene, count))
        exr_min.write(path, {k: exr_min.clamp_half(v)[0] for k, v in out.items()},
                      attrs={'samplesPerPixel': count, 'scene': scene,
                             'renderer': 'Blender 3.4.1 Cycles (stratified, from blocks)'})
        print(path)


if __name__ == '__main__':
    main(sys.argv[1], sys.argv[2])
