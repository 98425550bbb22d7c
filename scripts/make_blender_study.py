"""Writes tests/data/blender/study.glb with Blender's own glTF exporter (Blender 3.4 from Debian 12):
a furnished room as a user models one, for bakes no one tuned on. A 5 x 4 x 2.8 m room of 20 cm
thick walls (closed boxes, double-sided materials as Blender writes them), a 1.2 x 1.4 m window
with the sun shining through it (a 4 W/m^2 sun lamp), an emissive ceiling panel 1 cm under the
ceiling, a 25 W point light over a desk, a desk and a chair on thin legs, a bookshelf of 60
books, mugs (cylinders) and a ball (UV sphere), and a textured rug 3 mm above the floor. Random
sizes come from a fixed seed. The tests read the committed file; they do not need Blender.
Run: blender -b --factory-startup --python scripts/make_blender_study.py -- tests/data/blender/study.glb"""
import bpy, math, random, sys
import os
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from blender_scene import box, light, material, room_materials, start
out = start(7)
wall, floor, wood, metal, fabric = room_materials()

# Room: inside x 0..5, y 0..4, z 0..2.8; walls 0.2 m thick; the window in the wall at y = 0,
# x 1.6..2.8, z 0.9..2.3.
box('Floor', (-0.2, -0.2, -0.2), (5.2, 4.2, 0.0), floor)
box('Ceiling', (-0.2, -0.2, 2.8), (5.2, 4.2, 3.0), wall)
box('WallWest', (-0.2, 0.0, 0.0), (0.0, 4.0, 2.8), wall)
box('WallEast', (5.0, 0.0, 0.0), (5.2, 4.0, 2.8), wall)
box('WallNorth', (-0.2, 4.0, 0.0), (5.2, 4.2, 2.8), wall)
box('WallSouthLeft', (-0.2, -0.2, 0.0), (1.6, 0.0, 2.8), wall)
box('WallSouthRight', (2.8, -0.2, 0.0), (5.2, 0.0, 2.8), wall)
box('WallSouthSill', (1.6, -0.2, 0.0), (2.8, 0.0, 0.9), wall)
box('WallSouthLintel', (1.6, -0.2, 2.3), (2.8, 0.0, 2.8), wall)

# Ceiling panel: 0.6 m square, 1 cm under the ceiling, facing down.
bpy.ops.mesh.primitive_plane_add(size=0.6, location=(2.5, 2.2, 2.79), rotation=(math.pi, 0, 0))
panel = bpy.context.active_object
panel.name = 'CeilingPanel'
panel.data.materials.append(material('PanelLight', (0.8, 0.8, 0.8), (1.0, 0.95, 0.85), 8.0))

# Desk against the east wall, on four thin legs; a chair in front of it.
box('DeskTop', (3.6, 1.0, 0.72), (4.8, 2.2, 0.76), wood)
for x in (3.65, 4.72):
    for y in (1.05, 2.12):
        box('DeskLeg', (x, y, 0.0), (x + 0.03, y + 0.03, 0.72), metal)
box('ChairSeat', (3.0, 1.4, 0.44), (3.45, 1.85, 0.48), fabric)
box('ChairBack', (2.96, 1.4, 0.48), (3.0, 1.85, 0.95), fabric)
for x in (3.0, 3.42):
    for y in (1.42, 1.82):
        box('ChairLeg', (x, y, 0.0), (x + 0.025, y + 0.025, 0.44), metal)

# Bookshelf against the north wall: sides, four shelves, 60 books of random sizes and colours.
box('ShelfSideL', (0.4, 3.65, 0.0), (0.43, 3.98, 2.0), wood)
box('ShelfSideR', (2.17, 3.65, 0.0), (2.2, 3.98, 2.0), wood)
box('ShelfBack', (0.43, 3.96, 0.0), (2.17, 3.98, 2.0), wood)
books = 0
for level in range(4):
    z = 0.05 + level * 0.5
    box('Shelf', (0.43, 3.65, z - 0.02), (2.17, 3.96, z), wood)
    x = 0.46
    while x < 2.1 and books < 60:
        w = random.uniform(0.02, 0.06)
        h = random.uniform(0.18, 0.32)
        d = random.uniform(0.15, 0.25)
        colour = (random.uniform(0.1, 0.8), random.uniform(0.1, 0.6), random.uniform(0.1, 0.5))
        box('Book', (x, 3.94 - d, z), (x + w, 3.94, z + h), material('Book%d' % (books % 6), colour))
        x += w + random.uniform(0.0, 0.02)
        books += 1

# Mugs on the desk, a ball on the floor.
for i, (x, y) in enumerate([(3.9, 1.3), (4.2, 1.8), (4.5, 1.2)]):
    bpy.ops.mesh.primitive_cylinder_add(vertices=16, radius=0.04, depth=0.1, location=(x, y, 0.81))
    bpy.context.active_object.data.materials.append(material('Mug%d' % i, (0.8, 0.2 + 0.3 * i, 0.2)))
bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=0.15, location=(1.2, 1.5, 0.15))
bpy.context.active_object.data.materials.append(material('Ball', (0.85, 0.6, 0.1)))

# Rug 3 mm above the floor, with a 16 x 16 check texture packed into the file.
image = bpy.data.images.new('RugCheck', 16, 16)
pixels = []
for j in range(16):
    for i in range(16):
        c = (0.7, 0.15, 0.1) if (i // 4 + j // 4) % 2 == 0 else (0.9, 0.85, 0.7)
        pixels += [*c, 1.0]
image.pixels = pixels
image.pack()
bpy.ops.mesh.primitive_plane_add(size=1.0, location=(1.6, 1.8, 0.003))
rug = bpy.context.active_object
rug.name = 'Rug'
rug.scale = (2.0, 1.4, 1.0)
bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
rug.data.materials.append(material('Rug', (1, 1, 1), image=image))

# The sun from the south (-y), 35 degrees above the horizon, through the window onto the floor.
light('SUN', 'Sun', 4.0, (2.2, -3.0, 4.0), rotation=(math.radians(55), 0, math.radians(0)), color=(1.0, 0.95, 0.85))
light('POINT', 'DeskLamp', 25.0, (4.3, 1.6, 1.3), color=(1.0, 0.8, 0.55))
bpy.ops.export_scene.gltf(filepath=out, export_format='GLB', export_lights=True)
