"""Writes tests/data/blender/clutter.glb with Blender's own glTF exporter (Blender 3.4 from Debian 12):
a cluttered room as a user models one, every object a Blender cube (closed, double-sided materials as
Blender writes them). A 6 x 5 x 2.8 m room of 20 cm thick walls, two emissive ceiling panels 1 cm
under the ceiling and a point light, six tables on four legs, 24 chairs (seat, back, four legs), five
cabinets against the walls, and 300 small boxes (4 to 18 cm) on the tables and the floor. Random
sizes and places come from a fixed seed. The bench reads the committed file; it does not need
Blender.
Run: blender -b --factory-startup --python scripts/make_blender_clutter.py -- tests/data/blender/clutter.glb"""
import bpy, random, sys
import os
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from blender_scene import box, light, material, room_materials, start
out = start(11)
wall, floor, wood, metal, fabric = room_materials()
paint = [material('Paint%d' % i, c) for i, c in enumerate(
    [(0.7, 0.2, 0.15), (0.2, 0.5, 0.25), (0.8, 0.7, 0.2), (0.25, 0.3, 0.7), (0.6, 0.6, 0.6), (0.15, 0.15, 0.15)])]

# Room: inside x 0..6, y 0..5, z 0..2.8; walls 0.2 m thick, closed.
W, D, H = 6.0, 5.0, 2.8
box('Floor', (-0.2, -0.2, -0.2), (W + 0.2, D + 0.2, 0.0), floor)
box('Ceiling', (-0.2, -0.2, H), (W + 0.2, D + 0.2, H + 0.2), wall)
box('WallWest', (-0.2, 0.0, 0.0), (0.0, D, H), wall)
box('WallEast', (W, 0.0, 0.0), (W + 0.2, D, H), wall)
box('WallSouth', (-0.2, -0.2, 0.0), (W + 0.2, 0.0, H), wall)
box('WallNorth', (-0.2, D, 0.0), (W + 0.2, D + 0.2, H), wall)

# Two ceiling panels, 0.8 x 0.8 m, 1 cm under the ceiling, facing down; a point light.
for i, x in enumerate((2.0, 4.0)):
    bpy.ops.mesh.primitive_plane_add(size=0.8, location=(x, 2.5, H - 0.01), rotation=(3.14159265, 0, 0))
    p = bpy.context.active_object
    p.name = 'Panel%d' % i
    p.data.materials.append(material('PanelLight', (0.8, 0.8, 0.8), (1.0, 0.95, 0.85), 6.0))
light('POINT', 'Lamp', 60.0, (1.0, 4.2, 1.9), color=(1.0, 0.85, 0.6))

# Six tables in two rows, four chairs around each.
tables = []
for row in range(2):
    for col in range(3):
        x0, y0 = 0.8 + col * 1.8, 1.0 + row * 2.0
        x1, y1 = x0 + 1.2, y0 + 0.8
        tables.append((x0, y0, x1, y1))
        box('TableTop', (x0, y0, 0.72), (x1, y1, 0.76), wood)
        for x in (x0 + 0.04, x1 - 0.08):
            for y in (y0 + 0.04, y1 - 0.08):
                box('TableLeg', (x, y, 0.0), (x + 0.04, y + 0.04, 0.72), metal)
        for cx, cy, back in ((x0 + 0.1, y0 - 0.5, 'south'), (x1 - 0.55, y0 - 0.5, 'south'),
                             (x0 + 0.1, y1 + 0.05, 'north'), (x1 - 0.55, y1 + 0.05, 'north')):
            box('ChairSeat', (cx, cy, 0.44), (cx + 0.45, cy + 0.45, 0.48), fabric)
            by = cy if back == 'south' else cy + 0.41
            box('ChairBack', (cx, by, 0.48), (cx + 0.45, by + 0.04, 0.9), fabric)
            for lx in (cx + 0.01, cx + 0.41):
                for ly in (cy + 0.01, cy + 0.41):
                    box('ChairLeg', (lx, ly, 0.0), (lx + 0.03, ly + 0.03, 0.44), metal)

# Five cabinets against the walls.
for i, (lo, hi) in enumerate([((0.1, 4.4, 0.0), (1.3, 4.95, 1.8)), ((2.0, 4.5, 0.0), (3.0, 4.95, 0.9)),
                              ((4.6, 4.5, 0.0), (5.9, 4.95, 2.0)), ((5.45, 0.3, 0.0), (5.95, 1.5, 1.1)),
                              ((0.05, 0.2, 0.0), (0.55, 1.0, 1.4))]):
    box('Cabinet', lo, hi, wood)

# 300 small boxes: two thirds on the tables, the rest on the floor between them.
for n in range(300):
    s = [random.uniform(0.04, 0.18) for _ in range(3)]
    if n % 3 != 2:
        x0, y0, x1, y1 = tables[n % len(tables)]
        x = random.uniform(x0 + 0.02, x1 - 0.02 - s[0])
        y = random.uniform(y0 + 0.02, y1 - 0.02 - s[1])
        z = 0.76
    else:
        x = random.uniform(0.2, W - 0.4)
        y = random.uniform(0.1, 0.6) if random.random() < 0.5 else random.uniform(3.6, 4.3)
        z = 0.0
    box('Box', (x, y, z), (x + s[0], y + s[1], z + s[2]), paint[n % len(paint)])

bpy.ops.export_scene.gltf(filepath=out, export_format='GLB', export_lights=True)
