#!/usr/bin/env bash
# The main job: installs what is missing, builds the `video3dgs` tool and runs the demo into out/demo/.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
ensure_packages
build="$VIDEO3DGS_ROOT/build/release"
mkdir -p "$build"
configure_and_build "$build" -DVIDEO3DGS_BUILD_EXAMPLES=ON -- video3dgs_cli
out="$VIDEO3DGS_ROOT/out/demo"
mkdir -p "$out"
"$build/bin/video3dgs" demo --out "$out" "$@"
