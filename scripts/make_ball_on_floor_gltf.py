#!/usr/bin/env python3
"""Writes tests/data/ball-on-floor.gltf: a ball resting on a floor under a large light.

A 6 x 6 m floor (one quad, reflectance 0.5), a smooth UV sphere of radius 0.5 m (16 rings, 24
segments, reflectance 0.6) touching it at its lowest point, and a 6 x 6 m emissive quad 3 m above
(black, emissive strength 1) facing down. The ball meets the floor at one corner, so no edge
marks its contact shadow (bench/README.md, "A ball on a floor").

usage: make_ball_on_floor_gltf.py OUT.gltf
"""
import base64
import json
import math
import struct
import sys


def sphere(centre, radius, rings, segments):
    positions, indices = [], []
    for i in range(rings + 1):
        theta = math.pi * i / rings
        for j in range(segments):
            phi = 2.0 * math.pi * j / segments
            positions.append((centre[0] + radius * math.sin(theta) * math.cos(phi),
                              centre[1] + radius * math.cos(theta),
                              centre[2] - radius * math.sin(theta) * math.sin(phi)))
    for i in range(rings):
        for j in range(segments):
            a, b = i * segments + j, i * segments + (j + 1) % segments
            c, d = a + segments, b + segments
            if i > 0:
                indices += [a, c, b]
            if i < rings - 1:
                indices += [b, c, d]
    return positions, indices


def main():
    out = sys.argv[1]
    data = bytearray()
    doc = {"asset": {"version": "2.0", "generator": "hemibake scripts/make_ball_on_floor_gltf.py"},
           "scene": 0, "scenes": [{"nodes": []}], "nodes": [], "meshes": [], "materials": [],
           "accessors": [], "bufferViews": [], "extensionsUsed": ["KHR_materials_emissive_strength"]}

    def material(rgb, emission=None):
        m = {"pbrMetallicRoughness": {"baseColorFactor": [*rgb, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}}
        if emission is not None:
            m["emissiveFactor"] = [1.0, 1.0, 1.0]
            m["extensions"] = {"KHR_materials_emissive_strength": {"emissiveStrength": emission}}
        doc["materials"].append(m)
        return len(doc["materials"]) - 1

    def view(blob, target):
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(data), "byteLength": len(blob), "target": target})
        data.extend(blob)
        return len(doc["bufferViews"]) - 1

    def mesh(name, positions, indices, mat):
        pos = b"".join(struct.pack("<3f", *p) for p in positions)
        idx = b"".join(struct.pack("<I", i) for i in indices)
        lo = [min(p[k] for p in positions) for k in range(3)]
        hi = [max(p[k] for p in positions) for k in range(3)]
        doc["accessors"].append({"bufferView": view(pos, 34962), "componentType": 5126, "count": len(positions),
                                 "type": "VEC3", "min": lo, "max": hi})
        doc["accessors"].append({"bufferView": view(idx, 34963), "componentType": 5125, "count": len(indices),
                                 "type": "SCALAR"})
        n = len(doc["accessors"])
        doc["meshes"].append({"name": name, "primitives": [{"attributes": {"POSITION": n - 2}, "indices": n - 1,
                                                            "material": mat}]})
        doc["nodes"].append({"name": name, "mesh": len(doc["meshes"]) - 1})
        doc["scenes"][0]["nodes"].append(len(doc["nodes"]) - 1)

    mesh("floor", [(-3, 0, -3), (-3, 0, 3), (3, 0, 3), (3, 0, -3)], [0, 1, 2, 0, 2, 3], material((0.5, 0.5, 0.5)))
    mesh("ball", *sphere((0.0, 0.5, 0.0), 0.5, 16, 24), material((0.6, 0.6, 0.6)))
    mesh("light", [(-3, 3, -3), (3, 3, -3), (3, 3, 3), (-3, 3, 3)], [0, 1, 2, 0, 2, 3], material((0.0, 0.0, 0.0), 1.0))
    doc["buffers"] = [{"byteLength": len(data),
                       "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(data)).decode()}]
    with open(out, "w") as f:
        json.dump(doc, f)


if __name__ == "__main__":
    main()
