// decode.mjs IN.glb OUT.json
//
// Decodes a GLB (KHR_draco_mesh_compression included, through draco3dgltf) with gltf-transform and
// writes its mesh data as JSON, so C++ tests can compare what they wrote with what an independent
// reader gets back. Exit status: 0 written, 1 the file could not be read or decoded, 2 bad usage.
//
// Output:
// {
//   "file": "IN.glb",
//   "extensionsUsed": [...], "extensionsRequired": [...],
//   "materials": [{"name", "baseColorFactor", "unlit", "doubleSided"}],
//   "primitives": [                      // meshes[i].primitives[j], in document order
//     {"mesh": i, "meshName": "...", "primitive": j,
//      "nodes": ["..."],                 // names of the nodes that reference meshes[i]
//      "mode": 4, "material": k | null,  // index into "materials"
//      "vertexCount": n, "triangleCount": n,
//      "attributes": {"POSITION": {"type": "VEC3", "componentType": 5126, "normalized": false,
//                                  "count": n, "array": [x0, y0, z0, x1, ...]},
//                     "COLOR_0": {...}, "_RADIOSITY": {...}, "TEXCOORD_0": {...}, ...},
//      "indices": [...] | null}          // null for a non-indexed primitive
//   ]
// }
// Arrays are flat and hold the accessor's stored values (normalized integers are not divided);
// every attribute the primitive has is listed. NaN and infinities become null (JSON has neither).
import fs from 'node:fs';
import { createIO, fail } from './gltf-io.mjs';

const kScript = 'decode';

const [input, output, ...rest] = process.argv.slice(2);
if (!input || !output || rest.length > 0) fail(kScript, 'usage: node decode.mjs IN.glb OUT.json', 2);

let doc;
try {
  const io = await createIO();
  doc = await io.readBinary(new Uint8Array(fs.readFileSync(input)));
} catch (e) {
  fail(kScript, `cannot read ${input}: ${e.message}`);
}

const root = doc.getRoot();
const materials = root.listMaterials();
const materialIndex = new Map(materials.map((m, i) => [m, i]));

function triangleCount(mode, count) {
  switch (mode) {
    case 4: return Math.floor(count / 3); // TRIANGLES
    case 5: case 6: return Math.max(0, count - 2); // TRIANGLE_STRIP, TRIANGLE_FAN
    default: return 0; // points and lines
  }
}

const primitives = [];
root.listMeshes().forEach((mesh, i) => {
  const nodes = root.listNodes().filter((n) => n.getMesh() === mesh).map((n) => n.getName());
  mesh.listPrimitives().forEach((prim, j) => {
    const attributes = {};
    for (const semantic of prim.listSemantics()) {
      const a = prim.getAttribute(semantic);
      attributes[semantic] = {
        type: a.getType(),
        componentType: a.getComponentType(),
        normalized: a.getNormalized(),
        count: a.getCount(),
        array: Array.from(a.getArray() ?? []),
      };
    }
    const indices = prim.getIndices();
    const vertexCount = prim.getAttribute('POSITION')?.getCount() ?? 0;
    const elementCount = indices ? indices.getCount() : vertexCount;
    primitives.push({
      mesh: i,
      meshName: mesh.getName(),
      primitive: j,
      nodes,
      mode: prim.getMode(),
      material: prim.getMaterial() ? materialIndex.get(prim.getMaterial()) : null,
      vertexCount,
      triangleCount: triangleCount(prim.getMode(), elementCount),
      attributes,
      indices: indices ? Array.from(indices.getArray() ?? []) : null,
    });
  });
});

const result = {
  file: input,
  extensionsUsed: root.listExtensionsUsed().map((e) => e.extensionName),
  extensionsRequired: root.listExtensionsRequired().map((e) => e.extensionName),
  materials: materials.map((m) => ({
    name: m.getName(),
    baseColorFactor: m.getBaseColorFactor(),
    unlit: m.getExtension('KHR_materials_unlit') !== null,
    doubleSided: m.getDoubleSided(),
  })),
  primitives,
};

try {
  fs.writeFileSync(output, JSON.stringify(result) + '\n');
} catch (e) {
  fail(kScript, `cannot write ${output}: ${e.message}`);
}
