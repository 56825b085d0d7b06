#!/usr/bin/env bash
# Installs what is missing, builds video3dgs (Release) with its tests, examples and benchmarks, and runs
# the whole test suite. Exits non-zero on any failure.   Usage: scripts/test.sh [ctest args...]
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
# The tests also need clang with libFuzzer (fuzz_smoke; the header check's syntax-only pass).
VIDEO3DGS_PACKAGES+=(clang libclang-rt-dev)
ensure_packages
build="$VIDEO3DGS_ROOT/build/release"
mkdir -p "$build"
configure_and_build "$build" -DVIDEO3DGS_BUILD_TESTS=ON -DVIDEO3DGS_BUILD_EXAMPLES=ON -DVIDEO3DGS_BUILD_BENCHMARKS=ON \
  "-DVIDEO3DGS_HEADER_CHECK_COMPILER=$(command -v clang++)" --
cd "$build"
ctest --output-on-failure --timeout 900 --parallel "$(nproc)" "$@"
