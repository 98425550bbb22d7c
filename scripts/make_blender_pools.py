"""Writes tests/data/blender/glowing-spheres.glb with Blender's own glTF exporter (Blender 3.4 from
Debian 12; its Python needs python3-numpy): a 12 m floor (one quad), two small glowing UV spheres
(16 x 12; r 0.2 m at 0.6 m, strength 30, orange; r 0.15 m at 0.4 m, strength 40, blue) and a
0.8 m box, Z up, materials double-sided as Blender writes them. The floor's light pools under the
spheres; tests/bench/display_error_test.cpp bakes it with and without Params::pools. The tests
read the committed file; they do not need Blender.
Run: blender -b --factory-startup --python scripts/make_blender_pools.py -- tests/data/blender/glowing-spheres.glb"""
import bpy, sys
import os
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from blender_scene import material
out = sys.argv[sys.argv.index('--') + 1]

bpy.ops.wm.read_factory_settings(use_empty=True)

def add(obj_op, mat, **kw):
    obj_op(**kw)
    bpy.context.object.data.materials.append(mat)

add(bpy.ops.mesh.primitive_plane_add, material('floor', (0.6, 0.6, 0.6)), size=12, location=(0, 0, 0))
add(bpy.ops.mesh.primitive_uv_sphere_add, material('lava', (0.2, 0.2, 0.2), (1.0, 0.5, 0.2), 30.0),
    segments=16, ring_count=12, radius=0.2, location=(-1.5, 0, 0.6))
add(bpy.ops.mesh.primitive_uv_sphere_add, material('ice', (0.2, 0.2, 0.2), (0.3, 0.6, 1.0), 40.0),
    segments=16, ring_count=12, radius=0.15, location=(2, -1, 0.4))
add(bpy.ops.mesh.primitive_cube_add, material('box', (0.5, 0.4, 0.3)), size=0.8, location=(0.4, 1.1, 0.4))
bpy.ops.export_scene.gltf(filepath=out, export_format='GLB')
