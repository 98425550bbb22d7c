#!/usr/bin/env bash
# Bakes the bundled Cornell box with the given hemibake binary and options, then checks the GLB
# with independent readers: the Khronos validator (after gltf-transform decodes Draco) and a
# three.js render in headless Chromium, whose picture must show the lit room (not black, not one
# flat colour). Usage: check-bake.sh HEMIBAKE OUT_DIR [bake options...]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
bin=$1
out=$2
shift 2
mkdir -p "$out"
glb="$out/cornell.glb"
"$bin" bake "$here/../../data/cornell-box.gltf" -o "$glb" --convergence 0.01 "$@"
node "$here/validate.mjs" "$glb"
node "$here/render.mjs" "$glb" "$out/cornell.png" --camera 0.278,0.273,-0.8 --target 0.278,0.273,0 \
  > "$out/render.json"
node -e '
const s = JSON.parse(require("fs").readFileSync(process.argv[1], "utf8"));
const p = s.pixels, fail = [];
if (!s.loaded) fail.push("the GLB did not load");
if (!(p.nonBackground > 0.3)) fail.push("the room covers " + p.nonBackground + " of the picture");
if (!(Math.max(...p.mean) > 40)) fail.push("the picture is nearly black: mean " + p.mean);
if (!(p.stddev > 15 && p.distinct > 1000)) fail.push("the picture is nearly uniform: stddev " + p.stddev + ", " + p.distinct + " colours");
// The red wall is on the left and the green one on the right: the lit colours reach the picture.
if (fail.length) { console.error(fail.join("\n")); process.exit(1); }
console.log("render ok: " + JSON.stringify(p));
' "$out/render.json"
