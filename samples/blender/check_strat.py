"""check_strat.py: verify and measure mcpost's stratified fixtures
(samples/fixtures/strat, made by render_strat.py; see samples/README.md,
section "Stratified fixtures (strat/)").

Run with a python3 that has numpy:
  /usr/bin/python3 samples/blender/check_strat.py [STRAT_DIR [SCENE ...]]

For every scene folder <s> it checks the layout and headers of
blocks/<s>_r%d_b%02d.exr, <s>_features.exr and <s>_reference.exr, then
reports (n = number of samples, a multiple of the block size m = 32):

  mean_{r,n}  mean of replicate r's first n samples (mean of its first n/m
              block means);
  V_n         replicate 0's unbiased per-sample variance over its first n
              samples, combined exactly from the blocks' means and
              within-block variances (as stored, HALF);
  MSE_n       "true" MSE of an n-sample render: per pixel and channel, the
              mean over the replicates of (mean_{r,n} - ref)^2, minus the
              reference's own variance, estimated as E_1024 * 1024 / ref_spp
              (E_n = empirical variance across replicates, ddof 1; a
              stratified sampler converges at least as fast as 1/n, so this
              over-estimates it). Image figures use image means; the
              'median' figures are medians over pixels x channels of the
              per-pixel ratio, without the reference correction.

  (1) mean(V_n / n) / mean(MSE_n) at n = 32, 128, 512, 1024;
  (2) mean(E_n) / mean(MSE_n);
  (3) blocks as replicates: mean over replicates of the variance (ddof 1) of
      the 32 block means, / MSE_32, and / the variance over the replicates
      (each block, averaged over the blocks; equal sample counts on both
      sides); halves: D = (mean of samples n/2..n-1 - mean of samples
      0..n/2-1)^2 averaged over replicates, D/4 / MSE_n (what a
      two-half-buffer estimate of the variance of the n-sample mean gives)
      and D/2 / MSE_{n/2}, at n = 64, 256, 1024;
  (1)-(3) medians: the figure's ratio per pixel x channel, then the median;
      the "null" value is that median if V_n/n (or E_n) were exact, from
      the degrees of freedom, for Gaussian-like errors;
  (4) relMSE = mean of (c - ref)^2 / (ref^2 + 0.01) at n = 32, 128, 1024,
      for replicate 0 and averaged over the replicates;
  and a reference consistency figure: mean over the image of
  (mean of all replicates at 1024 - ref)^2 / mean(E_1024/R + E_1024/16),
  which should be near 1 if the reference renders the same scene.
Exit status 0 when the layout checks pass, 1 otherwise.
"""

import glob
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import exr_min  # noqa: E402

RES = 128
failures = []


def fail(msg):
    failures.append(msg)
    print('  FAIL: ' + msg)


def rgb(ch, prefix=''):
    return np.stack([ch[prefix + c] for c in 'RGB'], axis=-1).astype(np.float64)


def rel_mse(c, r):
    return float(np.mean((c - r) ** 2 / (r ** 2 + 0.01)))


def check_header(path, attrs, scene, channels, want, float_ok=()):
    if set(channels) != set(want):
        fail('%s: channels %s, expected %s' % (path, sorted(channels), sorted(want)))
    if not attrs.get('renderer', '').startswith('Blender ') or attrs.get('scene') != scene:
        fail('%s: renderer/scene %r %r' % (path, attrs.get('renderer'), attrs.get('scene')))
    if attrs['compression'] != exr_min.COMP_ZIP:
        fail('%s: compression %d' % (path, attrs['compression']))
    if attrs['dataWindow'] != (0, 0, RES - 1, RES - 1):
        fail('%s: dataWindow %s' % (path, attrs['dataWindow']))
    for name, ptype, _pl, _xs, _ys in attrs['channels']:
        if not (ptype == exr_min.HALF or (name in float_ok and ptype == exr_min.FLOAT)):
            fail('%s: channel %s has pixel type %d' % (path, name, ptype))
    for k, v in channels.items():
        if not np.all(np.isfinite(v)):
            fail('%s: channel %s has non-finite values' % (path, k))


def null_median(dof_num, dof_den, rng=np.random.default_rng(1)):
    """Median of (chi2_a/a) / (chi2_b/b): the per-pixel ratio's median if both
    estimates were exact in expectation and Gaussian-like."""
    x = rng.chisquare(dof_num, 200000) / dof_num
    y = rng.chisquare(dof_den, 200000) / dof_den
    return float(np.median(x / y))


def check_scene(d):
    s = os.path.basename(os.path.normpath(d))
    print('scene %s (%s)' % (s, d))
    files = sorted(glob.glob(os.path.join(d, 'blocks', '%s_r*_b*.exr' % s)))
    idx = {}
    for p in files:
        m = re.search(r'_r(\d+)_b(\d+)\.exr$', p)
        idx[(int(m.group(1)), int(m.group(2)))] = p
    if not idx:
        fail('%s: no block files' % s)
        return None
    R = 1 + max(r for r, _ in idx)
    B = 1 + max(b for _, b in idx)
    if len(idx) != R * B:
        fail('%s: %d block files, expected %d x %d' % (s, len(idx), R, B))
        return None
    means = np.zeros((R, B, RES, RES, 3))
    var0 = np.zeros((B, RES, RES, 3))
    m = None
    seeds = {}
    for (r, b), p in sorted(idx.items()):
        ch, at = exr_min.read(p)
        want = ['R', 'G', 'B'] + (['Variance.R', 'Variance.G', 'Variance.B'] if r == 0 else [])
        check_header(p, at, s, ch, want)
        if m is None:
            m = at.get('samplesPerPixel')
        if at.get('samplesPerPixel') != m or not isinstance(m, int):
            fail('%s: samplesPerPixel %r' % (p, at.get('samplesPerPixel')))
        if (at.get('replicate'), at.get('block'), at.get('sampleOffset')) != (r, b, m * b):
            fail('%s: replicate/block/sampleOffset %r %r %r' % (
                p, at.get('replicate'), at.get('block'), at.get('sampleOffset')))
        seeds.setdefault(r, set()).add(at.get('seed'))
        means[r, b] = rgb(ch)
        if r == 0:
            var0[b] = rgb(ch, 'Variance.')
    if any(len(v) != 1 for v in seeds.values()):
        fail('%s: a replicate has several seeds' % s)
    seed_list = [next(iter(seeds[r])) for r in range(R)]
    ch, at = exr_min.read(os.path.join(d, '%s_features.exr' % s))
    check_header(os.path.join(d, '%s_features.exr' % s), at, s, ch,
                 ['Albedo.R', 'Albedo.G', 'Albedo.B', 'N.X', 'N.Y', 'N.Z'])
    if at.get('samplesPerPixel') != m * B:
        fail('%s features: samplesPerPixel %r' % (s, at.get('samplesPerPixel')))
    ref_path = os.path.join(d, '%s_reference.exr' % s)
    ch, at = exr_min.read(ref_path)
    extra = [k for k in ch if k not in ('R', 'G', 'B')]
    check_header(ref_path, at, s, ch, ['R', 'G', 'B'] + extra, float_ok=('R', 'G', 'B'))
    ref = rgb(ch)
    ref_spp = at.get('samplesPerPixel')
    if not isinstance(ref_spp, int) or ref_spp < 16384:
        fail('%s: reference has %r spp' % (s, ref_spp))
    if 'seed' in at and at['seed'] in seed_list:
        fail('%s: reference seed equals a replicate seed' % s)
    print('  %d replicates x %d blocks x %d spp; seeds %s; reference %s spp'
          % (R, B, m, seed_list, ref_spp))

    N = B * m
    cum = np.cumsum(means, axis=1)                       # sums of block means

    def mean_n(n):                                        # (R, H, W, 3)
        return cum[:, n // m - 1] / (n // m)

    def v0(n):                                            # replicate 0's V_n
        k = n // m
        mu = means[0, :k].mean(axis=0)
        ss = (m - 1) * var0[:k].sum(axis=0) + m * ((means[0, :k] - mu) ** 2).sum(axis=0)
        return ss / (n - 1)

    E_N = np.var(mean_n(N), axis=0, ddof=1)
    vref = E_N * N / ref_spp

    def mse(n, px=False):
        raw = np.mean((mean_n(n) - ref) ** 2, axis=0)
        return raw if px else float(raw.mean() - vref.mean())

    out = {'R': R, 'B': B, 'm': m, 'ref_spp': ref_spp, 'seeds': seed_list}
    print('  reference variance estimate: mean %.4g = %.1f%% of MSE_%d'
          % (vref.mean(), 100 * vref.mean() / mse(N), N))

    rows = []
    for n in (32, 128, 512, 1024):
        if n > N:
            continue
        mse_n = mse(n)
        vn = v0(n) / n
        e_n = np.var(mean_n(n), axis=0, ddof=1)
        mse_px = np.maximum(mse(n, px=True), 1e-30)
        rows.append((n, vn.mean() / mse_n, float(np.median(vn / mse_px)),
                     null_median(n - 1, R), e_n.mean() / mse_n,
                     float(np.median(e_n / mse_px)), null_median(R - 1, R),
                     mse_n, vn.mean()))
        print('  n %4d: (1) mean(V/n)/MSE %.3f, median %.3f (null %.3f); '
              '(2) E/MSE %.3f, median %.3f (null %.3f); MSE %.4g, mean V/n %.4g' % rows[-1])
    out['var'] = rows

    bvar = np.var(means, axis=1, ddof=1).mean(axis=0)   # per pixel, mean over replicates
    mse32 = mse(m)
    out['blocks'] = (bvar.mean() / mse32,
                     float(np.median(bvar / np.maximum(mse(m, px=True), 1e-30))))
    print('  (3) variance of the %d block means / MSE_%d: %.3f (median pixel %.3f)'
          % (B, m, out['blocks'][0], out['blocks'][1]))
    # the same with equal sample counts on both sides: the spread over the 32
    # blocks (per replicate, averaged over the replicates) against the spread
    # over the 8 replicates (per block, averaged over the blocks). Heavy-tailed
    # pixels make the median above depend on how many samples each side saw.
    across = np.var(means, axis=0, ddof=1).mean(axis=0)
    out['blocks_eq'] = (bvar.mean() / across.mean(),
                        float(np.median(bvar / np.maximum(across, 1e-30))))
    print('  (3) the same against the spread over replicates averaged over blocks: '
          '%.3f (median pixel %.3f)' % out['blocks_eq'])
    halves = []
    for n in (64, 256, 1024):
        if n > N:
            continue
        k = n // m
        h1 = cum[:, k // 2 - 1] / (k // 2)
        h2 = (cum[:, k - 1] - cum[:, k // 2 - 1]) / (k - k // 2)
        D = ((h2 - h1) ** 2).mean(axis=0)
        halves.append((n, D.mean() / 4 / mse(n), D.mean() / 2 / mse(n // 2),
                       float(np.median(D / 4 / np.maximum(mse(n, px=True), 1e-30)))))
        print('  (3) halves at n %4d: (D/4)/MSE_n %.3f, (D/2)/MSE_n/2 %.3f, '
              'median pixel (D/4)/MSE_n %.3f' % halves[-1])
    out['halves'] = halves

    rel = []
    for n in (32, 128, 1024):
        if n > N:
            continue
        mn = mean_n(n)
        rel.append((n, rel_mse(mn[0], ref), float(np.mean([rel_mse(x, ref) for x in mn]))))
        print('  (4) relMSE at n %4d: replicate 0 %.4g, mean over replicates %.4g' % rel[-1])
    out['relmse'] = rel

    avg = mean_n(N).mean(axis=0)
    cons = float(np.mean((avg - ref) ** 2) / np.mean(E_N / R + vref))
    lo = ref < 1
    sums = float(avg[lo].sum() / ref[lo].sum() - 1)
    out['consistency'] = (cons, sums)
    print('  reference consistency: (all-replicate mean at %d - ref)^2 / expected %.3f; '
          'sum over pixels with ref < 1 differs by %+.3f%%' % (N, cons, 100 * sums))
    if not 0.5 <= cons <= 2.0:
        fail('%s: the reference does not match the replicates (%.3f)' % (s, cons))
    size = sum(os.path.getsize(f) for f in glob.glob(os.path.join(d, '**', '*.exr'),
                                                     recursive=True))
    out['size'] = size
    print('  size %.2f MB (blocks %.2f MB)' % (size / 1e6,
                                               sum(os.path.getsize(f) for f in files) / 1e6))
    return s, out


def main():
    argv = sys.argv[1:]
    root = argv[0] if argv else os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                             '..', 'fixtures', 'strat')
    scenes = sorted(p for p in glob.glob(os.path.join(root, '*')) if os.path.isdir(p))
    if argv[1:]:                                  # only the scenes named
        scenes = [p for p in scenes if os.path.basename(p) in argv[1:]]
    if not scenes:
        print('no scene folders under %s' % root)
        return 1
    res = {}
    for d in scenes:
        try:
            r = check_scene(d)
        except (OSError, exr_min.ExrError) as e:
            fail('%s: %s' % (d, e))
            continue
        if r:
            res[r[0]] = r[1]
    total = sum(v['size'] for v in res.values())
    print('total size of EXR files: %.2f MB' % (total / 1e6))

    print('\nMarkdown tables:\n')
    print('| scene | n | (1) mean V/n ÷ MSE | (1) median pixel (null) | (2) E ÷ MSE | '
          '(2) median pixel (null) |')
    print('|---|---|---|---|---|---|')
    for s, o in res.items():
        for n, r1, med, nm, r2, med2, nm2, _mse, _v in o['var']:
            print('| %s | %d | %.2f | %.2f (%.2f) | %.2f | %.2f (%.2f) |'
                  % (s, n, r1, med, nm, r2, med2, nm2))
    print('\n| scene | blocks: var of 32 block means ÷ MSE_32 (median) | '
          'same ÷ var over replicates (median) | halves n=64: '
          'D/4÷MSE_n, D/2÷MSE_n/2 (median pixel D/4÷MSE_n) | n=256 | n=1024 |')
    print('|---|---|---|---|---|---|')
    for s, o in res.items():
        print('| %s | %.2f (%.2f) | %.2f (%.2f) | %s |' % (
            s, o['blocks'][0], o['blocks'][1], o['blocks_eq'][0], o['blocks_eq'][1], ' | '.join(
            '%.2f, %.2f (%.2f)' % (a, b, c) for _n, a, b, c in o['halves'])))
    print('\n| scene | relMSE r0 / mean over replicates at 32 | 128 | 1024 | '
          'reference consistency | sum diff (ref<1) |')
    print('|---|---|---|---|---|---|')
    for s, o in res.items():
        print('| %s | %s | %.2f | %+.2f%% |' % (s, ' | '.join(
            '%.3g / %.3g' % (a, b) for _n, a, b in o['relmse']),
            o['consistency'][0], 100 * o['consistency'][1]))
    print('RESULT: %s' % ('PASS' if not failures else 'FAIL (%d problems)' % len(failures)))
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
