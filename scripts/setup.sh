#!/usr/bin/env bash
# Installs the Debian packages hemibake needs to build and run, and with --test also those its tests
# need; then the web page's three.js from npm (web/, at the versions in its package-lock.json), which
# the build embeds into hemibake-server (--container: what scripts/check-image.sh needs). Idempotent: when everything is present it only checks
# (dpkg-query, file dates) and returns in well under a second.
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(
  build-essential cmake pkg-config
  libglm-dev
  libtinygltf-dev libdraco-dev libstb-dev nlohmann-json3-dev
  libboost1.81-dev libsqlite3-dev libpq-dev libssl-dev libembree-dev zlib1g-dev
  libgtest-dev libgmock-dev libbenchmark-dev
)
# Node.js and npm: the build embeds the web page's three.js from npm (web/), and the tests' glTF
# checks run under node (a newer node already on the machine is kept).
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  packages+=(nodejs npm)
fi
# --container: podman, debootstrap and curl, for scripts/check-image.sh.
if [[ "${1:-}" == "--container" ]]; then
  packages+=(podman debootstrap curl)
fi
if [[ "${1:-}" == "--test" ]]; then
  # Chromium for the three.js render checks and the web page's browser tests.
  packages+=(chromium)
  # PostgreSQL 15 for the shared store's tests (tests/server/pg_server.h starts one on loopback):
  # initdb, pg_ctl and psql.
  packages+=(postgresql-15 postgresql-client-15)
  # clang and libFuzzer for the fuzz targets in tests/fuzz.
  packages+=(clang-14 libclang-rt-14-dev)
fi

missing=()
for p in "${packages[@]}"; do
  status=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
  [[ "$status" == "install ok installed" ]] || missing+=("$p")
done

if ((${#missing[@]} > 0)); then
  echo "setup: installing ${missing[*]}" >&2
  sudo=""
  if [[ $(id -u) -ne 0 ]]; then sudo="sudo"; fi
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -qq
  $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# three.js for the web page, at the version web/package-lock.json pins (again when the lock changes).
if [[ ! -f web/node_modules/.package-lock.json || web/package-lock.json -nt web/node_modules/.package-lock.json ]]; then
  echo "setup: installing the web page's node packages (web/, npm ci)" >&2
  (cd web && npm ci --no-audit --no-fund --loglevel=error)
fi
