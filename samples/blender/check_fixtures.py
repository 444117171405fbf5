"""check_fixtures.py: verify mcpost's Blender fixtures (samples/README.md).

Runs with a plain python3 that has numpy (Debian: apt-get install python3-numpy,
then /usr/bin/python3 samples/blender/check_fixtures.py [FIXTURES_DIR]) or
inside Blender's Python:
  blender -b --factory-startup --python samples/blender/check_fixtures.py -- [FIXTURES_DIR]

For every scene folder it checks the file layout and headers, then reports
  * the log-log slope of relMSE(series n vs reference) over n = 1..max,
    relMSE = mean over pixels x channels of (c - r)^2 / (r^2 + 0.01);
    must lie in [-1.2, -0.8];
  * for every realization spp n: mean over the image of Variance/n from the
    series file at n, divided by the mean over the image of the empirical
    variance (ddof 1) across the realizations at n; must lie in [0.8, 1.25].
Exit status 0 when everything passes, 1 otherwise.
"""

import glob
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import exr_min  # noqa: E402

SLOPE_RANGE = (-1.2, -0.8)
RATIO_RANGE = (0.8, 1.25)
BASE = ['R', 'G', 'B', 'Albedo.R', 'Albedo.G', 'Albedo.B', 'N.X', 'N.Y', 'N.Z']
VAR = ['Variance.R', 'Variance.G', 'Variance.B']

failures = []


def fail(msg):
    failures.append(msg)
    print('  FAIL: ' + msg)


def check_layout(path, scene, spp, want_var, allow_float_rgb=False, res=128):
    ch, attrs = exr_min.read(path)
    want = set(BASE + (VAR if want_var else []))
    if set(ch) != want:
        fail('%s: channels %s, expected %s' % (path, sorted(ch), sorted(want)))
    if spp is not None and attrs.get('samplesPerPixel') != spp:
        fail('%s: samplesPerPixel %r, expected %d' % (path, attrs.get('samplesPerPixel'), spp))
    if not attrs.get('renderer', '').startswith('Blender ') or attrs.get('scene') != scene:
        fail('%s: renderer/scene attributes %r %r' % (path, attrs.get('renderer'), attrs.get('scene')))
    if attrs['compression'] != exr_min.COMP_ZIP:
        fail('%s: compression %d, expected ZIP' % (path, attrs['compression']))
    if attrs['dataWindow'] != (0, 0, res - 1, res - 1):
        fail('%s: dataWindow %s' % (path, attrs['dataWindow']))
    for name, ptype, _pl, _xs, _ys in attrs['channels']:
        ok = ptype == exr_min.HALF or (allow_float_rgb and ptype == exr_min.FLOAT)
        if not ok:
            fail('%s: channel %s has pixel type %d' % (path, name, ptype))
    for k, v in ch.items():
        if not np.all(np.isfinite(v)):
            fail('%s: channel %s has non-finite values' % (path, k))
    return ch, attrs


def rgb(ch):
    return np.stack([ch['R'], ch['G'], ch['B']], axis=-1).astype(np.float64)


def rel_mse(c, r):
    return float(np.mean((c - r) ** 2 / (r ** 2 + 0.01)))


def check_scene(d):
    scene = os.path.basename(os.path.normpath(d))
    print('scene %s (%s)' % (scene, d))
    ref_ch, ref_at = check_layout(os.path.join(d, '%s_reference.exr' % scene), scene,
                                  None, False, allow_float_rgb=True)
    ref_spp = ref_at.get('samplesPerPixel')
    print('  reference: %s spp' % ref_spp)
    if not isinstance(ref_spp, int) or ref_spp < 8192:
        fail('%s: reference has %r spp, need >= 8192' % (scene, ref_spp))
    ref = rgb(ref_ch)

    series = {}
    for p in sorted(glob.glob(os.path.join(d, 'series', '%s_spp*.exr' % scene))):
        n = int(re.search(r'_spp(\d+)\.exr$', p).group(1))
        ch, _ = check_layout(p, scene, n, True)
        series[n] = ch
    ns = sorted(series)
    want = [2 ** k for k in range(len(ns))]
    if ns != want or ns[-1] < 1024:
        fail('%s: series spp %s, expected 1, 2, 4, ... >= 1024' % (scene, ns))
    errs = [rel_mse(rgb(series[n]), ref) for n in ns]
    for n, e in zip(ns, errs):
        v = np.mean([series[n][c] for c in VAR])
        print('  series spp %5d: relMSE %.5g   mean Variance %.5g' % (n, e, v))
    slope = float(np.polyfit(np.log(ns), np.log(errs), 1)[0])
    ok = SLOPE_RANGE[0] <= slope <= SLOPE_RANGE[1]
    print('  relMSE log-log slope over n=%d..%d: %.3f %s' % (ns[0], ns[-1], slope,
                                                           'ok' if ok else 'OUT OF RANGE'))
    if not ok:
        fail('%s: slope %.3f outside %s' % (scene, slope, SLOPE_RANGE))
    # the variance of the mean, per sample count, should follow Variance/n
    singles = sorted(glob.glob(os.path.join(d, 'singles', '%s_single*.exr' % scene)))
    print('  singles: %d files' % len(singles))
    if len(singles) < 16:
        fail('%s: %d singles, expected 16' % (scene, len(singles)))
    for i, p in enumerate(singles):
        ch, _ = check_layout(p, scene, 1, False)
        if i == 0 and not np.array_equal(rgb(ch), rgb(series[1])):
            fail('%s: single 00 differs from series spp 1' % scene)
    if len(singles) >= 2:
        m2 = np.mean([rgb(exr_min.read(p)[0]) for p in singles[:2]], axis=0)
        dev = np.abs(m2 - rgb(series[2])).max()
        print('  mean(single00, single01) vs series spp 2: max abs diff %.3g' % dev)

    reals = {}
    for p in sorted(glob.glob(os.path.join(d, 'realizations', '%s_spp*_r*.exr' % scene))):
        m = re.search(r'_spp(\d+)_r(\d+)\.exr$', p)
        n = int(m.group(1))
        ch, _ = check_layout(p, scene, n, False)
        reals.setdefault(n, []).append(rgb(ch))
    for n in sorted(reals):
        stack = np.stack(reals[n])
        emp = float(np.mean(np.var(stack, axis=0, ddof=1)))
        if n not in series:
            fail('%s: no series file at realization spp %d' % (scene, n))
            continue
        var_mean = float(np.mean([series[n][c] for c in VAR])) / n
        ratio = var_mean / emp
        ok = RATIO_RANGE[0] <= ratio <= RATIO_RANGE[1]
        real_err = np.mean([rel_mse(x, ref) for x in reals[n]])
        print('  realizations spp %d: %d files; mean Variance/spp %.5g, empirical var %.5g, '
              'ratio %.3f %s; mean relMSE %.5g (series %.5g)'
              % (n, len(reals[n]), var_mean, emp, ratio, 'ok' if ok else 'OUT OF RANGE',
                 real_err, rel_mse(rgb(series[n]), ref)))
        if not ok:
            fail('%s: variance ratio %.3f at spp %d outside %s' % (scene, ratio, n, RATIO_RANGE))
        if len(reals[n]) < 8:
            fail('%s: %d realizations at spp %d, expected 8' % (scene, len(reals[n]), n))


def main():
    argv = sys.argv[sys.argv.index('--') + 1:] if '--' in sys.argv else sys.argv[1:]
    root = argv[0] if argv else os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                             '..', 'fixtures')
    scenes = sorted(p for p in glob.glob(os.path.join(root, '*')) if os.path.isdir(p))
    # strat/ (stratified block fixtures) has its own layout and checker
    for p in [p for p in scenes if not os.path.isdir(os.path.join(p, 'series'))]:
        print('skipping %s: no series/ folder (strat/ is checked by check_strat.py)' % p)
    scenes = [p for p in scenes if os.path.isdir(os.path.join(p, 'series'))]
    if not scenes:
        print('no scene folders under %s' % root)
        return 1
    total = 0
    for d in scenes:
        check_scene(d)
        size = sum(os.path.getsize(f) for f in glob.glob(os.path.join(d, '**', '*.exr'),
                                                         recursive=True))
        print('  size %.2f MB' % (size / 1e6))
        total += size
    print('total size of EXR fixtures: %.2f MB (limit 40 MB)' % (total / 1e6))
    if total >= 40e6:
        fail('fixtures are %.2f MB' % (total / 1e6))
    print('RESULT: %s' % ('PASS' if not failures else 'FAIL (%d problems)' % len(failures)))
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
