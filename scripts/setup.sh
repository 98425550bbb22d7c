#!/usr/bin/env bash
# Installs the Debian packages hemibake needs to build and run, and with --test also those its tests
# need. Idempotent: when everything is present it only checks (dpkg-query) and returns in well under
# a second.
set -euo pipefail

packages=(
  build-essential cmake pkg-config
  libglm-dev
  libtinygltf-dev libdraco-dev libstb-dev nlohmann-json3-dev
  libboost1.81-dev libsqlite3-dev libssl-dev libembree-dev zlib1g-dev
  libgtest-dev libgmock-dev libbenchmark-dev
)
if [[ "${1:-}" == "--test" ]]; then
  # Chromium for the three.js render check; Node.js and npm for the independent glTF checks in
  # tests/e2e (a newer node already on the machine is kept).
  packages+=(chromium)
  # clang and libFuzzer for the fuzz targets in tests/fuzz.
  packages+=(clang-14 libclang-rt-14-dev)
  if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
    packages+=(nodejs npm)
  fi
fi

missing=()
for p in "${packages[@]}"; do
  status=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
  [[ "$status" == "install ok installed" ]] || missing+=("$p")
done

if ((${#missing[@]} == 0)); then
  exit 0
fi

echo "setup: installing ${missing[*]}" >&2
sudo=""
if [[ $(id -u) -ne 0 ]]; then sudo="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
