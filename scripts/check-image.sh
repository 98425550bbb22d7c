#!/usr/bin/env bash
# Builds the container image from docker/Dockerfile with podman and checks what it holds: the
# image's root is exported and hemibake-server is run from it in a chroot (running containers
# needs cgroups, which these machines do not give), then / and the page's JavaScript are fetched
# from it with curl and compared with web/src. With no registry to pull from, the base image is
# made with debootstrap (Debian bookworm, minbase) the first time.
#   scripts/check-image.sh [--no-build]     --no-build: check the image already built
set -euo pipefail
cd "$(dirname "$0")/.."
image=localhost/hemibake:check
base=docker.io/library/debian:bookworm-slim
work=${HEMIBAKE_IMAGE_WORK:-/tmp/hemibake-image}
scripts/setup.sh --container
mkdir -p "$work"
if [[ "${1:-}" != --no-build ]]; then
  if ! podman image exists "$base"; then
    echo "check-image: making $base with debootstrap" >&2
    rm -rf "$work/base"
    debootstrap --variant=minbase bookworm "$work/base" http://deb.debian.org/debian >"$work/debootstrap.log"
    tar -C "$work/base" -c . | podman import - "$base" >/dev/null
    rm -rf "$work/base"
  fi
  echo "check-image: podman build (the project is compiled inside; some minutes)" >&2
  start=$SECONDS
  # A proxy's CA, where node is told of one (NODE_EXTRA_CA_CERTS), for npm inside the build.
  ca=()
  [[ -n "${NODE_EXTRA_CA_CERTS:-}" && -s "${NODE_EXTRA_CA_CERTS}" ]] && ca=(--volume "$NODE_EXTRA_CA_CERTS:/etc/ssl/build-ca.crt:ro")
  podman build --isolation=chroot --pull=never "${ca[@]}" -f docker/Dockerfile -t "$image" . >"$work/build.log" 2>&1 ||
    { tail -30 "$work/build.log"; echo "check-image: podman build failed; log in $work/build.log" >&2; exit 1; }
  echo "check-image: built in $((SECONDS - start)) s" >&2
fi
podman image inspect --format '{{.Size}}' "$image" | awk '{printf "check-image: image size %.0f MB\n", $1 / 1e6}'
# The image's root as a directory.
root=$work/root
rm -rf "$root" && mkdir -p "$root"
container=$(podman create "$image")
trap 'podman rm -f "$container" >/dev/null 2>&1 || true' EXIT
podman export "$container" | tar -C "$root" -x
entry=$(podman image inspect --format '{{json .Config.Entrypoint}}' "$image")
user=$(podman image inspect --format '{{.Config.User}}' "$image")
echo "check-image: entrypoint $entry, user $user" >&2
[[ -x "$root/usr/local/bin/hemibake-server" ]] || { echo "check-image: no hemibake-server in the image" >&2; exit 1; }
# Every library the server needs is in the image (ldd inside the chroot).
if chroot "$root" ldd /usr/local/bin/hemibake-server | grep -q "not found"; then
  chroot "$root" ldd /usr/local/bin/hemibake-server | grep "not found" >&2
  echo "check-image: the image lacks libraries" >&2; exit 1
fi
# Run as the image runs it, as its user, on a free port instead of 8080.
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
mkdir -p "$root/data" && chroot "$root" chown "$user" /data
mount --bind /proc "$root/proc" 2>/dev/null || true
chroot --userspec="$user" "$root" /usr/local/bin/hemibake-server --listen "127.0.0.1:$port" --data /data >"$work/server.log" 2>&1 &
server=$!
cleanup() { kill "$server" 2>/dev/null || true; wait "$server" 2>/dev/null || true; umount "$root/proc" 2>/dev/null || true
            podman rm -f "$container" >/dev/null 2>&1 || true; }
trap cleanup EXIT
for _ in $(seq 100); do curl -sf "http://127.0.0.1:$port/healthz" >/dev/null && break; sleep 0.1; done
fail=0
page=$(curl -sf "http://127.0.0.1:$port/") || { echo "check-image: GET / failed" >&2; fail=1; }
if ! grep -q '<html' <<<"$page"; then echo "check-image: / is not the page" >&2; fail=1; fi
# The page's scripts byte for byte as in web/src, and three.js as npm installed it.
for f in web/src/*.js web/node_modules/three/build/three.module.js; do
  url=/assets/${f#web/src/}
  [[ "$f" == web/node_modules/* ]] && url=/assets/${f#web/node_modules/}
  got=$(curl -sf "http://127.0.0.1:$port$url" | sha256sum | cut -d' ' -f1)
  want=$(sha256sum <"$f" | cut -d' ' -f1)
  if [[ "$got" == "$want" ]]; then echo "check-image: $url as in $f"; else echo "check-image: $url differs from $f" >&2; fail=1; fi
done
ok=$(curl -s -o /dev/null -w '%{http_code}' "http://127.0.0.1:$port/healthz")
echo "check-image: /healthz $ok"
[[ "$ok" == 200 ]] || fail=1
((fail == 0)) && echo "check-image: the image serves the page" || { cat "$work/server.log" >&2; exit 1; }
