#!/usr/bin/env python3
"""Writes data/lit-yard.gltf: an open yard lit the way exporters write lights, for trying lights and
the sky. A 6 m x 6 m floor, a crate, a wall and a post, with KHR_lights_punctual: a directional
"Sun" (lux) on a node turned to shine down at an angle, a point "Bulb" (candela) on a node nested
under a scaled parent, and a "Spot" (candela, cone) pointing at the wall. A small emissive lamp
(glTF emission is a radiance) stands on the post. Nothing emits outside these, so the yard also
shows what a sky (--sky) adds. Run from the repository root."""
import base64
import json
import math
import struct

FLOOR, CRATE, WALL, LAMP = 0, 1, 2, 3
quads = []  # (corners, material); corners counter-clockwise seen from the front


def quad(a, b, c, d, material):
    quads.append(([a, b, c, d], material))


def box(lo, hi, material, bottom=False):
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    quad((x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0), material)  # top
    quad((x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (x1, y0, z0), material)  # -z
    quad((x1, y0, z1), (x1, y1, z1), (x0, y1, z1), (x0, y0, z1), material)  # +z
    quad((x0, y0, z1), (x0, y1, z1), (x0, y1, z0), (x0, y0, z0), material)  # -x
    quad((x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1), material)  # +x
    if bottom:
        quad((x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1), material)


quad((-3, 0, -3), (-3, 0, 3), (3, 0, 3), (3, 0, -3), FLOOR)
box((-0.5, 0, -0.5), (0.5, 0.8, 0.5), CRATE)
box((-2.5, 0, -2.6), (2.5, 1.6, -2.4), WALL)
box((1.9, 0, 1.9), (2.1, 1.2, 2.1), CRATE)
box((1.85, 1.2, 1.85), (2.15, 1.3, 2.15), LAMP, bottom=True)

blob = bytearray()
views, accessors, primitives = [], [], []
for material in (FLOOR, CRATE, WALL, LAMP):
    positions, indices = [], []
    for corners, m in quads:
        if m != material:
            continue
        base = len(positions)
        positions += corners
        indices += [base, base + 1, base + 2, base, base + 2, base + 3]
    pos_offset = len(blob)
    for p in positions:
        blob += struct.pack('<3f', *p)
    views.append({'buffer': 0, 'byteOffset': pos_offset, 'byteLength': len(blob) - pos_offset, 'target': 34962})
    lo = [struct.unpack('<f', struct.pack('<f', min(p[i] for p in positions)))[0] for i in range(3)]
    hi = [struct.unpack('<f', struct.pack('<f', max(p[i] for p in positions)))[0] for i in range(3)]
    accessors.append({'bufferView': len(views) - 1, 'componentType': 5126, 'count': len(positions),
                      'type': 'VEC3', 'min': lo, 'max': hi})
    idx_offset = len(blob)
    for i in indices:
        blob += struct.pack('<H', i)
    while len(blob) % 4:
        blob += b'\0'
    views.append({'buffer': 0, 'byteOffset': idx_offset, 'byteLength': 2 * len(indices), 'target': 34963})
    accessors.append({'bufferView': len(views) - 1, 'componentType': 5123, 'count': len(indices), 'type': 'SCALAR'})
    primitives.append({'attributes': {'POSITION': len(accessors) - 2}, 'indices': len(accessors) - 1,
                       'material': material})


def turn(axis, degrees):
    """A rotation quaternion (x, y, z, w)."""
    s = math.sin(math.radians(degrees) / 2)
    return [axis[0] * s, axis[1] * s, axis[2] * s, math.cos(math.radians(degrees) / 2)]


def mul(q, r):
    x1, y1, z1, w1 = q
    x2, y2, z2, w2 = r
    return [w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2]


gltf = {
    'asset': {'version': '2.0', 'generator': 'hemibake scripts/make_lit_yard_gltf.py'},
    'extensionsUsed': ['KHR_lights_punctual', 'KHR_materials_emissive_strength'],
    'extensionsRequired': ['KHR_lights_punctual'],
    'extensions': {'KHR_lights_punctual': {'lights': [
        {'name': 'Sun', 'type': 'directional', 'intensity': 2.0, 'color': [1.0, 0.95, 0.85]},
        {'name': 'Bulb', 'type': 'point', 'intensity': 1.5, 'color': [1.0, 0.7, 0.4], 'range': 4.0},
        {'name': 'Spot', 'type': 'spot', 'intensity': 6.0, 'color': [0.5, 0.7, 1.0],
         'spot': {'innerConeAngle': 0.25, 'outerConeAngle': 0.4}},
    ]}},
    'scene': 0,
    'scenes': [{'nodes': [0, 1, 2, 4]}],
    'nodes': [
        {'name': 'yard', 'mesh': 0},
        # Down at 50 degrees from the horizon, from the south-west.
        {'name': 'Sun', 'rotation': mul(turn((0, 1, 0), -35), turn((1, 0, 0), -50)),
         'extensions': {'KHR_lights_punctual': {'light': 0}}},
        {'name': 'Bulb holder', 'translation': [-1.5, 0.0, 1.0], 'scale': [2.0, 2.0, 2.0], 'children': [3]},
        {'name': 'Bulb', 'translation': [0.0, 0.4, 0.0], 'extensions': {'KHR_lights_punctual': {'light': 1}}},
        # At (1.5, 2.5, 1) looking down at the wall.
        {'name': 'Spot', 'translation': [1.5, 2.5, 1.0], 'rotation': turn((1, 0, 0), -30),
         'extensions': {'KHR_lights_punctual': {'light': 2}}},
    ],
    'meshes': [{'name': 'yard', 'primitives': primitives}],
    'materials': [
        {'name': 'ground', 'pbrMetallicRoughness': {'baseColorFactor': [0.6, 0.6, 0.55, 1.0], 'metallicFactor': 0.0}},
        {'name': 'crate', 'pbrMetallicRoughness': {'baseColorFactor': [0.7, 0.45, 0.25, 1.0], 'metallicFactor': 0.0}},
        {'name': 'wall', 'pbrMetallicRoughness': {'baseColorFactor': [0.75, 0.75, 0.75, 1.0], 'metallicFactor': 0.0}},
        {'name': 'lamp', 'pbrMetallicRoughness': {'baseColorFactor': [0.1, 0.1, 0.1, 1.0], 'metallicFactor': 0.0},
         'emissiveFactor': [1.0, 0.9, 0.6],
         'extensions': {'KHR_materials_emissive_strength': {'emissiveStrength': 3.0}}},
    ],
    'accessors': accessors,
    'bufferViews': views,
    'buffers': [{'byteLength': len(blob),
                 'uri': 'data:application/octet-stream;base64,' + base64.b64encode(bytes(blob)).decode()}],
}

with open('data/lit-yard.gltf', 'w') as f:
    json.dump(gltf, f, indent=1)
    f.write('\n')
