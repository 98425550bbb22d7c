"""Writes tests/data/blender/gallery.glb with Blender's own glTF exporter (Blender 3.4 from Debian 12):
a 12 x 6 x 4 m gallery of 20 cm wall boxes (double-sided, as Blender writes them) under a roof with
a 2 x 8 m skylight, a 3 W/m^2 sun through it, five 60 W spot lights on ten pictures (frames 1 cm
off the long walls, canvases 5 mm in front of the frames), five columns (16-sided cylinders) and
four benches on legs. A scene for the bench that nothing was tuned on. The tests do not need
Blender. Run: blender -b --factory-startup --python scripts/make_blender_gallery.py -- tests/data/blender/gallery.glb"""
import bpy, math, random, sys
import os
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from blender_scene import box, light, material
out = sys.argv[sys.argv.index('--') + 1]
random.seed(3)
bpy.ops.wm.read_factory_settings(use_empty=True)
wall = material('Wall', (0.8, 0.8, 0.78)); floor = material('Stone', (0.5, 0.48, 0.45))
frame = material('Frame', (0.25, 0.15, 0.08)); bench = material('Bench', (0.35, 0.2, 0.1))
# Gallery 12 x 6 x 4 m; roof with a 2 x 8 m skylight opening in the middle (roof boxes around it).
box('Floor', (-0.2, -0.2, -0.2), (12.2, 6.2, 0.0), floor)
box('WallW', (-0.2, 0, 0), (0, 6, 4), wall); box('WallE', (12, 0, 0), (12.2, 6, 4), wall)
box('WallS', (-0.2, -0.2, 0), (12.2, 0, 4), wall); box('WallN', (-0.2, 6, 0), (12.2, 6.2, 4), wall)
box('RoofS', (-0.2, -0.2, 4), (12.2, 2.0, 4.2), wall); box('RoofN', (-0.2, 4.0, 4), (12.2, 6.2, 4.2), wall)
box('RoofW', (-0.2, 2.0, 4), (2.0, 4.0, 4.2), wall); box('RoofE', (10.0, 2.0, 4), (12.2, 4.0, 4.2), wall)
# Columns along the middle (16-sided cylinders).
for i in range(5):
    bpy.ops.mesh.primitive_cylinder_add(vertices=16, radius=0.2, depth=4.0, location=(2 + 2 * i, 3.0, 2.0))
    bpy.context.active_object.data.materials.append(wall)
# Pictures: frames 1 cm off the long walls, each with a canvas 5 mm in front of the frame.
for i in range(5):
    x = 1.2 + 2.3 * i
    for y0, y1, sgn in ((0.01, 0.05, 1), (5.95, 5.99, -1)):
        box('Frame', (x, y0, 1.2), (x + 1.2, y1, 2.2), frame)
        cy0, cy1 = (y1, y1 + 0.005) if sgn > 0 else (y0 - 0.005, y0)
        col = (random.uniform(0.2, 0.9), random.uniform(0.2, 0.9), random.uniform(0.2, 0.9))
        box('Canvas', (x + 0.1, cy0, 1.3), (x + 1.1, cy1, 2.1), material('Paint%d%d' % (i, sgn), col))
# Benches on short legs between the columns.
for i in range(4):
    x = 2.6 + 2 * i
    box('BenchTop', (x, 2.6, 0.42), (x + 0.8, 3.4, 0.46), bench)
    for lx in (x + 0.05, x + 0.72):
        box('BenchLeg', (lx, 2.65, 0.0), (lx + 0.03, 3.35, 0.42), bench)
light('SUN', 'Sun', 3.0, (6, 3, 10), rotation=(math.radians(25), math.radians(10), 0), color=(1, 0.96, 0.9))
for i in range(5):
    s = light('SPOT', 'Spot%d' % i, 60.0, (1.8 + 2.3 * i, 1.2, 3.8), rotation=(math.radians(-40), 0, 0))
    s.data.spot_size = math.radians(40); s.data.spot_blend = 0.3
bpy.ops.export_scene.gltf(filepath=out, export_format='GLB', export_lights=True)
