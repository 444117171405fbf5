"""render_strat.py: render mcpost's *stratified* fixtures with Blender Cycles.

Run (one Blender process per scene; see samples/README.md, section
"Stratified fixtures (strat/)"):

  blender -b --factory-startup --python samples/blender/render_strat.py -- \
      --scene interior --out samples/fixtures/strat/interior

Unlike render_dumps.py's default 'iid' mode, the samples here are those of an
ordinary progressive Cycles render: one seed per replicate, sample_offset =
sample index from 0, Cycles' default Sobol-Burley pattern, so the samples
within a pixel are stratified. For every replicate r (own seed) the
--blocks * --block-spp samples are stored as blocks of --block-spp
consecutive samples (block b = samples block_spp*b .. block_spp*(b+1)-1):

  blocks/<s>_r%d_b%02d.exr   R,G,B block mean (HALF); replicate 0 also has
                             Variance.R/G/B, the unbiased per-sample variance
                             S_b/(block_spp-1) within the block
  <s>_features.exr           Albedo.R/G/B, N.X/Y/Z: mean over replicate 0's
                             samples (Denoising Albedo / Normal passes)
  <s>_reference.exr          --ref-spp samples (own seed), R,G,B FLOAT
                             (plus Albedo/N HALF, as render_dumps.py writes it)

Replicate 0 is rendered one sample per render call (samples=1,
sample_offset=i, same seed) so that its per-sample variance can be
accumulated (float64); replicates 1.. are one samples=block_spp render call
per block at sample_offset=block_spp*b. --verify B,... first checks, for
replicate 0's blocks B, that the single-sample calls average to the
samples=block_spp call.

The scene builders of cornell and texture are render_dumps.py's, unchanged;
'interior', 'window', 'lamp', 'corridor', 'fog', 'courtyard', 'stilllife'
and 'bathroom' are built here.
"""

import argparse
import os
import shutil
import sys
import tempfile
import time

import bmesh
import bpy
import mathutils
import numpy as np

_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, _HERE)
import exr_min  # noqa: E402
import render_dumps as rdm  # noqa: E402  (defines scenes, Renderer, sample_seed)


def build_interior():
    """A smooth, well-lit diffuse interior: the box with diffuse walls, two
    diffuse spheres and a diffuse cube, a large ceiling light and a large
    fill light on the left wall. No glass, no small light: converges
    steadily."""
    white = rdm._diffuse('white', (0.75, 0.75, 0.72))
    warm = rdm._diffuse('warm', (0.7, 0.5, 0.3))
    cool = rdm._diffuse('cool', (0.3, 0.45, 0.65))
    rdm._box(white, warm, cool, floor=rdm._diffuse('floor', (0.55, 0.5, 0.45)))
    rdm._sphere('ball_a', 0.35, (-0.4, 0.35, 0.35), rdm._diffuse('ball_a', (0.8, 0.75, 0.6)))
    rdm._sphere('ball_b', 0.25, (0.4, -0.25, 0.25), rdm._diffuse('ball_b', (0.35, 0.6, 0.4)))
    bpy.ops.mesh.primitive_cube_add(size=0.55, location=(0.35, 0.45, 0.275),
                                    rotation=(0, 0, np.radians(25)))
    cube = bpy.context.active_object
    cube.name = 'cube'
    cube.data.materials.append(rdm._diffuse('cube', (0.7, 0.7, 0.75)))
    rdm._area_light('light', 1.2, (0.0, 0.0, 1.97), 30.0, (1.0, 0.95, 0.88))
    fill = rdm._area_light('fill', 0.9, (-0.97, 0.1, 1.2), 10.0, (0.85, 0.9, 1.0))
    fill.rotation_euler = (0.0, -np.pi / 2, 0.0)   # local -Z -> world +X
    rdm._camera((0, -3.2, 1.0), (np.pi / 2, 0, 0), 40.0)
    rdm._world(0.0)


def _principled(name, rgb, roughness, metallic=0.0, specular=0.5, subsurface=None):
    """Principled BSDF; with subsurface = (scale, radius), random-walk subsurface
    scattering of weight `scale` (Blender 3.4's 'Subsurface', which also scales
    the radius), per-channel radius `radius`, subsurface colour = base colour."""
    def build(nodes, links):
        b = nodes.new('ShaderNodeBsdfPrincipled')
        b.inputs['Base Color'].default_value = (*rgb, 1.0)
        b.inputs['Roughness'].default_value = roughness
        b.inputs['Metallic'].default_value = metallic
        b.inputs['Specular'].default_value = specular
        if subsurface:
            b.subsurface_method = 'RANDOM_WALK'
            b.inputs['Subsurface Color'].default_value = (*rgb, 1.0)
            b.inputs['Subsurface'].default_value = subsurface[0]
            b.inputs['Subsurface Radius'].default_value = subsurface[1]
        return b.outputs['BSDF']
    return rdm._material(name, build)


def _slab(name, lo, hi, mat):
    """Axis-aligned box from corner lo to corner hi (a cube, scaled)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=tuple((lo + hi) / 2))
    ob = bpy.context.active_object
    ob.name = name
    ob.scale = tuple(hi - lo)
    ob.data.materials.append(mat)
    return ob


def _room_with_opening(box, e, floor_mat, wall, back, opening):
    """A closed room of thin boxes that overlap at the edges by e, so that no
    ray leaks through a seam: box = (x0, x1, y0, y1, z0, z1) inside, the
    floor, the ceiling and the front and right walls of `wall`, the back
    wall of `back`, and the left wall (x = x0) around an opening
    (wy0, wy1, wz0, wz1) in y and z. Returns the floor."""
    x0, x1, y0, y1, z0, z1 = box
    floor = _slab('floor', (x0 - e, y0 - e, z0 - e), (x1 + e, y1 + e, z0), floor_mat)
    _slab('ceiling', (x0 - e, y0 - e, z1), (x1 + e, y1 + e, z1 + e), wall)
    _slab('back', (x0 - e, y1, z0 - e), (x1 + e, y1 + e, z1 + e), back)
    _slab('front', (x0 - e, y0 - e, z0 - e), (x1 + e, y0, z1 + e), wall)
    _slab('right', (x1, y0 - e, z0 - e), (x1 + e, y1 + e, z1 + e), wall)
    wy0, wy1, wz0, wz1 = opening
    L = (x0 - e, x0)
    _slab('left_below', (L[0], y0 - e, z0 - e), (L[1], y1 + e, wz0), wall)
    _slab('left_above', (L[0], y0 - e, wz1), (L[1], y1 + e, z1 + e), wall)
    _slab('left_front', (L[0], y0 - e, wz0), (L[1], wy0, wz1), wall)
    _slab('left_back', (L[0], wy1, wz0), (L[1], y1 + e, wz1), wall)
    return floor


def build_window():
    """A closed room lit only through a window opening in its left wall: a
    sun lamp (5 degrees wide) and a constant blue sky (the world) outside,
    no light inside. Glossy wooden floor (Principled, roughness 0.3) with
    the sun patch on it, a clear glass sphere and a glass cube on a table
    (sharp glass, IOR 1.5) and a gold GGX sphere (roughness 0.25). The
    objects stand out of the direct sun, so there are no sun caustics
    through glass (cornell has those): everything but the floor patch and
    the sky seen through the opening is lit indirectly, by light that came
    in through the opening, and converges slowly; glossy and refracted
    views of the patch and the sky add noise."""
    white = rdm._diffuse('wall', (0.75, 0.74, 0.7))
    back = rdm._diffuse('back', (0.55, 0.62, 0.7))
    # room x in [-1, 1], y in [-2, 1], z in [0, 2]; the opening in the left
    # wall y in [wy0, wy1], z in [wz0, wz1]
    e = 0.02
    x0, x1, y0, y1, z0, z1 = -1.0, 1.0, -2.0, 1.0, 0.0, 2.0
    wy0, wy1, wz0, wz1 = -0.6, 0.6, 0.75, 1.65
    _room_with_opening((x0, x1, y0, y1, z0, z1), e,
                       _principled('floor', (0.45, 0.3, 0.18), 0.3), white, back,
                       (wy0, wy1, wz0, wz1))
    # a window cross (mullions) in the opening
    frame = rdm._diffuse('frame', (0.85, 0.85, 0.82))
    ym, zm = (wy0 + wy1) / 2, (wz0 + wz1) / 2
    _slab('mullion_v', (x0 - 0.03, ym - 0.02, wz0), (x0 + 0.01, ym + 0.02, wz1), frame)
    _slab('mullion_h', (x0 - 0.03, wy0, zm - 0.02), (x0 + 0.01, wy1, zm + 0.02), frame)
    # objects
    rdm._sphere('glass_ball', 0.25, (0.3, 0.35, 0.25), rdm._glass('glass', 1.5))
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=(0.7, 0.75, 0.6),
                                    rotation=(0, 0, np.radians(35)))
    cube = bpy.context.active_object
    cube.name = 'glass_cube'
    cube.data.materials.append(rdm._glass('glass_cube', 1.5))
    rdm._sphere('metal_ball', 0.3, (-0.35, 0.7, 0.3),
                rdm._glossy('gold', (0.9, 0.72, 0.42), 0.25))
    _slab('table', (0.45, 0.55, 0.0), (0.95, 0.95, 0.45), rdm._diffuse('table', (0.6, 0.3, 0.2)))
    # sun and sky
    sun_d = bpy.data.lights.new('sun', 'SUN')
    sun_d.energy = 10.0
    sun_d.angle = np.radians(5.0)
    sun_d.color = (1.0, 0.93, 0.82)
    sun = bpy.data.objects.new('sun', sun_d)
    d = mathutils.Vector((0.7, -0.35, -0.6)).normalized()   # direction of travel
    sun.rotation_euler = (-d).to_track_quat('Z', 'Y').to_euler()
    bpy.context.scene.collection.objects.link(sun)
    rdm._camera((0, -1.9, 1.1), (np.radians(78), 0, 0), 62.0)
    rdm._world(1.5, (0.45, 0.6, 0.9))


def _two_sided(name, rgb_front, rgb_back):
    """Diffuse, one colour on the front (normal) side, another on the back."""
    def build(nodes, links):
        geo = nodes.new('ShaderNodeNewGeometry')
        front = nodes.new('ShaderNodeBsdfDiffuse')
        front.inputs['Color'].default_value = (*rgb_front, 1.0)
        back = nodes.new('ShaderNodeBsdfDiffuse')
        back.inputs['Color'].default_value = (*rgb_back, 1.0)
        mix = nodes.new('ShaderNodeMixShader')
        links.new(geo.outputs['Backfacing'], mix.inputs['Fac'])
        links.new(front.outputs['BSDF'], mix.inputs[1])
        links.new(back.outputs['BSDF'], mix.inputs[2])
        return mix.outputs['Shader']
    return rdm._material(name, build)


def build_lamp():
    """A closed room at night lit only indirectly, by a floor lamp (a
    torchiere) whose opaque shade, a cone open at the top, dark outside and
    white inside, throws all the light of the bulb up onto the ceiling. No
    window, no sky: the camera sees only light that came off the ceiling
    and the shade, which makes heavy-tailed noise on the walls and floor.
    A rug with a fine checker, a rough copper torus (roughness 0.3, in
    focus), a diffuse ball with a bump-mapped noise texture, and mild depth
    of field on the camera."""
    wall = rdm._diffuse('wall', (0.75, 0.72, 0.66))
    back = rdm._diffuse('back', (0.45, 0.55, 0.45))
    ceiling = rdm._diffuse('ceiling', (0.8, 0.8, 0.78))
    # room x in [-1.2, 1.2], y in [-2, 1.2], z in [0, 2.4]; thin boxes that
    # overlap at the edges so that no ray leaks through a seam
    e = 0.02
    x0, x1, y0, y1, z0, z1 = -1.2, 1.2, -2.0, 1.2, 0.0, 2.4
    _slab('floor', (x0 - e, y0 - e, z0 - e), (x1 + e, y1 + e, z0),
          rdm._diffuse('floor', (0.4, 0.28, 0.18)))
    _slab('ceiling', (x0 - e, y0 - e, z1), (x1 + e, y1 + e, z1 + e), ceiling)
    _slab('back', (x0 - e, y1, z0 - e), (x1 + e, y1 + e, z1 + e), back)
    _slab('front', (x0 - e, y0 - e, z0 - e), (x1 + e, y0, z1 + e), wall)
    _slab('left', (x0 - e, y0 - e, z0 - e), (x0, y1 + e, z1 + e), wall)
    _slab('right', (x1, y0 - e, z0 - e), (x1 + e, y1 + e, z1 + e), wall)

    # rug: a plane (object coordinates in metres) with a checker of 1/12 m
    checker = rdm._checker(12.0, (0.75, 0.7, 0.6), (0.35, 0.08, 0.06))
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(-0.1, 0.05, 0.004))
    rug = bpy.context.active_object
    rug.name = 'rug'
    rug.data.transform(mathutils.Matrix.Diagonal((1.8, 1.5, 1.0, 1.0)))
    rug.data.materials.append(rdm._textured('rug', checker))

    # rough copper torus standing on the rug, turned 30 degrees
    bpy.ops.mesh.primitive_torus_add(major_radius=0.25, minor_radius=0.08,
                                     major_segments=96, minor_segments=32,
                                     location=(-0.35, 0.0, 0.33),
                                     rotation=(np.pi / 2, 0, np.radians(30)))
    torus = bpy.context.active_object
    torus.name = 'torus'
    bpy.ops.object.shade_smooth()
    torus.data.materials.append(rdm._glossy('copper', (0.95, 0.64, 0.54), 0.3))

    # diffuse ball with a bump-mapped noise texture
    noise = rdm._noise_ramp(10.0, (0.15, 0.3, 0.55), (0.85, 0.8, 0.65))
    rdm._sphere('ball', 0.3, (0.35, 0.35, 0.3), rdm._textured('ball', noise, 0.4))

    # the floor lamp: base, pole, shade (cone open at the top, closed at the
    # bottom by a disc), the bulb a small point light inside the shade
    lx, ly = 0.7, 0.65
    zb, zt, rb, rt = 1.55, 1.8, 0.12, 0.45     # shade: z bottom, top; radius bottom, top
    dark = rdm._diffuse('lamp_metal', (0.05, 0.05, 0.05))
    bpy.ops.mesh.primitive_cylinder_add(vertices=32, radius=0.16, depth=0.03,
                                        location=(lx, ly, 0.015))
    bpy.context.active_object.data.materials.append(dark)
    bpy.ops.mesh.primitive_cylinder_add(vertices=16, radius=0.015, depth=zb,
                                        location=(lx, ly, zb / 2))
    bpy.context.active_object.data.materials.append(dark)
    shade = _two_sided('shade', (0.05, 0.05, 0.05), (0.8, 0.77, 0.7))
    bpy.ops.mesh.primitive_cone_add(vertices=48, radius1=rb, radius2=rt, depth=zt - zb,
                                    end_fill_type='NOTHING',
                                    location=(lx, ly, (zb + zt) / 2))
    ob = bpy.context.active_object
    ob.name = 'shade'
    bpy.ops.object.shade_smooth()
    ob.data.materials.append(shade)
    bpy.ops.mesh.primitive_circle_add(vertices=48, radius=rb + 0.002, fill_type='NGON',
                                      location=(lx, ly, zb), rotation=(np.pi, 0, 0))
    bpy.context.active_object.data.materials.append(shade)   # normal -Z: dark below
    bulb_d = bpy.data.lights.new('bulb', 'POINT')
    bulb_d.energy = 80.0
    bulb_d.shadow_soft_size = 0.04
    bulb_d.color = (1.0, 0.85, 0.65)
    bulb = bpy.data.objects.new('bulb', bulb_d)
    bulb.location = (lx, ly, 1.74)     # 6 cm below the rim
    bpy.context.scene.collection.objects.link(bulb)

    cam = rdm._camera((0.0, -1.6, 1.0), (np.radians(80), 0, 0), 60.0)
    cam.data.dof.use_dof = True
    cam.data.dof.focus_object = torus
    cam.data.dof.aperture_fstop = 0.4
    rdm._world(0.0)


def _wall_plane(name, x, y0, y1, z0, z1, facing, mat):
    """A plane in the wall x = const from (y0, z0) to (y1, z1), facing +X
    (facing = 1) or -X (-1), whose object coordinates are metres along the
    wall (X) and up (Y)."""
    ob = rdm._plane(name, 1.0, (x, (y0 + y1) / 2, (z0 + z1) / 2),
                    (np.pi / 2, 0, facing * np.pi / 2), mat)
    ob.data.transform(mathutils.Matrix.Diagonal((y1 - y0, z1 - z0, 1.0, 1.0)))
    return ob


def build_corridor():
    """A long closed corridor seen in perspective, lit only by a row of four
    small area lights recessed in square shafts in the ceiling, lined with a
    dark baffle, so that the camera does not see the emitters (the floor
    reflects them). A glossy floor (Principled, roughness
    0.15) with blurry reflections of the lights and walls, brick walls whose
    courses are a few pixels high near the camera and sub-pixel far away,
    two doors in frames, a diffuse bench and a rough metal bin. The far end,
    beyond the last light, is lit only indirectly: a wide range of
    brightness along the corridor."""
    e = 0.02
    x0, x1, y0, y1, z0, z1 = -0.8, 0.8, -1.0, 12.5, 0.0, 2.4
    w, d = 0.15, 0.09                 # shafts: half-width, depth above the ceiling
    lights_y = (1.5, 4.0, 6.5, 9.0)
    zt = z1 + d                       # top of the shafts (underside of the plenum slab)
    white = rdm._diffuse('ceiling', (0.8, 0.8, 0.78))
    baffle = rdm._diffuse('baffle', (0.05, 0.05, 0.05))
    _slab('floor', (x0 - e, y0 - e, z0 - e), (x1 + e, y1 + e, z0),
          _principled('floor', (0.3, 0.27, 0.24), 0.15))
    _slab('left', (x0 - e, y0 - e, z0 - e), (x0, y1 + e, zt + e), white)
    _slab('right', (x1, y0 - e, z0 - e), (x1 + e, y1 + e, zt + e), white)
    _slab('front', (x0 - e, y0 - e, z0 - e), (x1 + e, y0, zt + e), white)
    _slab('end', (x0 - e, y1, z0 - e), (x1 + e, y1 + e, zt + e),
          rdm._diffuse('end', (0.5, 0.58, 0.65)))
    _slab('plenum', (x0 - e, y0 - e, zt), (x1 + e, y1 + e, zt + e), white)
    # ceiling: two side strips and the pieces between the shafts' openings
    _slab('ceiling_l', (x0 - e, y0 - e, z1), (-w, y1 + e, z1 + e), white)
    _slab('ceiling_r', (w, y0 - e, z1), (x1 + e, y1 + e, z1 + e), white)
    edges = [y0 - e] + [v for ly in lights_y for v in (ly - w, ly + w)] + [y1 + e]
    for k in range(0, len(edges), 2):
        _slab('ceiling_m%d' % (k // 2), (-w, edges[k], z1), (w, edges[k + 1], z1 + e), white)
    for i, ly in enumerate(lights_y):
        # shaft: a square tube open at both ends from the ceiling up to the plenum
        bpy.ops.mesh.primitive_cylinder_add(vertices=4, radius=w * np.sqrt(2), depth=d,
                                            end_fill_type='NOTHING',
                                            location=(0.0, ly, z1 + d / 2),
                                            rotation=(0, 0, np.pi / 4))
        bpy.context.active_object.data.materials.append(baffle)
        rdm._area_light('light%d' % i, 0.25, (0.0, ly, zt - 0.01), 45.0, (1.0, 0.9, 0.75))

    # brick on both side walls (object coordinates: metres along the wall, up)
    brick = rdm._textured('brick', rdm._brick(4.0, (0.55, 0.3, 0.2), (0.45, 0.38, 0.3),
                                              (0.8, 0.78, 0.72), 0.05), 0.3)
    _wall_plane('brick_l', x0 + 0.002, y0, y1, z0, z1, 1, brick)
    _wall_plane('brick_r', x1 - 0.002, y0, y1, z0, z1, -1, brick)

    # doors: a panel in a frame (two jambs and a lintel) standing out of the wall
    door = rdm._diffuse('door', (0.25, 0.4, 0.35))
    frame = rdm._diffuse('frame', (0.85, 0.85, 0.82))
    hw, hh, fw, fd = 0.45, 2.05, 0.07, 0.06     # half width, height; frame width, depth
    for side, yd in ((-1, 2.6), (1, 5.6)):
        xw = x0 if side < 0 else x1
        xi = xw - side * fd                     # frame's inner face
        xp = xw - side * 0.03                   # panel's inner face
        _slab('door%d' % side, (min(xw, xp), yd - hw, z0), (max(xw, xp), yd + hw, hh), door)
        for a, b in ((yd - hw - fw, yd - hw), (yd + hw, yd + hw + fw)):
            _slab('jamb', (min(xw, xi), a, z0), (max(xw, xi), b, hh + fw), frame)
        _slab('lintel', (min(xw, xi), yd - hw, hh), (max(xw, xi), yd + hw, hh + fw), frame)

    # a diffuse bench against the right wall and a rough metal bin on the left
    _slab('bench', (x1 - 0.4, 2.0, z0), (x1, 3.2, 0.45), rdm._diffuse('bench', (0.3, 0.42, 0.6)))
    bpy.ops.mesh.primitive_cylinder_add(vertices=48, radius=0.18, depth=0.65,
                                        location=(x0 + 0.25, 4.4, 0.325))
    ob = bpy.context.active_object
    ob.name = 'bin'
    bpy.ops.object.shade_smooth()
    ob.data.use_auto_smooth = True      # smooth side, sharp rim (30 degrees)
    ob.data.materials.append(rdm._glossy('bin', (0.8, 0.8, 0.82), 0.35))

    rdm._camera((0.0, -0.6, 1.45), (np.radians(78), 0, 0), 55.0)
    rdm._world(0.0)


def _fog_volume(name, density, anisotropy):
    """A material with only a homogeneous Volume Scatter (white: no
    absorption, extinction = scattering = density per metre)."""
    def build(nodes, links):
        vs = nodes.new('ShaderNodeVolumeScatter')
        vs.inputs['Color'].default_value = (1.0, 1.0, 1.0, 1.0)
        vs.inputs['Density'].default_value = density
        vs.inputs['Anisotropy'].default_value = anisotropy
        return vs.outputs['Volume']
    mat = rdm._material(name, build, output='Volume')
    mat.cycles.homogeneous_volume = True
    return mat


def build_fog():
    """A closed room filled with a thin homogeneous fog (participating
    media), lit only by a sun outside through a window opening with three
    horizontal slats, and a dim constant sky. The sun's shafts cross the
    fog onto the floor in bands. A floor with a fine checker, a diffuse
    table with a glass sphere on it (sharp glass, IOR 1.5) in front of the
    sunlit floor, and a rough metal sphere, all out of the direct sun (no
    sun caustics through glass). Everything the camera sees lies behind
    fog lit by the shafts; the rest of the room is lit by the sun patches,
    the sky and the shafts' scattered light."""
    wall = rdm._diffuse('wall', (0.75, 0.74, 0.7))
    back = rdm._diffuse('back', (0.6, 0.55, 0.5))
    # room x in [-1.2, 1.2], y in [-3, 1.3], z in [0, 2.2]; the opening in the
    # left wall y in [wy0, wy1], z in [wz0, wz1]
    e = 0.02
    x0, x1, y0, y1, z0, z1 = -1.2, 1.2, -3.0, 1.3, 0.0, 2.2
    wy0, wy1, wz0, wz1 = -0.6, 0.6, 0.8, 2.0
    # floor with a checker of 1/10 m (object coordinates in metres)
    checker = rdm._checker(10.0, (0.7, 0.68, 0.62), (0.22, 0.2, 0.2))
    floor = _room_with_opening((x0, x1, y0, y1, z0, z1), e,
                               rdm._textured('floor', checker), wall, back,
                               (wy0, wy1, wz0, wz1))
    floor.data.transform(mathutils.Matrix.Diagonal((*floor.scale, 1.0)))
    floor.scale = (1.0, 1.0, 1.0)
    # three horizontal slats across the opening, evenly spaced, 5 cm high and
    # 10 cm deep, flush with the wall's inner face
    slat = rdm._diffuse('slat', (0.8, 0.8, 0.78))
    for k in (1, 2, 3):
        zc = wz0 + (wz1 - wz0) * k / 4
        _slab('slat%d' % k, (x0 - 0.1, wy0, zc - 0.025), (x0, wy1, zc + 0.025), slat)
    # a diffuse table between the camera and the sunlit floor, a glass
    # sphere on it, a rough metal sphere at the back on the left
    _slab('table', (0.1, -1.6, z0), (0.6, -1.15, 0.55), rdm._diffuse('table', (0.55, 0.33, 0.2)))
    rdm._sphere('glass_ball', 0.17, (0.35, -1.375, 0.72), rdm._glass('glass', 1.5))
    rdm._sphere('metal_ball', 0.28, (-0.55, 1.0, 0.28),
                rdm._glossy('steel', (0.75, 0.75, 0.78), 0.35))
    # the fog: a box 1 mm inside the room. Homogeneous, so Cycles samples
    # distances analytically and does not ray-march it: the step settings
    # (Blender's defaults, made explicit) do not matter (a trial with step
    # rate 5 and 32 steps at most gave the same image to 1e-7)
    _slab('fog', (x0 + 0.001, y0 + 0.001, z0 + 0.001), (x1 - 0.001, y1 - 0.001, z1 - 0.001),
          _fog_volume('fog', 0.15, 0.3))
    sc = bpy.context.scene
    sc.cycles.volume_step_rate = 1.0
    sc.cycles.volume_max_steps = 1024
    # sun and sky
    sun_d = bpy.data.lights.new('sun', 'SUN')
    sun_d.energy = 25.0
    sun_d.angle = np.radians(2.0)
    sun_d.color = (1.0, 0.9, 0.75)
    sun = bpy.data.objects.new('sun', sun_d)
    d = mathutils.Vector((0.7, 0.0, -0.6)).normalized()   # direction of travel
    sun.rotation_euler = (-d).to_track_quat('Z', 'Y').to_euler()
    sc.collection.objects.link(sun)
    rdm._camera((0.3, -2.7, 1.25), (np.radians(78), 0, np.radians(8)), 62.0)
    rdm._world(1.5, (0.5, 0.62, 0.85))


def _sky_gradient(strength, horizon, zenith):
    """World: a sky whose colour runs linearly from `horizon` (at and below
    the horizon) to `zenith` (straight up) with the sine of the elevation
    (the Z of the ray's direction, which Cycles gives the world as its
    Generated coordinate)."""
    w = bpy.data.worlds.get('World') or bpy.data.worlds.new('World')
    bpy.context.scene.world = w
    w.use_nodes = True
    nt = w.node_tree
    bg = nt.nodes['Background']
    tc = nt.nodes.new('ShaderNodeTexCoord')
    sep = nt.nodes.new('ShaderNodeSeparateXYZ')
    ramp = nt.nodes.new('ShaderNodeValToRGB')
    ramp.color_ramp.elements[0].position = 0.0
    ramp.color_ramp.elements[0].color = (*horizon, 1.0)
    ramp.color_ramp.elements[1].position = 1.0
    ramp.color_ramp.elements[1].color = (*zenith, 1.0)
    nt.links.new(tc.outputs['Generated'], sep.inputs['Vector'])
    nt.links.new(sep.outputs['Z'], ramp.inputs['Fac'])
    nt.links.new(ramp.outputs['Color'], bg.inputs['Color'])
    bg.inputs['Strength'].default_value = strength
    # a non-constant world gets an importance map, rebuilt at every render
    # call: Blender's automatic choice (1024 wide) took 1.6 s a call; the
    # gradient is smooth, so a map 64 wide does as well
    w.cycles.sampling_method = 'MANUAL'
    w.cycles.sample_map_resolution = 64


def _object(name, data, mat):
    """An object of mesh or curve data with its one material, in the scene."""
    data.materials.append(mat)
    ob = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _bollard(name, r, h, xy, mat, segments=48, dome_rings=12):
    """A bollard standing on z = 0 at xy: a cylinder of radius r under a
    hemisphere from height h, one closed smooth-shaded mesh. (A cylinder with
    a separate sphere on top overlapped it near the seam, and which of the
    two a ray hit there changed from one render call to the next.)"""
    bm = bmesh.new()
    rings = [(r, 0.0), (r, h)]
    for k in range(1, dome_rings):
        a = np.pi / 2 * k / dome_rings
        rings.append((r * np.cos(a), h + r * np.sin(a)))
    verts = []
    for rad, z in rings:
        verts.append([bm.verts.new((xy[0] + rad * np.cos(2 * np.pi * j / segments),
                                    xy[1] + rad * np.sin(2 * np.pi * j / segments), z))
                      for j in range(segments)])
    apex = bm.verts.new((xy[0], xy[1], h + r))
    for lo, hi in zip(verts[:-1], verts[1:]):
        for j in range(segments):
            jn = (j + 1) % segments
            bm.faces.new((lo[j], lo[jn], hi[jn], hi[j]))
    for j in range(segments):
        bm.faces.new((verts[-1][j], verts[-1][(j + 1) % segments], apex))
    bm.faces.new(list(reversed(verts[0])))      # the bottom, facing down
    me = bpy.data.meshes.new(name)
    bm.to_mesh(me)
    bm.free()
    for f in me.polygons:
        f.use_smooth = True
    me.use_auto_smooth = True                   # smooth side and dome, sharp bottom edge
    return _object(name, me, mat)


def build_courtyard():
    """A small courtyard open to the sky at dusk, seen from slightly above
    through its open front. Brick walls on three sides, a paved floor (a
    checker of stone slabs); the light is a bluish gradient sky and a low,
    warm sun that leaves all of the courtyard in shadow but the top of the
    right wall. A wooden planter box with a bump-mapped, displaced green
    shrub, two shiny steel bollards and a raised pool of water (sharp
    glass surface, IOR 1.33, over a dark basin), all out of the direct sun
    (no sun caustics through the water, no sun reflected off the steel)."""
    # courtyard x in [x0, x1], y in [y0, y1], walls of height H and thickness
    # t outside it on the left, back and right; open at the front (y0)
    x0, x1, y0, y1, H, t = -2.5, 2.5, -2.0, 3.5, 3.2, 0.3
    # the ground: one slab far beyond the walls (no ray sees the world below
    # the horizon), paved with a checker of 1/3 m slabs, object coordinates
    # in metres
    paving = rdm._checker(3.0, (0.5, 0.48, 0.44), (0.36, 0.35, 0.33))
    ground = _slab('ground', (-12.0, -16.0, -0.05), (12.0, 12.0, 0.0),
                   rdm._textured('ground', paving))
    ground.data.transform(mathutils.Matrix.Diagonal((*ground.scale, 1.0)))
    ground.scale = (1.0, 1.0, 1.0)
    wall = rdm._diffuse('wall', (0.5, 0.38, 0.3))
    _slab('left', (x0 - t, y0, 0.0), (x0, y1 + t, H), wall)
    _slab('right', (x1, y0, 0.0), (x1 + t, y1 + t, H), wall)
    _slab('back', (x0 - t, y1, 0.0), (x1 + t, y1 + t, H), wall)
    # brick on the three inner faces, 2 mm in front of them (object
    # coordinates: metres along the wall, up)
    brick = rdm._textured('brick', rdm._brick(3.0, (0.55, 0.3, 0.2), (0.45, 0.38, 0.3),
                                              (0.8, 0.78, 0.72), 0.05), 0.3)
    _wall_plane('brick_l', x0 + 0.002, y0, y1, 0.0, H, 1, brick)
    _wall_plane('brick_r', x1 - 0.002, y0, y1, 0.0, H, -1, brick)
    ob = rdm._plane('brick_b', 1.0, ((x0 + x1) / 2, y1 - 0.002, H / 2), (np.pi / 2, 0, 0), brick)
    ob.data.transform(mathutils.Matrix.Diagonal((x1 - x0, H, 1.0, 1.0)))

    # a wooden planter box at the front left, soil inset in its top, and a
    # shrub: an icosphere displaced by a clouds texture, with a bump-mapped
    # noise of two greens
    px0, px1, py0, py1, ph = -2.3, -1.3, -0.2, 0.5, 0.55
    _slab('planter', (px0, py0, 0.0), (px1, py1, ph), rdm._diffuse('planter', (0.42, 0.27, 0.15)))
    _slab('soil', (px0 + 0.05, py0 + 0.05, ph - 0.05), (px1 - 0.05, py1 - 0.05, ph + 0.005),
          rdm._diffuse('soil', (0.12, 0.08, 0.05)))
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=5, radius=0.4,
                                          location=((px0 + px1) / 2, (py0 + py1) / 2, ph + 0.32))
    shrub = bpy.context.active_object
    shrub.name = 'shrub'
    shrub.scale = (1.0, 0.85, 0.85)
    tex = bpy.data.textures.new('shrub', 'CLOUDS')
    tex.noise_scale = 0.18
    tex.noise_depth = 2
    mod = shrub.modifiers.new('displace', 'DISPLACE')
    mod.texture = tex
    mod.texture_coords = 'LOCAL'
    mod.strength = 0.18
    mod.mid_level = 0.5
    bpy.ops.object.shade_smooth()
    shrub.data.materials.append(
        rdm._textured('shrub', rdm._noise_ramp(9.0, (0.04, 0.14, 0.03), (0.2, 0.4, 0.08)), 1.0))

    # two shiny steel bollards at the front right
    steel = rdm._glossy('steel', (0.8, 0.8, 0.82), 0.12)
    for i, (bx, by) in enumerate(((0.9, -1.3), (1.8, -1.3))):
        _bollard('bollard%d' % i, 0.09, 0.75, (bx, by), steel)

    # a raised pool at the back right: a stone curb, a dark basin (inside the
    # curb, reaching 1 cm into it: no face of it lies on a face of the curb)
    # and a water surface (a plane of sharp glass, IOR 1.33) 5 cm below the
    # rim, reaching 1 cm into the curb
    qx0, qx1, qy0, qy1, qh, c = 0.2, 2.0, 0.5, 1.9, 0.35, 0.12
    stone = rdm._diffuse('curb', (0.62, 0.6, 0.56))
    _slab('curb_f', (qx0, qy0, 0.0), (qx1, qy0 + c, qh), stone)
    _slab('curb_b', (qx0, qy1 - c, 0.0), (qx1, qy1, qh), stone)
    _slab('curb_l', (qx0, qy0, 0.0), (qx0 + c, qy1, qh), stone)
    _slab('curb_r', (qx1 - c, qy0, 0.0), (qx1, qy1, qh), stone)
    _slab('basin', (qx0 + c - 0.01, qy0 + c - 0.01, 0.0), (qx1 - c + 0.01, qy1 - c + 0.01, 0.04),
          rdm._diffuse('basin', (0.04, 0.06, 0.06)))
    water = rdm._plane('water', 1.0, ((qx0 + qx1) / 2, (qy0 + qy1) / 2, qh - 0.05), (0, 0, 0),
                       rdm._glass('water', 1.33))
    water.data.transform(mathutils.Matrix.Diagonal((qx1 - qx0 - 2 * c + 0.02,
                                                    qy1 - qy0 - 2 * c + 0.02, 1.0, 1.0)))

    # a low warm sun from the back left and the sky
    sc = bpy.context.scene
    sun_d = bpy.data.lights.new('sun', 'SUN')
    sun_d.energy = 5.0
    sun_d.angle = np.radians(1.0)
    sun_d.color = (1.0, 0.62, 0.36)
    sun = bpy.data.objects.new('sun', sun_d)
    el, az = np.radians(9.0), np.radians(25.0)
    d = mathutils.Vector((np.cos(el) * np.cos(az), -np.cos(el) * np.sin(az),
                          -np.sin(el)))    # direction of travel
    sun.rotation_euler = (-d).to_track_quat('Z', 'Y').to_euler()
    sc.collection.objects.link(sun)
    rdm._camera((-0.5, -4.6, 2.7), (np.radians(73), 0, np.radians(-8)), 60.0)
    _sky_gradient(1.5, (0.52, 0.58, 0.75), (0.2, 0.33, 0.75))


def _lathe(name, profile, xy, z0, mat, segments=64):
    """A closed solid of revolution about the vertical through xy: `profile`
    is a closed outline of (radius, height) points from z0, in order; a point
    of radius 0 is one vertex on the axis. One smooth-shaded mesh with sharp
    edges where the outline turns by more than 30 degrees (auto smooth), its
    normals pointing out."""
    bm = bmesh.new()
    rings = []
    for rad, z in profile:
        if rad == 0.0:
            rings.append([bm.verts.new((xy[0], xy[1], z0 + z))])
        else:
            rings.append([bm.verts.new((xy[0] + rad * np.cos(2 * np.pi * j / segments),
                                        xy[1] + rad * np.sin(2 * np.pi * j / segments),
                                        z0 + z)) for j in range(segments)])
    for lo, hi in zip(rings[:-1], rings[1:]):
        for j in range(segments):
            jn = (j + 1) % segments
            if len(lo) == 1:
                bm.faces.new((lo[0], hi[j], hi[jn]))
            elif len(hi) == 1:
                bm.faces.new((lo[j], lo[jn], hi[0]))
            else:
                bm.faces.new((lo[j], lo[jn], hi[jn], hi[j]))
    bmesh.ops.recalc_face_normals(bm, faces=bm.faces)
    me = bpy.data.meshes.new(name)
    bm.to_mesh(me)
    bm.free()
    for f in me.polygons:
        f.use_smooth = True
    me.use_auto_smooth = True
    return _object(name, me, mat)


def build_stilllife():
    """A still life on a table, seen close up through a lens with a shallow
    depth of field (which the other fixtures lack but for lamp's mild one):
    a checkered tablecloth, an apple (in focus), a bump-mapped orange, a
    plum in the blurred foreground, a glass tumbler (sharp glass, IOR 1.5)
    and a shiny metal cup behind, and a striped back wall far out of focus.
    The denoisers' albedo and normal features are blurred where the image
    is. Lit by a large soft area light from the left (a window) and a small
    bright lamp at the front right that puts sharper highlights on the
    fruit, the glass and the metal."""
    # a table (top at z0) on a floor, a tablecloth 1 mm above its top (a
    # plane, object coordinates in metres) with a checker of 2 cm squares,
    # and a back wall 1.4 m behind the table with vertical stripes (a plane,
    # object coordinates: metres along the wall, up)
    z0 = 0.75
    _slab('floor', (-3.0, -3.0, -0.05), (3.0, 3.0, 0.0), rdm._diffuse('floor', (0.3, 0.22, 0.15)))
    _slab('table', (-1.0, -1.2, z0 - 0.04), (1.0, 0.4, z0),
          rdm._diffuse('table', (0.35, 0.22, 0.12)))
    checker = rdm._checker(50.0, (0.8, 0.78, 0.72), (0.25, 0.32, 0.5))
    cloth = rdm._plane('cloth', 1.0, (0.0, -0.4, z0 + 0.001), (0, 0, 0),
                       rdm._textured('cloth', checker))
    cloth.data.transform(mathutils.Matrix.Diagonal((2.0, 1.6, 1.0, 1.0)))
    wall = rdm._plane('wall', 1.0, (0.0, 1.8, 1.25), (np.pi / 2, 0, 0),
                      rdm._textured('wall', rdm._wave_ramp(3.0, (0.55, 0.5, 0.38),
                                                         (0.75, 0.72, 0.62))))
    wall.data.transform(mathutils.Matrix.Diagonal((6.0, 2.5, 1.0, 1.0)))

    # on the cloth (zc), from front to back: a plum (glossy), an orange
    # (diffuse, bump-mapped noise of two oranges), an apple (glossy, squashed
    # 10%; the focus), a glass tumbler and a metal cup. The fruit sink 2-3 mm
    # into the cloth; the tumbler's and the cup's bases lie 0.5 mm below it,
    # between the cloth and the table top (no face lies on another)
    zc = z0 + 0.001
    apple = rdm._sphere('apple', 0.045, (0.0, 0.05, zc + 0.045 * 0.9 - 0.003),
                        _principled('apple', (0.55, 0.06, 0.04), 0.35))
    apple.scale = (1.0, 1.0, 0.9)
    rdm._sphere('orange', 0.042, (0.115, -0.03, zc + 0.042 - 0.003),
                rdm._textured('orange', rdm._noise_ramp(60.0, (0.75, 0.3, 0.03),
                                                         (0.9, 0.45, 0.05)), 0.5))
    rdm._sphere('plum', 0.03, (0.07, -0.24, zc + 0.03 - 0.002),
                _principled('plum', (0.18, 0.03, 0.14), 0.3))
    # an empty glass tumbler, 11 cm high, widening from r = 3.4 to 4 cm, its
    # wall 3 mm thick, its base 12 mm
    _lathe('tumbler', [(0.0, 0.0), (0.034, 0.0), (0.04, 0.11), (0.037, 0.11),
                       (0.0315, 0.012), (0.0, 0.012)], (-0.12, 0.13), zc - 0.0005,
           rdm._glass('tumbler', 1.5))
    # a shiny metal cup (GGX, roughness 0.15), 7.5 cm high, r = 3 to 3.6 cm,
    # its wall 2.5 mm thick, its base 5 mm
    _lathe('cup', [(0.0, 0.0), (0.03, 0.0), (0.036, 0.075), (0.0335, 0.075),
                   (0.028, 0.005), (0.0, 0.005)], (0.17, 0.3), zc - 0.0005,
           rdm._glossy('cup', (0.9, 0.88, 0.85), 0.15))

    # a large soft light from the left, like a window, aimed at the apple,
    # and a small bright lamp above at the front right (radius 6 cm: at 3 cm
    # its caustic through the tumbler's base left fireflies on the cloth)
    target = mathutils.Vector((0.0, 0.05, 0.8))
    win = rdm._area_light('window', 1.0, (-1.3, 0.2, 1.5), 40.0, (0.92, 0.95, 1.0))
    win.rotation_euler = (target - win.location).to_track_quat('-Z', 'Y').to_euler()
    lamp_d = bpy.data.lights.new('lamp', 'POINT')
    lamp_d.energy = 8.0
    lamp_d.shadow_soft_size = 0.06
    lamp_d.color = (1.0, 0.85, 0.65)
    lamp = bpy.data.objects.new('lamp', lamp_d)
    lamp.location = (0.6, -0.5, 1.45)
    bpy.context.scene.collection.objects.link(lamp)

    # an 85 mm lens (on Blender's 36 mm sensor) at f/1.8, 1.22 m from the
    # apple, looking along +Y tilted 20.4 degrees down at it
    cam = rdm._camera((0.0, -1.1, 1.2), (np.radians(90 - 20.4), 0, 0),
                      np.degrees(2 * np.arctan(18.0 / 85.0)))
    cam.data.lens_unit = 'MILLIMETERS'
    cam.data.lens = 85.0
    cam.data.dof.use_dof = True
    cam.data.dof.focus_object = apple
    cam.data.dof.aperture_fstop = 1.8
    rdm._world(0.1, (0.6, 0.65, 0.75))


def _emission(name, rgb, strength):
    def build(nodes, links):
        em = nodes.new('ShaderNodeEmission')
        em.inputs['Color'].default_value = (*rgb, 1.0)
        em.inputs['Strength'].default_value = strength
        return em.outputs['Emission']
    return rdm._material(name, build)


def _mirror(name, rgb):
    """A perfect mirror: Glossy BSDF, sharp."""
    def build(nodes, links):
        b = nodes.new('ShaderNodeBsdfGlossy')
        b.distribution = 'SHARP'
        b.inputs['Color'].default_value = (*rgb, 1.0)
        return b.outputs['BSDF']
    return rdm._material(name, build)


def _rough_glass(name, ior, roughness):
    """Frosted glass: Glass BSDF, GGX."""
    def build(nodes, links):
        b = nodes.new('ShaderNodeBsdfGlass')
        b.distribution = 'GGX'
        b.inputs['Color'].default_value = (1.0, 1.0, 1.0, 1.0)
        b.inputs['IOR'].default_value = ior
        b.inputs['Roughness'].default_value = roughness
        return b.outputs['BSDF']
    return rdm._material(name, build)


def _tiles(name, size, grout, tile_rgb, grout_rgb, rough_tile, rough_grout):
    """Glossy ceramic tiles: Principled BSDF whose base colour is Blender's
    brick texture with no row offset (a square grid of `size` tiles in the
    object coordinates, in metres) and grout lines of width `grout`; the
    roughness runs from `rough_tile` on the tiles to `rough_grout` on the
    grout (the texture's mortar mask)."""
    def build(nodes, links):
        tc = nodes.new('ShaderNodeTexCoord')
        t = nodes.new('ShaderNodeTexBrick')
        t.offset = 0.0
        t.squash = 1.0
        t.inputs['Scale'].default_value = 1.0
        t.inputs['Brick Width'].default_value = size
        t.inputs['Row Height'].default_value = size
        t.inputs['Color1'].default_value = (*tile_rgb, 1)
        t.inputs['Color2'].default_value = (*tile_rgb, 1)
        t.inputs['Mortar'].default_value = (*grout_rgb, 1)
        t.inputs['Mortar Size'].default_value = grout
        t.inputs['Mortar Smooth'].default_value = 0.0
        links.new(tc.outputs['Object'], t.inputs['Vector'])
        rough = nodes.new('ShaderNodeMath')
        rough.operation = 'MULTIPLY_ADD'
        links.new(t.outputs['Fac'], rough.inputs[0])
        rough.inputs[1].default_value = rough_grout - rough_tile
        rough.inputs[2].default_value = rough_tile
        b = nodes.new('ShaderNodeBsdfPrincipled')
        links.new(t.outputs['Color'], b.inputs['Base Color'])
        links.new(rough.outputs['Value'], b.inputs['Roughness'])
        b.inputs['Specular'].default_value = 0.5
        return b.outputs['BSDF']
    return rdm._material(name, build)


def _tube(name, corners, radius, bend, mat, steps=8):
    """A round tube of `radius` along the polyline through `corners`, each
    inner corner rounded by a quadratic Bezier arc that starts `bend` before
    it and ends `bend` after it; one curve object (bevelled, caps filled,
    smooth-shaded), so one closed surface with no overlapping parts."""
    c = [np.asarray(p, float) for p in corners]
    pts = [c[0]]
    for a, p, b in zip(c[:-2], c[1:-1], c[2:]):
        u, v = (p - a) / np.linalg.norm(p - a), (b - p) / np.linalg.norm(b - p)
        s, e = p - bend * u, p + bend * v
        for k in range(steps + 1):
            t = k / steps
            pts.append((1 - t) ** 2 * s + 2 * t * (1 - t) * p + t ** 2 * e)
    pts.append(c[-1])
    cu = bpy.data.curves.new(name, 'CURVE')
    cu.dimensions = '3D'
    cu.bevel_depth = radius
    cu.bevel_resolution = 6
    cu.use_fill_caps = True
    sp = cu.splines.new('POLY')
    sp.points.add(len(pts) - 1)
    for q, xyz in zip(sp.points, pts):
        q.co = (*xyz, 1.0)
    sp.use_smooth = True
    return _object(name, cu, mat)


def build_bathroom():
    """A small closed bathroom at night, lit only by one small bright LED
    downlight recessed in a square shaft in the ceiling (dark baffle; the
    camera does not see it) and a dim emissive strip behind a mirror that
    stands off the back wall (a halo on the wall around it). Glossy white
    ceramic tiles with grout lines on every wall (tiles of a few pixels),
    a large perfect mirror over a vanity, a glossy ceramic basin, a chrome
    gooseneck tap and a chrome towel rail (metallic, low roughness), a bar
    of soap and an unlit wax candle with subsurface scattering, and a
    shower corner beside a frosted (rough) glass screen. Specular-diffuse
    paths through the mirror, the chrome and the tiles give heavy tails."""
    e = 0.02
    x0, x1, y0, y1, z0, z1 = -1.0, 1.0, -1.5, 1.0, 0.0, 2.4
    w, d = 0.09, 0.05                 # the downlight's shaft: half-width, depth
    lx, ly = -0.1, 0.05               # its centre
    zt = z1 + d
    white = rdm._diffuse('ceiling', (0.7, 0.7, 0.68))
    baffle = rdm._diffuse('baffle', (0.05, 0.05, 0.05))
    wall = rdm._diffuse('wall', (0.7, 0.7, 0.68))
    floor = rdm._textured('floor', rdm._checker(5.0, (0.32, 0.31, 0.3), (0.2, 0.2, 0.21)))
    fl = _slab('floor', (x0 - e, y0 - e, z0 - e), (x1 + e, y1 + e, z0), floor)
    fl.data.transform(mathutils.Matrix.Diagonal((*fl.scale, 1.0)))
    fl.scale = (1.0, 1.0, 1.0)
    _slab('left', (x0 - e, y0 - e, z0 - e), (x0, y1 + e, zt + e), wall)
    _slab('right', (x1, y0 - e, z0 - e), (x1 + e, y1 + e, zt + e), wall)
    _slab('back', (x0 - e, y1, z0 - e), (x1 + e, y1 + e, zt + e), wall)
    _slab('front', (x0 - e, y0 - e, z0 - e), (x1 + e, y0, zt + e), wall)
    _slab('plenum', (x0 - e, y0 - e, zt), (x1 + e, y1 + e, zt + e), white)
    # the ceiling around the shaft's square opening, 1 mm wider than the
    # shaft, so that the ceiling's edges lie behind the baffle, not on it
    o = w + 0.001
    _slab('ceiling_l', (x0 - e, y0 - e, z1), (lx - o, y1 + e, z1 + e), white)
    _slab('ceiling_r', (lx + o, y0 - e, z1), (x1 + e, y1 + e, z1 + e), white)
    _slab('ceiling_f', (lx - o, y0 - e, z1), (lx + o, ly - o, z1 + e), white)
    _slab('ceiling_b', (lx - o, ly + o, z1), (lx + o, y1 + e, z1 + e), white)
    bpy.ops.mesh.primitive_cylinder_add(vertices=4, radius=w * np.sqrt(2), depth=d,
                                        end_fill_type='NOTHING',
                                        location=(lx, ly, z1 + d / 2),
                                        rotation=(0, 0, np.pi / 4))
    bpy.context.active_object.data.materials.append(baffle)
    led = bpy.data.lights.new('downlight', 'AREA')
    led.shape = 'DISK'
    led.size = 0.14
    led.energy = 20.0
    led.color = (1.0, 0.92, 0.8)
    ob = bpy.data.objects.new('downlight', led)
    ob.location = (lx, ly, zt - 0.01)
    bpy.context.scene.collection.objects.link(ob)

    # tiles, 10 cm, 5 mm grout, on planes 2 mm in front of the four walls
    tiles = _tiles('tiles', 0.1, 0.005, (0.75, 0.75, 0.73), (0.4, 0.39, 0.37), 0.15, 0.6)
    _wall_plane('tiles_l', x0 + 0.002, y0, y1, z0, z1, 1, tiles)
    _wall_plane('tiles_r', x1 - 0.002, y0, y1, z0, z1, -1, tiles)
    ob = rdm._plane('tiles_b', 1.0, ((x0 + x1) / 2, y1 - 0.002, (z0 + z1) / 2),
                    (np.pi / 2, 0, 0), tiles)
    ob.data.transform(mathutils.Matrix.Diagonal((x1 - x0, z1 - z0, 1.0, 1.0)))
    ob = rdm._plane('tiles_f', 1.0, ((x0 + x1) / 2, y0 + 0.002, (z0 + z1) / 2),
                    (-np.pi / 2, 0, 0), tiles)
    ob.data.transform(mathutils.Matrix.Diagonal((x1 - x0, z1 - z0, 1.0, 1.0)))
    # a door in the front wall (seen in the mirror)
    _slab('door', (-0.7, y0 - 0.01, z0), (0.1, y0 + 0.03, 2.0), rdm._diffuse('door', (0.45, 0.3, 0.2)))

    # the vanity: a cabinet against the back wall, a counter on it
    zc = 0.85
    _slab('cabinet', (x0 - 0.01, 0.47, z0 - 0.01), (0.2, y1 + 0.01, zc - 0.05),
          rdm._diffuse('cabinet', (0.25, 0.35, 0.42)))
    _slab('counter', (x0 - 0.01, 0.45, zc - 0.05), (0.25, y1 + 0.01, zc),
          _principled('counter', (0.7, 0.68, 0.64), 0.25))
    # a glossy ceramic basin on the counter (base 0.5 mm below its top)
    _lathe('basin', [(0.0, 0.0), (0.06, 0.0), (0.17, 0.12), (0.16, 0.12),
                     (0.055, 0.012), (0.0, 0.012)], (-0.35, 0.68), zc - 0.0005,
           _principled('basin', (0.85, 0.85, 0.84), 0.1))
    chrome = _principled('chrome', (0.9, 0.9, 0.92), 0.1, metallic=1.0)
    # a gooseneck tap behind the basin and a towel rail on the cabinet front
    _tube('tap', [(-0.35, 0.92, zc - 0.01), (-0.35, 0.92, 1.15), (-0.35, 0.78, 1.15),
                  (-0.35, 0.78, 1.05)], 0.012, 0.05, chrome)
    _tube('rail', [(-0.75, 0.48, 0.68), (-0.75, 0.41, 0.68), (0.1, 0.41, 0.68),
                   (0.1, 0.48, 0.68)], 0.01, 0.03, chrome)
    # a bar of soap (a squashed ellipsoid) and an unlit candle, subsurface
    soap = rdm._sphere('soap', 1.0, (-0.05, 0.72, zc + 0.014),
                       _principled('soap', (0.85, 0.62, 0.58), 0.3,
                                   subsurface=(0.01, (1.0, 0.6, 0.45))))
    soap.data.transform(mathutils.Matrix.Diagonal((0.045, 0.03, 0.016, 1.0)))
    _lathe('candle', [(0.0, 0.0), (0.035, 0.0), (0.035, 0.12), (0.0, 0.12)],
           (-0.78, 0.78), zc - 0.0005,
           _principled('wax', (0.9, 0.82, 0.62), 0.4,
                       subsurface=(0.03, (1.0, 0.55, 0.3))))

    # the mirror, 2 cm thick, standing 2.3 cm off the tiles; a dim emissive
    # strip (four bars, 4 cm inside its edge) behind it lights the tiles
    mx0, mx1, mz0, mz1, my0, my1 = -0.85, 0.15, 1.1, 1.85, 0.955, 0.975
    _slab('mirror', (mx0, my0, mz0), (mx1, my1, mz1), _mirror('mirror', (0.92, 0.92, 0.92)))
    strip = _emission('strip', (1.0, 0.85, 0.65), 3.0)
    # not sampled as a light: lit only through the gap, it would take light
    # samples from the downlight everywhere else (trials: 24% less variance)
    strip.cycles.sample_as_light = False
    i, t, sy0, sy1 = 0.04, 0.01, my1 + 0.003, my1 + 0.01
    _slab('strip_b', (mx0 + i, sy0, mz0 + i), (mx1 - i, sy1, mz0 + i + t), strip)
    _slab('strip_t', (mx0 + i, sy0, mz1 - i - t), (mx1 - i, sy1, mz1 - i), strip)
    _slab('strip_l', (mx0 + i, sy0, mz0 + i + t), (mx0 + i + t, sy1, mz1 - i - t), strip)
    _slab('strip_r', (mx1 - i - t, sy0, mz0 + i + t), (mx1 - i, sy1, mz1 - i - t), strip)

    # the shower corner: a raised tray, open at the front, and a frosted
    # glass screen, 8 mm thick, from the back wall, standing 1 mm above the
    # tray (no face lies on another)
    sx0, sy_ = 0.32, 0.1
    _slab('tray', (sx0, sy_, z0 - 0.01), (x1 + 0.01, y1 + 0.01, 0.05),
          _principled('tray', (0.8, 0.8, 0.79), 0.1))
    _slab('screen', (sx0, 0.5, 0.051), (sx0 + 0.008, y1 - 0.001, 1.9),
          _rough_glass('frosted', 1.5, 0.4))

    # fewer bounces than Blender's defaults (diffuse 4, glossy 4,
    # transmission 12) keep a sample's cost down in this closed white room
    sc = bpy.context.scene
    sc.cycles.diffuse_bounces = 3
    sc.cycles.glossy_bounces = 3
    sc.cycles.transmission_bounces = 6
    rdm._camera((0.05, -1.3, 1.5), (np.radians(78), 0, 0), 70.0)
    rdm._world(0.0)


SCENES = {'cornell': rdm.build_cornell, 'texture': rdm.build_texture,
          'interior': build_interior, 'window': build_window, 'lamp': build_lamp,
          'corridor': build_corridor, 'fog': build_fog, 'courtyard': build_courtyard,
          'stilllife': build_stilllife, 'bathroom': build_bathroom}


def replicate_seed(stream, r):
    """Cycles seed of replicate r: a hashed 31-bit seed (render_dumps'
    sample_seed), so replicates' seeds differ in all bits."""
    return rdm.sample_seed(stream + r, 0)


def log(msg):
    print('[render_strat %s] %s' % (time.strftime('%H:%M:%S'), msg), flush=True)


def parse_args(argv):
    ap = argparse.ArgumentParser(prog='render_strat.py',
                                 description='Render mcpost stratified fixtures with Cycles.')
    ap.add_argument('--scene', choices=sorted(SCENES), required=True)
    ap.add_argument('--out', required=True, help='output folder for this scene')
    ap.add_argument('--res', type=int, default=128)
    ap.add_argument('--replicates', type=int, default=8)
    ap.add_argument('--blocks', type=int, default=32)
    ap.add_argument('--block-spp', type=int, default=32)
    ap.add_argument('--seed-stream', type=int, default=3000,
                    help='replicate r uses seed sample_seed(seed_stream + r, 0)')
    ap.add_argument('--seed-ref', type=int, default=9001)
    ap.add_argument('--ref-spp', type=int, default=16384)
    ap.add_argument('--ref-batch', type=int, default=1024)
    ap.add_argument('--pattern', default='SOBOL', choices=['SOBOL', 'PROGRESSIVE_MULTI_JITTER'])
    ap.add_argument('--threads', type=int, default=2)
    ap.add_argument('--verify', default='', help='comma list of blocks to verify first')
    ap.add_argument('--verify-only', action='store_true')
    ap.add_argument('--skip', default='', help='comma list of parts to skip: '
                    'replicate0,replicates,reference')
    return ap.parse_args(argv)


def half(a, counter):
    v, k = exr_min.clamp_half(a)
    counter[0] += k
    return v


def main():
    argv = sys.argv[sys.argv.index('--') + 1:] if '--' in sys.argv else []
    a = parse_args(argv)
    skip = set(s for s in a.skip.split(',') if s)
    name = a.scene
    B, m = a.blocks, a.block_spp
    seeds = [replicate_seed(a.seed_stream, r) for r in range(a.replicates)]
    if len(set(seeds + [a.seed_ref])) != len(seeds) + 1:
        raise RuntimeError('seed collision; choose another --seed-stream')
    t_start = time.time()

    rdm._clear_scene()
    SCENES[name]()
    tmpdir = tempfile.mkdtemp(prefix='render_strat_',
                              dir='/dev/shm' if os.path.isdir('/dev/shm') else None)
    rd = rdm.Renderer(a.res, a.threads, a.pattern, tmpdir)
    tag = 'Blender %s Cycles' % bpy.app.version_string.split()[0]
    log('%s: %s, %dx%d, pattern %s, threads %d, %d replicates x %d blocks x %d spp, seeds %s'
        % (name, tag, a.res, a.res, a.pattern, a.threads, a.replicates, B, m, seeds))
    clamped = [0]
    nbytes = [0]
    times = {}

    def write(path, ch, attrs, types=None):
        at = {'renderer': tag, 'scene': name}
        at.update(attrs)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        nbytes[0] += exr_min.write(path, ch, at, pixel_type=exr_min.HALF,
                                   compression=exr_min.COMP_ZIP, pixel_types=types)

    def block_attrs(r, b):
        return {'samplesPerPixel': m, 'replicate': r, 'block': b, 'seed': seeds[r],
                'sampleOffset': m * b,
                'sampling': '%s stratified, progressive: seed %d, samples %d..%d'
                            % (a.pattern, seeds[r], m * b, m * b + m - 1)}

    # --- verification: single-sample calls vs one multi-sample call
    if a.verify:
        for b in [int(x) for x in a.verify.split(',')]:
            acc = rdm.Accum()
            for i in range(m):
                acc.add(rd.render(1, seeds[0], m * b + i))
            one = rd.render(m, seeds[0], m * b)['rgb']
            mean = acc.mean()[0]
            d = np.abs(mean - one)
            rel = d / np.maximum(np.abs(one), 1e-3)
            log('verify block %d: %d x samples=1 vs samples=%d at offset %d: max abs diff '
                '%.3g, max rel diff %.3g, mean abs diff %.3g, image mean %.6f vs %.6f, '
                'pixels differing > 1e-5: %d'
                % (b, m, m, m * b, d.max(), rel.max(), d.mean(), mean.mean(), one.mean(),
                   int((d.max(axis=-1) > 1e-5).sum())))
            # a second identical multi-sample call: run-to-run repeatability
            two = rd.render(m, seeds[0], m * b)['rgb']
            log('verify block %d: two identical samples=%d calls: max abs diff %.3g'
                % (b, m, np.abs(two - one).max()))
        if a.verify_only:
            shutil.rmtree(tmpdir, ignore_errors=True)
            return

    # --- replicate 0: one render call per sample
    if 'replicate0' not in skip:
        t0 = time.time()
        feat = rdm.Accum()
        for b in range(B):
            acc = rdm.Accum()
            for i in range(m):
                px = rd.render(1, seeds[0], m * b + i)
                acc.add(px)
                feat.add(px)
            mean = acc.mean()[0]
            var = acc.var_per_sample()
            ch = {}
            for k, c in enumerate('RGB'):
                ch[c] = half(mean[..., k], clamped)
                ch['Variance.' + c] = half(var[..., k], clamped)
            write(os.path.join(a.out, 'blocks', '%s_r0_b%02d.exr' % (name, b)), ch,
                  block_attrs(0, b))
            el = time.time() - t0
            log('r0 block %d written (%.1f s, %.3f s/render; mean %.4f, mean var %.4f)'
                % (b, el, el / (m * (b + 1)), mean.mean(), var.mean()))
        _, alb, nrm = feat.mean()
        ch = {}
        for k, c in enumerate('RGB'):
            ch['Albedo.' + c] = half(alb[..., k], clamped)
        for k, c in enumerate('XYZ'):
            ch['N.' + c] = nrm[..., k]
        write(os.path.join(a.out, '%s_features.exr' % name), ch,
              {'samplesPerPixel': B * m, 'replicate': 0, 'seed': seeds[0],
               'sampleOffset': 0,
               'sampling': 'mean of replicate 0 samples 0..%d' % (B * m - 1)})
        times['replicate0'] = time.time() - t0
        log('replicate 0 done: %d renders in %.1f s' % (B * m, times['replicate0']))

    # --- replicates 1..: one render call per block
    if 'replicates' not in skip:
        t0 = time.time()
        for r in range(1, a.replicates):
            for b in range(B):
                rgb = rd.render(m, seeds[r], m * b)['rgb']
                ch = {c: half(rgb[..., k], clamped) for k, c in enumerate('RGB')}
                write(os.path.join(a.out, 'blocks', '%s_r%d_b%02d.exr' % (name, r, b)), ch,
                      block_attrs(r, b))
            log('replicate %d written (seed %d, %.1f s)' % (r, seeds[r], time.time() - t0))
        times['replicates'] = time.time() - t0

    # --- reference: batches of one seed at consecutive sample offsets
    if 'reference' not in skip:
        t0 = time.time()
        acc = rdm.Accum()
        while acc.n < a.ref_spp:
            nb = min(a.ref_batch, a.ref_spp - acc.n)
            acc.add(rd.render(nb, a.seed_ref, acc.n), nb)
            log('reference %d/%d spp (%.1f s)' % (acc.n, a.ref_spp, time.time() - t0))
        mean, alb, nrm = acc.mean()
        wr = rdm.Writer(name, tag)
        wr.write(os.path.join(a.out, '%s_reference.exr' % name), acc.n,
                 mean, alb, nrm, rgb_float=True)
        clamped[0] += wr.clamped
        nbytes[0] += wr.bytes
        times['reference'] = time.time() - t0
        log('reference done in %.1f s' % times['reference'])

    shutil.rmtree(tmpdir, ignore_errors=True)
    log('%s finished: %d renders, %.1f s in render calls, %.1f s total (%s), %d values '
        'clamped to the half range, %.2f MB written'
        % (name, rd.renders, rd.seconds, time.time() - t_start,
           ', '.join('%s %.0f s' % kv for kv in times.items()), clamped[0], nbytes[0] / 1e6))


if __name__ == '__main__':
    rdm.run_main(main, 'render_strat')
