#!/usr/bin/env bash
# Sets up (Debian packages), builds Release, and runs the hemibake service on 127.0.0.1:8080 with
# its embedded job store in ./hemibake-data. Options after ./run.sh go to hemibake-server
# (see build/bin/hemibake-server --help). To bake one file without the service:
#   build/bin/hemibake bake data/cornell-box.gltf -o cornell.glb
set -euo pipefail
cd "$(dirname "$0")"
scripts/setup.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" --target hemibake hemibake-server
cat <<'TXT'
Open http://127.0.0.1:8080/ in a browser, or try, from another terminal:
  curl -sS -X POST --data-binary @data/cornell-box.gltf -H 'Content-Type: model/gltf+json' \
       http://127.0.0.1:8080/v1/jobs                      # -> 202 with the job's id
  curl -sS -N http://127.0.0.1:8080/v1/jobs/ID/events     # live progress
  curl -sS -o cornell.glb http://127.0.0.1:8080/v1/jobs/ID/result
TXT
exec build/bin/hemibake-server --listen 127.0.0.1:8080 --data hemibake-data "$@"
