"""mcpost-cycles-render.py: render a .blend with Cycles into what mcpost needs.

Cycles writes no variance pass, so a plain Cycles render cannot be estimated,
blended or adapted. This tool renders the scene of a .blend K times with other
seeds ("replicates"), each as a progressive render in C chunks at sample offsets,
and writes after every chunk the running mean as one multilayer EXR in Cycles'
own naming (<layer>.Combined.R/G/B, <layer>.Denoising Albedo.R/G/B,
<layer>.Denoising Normal.X/Y/Z, string cycles.<layer>.samples), which mcpost
reads as they are: `mcpost merge` (which the tool runs where it finds mcpost)
makes of the K seeds' checkpoints at each sample count one dump whose variance
comes from their spread, and those merged checkpoints are a progressive series
for `estimate --series` and `blend`. docs/conventions.md, "From a .blend to an
estimate", shows the whole path.

Run it inside Blender (its options after `--`):

  blender -b scene.blend --python tools/mcpost-cycles-render.py -- \
      --out renders --seeds 4 --spp 256 --chunks 8

`... --python tools/mcpost-cycles-render.py -- --help` (or plain
`python3 tools/mcpost-cycles-render.py --help`) prints the options.

Works with Blender 3.4 (Debian 12): chunk c is cycles.samples = N/C at
cycles.sample_offset = c*N/C. Blender 4.x replaced that with the sample subset
(cycles.use_sample_subset, cycles.sample_offset, cycles.sample_subset_length,
with cycles.samples the whole count N); the tool uses those where they exist.
"""

import argparse
import os
import shutil
import struct
import sys
import tempfile
import time
import zlib

PROG = 'mcpost-cycles-render.py'

EPILOG = """\
files written (N = --spp, m = N/C, K = --seeds):
  OUT/seed<k>/<name>_spp%%04d.exr   k = 0..K-1: seed k's running mean after each chunk,
                                   at m, 2m, ..., N samples (the last one is seed k's
                                   whole render); no variance, as Cycles writes none
  OUT/<name>_spp%%04d.exr           with K >= 2 and mcpost found (--mcpost): at K*m,
                                   2K*m, ..., K*N samples, the K seeds' checkpoints
                                   merged by `mcpost merge` (variance of the mean from
                                   their spread, K - 1 degrees of freedom): a series
  OUT/mcpost-cycles-render.txt     the settings and the mcpost commands for them

then (K = 4, N = 64, C = 4, --name render; a run prints its own):
  mcpost estimate OUT/render_spp0256.exr -o OUT/estimate
  mcpost estimate --series 'OUT/render_spp%%04d.exr' --spp 64,128,192,256 -o OUT/series
  mcpost blend 'OUT/render_spp%%04d.exr' --spp 64,128,192,256 -o OUT/blend
without mcpost at render time, the same merge by hand (one per checkpoint):
  mcpost merge OUT/seed*/render_spp0064.exr -o OUT/render_spp0256.exr
in a job file: frame: {replicates: OUT/seed*/render_spp0064.exr}

One seed's checkpoints alone have no variance (mcpost's increments give none to the
first member of a series), so estimate, blend and adaptive need the merged files.
Cycles (3.4) cannot render a per-pixel sample count, so `mcpost adaptive` cannot
drive it: docs/conventions.md, "From a .blend to an estimate".
"""


def parse_args(argv):
    ap = argparse.ArgumentParser(
        prog='blender -b scene.blend --python %s --' % PROG,
        description='Render the scene of a .blend with Cycles into multilayer EXRs that '
                    'mcpost can estimate, blend and merge: --seeds independent renders '
                    '(own seed each), each progressive in --chunks chunks at sample '
                    'offsets, the running mean written after every chunk, with the '
                    'Denoising Albedo and Normal passes. Adaptive sampling and denoising '
                    'are switched off; everything else is the scene\'s.',
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--out', required=True, help='output folder (created)')
    ap.add_argument('--seeds', type=int, default=4, metavar='K',
                    help='independent renders (replicates), at least 2 for `mcpost merge` '
                         '[4]')
    ap.add_argument('--spp', type=int, default=64, metavar='N',
                    help='samples per pixel of each seed\'s render [64]')
    ap.add_argument('--chunks', type=int, default=4, metavar='C',
                    help='chunks of N/C samples per seed: the checkpoints of its '
                         'series, at least 2 for the increments; C must divide N [4]')
    ap.add_argument('--resolution', metavar='WxH',
                    help='image size (at 100%%) [the scene\'s, at its percentage]')
    ap.add_argument('--frame', type=int, help='frame to render [the scene\'s current]')
    ap.add_argument('--name', default='render',
                    help='file name stem: seed<k>/<name>_spp%%04d.exr [render]')
    ap.add_argument('--seed-base', type=int, default=0, metavar='S',
                    help='seed k renders with Cycles seed hash(S + k) [0]')
    ap.add_argument('--device', choices=['CPU', 'GPU'],
                    help='Cycles device [the scene\'s]')
    ap.add_argument('--threads', type=int, default=0,
                    help='render threads, 0: all [0]')
    ap.add_argument('--mcpost', metavar='PATH',
                    help='the mcpost tool that merges the seeds\' checkpoints [mcpost on '
                         'PATH; none: no merge]')
    ap.add_argument('--keep-chunks', action='store_true',
                    help='keep each chunk\'s own Cycles EXR as OUT/seed<k>/chunks/'
                         '<name>_c%%02d.exr (N/C samples each)')
    a = ap.parse_args(argv)
    if a.seeds < 1 or a.spp < 1 or a.chunks < 1:
        ap.error('--seeds, --spp and --chunks must be positive')
    if a.spp % a.chunks:
        ap.error('--chunks %d does not divide --spp %d' % (a.chunks, a.spp))
    if a.resolution:
        try:
            w, h = (int(v) for v in a.resolution.lower().split('x'))
            if w < 1 or h < 1:
                raise ValueError
        except ValueError:
            ap.error('--resolution: expected WxH, e.g. 640x360, got %r' % a.resolution)
        a.size = (w, h)
    else:
        a.size = None
    return a


def seed_of(base, k):
    """Cycles seed of replicate k: a 32-bit integer hash, so that the seeds differ in
    all bits (Cycles mixes the seed into its per-pixel hash). In [0, 2^31)."""
    x = ((base + k) * 0x9E3779B1 + 0x165667B1) & 0xFFFFFFFF
    x ^= x >> 16
    x = (x * 0x7FEB352D) & 0xFFFFFFFF
    x ^= x >> 15
    x = (x * 0x846CA68B) & 0xFFFFFFFF
    x ^= x >> 16
    return x & 0x7FFFFFFF


# ------------------------------------------------------------------ EXR I/O
# Blender writes the chunks uncompressed float32 (set below); the checkpoints are
# written as float32 with ZIP compression. Single-part scanline files only.

def _cstr(buf, pos):
    end = buf.index(b'\0', pos)
    return buf[pos:end].decode('latin-1'), end + 1


def exr_read(path):
    """(channels {name: float32 (h, w)}, string attributes) of an uncompressed
    scanline EXR with FLOAT/HALF channels, as Blender writes it with codec NONE."""
    import numpy as np
    with open(path, 'rb') as f:
        buf = f.read()
    magic, version = struct.unpack_from('<ii', buf, 0)
    if magic != 20000630 or (version & 0xFF) != 2 or version & 0x1A00:
        raise RuntimeError('%s: not a single-part scanline EXR' % path)
    pos, chans, strings, comp, win = 8, [], {}, None, None
    while buf[pos] != 0:
        name, pos = _cstr(buf, pos)
        typ, pos = _cstr(buf, pos)
        size = struct.unpack_from('<i', buf, pos)[0]
        pos += 4
        val = buf[pos:pos + size]
        pos += size
        if typ == 'chlist':
            p = 0
            while val[p] != 0:
                cname, p = _cstr(val, p)
                ptype = struct.unpack_from('<i', val, p)[0]
                p += 16
                chans.append((cname, ptype))
        elif typ == 'compression':
            comp = val[0]
        elif name == 'dataWindow':
            win = struct.unpack('<iiii', val)
        elif typ == 'string':
            strings[name] = val.decode('utf-8', 'replace')
    pos += 1
    if comp != 0:
        raise RuntimeError('%s: compressed (%d); expected an uncompressed EXR' % (path, comp))
    w, h = win[2] - win[0] + 1, win[3] - win[1] + 1
    dt = {1: np.dtype('<f2'), 2: np.dtype('<f4')}
    for c in chans:
        if c[1] not in dt:
            raise RuntimeError('%s: channel %s is not HALF or FLOAT' % (path, c[0]))
    line = np.dtype([(c[0], dt[c[1]], (w,)) for c in chans])
    offsets = struct.unpack_from('<%dQ' % h, buf, pos)
    out = {c[0]: np.empty((h, w), np.float32) for c in chans}
    for off in offsets:
        y, size = struct.unpack_from('<ii', buf, off)
        row = np.frombuffer(buf, line, 1, off + 8)
        for c in chans:
            out[c[0]][y - win[1]] = row[c[0]][0]
    return out, strings


def _attr(name, typ, payload):
    return (name.encode('latin-1') + b'\0' + typ.encode('latin-1') + b'\0'
            + struct.pack('<i', len(payload)) + payload)


def exr_write(path, channels, strings):
    """Write channels {name: (h, w)} as float32, ZIP (16 lines a chunk), with string
    attributes; to a temporary name, then renamed."""
    import numpy as np
    names = sorted(channels)
    h, w = channels[names[0]].shape
    chl = b''.join(n.encode('latin-1') + b'\0' + struct.pack('<iBBBBii', 2, 0, 0, 0, 0, 1, 1)
                   for n in names) + b'\0'
    hdr = [_attr('channels', 'chlist', chl),
           _attr('compression', 'compression', bytes([3])),
           _attr('dataWindow', 'box2i', struct.pack('<iiii', 0, 0, w - 1, h - 1)),
           _attr('displayWindow', 'box2i', struct.pack('<iiii', 0, 0, w - 1, h - 1)),
           _attr('lineOrder', 'lineOrder', bytes([0])),
           _attr('pixelAspectRatio', 'float', struct.pack('<f', 1.0)),
           _attr('screenWindowCenter', 'v2f', struct.pack('<ff', 0.0, 0.0)),
           _attr('screenWindowWidth', 'float', struct.pack('<f', 1.0))]
    for k in sorted(strings):
        hdr.append(_attr(k, 'string', strings[k].encode('utf-8')))
    head = struct.pack('<ii', 20000630, 2) + b''.join(hdr) + b'\0'
    # one row = every channel's w values, channels in name order
    rows = np.stack([np.asarray(channels[n], '<f4') for n in names], axis=1)  # h, c, w
    chunks = []
    for y0 in range(0, h, 16):
        raw = rows[y0:y0 + 16].tobytes()
        t = np.frombuffer(raw, np.uint8)
        t = np.concatenate([t[0::2], t[1::2]])           # even bytes, then odd
        d = t.astype(np.int16)
        d[1:] = (d[1:] - d[:-1] + 128) & 0xFF            # delta predictor
        z = zlib.compress(d.astype(np.uint8).tobytes(), 6)
        data = z if len(z) < len(raw) else raw
        chunks.append(struct.pack('<ii', y0, len(data)) + data)
    pos = len(head) + 8 * len(chunks)
    table = []
    for c in chunks:
        table.append(struct.pack('<Q', pos))
        pos += len(c)
    tmp = path + '.tmp'
    with open(tmp, 'wb') as f:
        f.write(head + b''.join(table) + b''.join(chunks))
    os.replace(tmp, path)


# --------------------------------------------------------------- rendering

def log(msg):
    print('[%s %s] %s' % (PROG, time.strftime('%H:%M:%S'), msg), flush=True)


def setup_scene(a, tmp):
    import bpy
    sc = bpy.context.scene
    if a.frame is not None:
        sc.frame_set(a.frame)
    r = sc.render
    r.engine = 'CYCLES'
    cy = sc.cycles
    if a.device:
        cy.device = a.device
    cy.use_adaptive_sampling = False      # one sample count for every pixel
    cy.use_denoising = False
    cy.use_animated_seed = False
    if hasattr(cy, 'time_limit'):
        cy.time_limit = 0.0
    if a.size:
        r.resolution_x, r.resolution_y = a.size
        r.resolution_percentage = 100
    # Persistent data must stay off: with it, Blender 3.4 in background mode renders
    # the first result again and ignores later changes of seed and sample offset.
    r.use_persistent_data = False
    r.use_compositing = False
    r.use_sequencer = False
    if a.threads > 0:
        r.threads_mode = 'FIXED'
        r.threads = a.threads
    im = r.image_settings
    im.file_format = 'OPEN_EXR_MULTILAYER'
    im.color_depth = '32'
    im.exr_codec = 'NONE'
    vl = bpy.context.view_layer
    if hasattr(r, 'use_single_layer'):
        r.use_single_layer = True         # the active view layer only
    vl.use_pass_combined = True
    vl.cycles.denoising_store_passes = True   # Denoising Albedo and Normal
    r.filepath = os.path.join(tmp, 'chunk.exr')
    return sc, vl.name


def render_chunk(sc, layer, path, seed, offset, m, total):
    """Cycles renders samples offset .. offset+m-1 of seed; returns the chunk's
    channels of the layer (float32) and Blender's string attributes."""
    import bpy
    cy = sc.cycles
    cy.seed = seed
    if hasattr(cy, 'use_sample_subset'):      # Blender 4.x: the sample subset
        cy.samples = total
        cy.use_sample_subset = True
        cy.sample_offset = offset
        cy.sample_subset_length = m
    else:                                     # Blender 3.x: samples at an offset
        cy.samples = m
        cy.sample_offset = offset
    if os.path.exists(path):
        os.remove(path)
    bpy.ops.render.render(write_still=True)
    ch, strings = exr_read(path)
    got = strings.get('cycles.%s.samples' % layer)
    if got is not None and not hasattr(cy, 'use_sample_subset') and int(got) != m:
        raise RuntimeError('Cycles rendered %s samples, wanted %d' % (got, m))
    return ch, strings


PASSES = (('Combined', 'RGB'), ('Denoising Albedo', 'RGB'), ('Denoising Normal', 'XYZ'))


def mcpost_commands(a, spps, merged):
    """The mcpost commands for the files written; merged: whether the run merged."""
    K, out = a.seeds, a.out
    cmds = []
    if K < 2:
        if len(spps) < 2:
            return ['(one seed, one checkpoint: nothing gives it a variance; render '
                    '--seeds 2 or more, or --chunks 2 or more)']
        pat = "'%s/seed0/%s_spp%%04d.exr'" % (out, a.name)
        lst = ','.join(str(n) for n in spps)
        return ['mcpost estimate --series %s --spp %s -o %s/series' % (pat, lst, out),
                'mcpost blend %s --spp %s -o %s/blend' % (pat, lst, out)]
    if not merged:
        for n in spps:
            cmds.append('mcpost merge %s/seed*/%s_spp%04d.exr -o %s/%s_spp%04d.exr'
                        % (out, a.name, n, out, a.name, K * n))
    cmds.append('mcpost estimate %s/%s_spp%04d.exr -o %s/estimate'
                % (out, a.name, K * a.spp, out))
    if len(spps) >= 2:
        pat = "'%s/%s_spp%%04d.exr'" % (out, a.name)
        lst = ','.join(str(K * n) for n in spps)
        cmds.append('mcpost estimate --series %s --spp %s -o %s/series' % (pat, lst, out))
        cmds.append('mcpost blend %s --spp %s -o %s/blend' % (pat, lst, out))
    return cmds


def merge_checkpoints(a, spps, tool):
    """`mcpost merge` of the K seeds' checkpoints at each sample count."""
    import glob
    import subprocess
    for n in spps:
        parts = sorted(glob.glob(os.path.join(glob.escape(a.out), 'seed*',
                                              '%s_spp%04d.exr' % (a.name, n))))
        out = os.path.join(a.out, '%s_spp%04d.exr' % (a.name, a.seeds * n))
        cmd = [tool, 'merge'] + parts + ['-o', out]
        log(' '.join(cmd))
        subprocess.run(cmd, check=True)


def main():
    argv = sys.argv[sys.argv.index('--') + 1:] if '--' in sys.argv else sys.argv[1:]
    if 'bpy' not in sys.modules and any(x in ('-h', '--help') for x in argv):
        parse_args(argv)                      # --help outside Blender
    a = parse_args(argv)
    try:
        import bpy
    except ImportError:
        sys.exit('%s: run it inside Blender: blender -b scene.blend --python %s -- '
                 '--out DIR ...' % (PROG, sys.argv[0]))
    import numpy as np
    os.makedirs(a.out, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix='mcpost-cycles-', dir=a.out)
    try:
        sc, layer = setup_scene(a, tmp)
        m = a.spp // a.chunks
        spps = [m * (c + 1) for c in range(a.chunks)]
        tag = 'Blender %s Cycles' % bpy.app.version_string.split()[0]
        w = sc.render.resolution_x * sc.render.resolution_percentage // 100
        h = sc.render.resolution_y * sc.render.resolution_percentage // 100
        seeds = [seed_of(a.seed_base, k) for k in range(a.seeds)]
        log('%s, %s: %dx%d, frame %d, %d seeds x %d chunks x %d spp, layer %s'
            % (tag, bpy.data.filepath or '(unsaved scene)', w, h, sc.frame_current,
               a.seeds, a.chunks, m, layer))
        t0 = time.time()
        for k, seed in enumerate(seeds):
            folder = os.path.join(a.out, 'seed%d' % k)
            os.makedirs(folder, exist_ok=True)
            acc = None
            for c in range(a.chunks):
                ch, strings = render_chunk(sc, layer, sc.render.filepath, seed, c * m, m,
                                           a.spp)
                names = ['%s.%s.%s' % (layer, p, x) for p, comps in PASSES for x in comps]
                missing = [n for n in names if n not in ch]
                if missing:
                    raise RuntimeError('the render has no %s (channels: %s)'
                                       % (', '.join(missing), ', '.join(sorted(ch))))
                if a.keep_chunks:
                    os.makedirs(os.path.join(folder, 'chunks'), exist_ok=True)
                    shutil.copyfile(sc.render.filepath, os.path.join(
                        folder, 'chunks', '%s_c%02d.exr' % (a.name, c)))
                if acc is None:
                    acc = {n: np.zeros(ch[n].shape, np.float64) for n in names}
                for n in names:
                    acc[n] += ch[n]
                n_done = spps[c]
                mean = {n: (acc[n] / (c + 1)).astype(np.float32) for n in names}
                keep = {kk: v for kk, v in strings.items()
                        if not kk.startswith('cycles.') and kk != 'Time'}
                keep.update({'cycles.%s.samples' % layer: str(n_done),
                             'renderer': tag, 'mcpost:cyclesSeed': str(seed),
                             'mcpost:sampling': 'progressive: seed %d, samples 0..%d in %d '
                                                'chunks of %d' % (seed, n_done - 1, c + 1, m)})
                path = os.path.join(folder, '%s_spp%04d.exr' % (a.name, n_done))
                exr_write(path, mean, keep)
            log('seed %d (Cycles seed %d): %s (%.1f s so far)'
                % (k, seed, ', '.join('%d' % s for s in spps), time.time() - t0))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    tool = a.mcpost or shutil.which('mcpost')
    merged = bool(a.seeds >= 2 and tool and tool != 'none')
    if merged:
        merge_checkpoints(a, spps, tool)
    elif a.seeds >= 2:
        log('no mcpost (--mcpost PATH, or on PATH): the checkpoints are not merged')
    cmds = mcpost_commands(a, spps, merged)
    with open(os.path.join(a.out, 'mcpost-cycles-render.txt'), 'w') as f:
        f.write('%s: %s, %d seeds (%s), %d spp in %d chunks of %d, %dx%d, frame %d\n'
                % (PROG, bpy.data.filepath or '(unsaved scene)', a.seeds,
                   ' '.join(map(str, seeds)), a.spp, a.chunks, m, w, h, sc.frame_current))
        f.write('then:\n' + ''.join('  %s\n' % c for c in cmds))
    log('done in %.1f s; then:\n%s' % (time.time() - t0, '\n'.join('  ' + c for c in cmds)))


def run():
    """Inside Blender a failure must end the process with a non-zero status (Blender
    itself carries on and exits 0 after a script's exception)."""
    try:
        main()
    except SystemExit as e:
        if e.code:
            if not isinstance(e.code, int):
                print(e.code, file=sys.stderr)
            sys.stdout.flush()
            os._exit(e.code if isinstance(e.code, int) else 1)
        if 'bpy' in sys.modules:
            sys.stdout.flush()
            os._exit(0)
        raise
    except Exception:
        import traceback
        traceback.print_exc()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(1)


if __name__ == '__main__':
    run()
