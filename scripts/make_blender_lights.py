"""Writes tests/data/blender-lights.glb and tests/data/blender-point.glb with Blender's own glTF
exporter (Blender 3.4 from Debian 12), as users' files come: Z-up scenes, lights in watts, materials
double-sided. blender-lights.glb: a 4 m floor, a crate, an emissive lamp facing down, a 100 W point
light "Bulb" at (0.5, -0.5, 1), a 3 W/m^2 sun "Sun" turned (40, 0, 30) degrees, a 200 W spot "Spot"
at (-1, 1, 2) pointing down (size 60 degrees, blend 0.25). blender-point.glb: the floor and a
50 W point light at (0.3, 0.2, 0.8). The tests read the committed files; they do not need Blender.
Run: blender -b --factory-startup --python scripts/make_blender_lights.py -- \
       tests/data/blender-lights.glb tests/data/blender-point.glb"""
import bpy, math, sys
import os
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from blender_scene import light, material
out_all, out_point = sys.argv[sys.argv.index('--') + 1:]

def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)

def floor():
    bpy.ops.mesh.primitive_plane_add(size=4, location=(0, 0, 0))
    o = bpy.context.active_object
    o.name = 'Floor'
    o.data.materials.append(material('Ground', (0.6, 0.6, 0.6)))

reset()
floor()
bpy.ops.mesh.primitive_cube_add(size=0.6, location=(0.8, 0.6, 0.3))
bpy.context.active_object.data.materials.append(material('Crate', (0.5, 0.3, 0.2)))
bpy.ops.mesh.primitive_plane_add(size=0.4, location=(-1, -1, 1.5), rotation=(math.pi, 0, 0))
bpy.context.active_object.data.materials.append(material('Lamp', (0.05, 0.05, 0.05), (1, 0.5, 0.2), 3.0))
light('POINT', 'Bulb', 100.0, (0.5, -0.5, 1.0), color=(1, 0.8, 0.6))
light('SUN', 'Sun', 3.0, (0, 0, 5), rotation=(math.radians(40), 0, math.radians(30)))
s = light('SPOT', 'Spot', 200.0, (-1, 1, 2))
s.data.spot_size = math.radians(60)
s.data.spot_blend = 0.25
bpy.ops.export_scene.gltf(filepath=out_all, export_format='GLB', export_lights=True)

reset()
floor()
light('POINT', 'Bulb', 50.0, (0.3, 0.2, 0.8))
bpy.ops.export_scene.gltf(filepath=out_point, export_format='GLB', export_lights=True)
