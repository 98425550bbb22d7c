#!/usr/bin/env bash
# Sets up (Debian packages), builds Release, and runs hemibake's main job: a bake of the built-in
# Cornell box, with a render of the result in build/cornell.png.
set -euo pipefail
cd "$(dirname "$0")"
scripts/setup.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" --target hemibake
exec build/bin/hemibake cornell --render build/cornell.png --wireframe build/cornell-mesh.png "$@"
