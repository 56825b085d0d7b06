# Sourced by scripts/test.sh and scripts/demo.sh: makes sure the Debian packages video3dgs needs are
# installed (installing them when run as root, otherwise printing the exact command and stopping), then
# defines `configure_and_build BUILD_DIR TARGET...`.
set -euo pipefail

VIDEO3DGS_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VIDEO3DGS_PACKAGES=(build-essential cmake pkg-config libeigen3-dev libstb-dev libpng-dev libjpeg-dev zlib1g-dev doctest-dev
                    libcli11-dev nlohmann-json3-dev libsqlite3-dev jq parallel colmap ffmpeg gnuplot-nox)

ensure_packages() {
  local missing=()
  for p in "${VIDEO3DGS_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  local cmd="apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends ${missing[*]}"
  if [ "$(id -u)" -ne 0 ]; then
    echo "video3dgs needs these Debian packages: ${missing[*]}" >&2
    echo "Run as root:  $cmd" >&2
    exit 1
  fi
  echo "== installing: ${missing[*]}"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

# configure_and_build BUILD_DIR [cmake -D options...] -- [targets...]
configure_and_build() {
  local dir="$1"; shift
  local opts=() targets=()
  while [ $# -gt 0 ] && [ "$1" != "--" ]; do opts+=("$1"); shift; done
  [ $# -gt 0 ] && shift
  targets=("$@")
  cmake -S "$VIDEO3DGS_ROOT" -B "$dir" -DCMAKE_BUILD_TYPE=Release "${opts[@]}" > "$dir.configure.log" 2>&1 \
    || { cat "$dir.configure.log"; exit 1; }
  local jobs; jobs="$(nproc)"
  if [ ${#targets[@]} -eq 0 ]; then
    cmake --build "$dir" -j "$jobs"
  else
    cmake --build "$dir" -j "$jobs" --target "${targets[@]}"
  fi
}
