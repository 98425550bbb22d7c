// make-sample.mjs OUT.glb [--plain] [--unclamped-color]
//
// Writes a small baked-looking scene to develop and test decode.mjs, validate.mjs and render.mjs
// against: a floor (8 x 8 grid of quads, 81 vertices, 128 triangles) and a box standing on it
// (6 faces x 4 vertices, 12 triangles), each with per-vertex COLOR_0 (float VEC3 in [0, 1], varying
// across vertices), a `_RADIOSITY` float VEC3 custom attribute (unbounded radiosity, here 1.5 x the
// colour) and TEXCOORD_0, sharing one KHR_materials_unlit material, compressed with
// KHR_draco_mesh_compression (edgebreaker, so Draco reorders the vertices).
//
//   --plain            skip Draco compression
//   --unclamped-color  put COLOR_0 values above 1 (a negative control: validate.mjs must fail it
//                      with ACCESSOR_NON_CLAMPED)
import { Document } from '@gltf-transform/core';
import { KHRDracoMeshCompression, KHRMaterialsUnlit } from '@gltf-transform/extensions';
import { createIO, fail } from './gltf-io.mjs';

const kScript = 'make-sample';

const args = process.argv.slice(2);
const out = args.find((a) => !a.startsWith('--'));
const plain = args.includes('--plain');
const unclamped = args.includes('--unclamped-color');
const unknown = args.filter((a) => a.startsWith('--') && a !== '--plain' && a !== '--unclamped-color');
if (!out || unknown.length > 0) {
  fail(kScript, `usage: node make-sample.mjs OUT.glb [--plain] [--unclamped-color]` +
    (unknown.length ? ` (unknown option ${unknown[0]})` : ''), 2);
}

const doc = new Document();
doc.getRoot().getAsset().generator = 'hemibake tests/e2e/make-sample.mjs';
const buffer = doc.createBuffer();

const unlit = doc.createExtension(KHRMaterialsUnlit);
const material = doc.createMaterial('baked')
  .setBaseColorFactor([1, 1, 1, 1])
  .setExtension('KHR_materials_unlit', unlit.createUnlit());

// Radiosity is unbounded; COLOR_0 is what a viewer shows and must stay in [0, 1].
const kRadiosityScale = 1.5;

function addPrimitive(name, positions, colors, uvs, indices) {
  if (unclamped) colors = colors.map((c) => c * 1.6);
  const accessor = (type, array) => doc.createAccessor().setType(type).setArray(array).setBuffer(buffer);
  const prim = doc.createPrimitive()
    .setAttribute('POSITION', accessor('VEC3', new Float32Array(positions)))
    .setAttribute('COLOR_0', accessor('VEC3', new Float32Array(colors)))
    .setAttribute('_RADIOSITY', accessor('VEC3', new Float32Array(colors.map((c) => c * kRadiosityScale))))
    .setAttribute('TEXCOORD_0', accessor('VEC2', new Float32Array(uvs)))
    .setIndices(accessor('SCALAR', new Uint16Array(indices)))
    .setMaterial(material);
  const mesh = doc.createMesh(name).addPrimitive(prim);
  return doc.createNode(name).setMesh(mesh);
}

// Floor: y = 0 over x, z in [-2, 2], facing +y; colour varies smoothly across the grid.
function floor(n) {
  const positions = [], colors = [], uvs = [], indices = [];
  for (let j = 0; j <= n; ++j) {
    for (let i = 0; i <= n; ++i) {
      const u = i / n, v = j / n;
      positions.push(-2 + 4 * u, 0, -2 + 4 * v);
      colors.push(0.15 + 0.7 * u, 0.2 + 0.6 * v, 0.9 - 0.6 * u * v);
      uvs.push(u, v);
    }
  }
  const at = (i, j) => j * (n + 1) + i;
  for (let j = 0; j < n; ++j) {
    for (let i = 0; i < n; ++i) {
      // Counter-clockwise seen from +y: (i,j) -> (i,j+1) -> (i+1,j+1).
      indices.push(at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i, j), at(i + 1, j + 1), at(i + 1, j));
    }
  }
  return addPrimitive('floor', positions, colors, uvs, indices);
}

// Box: [-0.6, 0.6] x [0, 1.2] x [-0.6, 0.6], 4 vertices per face so faces do not share colours;
// each vertex's colour comes from its position, so every face shows a gradient.
function box() {
  const h = 0.6;
  // Each face: centre direction and two tangents whose cross product points outwards.
  const faces = [
    [[1, 0, 0], [0, 0, -1], [0, 1, 0]], [[-1, 0, 0], [0, 0, 1], [0, 1, 0]],
    [[0, 1, 0], [1, 0, 0], [0, 0, -1]], [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
    [[0, 0, 1], [1, 0, 0], [0, 1, 0]], [[0, 0, -1], [-1, 0, 0], [0, 1, 0]],
  ];
  const positions = [], colors = [], uvs = [], indices = [];
  for (const [n, s, t] of faces) {
    const base = positions.length / 3;
    for (const [a, b] of [[-1, -1], [1, -1], [1, 1], [-1, 1]]) {
      const p = [0, 1, 2].map((k) => h * (n[k] + a * s[k] + b * t[k]));
      p[1] += h;
      positions.push(...p);
      colors.push(0.9 - 0.6 * (p[1] / (2 * h)), 0.3 + 0.5 * ((p[0] + h) / (2 * h)), 0.2 + 0.6 * ((p[2] + h) / (2 * h)));
      uvs.push((a + 1) / 2, (b + 1) / 2);
    }
    indices.push(base, base + 1, base + 2, base, base + 2, base + 3);
  }
  return addPrimitive('box', positions, colors, uvs, indices);
}

const scene = doc.createScene('sample').addChild(floor(8)).addChild(box());
doc.getRoot().setDefaultScene(scene);

if (!plain) {
  doc.createExtension(KHRDracoMeshCompression)
    .setRequired(true)
    .setEncoderOptions({ method: KHRDracoMeshCompression.EncoderMethod.EDGEBREAKER });
}

try {
  const io = await createIO({ encoder: !plain });
  await io.write(out, doc);
} catch (e) {
  fail(kScript, `cannot write ${out}: ${e.message}`);
}
