#!/usr/bin/env python3
"""Writes data/cornell-box.gltf: the Cornell box (Cornell University Program of Computer Graphics'
published geometry, converted from millimetres to metres) as glTF 2.0 with an embedded buffer.

Materials use the common RGB reduction of the measured reflectances; the light is an emissive
material (emissiveFactor times KHR_materials_emissive_strength). The ceiling is cut into eight
quads around the light so that nothing overlaps. Run from the repository root."""
import base64
import json
import math
import struct

MM = 0.001
WHITE, RED, GREEN, LIGHT = 0, 1, 2, 3

quads = []  # (corners, material); corners counter-clockwise seen from the front


def quad(a, b, c, d, material):
    quads.append(([a, b, c, d], material))


quad((552.8, 0, 0), (0, 0, 0), (0, 0, 559.2), (549.6, 0, 559.2), WHITE)  # floor
quad((549.6, 0, 559.2), (0, 0, 559.2), (0, 548.8, 559.2), (556, 548.8, 559.2), WHITE)  # back
quad((552.8, 0, 0), (549.6, 0, 559.2), (556, 548.8, 559.2), (556, 548.8, 0), RED)  # left
quad((0, 0, 559.2), (0, 0, 0), (0, 548.8, 0), (0, 548.8, 559.2), GREEN)  # right
xs, zs = (0, 213, 343, 556), (0, 227, 332, 559.2)
for i in range(3):
    for k in range(3):
        m = LIGHT if (i, k) == (1, 1) else WHITE
        quad((xs[i], 548.8, zs[k]), (xs[i + 1], 548.8, zs[k]), (xs[i + 1], 548.8, zs[k + 1]),
             (xs[i], 548.8, zs[k + 1]), m)


def block(top):
    quad(top[0], top[1], top[2], top[3], WHITE)
    cx = sum(t[0] for t in top) / 4
    cz = sum(t[2] for t in top) / 4
    for i in range(4):
        a, b = top[i], top[(i + 1) % 4]
        qa, qb = (a[0], 0, a[2]), (b[0], 0, b[2])
        # Normal of (a, qa, qb, b) is (qa - a) x (qb - qa); keep it pointing away from the axis.
        u = (qa[0] - a[0], qa[1] - a[1], qa[2] - a[2])
        v = (qb[0] - qa[0], qb[1] - qa[1], qb[2] - qa[2])
        n = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
        out = ((a[0] + b[0]) / 2 - cx, 0, (a[2] + b[2]) / 2 - cz)
        if n[0] * out[0] + n[2] * out[2] > 0:
            quad(a, qa, qb, b, WHITE)
        else:
            quad(b, qb, qa, a, WHITE)


block([(130, 165, 65), (82, 165, 225), (240, 165, 272), (290, 165, 114)])
block([(423, 330, 247), (265, 330, 296), (314, 330, 456), (472, 330, 406)])

# One primitive per material; each quad is two triangles sharing its diagonal.
blob = bytearray()
views, accessors, primitives = [], [], []
for material in (WHITE, RED, GREEN, LIGHT):
    positions, indices = [], []
    for corners, m in quads:
        if m != material:
            continue
        base = len(positions)
        positions += [tuple(c * MM for c in p) for p in corners]
        indices += [base, base + 1, base + 2, base, base + 2, base + 3]
    pos_offset = len(blob)
    for p in positions:
        blob += struct.pack('<3f', *p)
    views.append({'buffer': 0, 'byteOffset': pos_offset, 'byteLength': len(blob) - pos_offset, 'target': 34962})
    lo = [min(p[i] for p in positions) for i in range(3)]
    hi = [max(p[i] for p in positions) for i in range(3)]
    # Bounds must be those of the stored 32-bit floats.
    lo = [struct.unpack('<f', struct.pack('<f', v))[0] for v in lo]
    hi = [struct.unpack('<f', struct.pack('<f', v))[0] for v in hi]
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

gltf = {
    'asset': {'version': '2.0', 'generator': 'hemibake scripts/make_cornell_gltf.py'},
    'extensionsUsed': ['KHR_materials_emissive_strength'],
    'scene': 0,
    'scenes': [{'name': 'Cornell box', 'nodes': [0]}],
    'nodes': [{'name': 'Cornell box', 'mesh': 0}],
    'meshes': [{'name': 'Cornell box', 'primitives': primitives}],
    'materials': [
        {'name': 'white', 'pbrMetallicRoughness': {'baseColorFactor': [0.755, 0.748, 0.751, 1.0],
                                                    'metallicFactor': 0.0}},
        {'name': 'red', 'pbrMetallicRoughness': {'baseColorFactor': [0.443, 0.061, 0.062, 1.0],
                                                  'metallicFactor': 0.0}},
        {'name': 'green', 'pbrMetallicRoughness': {'baseColorFactor': [0.136, 0.406, 0.107, 1.0],
                                                    'metallicFactor': 0.0}},
        {'name': 'light', 'pbrMetallicRoughness': {'baseColorFactor': [0.78, 0.78, 0.78, 1.0],
                                                    'metallicFactor': 0.0},
         'emissiveFactor': [1.0, 11.65 / 15.94, 5.12 / 15.94],
         # glTF's emission is a radiance: the exitance 15.94 over pi.
         'extensions': {'KHR_materials_emissive_strength': {'emissiveStrength': 15.94 / math.pi}}},
    ],
    'buffers': [{'byteLength': len(blob),
                 'uri': 'data:application/octet-stream;base64,' + base64.b64encode(bytes(blob)).decode()}],
    'bufferViews': views,
    'accessors': accessors,
}
with open('data/cornell-box.gltf', 'w') as f:
    json.dump(gltf, f, indent=1)
    f.write('\n')
