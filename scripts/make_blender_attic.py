"""Writes an attic scene with Blender's own glTF exporter (Blender 3.4 from Debian 12), for bakes no
one tuned on. `attic` (the default): a 6 x 5 x 2.4 m room modelled as one cube with its normals
flipped to face in (double-sided, as Blender writes it), under a gabled roof rising 1.2 m to a
ridge, its south slope with a 1.2 x 0.8 m skylight; the room's top face closes the room, so the
attic between it and the roof is a space of its own, lit by the sun through the skylight and by
a glowing sphere hung 60 cm over the attic floor. In the room: a table turned 30 degrees (node
rotations, not applied) on four legs, eight boxes on it, a sofa turned -15 degrees, four smooth
24-sided columns from floor to ceiling, and an 80 W spot light over the table. `wedge`: the attic
alone as a closed prism (one-sided faces looking in), lit by a 0.6 m panel 40 cm under the ridge:
the floor meets each slope at 25.6 degrees along the eaves.
Run: blender -b --factory-startup --python scripts/make_blender_attic.py -- OUT.glb [attic|wedge]"""
import bpy, math, random, sys
import os
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from blender_scene import light, material, start
out = start(7)
args = sys.argv[sys.argv.index('--') + 1:]
mode = args[1] if len(args) > 1 else 'attic'
if mode not in ('attic', 'wedge'):
    sys.exit('mode must be attic or wedge')
plaster = material('Plaster', (0.8, 0.78, 0.74))
RIDGE = 1.2  # the roof's rise over the eaves


def polygon(name, points, mat):
    """One face through `points` (counter-clockwise seen from its front)."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(points, [], [tuple(range(len(points)))])
    o = bpy.data.objects.new(name, mesh)
    bpy.context.collection.objects.link(o)
    o.data.materials.append(mat)
    return o


if mode == 'wedge':
    plaster.use_backface_culling = True  # exported as one-sided
    polygon('Floor', [(0, 0, 0), (6, 0, 0), (6, 5, 0), (0, 5, 0)], plaster)
    polygon('SlopeSouth', [(0, 0, 0), (0, 2.5, RIDGE), (6, 2.5, RIDGE), (6, 0, 0)], plaster)
    polygon('SlopeNorth', [(0, 5, 0), (6, 5, 0), (6, 2.5, RIDGE), (0, 2.5, RIDGE)], plaster)
    polygon('GableWest', [(0, 0, 0), (0, 5, 0), (0, 2.5, RIDGE)], plaster)
    polygon('GableEast', [(6, 0, 0), (6, 2.5, RIDGE), (6, 5, 0)], plaster)
    glow = material('Glow', (0.8, 0.8, 0.8), (1.0, 1.0, 1.0), 10.0)
    glow.use_backface_culling = True
    polygon('Panel', [(2.7, 2.2, 0.8), (2.7, 2.8, 0.8), (3.3, 2.8, 0.8), (3.3, 2.2, 0.8)], glow)
    bpy.ops.export_scene.gltf(filepath=out, export_format='GLB')
    sys.exit(0)

wood = material('Wood', (0.5, 0.33, 0.2))
dark = material('Dark', (0.15, 0.15, 0.17))
# The room: one cube, its normals flipped to face in.
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(3.0, 2.5, 1.2))
room = bpy.context.active_object
room.name = 'Room'
room.scale = (6.0, 5.0, 2.4)
bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
bpy.ops.object.mode_set(mode='EDIT')
bpy.ops.mesh.select_all(action='SELECT')
bpy.ops.mesh.flip_normals()
bpy.ops.object.mode_set(mode='OBJECT')
room.data.materials.append(plaster)


def slope(y0, y1, x0, x1, name, flip):
    """A strip of the roof over y0..y1, x0..x1, facing down into the attic."""
    z = lambda y: 2.4 + RIDGE * (1 - abs(y - 2.5) / 2.5)
    p = [(x0, y0, z(y0)), (x1, y0, z(y0)), (x1, y1, z(y1)), (x0, y1, z(y1))]
    return polygon(name, p[::-1] if flip else p, plaster)


slope(2.5, 5.0, 0.0, 6.0, 'RoofNorth', False)
slope(0.0, 0.8, 0.0, 6.0, 'RoofSouthA', True)  # the south slope around the skylight
slope(1.6, 2.5, 0.0, 6.0, 'RoofSouthB', True)
slope(0.8, 1.6, 0.0, 2.4, 'RoofSouthC', True)
slope(0.8, 1.6, 3.6, 6.0, 'RoofSouthD', True)
polygon('GableWest', [(0.0, 2.5, 2.4 + RIDGE), (0.0, 5.0, 2.4), (0.0, 0.0, 2.4)], plaster)
polygon('GableEast', [(6.0, 0.0, 2.4), (6.0, 5.0, 2.4), (6.0, 2.5, 2.4 + RIDGE)], plaster)
# A table turned 30 degrees about Z (kept on the nodes), on four legs.
turn = math.radians(30)
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(3.0, 2.6, 0.74))
top = bpy.context.active_object
top.name = 'TableTop'
top.scale = (1.6, 0.9, 0.04)
top.rotation_euler = (0, 0, turn)
top.data.materials.append(wood)
for dx in (-0.7, 0.7):
    for dy in (-0.38, 0.38):
        x = 3.0 + math.cos(turn) * dx - math.sin(turn) * dy
        y = 2.6 + math.sin(turn) * dx + math.cos(turn) * dy
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=(x, y, 0.36))
        leg = bpy.context.active_object
        leg.name = 'Leg'
        leg.scale = (0.05, 0.05, 0.72)
        leg.rotation_euler = (0, 0, turn)
        leg.data.materials.append(wood)
# Smooth columns from floor to ceiling.
for i, (x, y) in enumerate([(1.0, 1.0), (5.0, 1.0), (1.0, 4.0), (5.0, 4.0)]):
    bpy.ops.mesh.primitive_cylinder_add(vertices=24, radius=0.12, depth=2.4, location=(x, y, 1.2))
    column = bpy.context.active_object
    column.name = 'Column%d' % i
    bpy.ops.object.shade_smooth()
    column.data.materials.append(dark if i % 2 else plaster)
# Boxes on the table, each turned at random, and a sofa.
for i in range(8):
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(3.0 + random.uniform(-0.5, 0.5), 2.6 + random.uniform(-0.25, 0.25), 0.81))
    b = bpy.context.active_object
    b.name = 'Box'
    b.scale = (random.uniform(0.05, 0.15), random.uniform(0.05, 0.15), 0.1)
    b.rotation_euler = (0, 0, random.uniform(0, math.pi))
    colour = (random.uniform(0.2, 0.8), random.uniform(0.2, 0.8), random.uniform(0.2, 0.8))
    b.data.materials.append(material('Box%d' % (i % 3), colour))
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(1.4, 3.2, 0.25))
sofa = bpy.context.active_object
sofa.name = 'Sofa'
sofa.scale = (1.8, 0.8, 0.5)
sofa.rotation_euler = (0, 0, math.radians(-15))
sofa.data.materials.append(material('Fabric', (0.25, 0.35, 0.6)))
# A glowing sphere in the attic, 60 cm under the ridge; a spot light over the table; the sun.
bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=0.15, location=(3.0, 2.5, 3.0))
pendant = bpy.context.active_object
pendant.name = 'Pendant'
bpy.ops.object.shade_smooth()
pendant.data.materials.append(material('PendantGlow', (0.9, 0.9, 0.9), (1.0, 0.9, 0.7), 15.0))
spot = light('SPOT', 'TableSpot', 80.0, (3.0, 2.6, 2.3), color=(1.0, 0.95, 0.9))
spot.data.spot_size = math.radians(50)
spot.data.spot_blend = 0.3
light('SUN', 'Sun', 3.0, (3.0, -2.0, 6.0), rotation=(math.radians(30), 0, 0), color=(1.0, 0.95, 0.85))
bpy.ops.export_scene.gltf(filepath=out, export_format='GLB', export_lights=True)
