#!/usr/bin/env python3
"""Writes a table of small boxes lit by one large emitter, as glTF with embedded buffers: a
1.2 x 0.8 m table top (a closed 3 cm slab, its top 0.75 m up, reflectance 0.7) and up to N boxes
of 4 to 18 cm a side standing on it, 5 mm apart at least, placed at random from SEED
(reflectance 0.6, 0.5, 0.4), lit by LIGHT alone (emission 1, reflecting nothing), open:
  wall  a 3 x 2.5 m glowing wall 3 m from the table's centre, facing it (x = -3);
  ceil  a 2 x 2 m panel 1.25 m over the table top, facing down;
  side  a 2.4 x 1.6 m panel 2.5 m from the table's centre on the other side (x = 2.5).
The error as displayed on such tables is in README.md ("Small objects close to a large emitter")
and bench/README.md; tests/bench/display_error_test.cpp builds a `wall` table of its own (its
boxes placed by C++'s generator).
Places the boxes it can (a table of 0.96 m^2 holds about 65); prints how many.
Run: python3 scripts/make_table_of_boxes.py OUT.gltf [SEED [N [LIGHT]]]"""
import base64
import json
import random
import struct
import sys


def main():
    out = sys.argv[1]
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    count = int(sys.argv[3]) if len(sys.argv) > 3 else 60
    light = sys.argv[4] if len(sys.argv) > 4 else 'wall'
    quads = {'table': [], 'box': [], 'light': []}

    def box(cx, cz, sx, sy, sz, base, mat):
        x0, x1, z0, z1, y0, y1 = cx - sx / 2, cx + sx / 2, cz - sz / 2, cz + sz / 2, base, base + sy
        q = quads[mat]
        q.append(((x0, y1, z1), (x1, y1, z1), (x1, y1, z0), (x0, y1, z0)))  # top, +y
        q.append(((x0, y0, z1), (x0, y1, z1), (x0, y1, z0), (x0, y0, z0)))  # -x
        q.append(((x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)))  # +x
        q.append(((x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)))  # +z
        q.append(((x1, y0, z0), (x0, y0, z0), (x0, y1, z0), (x1, y1, z0)))  # -z
        q.append(((x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)))  # bottom, -y

    top = 0.75
    box(0.0, 0.0, 1.2, 0.03, 0.8, top - 0.03, 'table')
    rng = random.Random(seed)
    placed = []
    for _ in range(10000):
        if len(placed) >= count:
            break
        sx, sy, sz = (rng.uniform(0.04, 0.18) for _ in range(3))
        cx = rng.uniform(-0.6 + sx / 2, 0.6 - sx / 2)
        cz = rng.uniform(-0.4 + sz / 2, 0.4 - sz / 2)
        if any(abs(cx - px) < (sx + psx) / 2 + 0.005 and abs(cz - pz) < (sz + psz) / 2 + 0.005
               for px, pz, psx, psz in placed):
            continue
        placed.append((cx, cz, sx, sz))
        box(cx, cz, sx, sy, sz, top, 'box')
    emitters = {
        'wall': ((-3, 2.5, -1.5), (-3, 2.5, 1.5), (-3, 0, 1.5), (-3, 0, -1.5)),
        'ceil': ((-1, 2.0, -1), (1, 2.0, -1), (1, 2.0, 1), (-1, 2.0, 1)),
        'side': ((2.5, 1.8, 1.2), (2.5, 1.8, -1.2), (2.5, 0.2, -1.2), (2.5, 0.2, 1.2)),
    }
    if light not in emitters:
        sys.exit('LIGHT is wall, ceil or side, not ' + light)
    quads['light'].append(emitters[light])

    materials = [
        {'name': 'table', 'pbrMetallicRoughness': {'baseColorFactor': [0.7, 0.7, 0.7, 1], 'metallicFactor': 0}},
        {'name': 'box', 'pbrMetallicRoughness': {'baseColorFactor': [0.6, 0.5, 0.4, 1], 'metallicFactor': 0}},
        {'name': 'light', 'pbrMetallicRoughness': {'baseColorFactor': [0, 0, 0, 1], 'metallicFactor': 0}, 'emissiveFactor': [1, 1, 1]},
    ]
    buf = bytearray()
    views, accessors, meshes = [], [], []
    for index, name in enumerate(['table', 'box', 'light']):
        positions, indices = [], []
        for q in quads[name]:
            base = len(positions)
            positions.extend(q)
            indices.extend([base, base + 1, base + 2, base, base + 2, base + 3])
        views.append({'buffer': 0, 'byteOffset': len(buf), 'byteLength': 12 * len(positions)})
        for p in positions:
            buf += struct.pack('<3f', *p)
        accessors.append({'bufferView': len(views) - 1, 'componentType': 5126, 'count': len(positions), 'type': 'VEC3',
                          'min': [min(p[k] for p in positions) for k in range(3)],
                          'max': [max(p[k] for p in positions) for k in range(3)]})
        views.append({'buffer': 0, 'byteOffset': len(buf), 'byteLength': 4 * len(indices)})
        buf += struct.pack('<%dI' % len(indices), *indices)
        accessors.append({'bufferView': len(views) - 1, 'componentType': 5125, 'count': len(indices), 'type': 'SCALAR'})
        meshes.append({'name': name, 'primitives': [{'attributes': {'POSITION': len(accessors) - 2},
                                                     'indices': len(accessors) - 1, 'material': index}]})
    gltf = {
        'asset': {'version': '2.0', 'generator': 'scripts/make_table_of_boxes.py'},
        'scene': 0, 'scenes': [{'nodes': [0, 1, 2]}], 'nodes': [{'mesh': i} for i in range(3)],
        'meshes': meshes, 'materials': materials, 'accessors': accessors, 'bufferViews': views,
        'buffers': [{'byteLength': len(buf),
                     'uri': 'data:application/octet-stream;base64,' + base64.b64encode(bytes(buf)).decode()}],
    }
    with open(out, 'w') as f:
        json.dump(gltf, f)
    print(len(placed), 'boxes')


if __name__ == '__main__':
    main()
