#!/usr/bin/env bash
# An emitter with a dark base colour (lava: dark rock that glows) must look lit in a viewer, not
# like dark rock. Writes a floor under a lava panel (base colour 0.05, emissive (1, 0.3, 0.05) at
# strength 2) and a point light, bakes it with the given hemibake binary, validates the GLB and
# renders it in three.js from just under the panel, so that the panel fills the picture: its pixels
# must be bright and keep the emission's hue (red over green over blue). Shown by its base colour,
# the panel would be under 70 of 255 in every channel.
# Usage: check-emitter.sh HEMIBAKE OUT_DIR [bake options...]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
bin=$1
out=$2
shift 2
mkdir -p "$out"
node -e '
const fs = require("fs");
// Two quads: the floor (y = 0, facing up) and the panel (y = 0.8, facing down).
const pos = new Float32Array([
  -1, 0, -1,  -1, 0, 1,  1, 0, 1,  1, 0, -1,
  -0.3, 0.8, -0.3,  0.3, 0.8, -0.3,  0.3, 0.8, 0.3,  -0.3, 0.8, 0.3]);
const idx = new Uint16Array([0, 1, 2, 0, 2, 3, 0, 1, 2, 0, 2, 3]);
const bin = Buffer.concat([Buffer.from(pos.buffer), Buffer.from(idx.buffer)]);
const view = (offset, length) => ({buffer: 0, byteOffset: offset, byteLength: length});
const gltf = {
  asset: {version: "2.0"},
  extensionsUsed: ["KHR_materials_emissive_strength", "KHR_lights_punctual"],
  extensions: {KHR_lights_punctual: {lights: [{type: "point", intensity: 0.5}]}},
  scene: 0, scenes: [{nodes: [0, 1, 2]}],
  nodes: [{mesh: 0, name: "floor"}, {mesh: 1, name: "lava"},
          {translation: [0.7, 0.5, 0.7], extensions: {KHR_lights_punctual: {light: 0}}}],
  meshes: [{primitives: [{attributes: {POSITION: 0}, indices: 2, material: 0}]},
           {primitives: [{attributes: {POSITION: 1}, indices: 3, material: 1}]}],
  materials: [
    {name: "ground", pbrMetallicRoughness: {baseColorFactor: [0.6, 0.6, 0.6, 1]}},
    {name: "lava", pbrMetallicRoughness: {baseColorFactor: [0.05, 0.04, 0.04, 1]}, emissiveFactor: [1, 0.3, 0.05],
     extensions: {KHR_materials_emissive_strength: {emissiveStrength: 2}}}],
  accessors: [
    {bufferView: 0, componentType: 5126, count: 4, type: "VEC3", min: [-1, 0, -1], max: [1, 0, 1]},
    {bufferView: 1, componentType: 5126, count: 4, type: "VEC3", min: [-0.3, 0.8, -0.3], max: [0.3, 0.8, 0.3]},
    {bufferView: 2, componentType: 5123, count: 6, type: "SCALAR"},
    {bufferView: 3, componentType: 5123, count: 6, type: "SCALAR"}],
  bufferViews: [view(0, 48), view(48, 48), view(96, 12), view(108, 12)],
  buffers: [{byteLength: bin.length, uri: "data:application/octet-stream;base64," + bin.toString("base64")}],
};
fs.writeFileSync(process.argv[1], JSON.stringify(gltf));
' "$out/lava.gltf"
glb="$out/lava.glb"
"$bin" bake "$out/lava.gltf" -o "$glb" --convergence 0.01 "$@"
node "$here/validate.mjs" "$glb"
node "$here/render.mjs" "$glb" "$out/lava.png" --camera 0,0.45,0 --target 0,0.8,0.001 > "$out/render.json"
node -e '
const s = JSON.parse(require("fs").readFileSync(process.argv[1], "utf8"));
const p = s.pixels, m = p.mean, fail = [];
if (!s.loaded) fail.push("the GLB did not load");
if (!(p.nonBackground > 0.95)) fail.push("the panel covers " + p.nonBackground + " of the picture");
if (!(m[0] > 200)) fail.push("the panel is not bright: mean " + m);
if (!(m[0] > m[1] + 40 && m[1] > m[2])) fail.push("the panel lost its hue: mean " + m);
if (fail.length) { console.error(fail.join("\n")); process.exit(1); }
console.log("lava ok: " + JSON.stringify(p));
' "$out/render.json"
