#!/usr/bin/env bash
# The unit-test programs built with AddressSanitizer + UndefinedBehaviorSanitizer (VIDEO3DGS_SANITIZE) and
# run; any sanitizer report fails the run (UBSan does not recover, ASan's leak check is on).
#
# By default (and in .ci/run) every test folder runs except training, refine and pipeline: those train
# whole clips (a minute normally, more than ten under the sanitizers, and four minutes of sanitised
# build) through the kernels whose own tests do run here (rasterizer, hash_grid, optim, model, loss,
# ...); and fuzz: the test suite's fuzz_smoke runs the same targets on the same seeds and regression
# inputs under ASan + UBSan (clang), and the ordinary build's fuzz test checks their error ids.
# `--all` adds them. Never here: the end-to-end tests that drive the command-line tool (cli_*),
# the consumer builds and the doc snippets (they test programs and builds, not our code's memory use),
# the training-variant instantiation test (it checks that templates compile) and fuzz_smoke (its clang
# build is sanitised already). It compiles with clang++ (about half g++'s CPU time for these programs
# under the sanitizers), which scripts/test.sh installs as well. docs/testing.md has the figures.
# Usage: scripts/test_sanitized.sh [--all] [ctest args...]
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
left_out='training;refine;pipeline;fuzz'
if [[ "${1:-}" == "--all" ]]; then
  left_out=''
  shift
fi
VIDEO3DGS_PACKAGES+=(clang libclang-rt-dev)
ensure_packages
build="$VIDEO3DGS_ROOT/build/sanitize"
mkdir -p "$build"
cmake -S "$VIDEO3DGS_ROOT" -B "$build" "-DCMAKE_CXX_COMPILER=$(command -v clang++)" -DCMAKE_BUILD_TYPE=Release -DVIDEO3DGS_SANITIZE=ON -DVIDEO3DGS_BUILD_TESTS=ON \
  -DVIDEO3DGS_BUILD_EXAMPLES=OFF -DVIDEO3DGS_BUILD_BENCHMARKS=OFF "-DVIDEO3DGS_SANITIZE_SKIP_FOLDERS=${left_out:+$left_out;}instantiation" \
  > "$build.configure.log" 2>&1 || { cat "$build.configure.log"; exit 1; }
cmake --build "$build" -j "$(nproc)" --target video3dgs_sanitized_tests
export ASAN_OPTIONS="detect_leaks=1:abort_on_error=0:strict_string_checks=1:detect_stack_use_after_return=1"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1"
cd "$build"
skip="${left_out//;/|}"
ctest --output-on-failure --timeout 1200 --parallel "$(nproc)" -E "^(consumer_|cli_|doc_snippets|fuzz_smoke|instantiation${skip:+|(${skip})(_shared_data)?\$})" "$@"
