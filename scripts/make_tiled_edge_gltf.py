#!/usr/bin/env python3
"""Writes a glTF scene for timing scene preparation and the mesh's T-junctions on hostile input: a
10 m x 10 m floor of one quad, edged along x = 10 by a 5 cm strip of N coplanar tiles of the same
material (N T-junctions on one edge of the floor), lit by a 1 m emissive square 3 m above the
floor's middle. With `upright`, the tiles stand on the floor's edge, 5 cm high, facing the floor's
middle (N seams between surfaces at 90 degrees on one edge). Usage: make_tiled_edge_gltf.py OUT.gltf
[N] [upright] (N defaults to 20000)."""
import base64
import json
import struct
import sys

out = sys.argv[1] if len(sys.argv) > 1 else "tiled-edge.gltf"
n = int(sys.argv[2]) if len(sys.argv) > 2 else 20000
upright = len(sys.argv) > 3 and sys.argv[3] == "upright"
positions, floor, lamp = [], [], []


def quad(target, a, b, c, d):
    """Two triangles, counter-clockwise seen from the front."""
    i = len(positions)
    positions.extend([a, b, c, d])
    target.extend([i, i + 1, i + 2, i, i + 2, i + 3])


quad(floor, (0, 0, 0), (0, 0, 10), (10, 0, 10), (10, 0, 0))
width = 10.0 / n
for i in range(n):
    z0, z1 = i * width, (i + 1) * width
    if upright:
        quad(floor, (10, 0, z0), (10, 0, z1), (10, 0.05, z1), (10, 0.05, z0))
    else:
        quad(floor, (10, 0, z0), (10, 0, z1), (10.05, 0, z1), (10.05, 0, z0))
quad(lamp, (4.5, 3, 4.5), (5.5, 3, 4.5), (5.5, 3, 5.5), (4.5, 3, 5.5))

position_bytes = b"".join(struct.pack("<3f", *p) for p in positions)
floor_bytes = b"".join(struct.pack("<I", i) for i in floor)
lamp_bytes = b"".join(struct.pack("<I", i) for i in lamp)
data = position_bytes + floor_bytes + lamp_bytes
gltf = {
    "asset": {"version": "2.0", "generator": "make_tiled_edge_gltf.py"},
    "scene": 0,
    "scenes": [{"nodes": [0]}],
    "nodes": [{"mesh": 0}],
    "meshes": [{"primitives": [
        {"attributes": {"POSITION": 0}, "indices": 1, "material": 0},
        {"attributes": {"POSITION": 0}, "indices": 2, "material": 1},
    ]}],
    "materials": [
        {"pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.6, 0.6, 1], "metallicFactor": 0}},
        {"pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0},
         "emissiveFactor": [1, 1, 1],
         "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 10}}},
    ],
    "extensionsUsed": ["KHR_materials_emissive_strength"],
    "buffers": [{"byteLength": len(data),
                 "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()}],
    "bufferViews": [
        {"buffer": 0, "byteOffset": 0, "byteLength": len(position_bytes)},
        {"buffer": 0, "byteOffset": len(position_bytes), "byteLength": len(floor_bytes)},
        {"buffer": 0, "byteOffset": len(position_bytes) + len(floor_bytes), "byteLength": len(lamp_bytes)},
    ],
    "accessors": [
        {"bufferView": 0, "componentType": 5126, "count": len(positions), "type": "VEC3",
         "min": [min(p[k] for p in positions) for k in range(3)],
         "max": [max(p[k] for p in positions) for k in range(3)]},
        {"bufferView": 1, "componentType": 5125, "count": len(floor), "type": "SCALAR"},
        {"bufferView": 2, "componentType": 5125, "count": len(lamp), "type": "SCALAR"},
    ],
}
with open(out, "w") as f:
    json.dump(gltf, f)
print(f"wrote {out}: {len(positions)} vertices, {(len(floor) + len(lamp)) // 3} triangles")
