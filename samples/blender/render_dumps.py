"""render_dumps.py: render mcpost's sample fixtures with Blender Cycles.

Run (one Blender process per scene; see samples/README.md):

  blender -b --factory-startup --python samples/blender/render_dumps.py -- \
      --scene cornell --out samples/fixtures/cornell

It builds the scene from code, then writes, in pbrt-v4's GBufferFilm naming
(R,G,B, Variance.R/G/B, Albedo.R/G/B, N.X/Y/Z, int samplesPerPixel):

  series/<s>_spp%04d.exr        running mean and per-sample variance S/(n-1)
                                of the first n single-sample renders,
                                n = 1, 2, 4, ..., max_spp (nested series)
  singles/<s>_single%02d.exr    the first --singles of those 1-spp renders
  realizations/<s>_spp%04d_r%d.exr
                                independent estimates at the --real-spp
                                counts, --real-count of each
  <s>_reference.exr             --ref-spp samples (own seed), float32 R,G,B

Cycles writes no variance, so every sample of the series is its own render
(samples=1) written to a temporary float32 uncompressed multilayer EXR, read
back with exr_min.py and accumulated in float64. Fixture files are written
with exr_min.py (HALF, ZIP).

Sampling (--sampling): Cycles' samples within a pixel are stratified
(Sobol-Burley or PMJ), so a per-sample variance divided by n overestimates
the variance of an n-sample Cycles render (measured 1.9-2.2x on the texture
scene). The default 'iid' mode therefore gives every sample its own seed
(sample_seed(stream, i)) and sample index i+1 (index 0 is special in
Cycles: its camera ray goes through the pixel centre), which makes the
samples independent, and builds each realization the same way from its own
seed stream. 'qmc' reproduces a progressive Cycles render instead (one seed,
sample_offset i; realizations are ordinary spp-sample renders).
"""

import argparse
import os
import shutil
import sys
import tempfile
import time

import bpy
import numpy as np

_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, _HERE)
import exr_min  # noqa: E402

# ------------------------------------------------------------------ scenes


def _clear_scene():
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    for coll in (bpy.data.meshes, bpy.data.materials, bpy.data.lights,
                 bpy.data.cameras, bpy.data.node_groups):
        for block in list(coll):
            coll.remove(block)


def _material(name, build, output='Surface'):
    """New node material; build(nodes, links) returns the shader socket
    that goes to the output's `output` input (Surface, or Volume)."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new('ShaderNodeOutputMaterial')
    sock = build(nt.nodes, nt.links)
    nt.links.new(sock, out.inputs[output])
    return mat


def _diffuse(name, rgb):
    def build(nodes, links):
        b = nodes.new('ShaderNodeBsdfDiffuse')
        b.inputs['Color'].default_value = (*rgb, 1.0)
        return b.outputs['BSDF']
    return _material(name, build)


def _glossy(name, rgb, roughness):
    def build(nodes, links):
        b = nodes.new('ShaderNodeBsdfGlossy')
        b.distribution = 'GGX'
        b.inputs['Color'].default_value = (*rgb, 1.0)
        b.inputs['Roughness'].default_value = roughness
        return b.outputs['BSDF']
    return _material(name, build)


def _glass(name, ior):
    def build(nodes, links):
        b = nodes.new('ShaderNodeBsdfGlass')
        b.distribution = 'SHARP'
        b.inputs['Color'].default_value = (1.0, 1.0, 1.0, 1.0)
        b.inputs['IOR'].default_value = ior
        return b.outputs['BSDF']
    return _material(name, build)


def _plane(name, size, loc, rot, mat):
    bpy.ops.mesh.primitive_plane_add(size=size, location=loc, rotation=rot)
    ob = bpy.context.active_object
    ob.name = name
    ob.data.materials.append(mat)
    return ob


def _sphere(name, radius, loc, mat):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48,
                                         radius=radius, location=loc)
    ob = bpy.context.active_object
    ob.name = name
    bpy.ops.object.shade_smooth()
    ob.data.materials.append(mat)
    return ob


def _area_light(name, size, loc, power, rgb=(1.0, 1.0, 1.0)):
    data = bpy.data.lights.new(name, 'AREA')
    data.shape = 'SQUARE'
    data.size = size
    data.energy = power
    data.color = rgb
    ob = bpy.data.objects.new(name, data)
    ob.location = loc            # area lights emit along their local -Z
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _camera(loc, rot, fov_deg):
    data = bpy.data.cameras.new('cam')
    data.lens_unit = 'FOV'
    data.angle = np.radians(fov_deg)
    ob = bpy.data.objects.new('cam', data)
    ob.location = loc
    ob.rotation_euler = rot
    bpy.context.scene.collection.objects.link(ob)
    bpy.context.scene.camera = ob
    return ob


def _world(strength, rgb=(1.0, 1.0, 1.0)):
    w = bpy.data.worlds.get('World') or bpy.data.worlds.new('World')
    bpy.context.scene.world = w
    w.use_nodes = True
    bg = w.node_tree.nodes['Background']
    bg.inputs['Color'].default_value = (*rgb, 1.0)
    bg.inputs['Strength'].default_value = strength


def _box(white, left, right, floor=None, back=None, ceiling=None):
    """Cornell-style box [-1,1] x [-1,1] x [0,2], open towards -Y."""
    half_pi = np.pi / 2
    _plane('floor', 2, (0, 0, 0), (0, 0, 0), floor or white)
    _plane('ceiling', 2, (0, 0, 2), (np.pi, 0, 0), ceiling or white)
    _plane('back', 2, (0, 1, 1), (half_pi, 0, 0), back or white)
    _plane('left', 2, (-1, 0, 1), (0, half_pi, 0), left)
    _plane('right', 2, (1, 0, 1), (0, -half_pi, 0), right)


def build_cornell():
    """Cornell box with a glass sphere (caustics) and a glossy sphere, lit by
    a small area light under the ceiling: fireflies at low spp."""
    white = _diffuse('white', (0.73, 0.73, 0.73))
    red = _diffuse('red', (0.65, 0.05, 0.05))
    green = _diffuse('green', (0.12, 0.45, 0.15))
    _box(white, red, green)
    _sphere('glossy', 0.35, (-0.42, 0.35, 0.35), _glossy('metal', (0.9, 0.9, 0.9), 0.25))
    _sphere('glass', 0.3, (0.38, -0.15, 0.3), _glass('glass', 1.5))
    _area_light('light', 0.4, (0.0, 0.0, 1.98), 40.0, (1.0, 0.85, 0.7))
    _camera((0, -3.7, 1.0), (np.pi / 2, 0, 0), 40.0)
    _world(0.0)


def _textured(name, build_color, roughness_bump=None):
    """Diffuse material whose colour comes from build_color(nodes, links,
    coord_socket); optional bump from the same colour."""
    def build(nodes, links):
        tc = nodes.new('ShaderNodeTexCoord')
        col = build_color(nodes, links, tc.outputs['Object'])
        b = nodes.new('ShaderNodeBsdfDiffuse')
        links.new(col, b.inputs['Color'])
        if roughness_bump is not None:
            bump = nodes.new('ShaderNodeBump')
            bump.inputs['Strength'].default_value = roughness_bump
            links.new(col, bump.inputs['Height'])
            links.new(bump.outputs['Normal'], b.inputs['Normal'])
        return b.outputs['BSDF']
    return _material(name, build)


def _checker(scale, one, two):
    """A _textured() colour builder: a checker of `scale` squares per unit in colours
    `one` and `two`."""
    def build(nodes, links, co):
        t = nodes.new('ShaderNodeTexChecker')
        t.inputs['Scale'].default_value = scale
        t.inputs['Color1'].default_value = (*one, 1)
        t.inputs['Color2'].default_value = (*two, 1)
        links.new(co, t.inputs['Vector'])
        return t.outputs['Color']
    return build


def _noise_ramp(scale, low, high):
    """A _textured() colour builder: multi-octave noise (detail 6, roughness 0.7) at
    `scale` through a ramp from `low` (at 0.35) to `high` (at 0.65)."""
    def build(nodes, links, co):
        n = nodes.new('ShaderNodeTexNoise')
        n.inputs['Scale'].default_value = scale
        n.inputs['Detail'].default_value = 6.0
        n.inputs['Roughness'].default_value = 0.7
        links.new(co, n.inputs['Vector'])
        ramp = nodes.new('ShaderNodeValToRGB')
        ramp.color_ramp.elements[0].position = 0.35
        ramp.color_ramp.elements[0].color = (*low, 1)
        ramp.color_ramp.elements[1].position = 0.65
        ramp.color_ramp.elements[1].color = (*high, 1)
        links.new(n.outputs['Fac'], ramp.inputs['Fac'])
        return ramp.outputs['Color']
    return build


def _wave_ramp(scale, one, two, direction='X', distortion=0.0):
    """A _textured() colour builder: stripes, Blender's wave texture (bands along
    `direction`, sine profile; a period of pi/10/scale units without distortion)
    through a ramp from `one` to `two`."""
    def build(nodes, links, co):
        w = nodes.new('ShaderNodeTexWave')
        w.wave_type = 'BANDS'
        w.bands_direction = direction
        w.wave_profile = 'SIN'
        w.inputs['Scale'].default_value = scale
        w.inputs['Distortion'].default_value = distortion
        links.new(co, w.inputs['Vector'])
        ramp = nodes.new('ShaderNodeValToRGB')
        ramp.color_ramp.elements[0].color = (*one, 1)
        ramp.color_ramp.elements[1].color = (*two, 1)
        links.new(w.outputs['Fac'], ramp.inputs['Fac'])
        return ramp.outputs['Color']
    return build


def _brick(scale, one, two, mortar, mortar_size):
    """A _textured() colour builder: Blender's brick texture at `scale` (bricks
    0.5/scale by 0.25/scale units in the vector's X-Y plane), bricks in colours
    `one` and `two`, `mortar` lines of `mortar_size`."""
    def build(nodes, links, co):
        t = nodes.new('ShaderNodeTexBrick')
        t.inputs['Scale'].default_value = scale
        t.inputs['Color1'].default_value = (*one, 1)
        t.inputs['Color2'].default_value = (*two, 1)
        t.inputs['Mortar'].default_value = (*mortar, 1)
        t.inputs['Mortar Size'].default_value = mortar_size
        links.new(co, t.inputs['Vector'])
        return t.outputs['Color']
    return build


def build_texture():
    """Box whose floor, walls and objects carry high-frequency procedural
    textures (checker, brick, wave, noise): detail at the 1-3 pixel scale
    that denoisers blur. Lit by a large area light: converges steadily."""
    checker = _checker(14.0, (0.8, 0.78, 0.7), (0.08, 0.1, 0.15))
    brick = _brick(4.0, (0.6, 0.22, 0.12), (0.45, 0.35, 0.25), (0.85, 0.85, 0.8), 0.04)

    def stripes(rgb_a, rgb_b, scale):
        return _wave_ramp(scale, rgb_a, rgb_b, direction='DIAGONAL', distortion=1.5)

    noise = _noise_ramp(12.0, (0.05, 0.2, 0.5), (0.9, 0.8, 0.3))

    white = _diffuse('white', (0.7, 0.7, 0.7))
    _box(white,
         _textured('left', stripes((0.6, 0.1, 0.1), (0.9, 0.85, 0.8), 2.5)),
         _textured('right', stripes((0.1, 0.4, 0.15), (0.85, 0.9, 0.8), 2.5)),
         floor=_textured('floor', checker),
         back=_textured('back', brick, roughness_bump=0.3))
    _sphere('ball', 0.38, (-0.4, 0.25, 0.38), _textured('ball', noise, 0.4))
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(0.45, 0.1, 0.25),
                                    rotation=(0, 0, np.radians(30)))
    cube = bpy.context.active_object
    cube.name = 'cube'
    cube.data.materials.append(_textured('cube', stripes((0.15, 0.15, 0.5), (0.9, 0.9, 0.6), 5.0)))
    _area_light('light', 1.0, (0.0, 0.0, 1.97), 60.0)
    _camera((0, -3.2, 1.0), (np.pi / 2, 0, 0), 40.0)
    _world(0.0)


SCENES = {'cornell': build_cornell, 'texture': build_texture}

# --------------------------------------------------------------- rendering


class Renderer:
    """One scene; renders to a temporary EXR and reads it back."""

    def __init__(self, res, threads, pattern, tmpdir):
        sc = bpy.context.scene
        self.sc = sc
        sc.render.engine = 'CYCLES'
        cy = sc.cycles
        cy.device = 'CPU'
        cy.use_adaptive_sampling = False
        cy.use_denoising = False
        cy.use_preview_denoising = False
        cy.use_animated_seed = False
        cy.blur_glossy = 0.0
        cy.sample_clamp_direct = 0.0
        cy.sample_clamp_indirect = 0.0
        cy.sampling_pattern = pattern
        cy.caustics_reflective = True
        cy.caustics_refractive = True
        cy.max_bounces = 12
        cy.pixel_filter_type = 'BLACKMAN_HARRIS'  # the defaults, made explicit
        cy.filter_width = 1.5
        r = sc.render
        r.resolution_x = res
        r.resolution_y = res
        r.resolution_percentage = 100
        # Persistent data must stay off: with it, Blender 3.4 in background mode
        # re-renders the first result and ignores later changes of samples,
        # seed and sample_offset (checked: every render came back identical).
        r.use_persistent_data = False
        r.use_compositing = False
        r.use_sequencer = False
        r.film_transparent = False
        if threads > 0:
            r.threads_mode = 'FIXED'
            r.threads = threads
        im = r.image_settings
        im.file_format = 'OPEN_EXR_MULTILAYER'
        im.color_depth = '32'
        im.exr_codec = 'NONE'
        vl = bpy.context.view_layer
        vl.use_pass_combined = True
        vl.cycles.denoising_store_passes = True
        self.layer = vl.name
        self.path = os.path.join(tmpdir, 'render.exr')
        r.filepath = self.path
        self.renders = 0
        self.seconds = 0.0

    def render(self, spp, seed, offset):
        """Render and return dict of float64 (h, w, 3) arrays 'rgb', 'albedo',
        'normal'."""
        cy = self.sc.cycles
        cy.samples = spp
        cy.seed = seed
        cy.sample_offset = offset
        if os.path.exists(self.path):
            os.remove(self.path)
        t0 = time.time()
        bpy.ops.render.render(write_still=True)
        self.seconds += time.time() - t0
        self.renders += 1
        ch, attrs = exr_min.read(self.path)
        got = attrs.get('cycles.%s.samples' % self.layer)
        if got is not None and int(got) != spp:
            raise RuntimeError('Cycles rendered %s samples, wanted %d' % (got, spp))
        p = self.layer + '.'

        def stack(prefix, comps):
            return np.stack([ch[p + prefix + c] for c in comps], axis=-1).astype(np.float64)
        return {'rgb': stack('Combined.', 'RGB'),
                'albedo': stack('Denoising Albedo.', 'RGB'),
                'normal': stack('Denoising Normal.', 'XYZ')}


class Writer:
    def __init__(self, scene_name, renderer_tag):
        self.attrs = {'renderer': renderer_tag, 'scene': scene_name}
        self.clamped = 0
        self.bytes = 0

    def write(self, path, spp, rgb, albedo, normal, var=None, rgb_float=False):
        ch = {}
        types = {}
        for i, c in enumerate('RGB'):
            if rgb_float:
                ch[c] = rgb[..., i].astype(np.float32)
                types[c] = exr_min.FLOAT
            else:
                ch[c], k = exr_min.clamp_half(rgb[..., i])
                self.clamped += k
            ch['Albedo.' + c], k = exr_min.clamp_half(albedo[..., i])
            self.clamped += k
            if var is not None:
                ch['Variance.' + c], k = exr_min.clamp_half(var[..., i])
                self.clamped += k
        for i, c in enumerate('XYZ'):
            ch['N.' + c] = normal[..., i]
        attrs = dict(self.attrs)
        attrs['samplesPerPixel'] = int(spp)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        self.bytes += exr_min.write(path, ch, attrs, pixel_type=exr_min.HALF,
                                    compression=exr_min.COMP_ZIP, pixel_types=types)


def log(msg):
    print('[render_dumps %s] %s' % (time.strftime('%H:%M:%S'), msg), flush=True)


# Cycles places the camera ray of sample index 0 at the pixel centre (no
# filter jitter; kernel/integrator/init_from_camera.h), so a series made only
# of index-0 samples is biased and misses the anti-aliasing noise. iid mode
# therefore gives sample i the index IID_OFFSET + i (>= 1) as well as its own
# seed.
IID_OFFSET = 1


def sample_seed(stream, index):
    """Cycles seed of sample `index` of seed stream `stream` (iid mode).

    A 32-bit integer hash (splitmix32-style finaliser) so that the seeds of
    neighbouring samples differ in all bits, not just the low ones: Cycles
    XORs the seed into its per-pixel hash. Result in [0, 2^31), the range
    of the cycles.seed property."""
    x = (stream * 0x9E3779B1 + index * 0x85EBCA77 + 0x165667B1) & 0xFFFFFFFF
    x ^= x >> 16
    x = (x * 0x7FEB352D) & 0xFFFFFFFF
    x ^= x >> 15
    x = (x * 0x846CA68B) & 0xFFFFFFFF
    x ^= x >> 16
    return x & 0x7FFFFFFF


def parse_args(argv):
    ap = argparse.ArgumentParser(prog='render_dumps.py',
                                 description='Render mcpost sample fixtures with Cycles.')
    ap.add_argument('--scene', choices=sorted(SCENES), required=True)
    ap.add_argument('--out', required=True, help='output folder for this scene')
    ap.add_argument('--res', type=int, default=128)
    ap.add_argument('--max-spp', type=int, default=1024,
                    help='series up to this power of two')
    ap.add_argument('--singles', type=int, default=16)
    ap.add_argument('--real-spp', default='32,128', help='comma-separated, or empty')
    ap.add_argument('--real-count', type=int, default=8)
    ap.add_argument('--ref-spp', type=int, default=16384)
    ap.add_argument('--ref-batch', type=int, default=1024,
                    help='reference rendered in batches of this many samples '
                         '(same seed, consecutive sample offsets)')
    ap.add_argument('--sampling', choices=['iid', 'qmc'], default='iid',
                    help='iid (default): sample i of the series is a 1-spp render '
                         'with seed sample_seed(seed_series, i) and sample_offset '
                         'i+1, and a realization is the mean of spp such renders '
                         'with seeds sample_seed(seed_real + k, j), offsets j+1; '
                         'samples are independent, '
                         'so Variance/spp is the variance of the mean. qmc: sample '
                         'i of the series is seed_series with sample_offset i, and '
                         'a realization is one spp-sample render with seed '
                         'seed_real + k; Cycles\' stratified (Sobol/PMJ) samples '
                         'make Variance/spp overestimate the variance of the mean')
    ap.add_argument('--seed-series', type=int, default=1)
    ap.add_argument('--seed-real', type=int, default=1000,
                    help='realization k (counted over all real-spp) uses seed '
                         'stream seed-real + k')
    ap.add_argument('--seed-ref', type=int, default=9001)
    ap.add_argument('--pattern', default='SOBOL', choices=['SOBOL', 'PROGRESSIVE_MULTI_JITTER'])
    ap.add_argument('--threads', type=int, default=0, help='0 = Blender default')
    ap.add_argument('--skip', default='', help='comma list of parts to skip: '
                    'series,realizations,reference')
    return ap.parse_args(argv)


class Accum:
    """float64 running sums of one pixel estimator over samples."""

    def __init__(self):
        self.n = 0
        self.rgb = self.rgb2 = self.albedo = self.normal = None

    def add(self, px, weight=1):
        if self.rgb is None:
            self.rgb = np.zeros_like(px['rgb'])
            self.rgb2 = np.zeros_like(px['rgb'])
            self.albedo = np.zeros_like(px['rgb'])
            self.normal = np.zeros_like(px['rgb'])
        self.rgb += px['rgb'] * weight
        self.rgb2 += px['rgb'] ** 2 * weight
        self.albedo += px['albedo'] * weight
        self.normal += px['normal'] * weight
        self.n += weight

    def mean(self):
        n = self.n
        return self.rgb / n, self.albedo / n, self.normal / n

    def var_per_sample(self):
        """Unbiased per-sample variance S/(n-1) (0 at n = 1); only meaningful
        when every add() was one sample."""
        n = self.n
        if n < 2:
            return np.zeros_like(self.rgb)
        return np.maximum(self.rgb2 - self.rgb * (self.rgb / n), 0.0) / (n - 1)


def main():
    argv = sys.argv[sys.argv.index('--') + 1:] if '--' in sys.argv else []
    a = parse_args(argv)
    skip = set(s for s in a.skip.split(',') if s)
    name = a.scene
    iid = a.sampling == 'iid'
    real_spps = [int(x) for x in a.real_spp.split(',') if x]
    t_start = time.time()

    # every Cycles seed used, to make sure no two estimators share one
    seeds = []
    if iid:
        seeds += [sample_seed(a.seed_series, i) for i in range(a.max_spp)]
        k = 0
        for spp in real_spps:
            for r in range(a.real_count):
                seeds += [sample_seed(a.seed_real + k, j) for j in range(spp)]
                k += 1
    else:
        seeds += [a.seed_series]
        seeds += [a.seed_real + k for k in range(len(real_spps) * a.real_count)]
    seeds.append(a.seed_ref)
    if len(set(seeds)) != len(seeds):
        raise RuntimeError('seed collision; choose other --seed-* values')

    _clear_scene()
    SCENES[name]()
    tmpdir = tempfile.mkdtemp(prefix='render_dumps_',
                              dir='/dev/shm' if os.path.isdir('/dev/shm') else None)
    rd = Renderer(a.res, a.threads, a.pattern, tmpdir)
    tag = 'Blender %s Cycles' % bpy.app.version_string.split()[0]
    wr = Writer(name, tag)
    log('%s: %s, %dx%d, pattern %s, sampling %s, threads %s'
        % (name, tag, a.res, a.res, a.pattern, a.sampling, a.threads or 'auto'))
    times = {}

    # --- series and singles: one 1-spp render per sample
    if 'series' not in skip:
        t0 = time.time()
        acc = Accum()
        next_pow = 1
        for i in range(a.max_spp):
            if iid:
                px = rd.render(1, sample_seed(a.seed_series, i), IID_OFFSET + i)
            else:
                px = rd.render(1, a.seed_series, i)
            acc.add(px)
            if i < a.singles:
                wr.write(os.path.join(a.out, 'singles', '%s_single%02d.exr' % (name, i)),
                         1, px['rgb'], px['albedo'], px['normal'])
            n = i + 1
            if n == next_pow:
                mean, alb, nrm = acc.mean()
                var = acc.var_per_sample()
                wr.write(os.path.join(a.out, 'series', '%s_spp%04d.exr' % (name, n)),
                         n, mean, alb, nrm, var=var)
                el = time.time() - t0
                log('series spp %d written (%.1f s, %.3f s/render, mean %.4f, '
                    'max %.1f, mean var %.4f)' % (n, el, el / n, mean.mean(),
                                                   mean.max(), var.mean()))
                next_pow *= 2
        times['series'] = time.time() - t0
        log('series done: %d renders in %.1f s' % (a.max_spp, times['series']))

    # --- realizations: independent seeds
    if 'realizations' not in skip and real_spps:
        t0 = time.time()
        k = 0
        for spp in real_spps:
            for r in range(a.real_count):
                acc = Accum()
                if iid:
                    for j in range(spp):
                        acc.add(rd.render(1, sample_seed(a.seed_real + k, j), IID_OFFSET + j))
                else:
                    acc.add(rd.render(spp, a.seed_real + k, 0), spp)
                mean, alb, nrm = acc.mean()
                wr.write(os.path.join(a.out, 'realizations',
                                      '%s_spp%04d_r%d.exr' % (name, spp, r)),
                         spp, mean, alb, nrm)
                log('realization spp %d r %d (seed stream %d) written, %.1f s'
                    % (spp, r, a.seed_real + k, time.time() - t0))
                k += 1
        times['realizations'] = time.time() - t0
        log('realizations done in %.1f s' % times['realizations'])

    # --- reference: batches of one seed with consecutive sample offsets
    # (Cycles' stratified sampling: the most accurate estimate per sample)
    if 'reference' not in skip:
        t0 = time.time()
        acc = Accum()
        while acc.n < a.ref_spp:
            b = min(a.ref_batch, a.ref_spp - acc.n)
            acc.add(rd.render(b, a.seed_ref, acc.n), b)
            log('reference %d/%d spp (%.1f s)' % (acc.n, a.ref_spp, time.time() - t0))
        mean, alb, nrm = acc.mean()
        wr.write(os.path.join(a.out, '%s_reference.exr' % name), acc.n,
                 mean, alb, nrm, rgb_float=True)
        times['reference'] = time.time() - t0
        log('reference done in %.1f s' % times['reference'])

    shutil.rmtree(tmpdir, ignore_errors=True)
    log('%s finished: %d renders, %.1f s in render calls, %.1f s total (%s), %d values '
        'clamped to the half range, %.2f MB written'
        % (name, rd.renders, rd.seconds, time.time() - t_start,
           ', '.join('%s %.0f s' % kv for kv in times.items()), wr.clamped, wr.bytes / 1e6))


def run_main(main_fn, name):
    """Runs a script's main inside Blender so that a failure ends the process with a
    non-zero status and a traceback (Blender itself would carry on and exit 0)."""
    try:
        main_fn()
    except SystemExit as e:
        if e.code:
            print('%s: failed (%s)' % (name, e.code), file=sys.stderr)
            sys.exit(e.code)
    except Exception:
        import traceback
        traceback.print_exc()
        sys.exit(1)


if __name__ == '__main__':
    run_main(main, 'render_dumps')
