"""Helpers the scripts that build Blender scenes share (run inside Blender: `import bpy`)."""
import random
import sys

import bpy


def start(seed):
    """Empties Blender's scene, seeds `random`, and returns the output path given after `--`."""
    out = sys.argv[sys.argv.index('--') + 1]
    random.seed(seed)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return out


def material(name, base, emission=None, strength=0.0, image=None):
    """A Principled BSDF material of base colour `base` (or texture `image`), emitting `emission`
    at `strength`; the one of that name if the file has it already."""
    m = bpy.data.materials.get(name)
    if m is not None:
        return m
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    b = m.node_tree.nodes['Principled BSDF']
    b.inputs['Base Color'].default_value = (*base, 1.0)
    if emission:
        b.inputs['Emission'].default_value = (*emission, 1.0)
        b.inputs['Emission Strength'].default_value = strength
    if image is not None:
        t = m.node_tree.nodes.new('ShaderNodeTexImage')
        t.image = image
        m.node_tree.links.new(t.outputs['Color'], b.inputs['Base Color'])
    return m


def box(name, lo, hi, mat):
    """An axis-aligned box from corner lo to corner hi (metres, Z up), its scale applied."""
    centre = [(a + b) / 2 for a, b in zip(lo, hi)]
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=centre)
    o = bpy.context.active_object
    o.name = name
    o.scale = [b - a for a, b in zip(lo, hi)]
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    o.data.materials.append(mat)
    return o


def light(kind, name, energy, location, rotation=(0, 0, 0), color=(1, 1, 1)):
    """A light of Blender's `kind` ('POINT', 'SUN', 'SPOT'), `energy` in watts (W/m^2 for a sun)."""
    bpy.ops.object.light_add(type=kind, location=location, rotation=rotation)
    o = bpy.context.active_object
    o.name = name
    o.data.name = name
    o.data.energy = energy
    o.data.color = color
    return o


def room_materials():
    """The furnished rooms' materials: plaster walls, an oak floor, walnut, steel and blue fabric."""
    return (material('Plaster', (0.75, 0.72, 0.68)), material('Oak', (0.45, 0.3, 0.18)),
            material('Walnut', (0.3, 0.18, 0.1)), material('Steel', (0.5, 0.5, 0.52)),
            material('Fabric', (0.2, 0.3, 0.55)))
