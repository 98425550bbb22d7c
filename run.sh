#!/usr/bin/env bash
# Sets up (Debian packages), builds Release, and runs hemibake's main job: a bake of the bundled
# Cornell box (data/cornell-box.gltf) to build/cornell-box.glb, with renders of the result in
# build/cornell.png (Gouraud) and build/cornell-mesh.png (the adaptive mesh).
set -euo pipefail
cd "$(dirname "$0")"
scripts/setup.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" --target hemibake
exec build/bin/hemibake bake data/cornell-box.gltf -o build/cornell-box.glb \
  --render build/cornell.png --wireframe build/cornell-mesh.png \
  --camera 0.278,0.273,-0.8:0.278,0.273,0 "$@"
