"""Writes tests/data/blender/pavilion.glb with Blender's own glTF exporter (Blender 3.4 from Debian 12):
an open scene, as a user models one, for bakes no one tuned on. A 30 x 30 m lawn (one plane), a
stone platform under a tilted wooden roof on four pillars (linked duplicates of one cylinder, their
scale left unapplied), two benches with their mirror images (negative scale), a subdivided, smooth
Suzanne on a rotated and scaled parent, a torus, a small emissive lantern, crates on the lawn, a
3 W/m^2 sun and a 200 W spot under the roof. Every material is double-sided, as Blender writes
them. Random places come from a fixed seed. The tests read the committed file; they do not need
Blender.
Run: blender -b --factory-startup --python scripts/make_blender_pavilion.py -- tests/data/blender/pavilion.glb"""
import bpy, math, random, sys
import os
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from blender_scene import box, light, material, start
out = start(11)
stone = material('Stone', (0.6, 0.58, 0.55))
grass = material('Grass', (0.25, 0.4, 0.15))
wood = material('Wood', (0.5, 0.32, 0.18))
red = material('Red', (0.7, 0.12, 0.1))

bpy.ops.mesh.primitive_plane_add(size=30.0, location=(0, 0, 0))
lawn = bpy.context.active_object
lawn.name = 'Ground'
lawn.data.materials.append(grass)
box('Platform', (-3, -2, 0.0), (3, 2, 0.2), stone)

# Pillars: one cylinder mesh shared by four objects, each scaled (0.15, 0.15, 2.5) by its node.
bpy.ops.mesh.primitive_cylinder_add(vertices=12, radius=1.0, depth=1.0, location=(-2.6, -1.6, 1.45))
pillar = bpy.context.active_object
pillar.name = 'Pillar'
pillar.data.materials.append(stone)
pillar.scale = (0.15, 0.15, 2.5)
for (x, y) in [(2.6, -1.6), (-2.6, 1.6), (2.6, 1.6)]:
    copy = pillar.copy()
    copy.location = (x, y, 1.45)
    bpy.context.collection.objects.link(copy)

# Roof: a cube whose scale and 4 degree tilt stay on its node.
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 2.8), rotation=(math.radians(4), 0, 0))
roof = bpy.context.active_object
roof.name = 'Roof'
roof.scale = (6.4, 4.4, 0.2)
roof.data.materials.append(wood)

# A bench (seat and a tilted back) and its mirror image through x = 0 (scale -1 on x).
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 0))
seat = bpy.context.active_object
seat.name = 'Bench'
bpy.ops.object.mode_set(mode='EDIT')
bpy.ops.mesh.select_all(action='SELECT')
bpy.ops.transform.resize(value=(1.2, 0.4, 0.1))
bpy.ops.object.mode_set(mode='OBJECT')
seat.location = (-1.2, 0.8, 0.65)
seat.data.materials.append(wood)
back = seat.copy()
back.data = seat.data.copy()
bpy.context.collection.objects.link(back)
back.name = 'BenchBack'
back.location = (-1.2, 1.05, 0.95)
back.rotation_euler = (math.radians(80), 0, math.radians(10))
for part, name, loc, rot in [(seat, 'BenchMirror', (1.2, 0.8, 0.65), None),
                             (back, 'BenchBackMirror', (1.2, 1.05, 0.95), (math.radians(80), 0, math.radians(-10)))]:
    m = part.copy()
    m.name = name
    bpy.context.collection.objects.link(m)
    m.location = loc
    m.scale = (-1, 1, 1)
    if rot:
        m.rotation_euler = rot

# Suzanne, subdivided once and smooth, on an empty turned 30 degrees and scaled by a half.
bpy.ops.object.empty_add(location=(0, -0.6, 0.2), rotation=(0, 0, math.radians(30)))
parent = bpy.context.active_object
parent.name = 'Pedestal'
parent.scale = (0.5, 0.5, 0.5)
bpy.ops.mesh.primitive_monkey_add(location=(0, 0, 0))
monkey = bpy.context.active_object
monkey.name = 'Monkey'
monkey.data.materials.append(red)
monkey.modifiers.new('sub', 'SUBSURF').levels = 1
bpy.ops.object.shade_smooth()
monkey.parent = parent
monkey.location = (0, 0, 1.0)

bpy.ops.mesh.primitive_torus_add(location=(5, 3, 0.3), major_radius=0.8, minor_radius=0.25)
bpy.context.active_object.data.materials.append(stone)
bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=0.12, location=(0, 0.5, 2.35))
bpy.context.active_object.name = 'Lantern'
bpy.context.active_object.data.materials.append(material('LanternGlow', (1, 1, 1), (1.0, 0.7, 0.4), 30.0))

# Crates on the lawn, off the platform.
for i in range(12):
    x, y = random.uniform(-8, 8), random.uniform(-8, 8)
    if abs(x) < 4 and abs(y) < 3:
        continue
    size = random.uniform(0.3, 0.8)
    box('Crate', (x, y, 0), (x + size, y + size, size), wood)

light('SUN', 'Sun', 3.0, (0, 0, 10), rotation=(math.radians(40), math.radians(15), math.radians(30)), color=(1.0, 0.95, 0.85))
light('SPOT', 'Spot', 200.0, (0, -1.0, 2.5), rotation=(math.radians(20), 0, 0))
bpy.ops.export_scene.gltf(filepath=out, export_format='GLB', export_lights=True)
