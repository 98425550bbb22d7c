"""Writes tests/data/blender/kitchen.glb with Blender's own glTF exporter (Blender 3.4 from Debian 12;
its Python needs python3-numpy):
a kitchen as a user models one, for bakes no one tuned on. A 4 x 3 x 2.6 m room of 15 cm thick
walls (closed boxes, double-sided materials as Blender writes them), a counter along the north wall
under a row of wall cabinets, an emissive strip light on the cabinets' underside 1 cm above their
bottom edge, facing the counter 55 cm below; a 40 W spot light over a table, pointing down; a
window opening in the west wall with no glass and no sun, dark outside; on the counter bottles and
jars (smooth-shaded cylinders), a bowl (a UV sphere's lower half, open, seen inside and out) and
small boxes; a table with four legs and two stools. Random sizes come from a fixed seed. The tests
read the committed file; they do not need Blender.
Run: blender -b --factory-startup --python scripts/make_blender_kitchen.py -- tests/data/blender/kitchen.glb"""
import bpy, bmesh, math, random, sys
import os
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from blender_scene import box, light, material, room_materials, start
out = start(11)
wall, floor, wood, metal, fabric = room_materials()
tile = material('Tile', (0.82, 0.84, 0.86))
cabinet = material('Cabinet', (0.55, 0.62, 0.58))
stone = material('Worktop', (0.25, 0.25, 0.27))

# Room: inside x 0..4, y 0..3, z 0..2.6; walls 0.15 m thick; a window opening in the west wall
# (x = 0) at y 1.0..2.0, z 1.0..2.0, open to a dark outside.
box('Floor', (-0.15, -0.15, -0.15), (4.15, 3.15, 0.0), floor)
box('Ceiling', (-0.15, -0.15, 2.6), (4.15, 3.15, 2.75), wall)
box('WallSouth', (-0.15, -0.15, 0.0), (4.15, 0.0, 2.6), wall)
box('WallNorth', (-0.15, 3.0, 0.0), (4.15, 3.15, 2.6), tile)
box('WallEast', (4.0, 0.0, 0.0), (4.15, 3.0, 2.6), wall)
box('WallWestA', (-0.15, 0.0, 0.0), (0.0, 1.0, 2.6), wall)
box('WallWestB', (-0.15, 2.0, 0.0), (0.0, 3.0, 2.6), wall)
box('WallWestSill', (-0.15, 1.0, 0.0), (0.0, 2.0, 1.0), wall)
box('WallWestLintel', (-0.15, 1.0, 2.0), (0.0, 2.0, 2.6), wall)

# Counter along the north wall: base cabinets, a worktop 0.9 m up; wall cabinets 0.55 m above it.
box('BaseCabinets', (0.6, 2.42, 0.0), (3.8, 3.0, 0.86), cabinet)
box('Worktop', (0.6, 2.38, 0.86), (3.8, 3.0, 0.9), stone)
box('WallCabinets', (0.6, 2.65, 1.45), (3.8, 3.0, 2.2), cabinet)

# The strip light under the wall cabinets: 3 m x 4 cm, 1 cm below their bottom, facing down.
bpy.ops.mesh.primitive_plane_add(size=1.0, location=(2.2, 2.72, 1.44), rotation=(math.pi, 0, 0))
strip = bpy.context.active_object
strip.name = 'StripLight'
strip.scale = (3.0, 0.04, 1.0)
bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
strip.data.materials.append(material('StripLight', (0.9, 0.9, 0.9), (1.0, 0.92, 0.8), 30.0))

# On the worktop: bottles and jars (smooth-shaded cylinders), small boxes, an open bowl.
x = 0.75
n = 0
while x < 3.6:
    r = random.uniform(0.03, 0.06)
    h = random.uniform(0.08, 0.3)
    bpy.ops.mesh.primitive_cylinder_add(vertices=24, radius=r, depth=h, location=(x + r, random.uniform(2.75, 2.9), 0.9 + h / 2))
    o = bpy.context.active_object
    o.name = 'Jar'
    bpy.ops.object.shade_smooth()
    colour = (random.uniform(0.2, 0.9), random.uniform(0.2, 0.8), random.uniform(0.1, 0.6))
    o.data.materials.append(material('Jar%d' % (n % 5), colour))
    x += 2 * r + random.uniform(0.02, 0.25)
    n += 1
for i in range(6):
    cx, cy = random.uniform(0.8, 3.5), random.uniform(2.45, 2.6)
    s = random.uniform(0.04, 0.12)
    box('SmallBox', (cx, cy, 0.9), (cx + s, cy + s * 0.8, 0.9 + s * 1.2), material('Box%d' % (i % 3), (0.7, 0.5, 0.3)))
# The bowl: the lower half of a UV sphere of radius 12 cm, open at the top, on the worktop.
bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=0.12, location=(2.0, 2.55, 1.02))
bowl = bpy.context.active_object
bowl.name = 'Bowl'
bm = bmesh.new()
bm.from_mesh(bowl.data)
bmesh.ops.delete(bm, geom=[v for v in bm.verts if v.co.z > 1e-4], context='VERTS')
bm.to_mesh(bowl.data)
bm.free()
bpy.ops.object.shade_smooth()
bowl.data.materials.append(material('Bowl', (0.85, 0.85, 0.8)))

# A table in the middle of the room on four legs, two stools, a fruit box on the table.
box('TableTop', (1.4, 0.8, 0.72), (2.6, 1.6, 0.76), wood)
for lx in (1.45, 2.52):
    for ly in (0.85, 1.52):
        box('TableLeg', (lx, ly, 0.0), (lx + 0.03, ly + 0.03, 0.72), metal)
for sx in (1.2, 2.7):
    bpy.ops.mesh.primitive_cylinder_add(vertices=20, radius=0.16, depth=0.04, location=(sx, 1.2, 0.62))
    bpy.ops.object.shade_smooth()
    bpy.context.active_object.data.materials.append(fabric)
    bpy.ops.mesh.primitive_cylinder_add(vertices=12, radius=0.02, depth=0.6, location=(sx, 1.2, 0.3))
    bpy.context.active_object.data.materials.append(metal)
box('FruitBox', (1.8, 1.05, 0.76), (2.1, 1.3, 0.86), wood)

# A 40 W spot light 1.2 m over the table, pointing straight down, 70 degree cone.
spot = light('SPOT', 'Pendant', 40.0, (2.0, 1.2, 1.95), color=(1.0, 0.85, 0.65))
spot.data.spot_size = math.radians(70)
spot.data.spot_blend = 0.3
bpy.ops.export_scene.gltf(filepath=out, export_format='GLB', export_lights=True)
