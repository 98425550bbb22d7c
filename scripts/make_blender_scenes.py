# Writes the Blender-exported test scenes in tests/data/blender (run by Blender 3.4, headless):
#   blender -b --factory-startup --python scripts/make_blender_scenes.py -- OUTDIR
# Each scene is written twice: as Blender exports it by default (materials double-sided) and with
# backface culling on (single-sided), so tests can compare the two.
import sys

import bpy

out_dir = sys.argv[sys.argv.index("--") + 1] if "--" in sys.argv else "."


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def material(name, colour, emission=None, strength=1.0, single_sided=False):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    bsdf = m.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    if emission is not None:
        bsdf.inputs["Emission"].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = strength
    m.use_backface_culling = single_sided
    return m


def box(name, size, location, mat, flip=False):
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=location)
    o = bpy.context.active_object
    o.name = name
    o.scale = size
    bpy.ops.object.transform_apply(scale=True)
    if flip:
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        bpy.ops.mesh.flip_normals()
        bpy.ops.object.mode_set(mode="OBJECT")
    o.data.materials.append(mat)
    return o


def plane(name, size, location, mat, rotation=(0.0, 0.0, 0.0)):
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=location, rotation=rotation)
    o = bpy.context.active_object
    o.name = name
    o.scale = (size[0], size[1], 1.0)
    bpy.ops.object.transform_apply(scale=True, rotation=True)
    o.data.materials.append(mat)
    return o


def export(name):
    bpy.ops.export_scene.gltf(filepath=f"{out_dir}/{name}.glb", export_format="GLB", export_lights=True,
                              export_apply=True)


def room_with_panel(single_sided):
    """A 4 x 4 x 3 m room made from a cube (normals outward, as Blender makes it), a table-sized
    closed block on the floor, and an emissive panel 1 mm under the ceiling, facing down."""
    reset()
    white = material("white", (0.7, 0.7, 0.7), single_sided=single_sided)
    wood = material("block", (0.5, 0.35, 0.2), single_sided=single_sided)
    light = material("panel", (0.8, 0.8, 0.8), emission=(1.0, 0.95, 0.9), strength=5.0, single_sided=single_sided)
    box("room", (4.0, 4.0, 3.0), (0.0, 0.0, 1.5), white, flip=single_sided)
    box("block", (1.0, 0.6, 0.8), (0.6, -0.4, 0.4), wood)
    panel = plane("panel", (1.0, 1.0), (0.0, 0.0, 2.999), light, rotation=(3.14159265, 0.0, 0.0))
    return panel


def room_with_window(single_sided):
    """The same room with a 1.2 x 1.0 m window in its +x wall and an emissive 'sky' plane outside
    it, facing in: the only light. The walls' faces point out (as a cube's do), or in when
    single-sided."""
    reset()
    white = material("white", (0.7, 0.7, 0.7), single_sided=single_sided)
    sky = material("sky", (0.0, 0.0, 0.0), emission=(0.6, 0.7, 1.0), strength=3.0, single_sided=single_sided)
    x0, x1, y0, y1, z0, z1 = -2.0, 2.0, -2.0, 2.0, 0.0, 3.0
    wy0, wy1, wz0, wz1 = -0.6, 0.6, 1.0, 2.0  # the window in the x = x1 wall
    v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0),
         (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1),
         (x1, wy0, wz0), (x1, wy1, wz0), (x1, wy1, wz1), (x1, wy0, wz1),
         (x1, wy0, z0), (x1, wy1, z0), (x1, wy1, z1), (x1, wy0, z1)]
    faces = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (0, 4, 7, 3),  # outward
             (1, 12, 15, 5), (13, 2, 6, 14),                       # the +x wall beside the window
             (12, 13, 9, 8), (11, 10, 14, 15)]                     # below and above it
    if single_sided:
        faces = [tuple(reversed(f)) for f in faces]
    mesh = bpy.data.meshes.new("room")
    mesh.from_pydata(v, [], faces)
    mesh.update()
    room = bpy.data.objects.new("room", mesh)
    bpy.context.scene.collection.objects.link(room)
    room.data.materials.append(white)
    plane("sky", (1.6, 1.4), (2.3, 0.0, 1.5), sky, rotation=(0.0, -1.5707963, 0.0))
for single in (False, True):
    suffix = "-single" if single else ""
    room_with_panel(single)
    export("room-panel" + suffix)
    room_with_window(single)
    export("room-window" + suffix)
