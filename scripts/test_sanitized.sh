#!/usr/bin/env bash
# The unit-test programs built with AddressSanitizer + UndefinedBehaviorSanitizer (VIDEO3DGS_SANITIZE) and
# run; any sanitizer report fails the run (UBSan does not recover, ASan's leak check is on). The end-to-end
# tests that drive the command-line tool, the consumer builds and the doc snippets stay in the ordinary
# run (scripts/test.sh): they add build time here, not checks of our code's memory use. So do the
# training-variant instantiation test (it checks that templates compile; 84 s of build) and fuzz_smoke
# (its clang build is already sanitized).
# Usage: scripts/test_sanitized.sh [ctest args...]
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
ensure_packages
build="$VIDEO3DGS_ROOT/build/sanitize"
mkdir -p "$build"
cmake -S "$VIDEO3DGS_ROOT" -B "$build" -DCMAKE_BUILD_TYPE=Release -DVIDEO3DGS_SANITIZE=ON -DVIDEO3DGS_BUILD_TESTS=ON \
  -DVIDEO3DGS_BUILD_EXAMPLES=OFF -DVIDEO3DGS_BUILD_BENCHMARKS=OFF > "$build.configure.log" 2>&1 || { cat "$build.configure.log"; exit 1; }
mapfile -t targets < <(cmake --build "$build" --target help | sed -n 's/^\.\.\. \(video3dgs_test_[a-z_0-9]*\).*/\1/p' |
                       grep -v -e '^video3dgs_test_main$' -e '^video3dgs_test_doc_snippets$' -e '^video3dgs_test_instantiation$' \
                             -e 'header_check')
cmake --build "$build" -j "$(nproc)" --target "${targets[@]}"
export ASAN_OPTIONS="detect_leaks=1:abort_on_error=0:strict_string_checks=1:detect_stack_use_after_return=1"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1"
cd "$build"
ctest --output-on-failure --timeout 1200 --parallel "$(nproc)" -E '^(consumer_|cli_|doc_snippets|fuzz_smoke|instantiation)' "$@"
