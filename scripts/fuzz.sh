#!/usr/bin/env bash
# Builds the libFuzzer targets of fuzz/ with clang (ASan + UBSan) and fuzzes the readers of user files.
#
#   scripts/fuzz.sh TARGET SECONDS   fuzz one target (ply colmap model checkpoint flo image camera_json state)
#   scripts/fuzz.sh all SECONDS      each target in turn, SECONDS each
#   scripts/fuzz.sh smoke [SECONDS]  build, then run every target briefly (default 3 s each): the test
#                                    suite's fuzz_smoke entry; exits 77 (skipped) when clang or libFuzzer is
#                                    missing, unless VIDEO3DGS_REQUIRE_SHARED_DATA=1 (.ci/run), then fails
#
# Build: $VIDEO3DGS_FUZZ_BUILD (default build/fuzz), $VIDEO3DGS_FUZZ_JOBS parallel jobs (default 1).
# Each run starts from the target's seeds (written by the target itself from the library's own writers)
# and a persistent corpus, $BUILD/corpus/TARGET, that grows between runs. A crash, leak, sanitizer report,
# timeout or oversized allocation stops the run and leaves the input in $BUILD/crashes/TARGET/; the
# script then exits non-zero. Final statistics (executions, cov, ft) go to $BUILD/logs/TARGET.log.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${VIDEO3DGS_FUZZ_BUILD:-$root/build/fuzz}"
jobs="${VIDEO3DGS_FUZZ_JOBS:-1}"
targets=(ply colmap model checkpoint flo image camera_json state)

usage() { sed -n '2,15p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//' >&2; exit 2; }
[ $# -ge 1 ] || usage
what="$1"
seconds="${2:-}"
if [ "$what" = smoke ]; then seconds="${seconds:-3}"; fi
[ -n "$seconds" ] || usage
if [ "$what" != all ] && [ "$what" != smoke ] && [[ ! " ${targets[*]} " =~ " $what " ]]; then
  echo "unknown fuzz target '$what' (known: ${targets[*]})" >&2
  exit 2
fi

# clang with libFuzzer: a one-line fuzzer must link.
have_libfuzzer() {
  command -v clang++ > /dev/null 2>&1 || return 1
  local probe; probe="$(mktemp -d)"
  printf 'extern "C" int LLVMFuzzerTestOneInput(const unsigned char*, unsigned long) { return 0; }\n' > "$probe/p.cpp"
  clang++ -fsanitize=fuzzer,address,undefined "$probe/p.cpp" -o "$probe/p" > /dev/null 2>&1
  local rc=$?
  rm -rf "$probe"
  return $rc
}
if ! have_libfuzzer; then
  msg="clang++ with libFuzzer not found (Debian: apt-get install clang libclang-rt-dev)"
  if [ "$what" = smoke ]; then
    if [ "${VIDEO3DGS_REQUIRE_SHARED_DATA:-0}" != 0 ] && [ -n "${VIDEO3DGS_REQUIRE_SHARED_DATA:-}" ]; then
      echo "FAIL: $msg (required: VIDEO3DGS_REQUIRE_SHARED_DATA is set)" >&2
      exit 1
    fi
    echo "skipped: $msg"
    exit 77
  fi
  if [ "$(id -u)" -eq 0 ]; then
    echo "== installing clang libclang-rt-dev"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends clang libclang-rt-dev
  else
    echo "$msg; run as root: apt-get install clang libclang-rt-dev" >&2
    exit 1
  fi
fi

mkdir -p "$build"
cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_COMPILER=clang++ \
  -DVIDEO3DGS_BUILD_FUZZERS=ON -DVIDEO3DGS_BUILD_TESTS=OFF -DVIDEO3DGS_BUILD_EXAMPLES=OFF \
  -DVIDEO3DGS_BUILD_BENCHMARKS=OFF -DVIDEO3DGS_INSTALL=OFF > "$build/configure.log" 2>&1 \
  || { cat "$build/configure.log" >&2; exit 1; }
run_list=("$what")
if [ "$what" = all ] || [ "$what" = smoke ]; then run_list=("${targets[@]}"); fi
cmake --build "$build" -j "$jobs" --target "${run_list[@]/#/fuzz_}"

# fuzz TARGET SECONDS: seeds, then libFuzzer; prints the final statistics.
fuzz() {
  local t="$1" secs="$2"
  local seeds="$build/seeds/$t" corpus="$build/corpus/$t" crashes="$build/crashes/$t" log="$build/logs/$t.log"
  rm -rf "$seeds"
  mkdir -p "$corpus" "$crashes" "$build/logs"
  VIDEO3DGS_FUZZ_WRITE_SEEDS="$seeds" "$build/fuzz/fuzz_$t"
  echo "== fuzz_$t for $secs s (corpus $corpus)"
  local rc=0
  # libFuzzer runs every input of these folders before it mutates: the corpus (written to), the seeds and
  # the inputs that once broke a reader (fuzz/regressions/TARGET), so every run replays those under
  # ASan + UBSan (tests/fuzz checks their error ids without sanitizers).
  local inputs=("$corpus" "$seeds")
  if [ -d "$root/fuzz/regressions/$t" ]; then inputs+=("$root/fuzz/regressions/$t"); fi
  "$build/fuzz/fuzz_$t" -max_total_time="$secs" -rss_limit_mb=2048 -malloc_limit_mb=2048 -timeout=20 -error_exitcode=1 \
    -print_final_stats=1 -artifact_prefix="$crashes/" "${inputs[@]}" > "$log" 2>&1 || rc=$?
  grep -E '^stat::(number_of_executed_units|peak_rss_mb)|^#[0-9]+ *DONE' "$log" || true
  if [ $rc -ne 0 ]; then
    echo "fuzz_$t FAILED (exit $rc): see $log and $crashes/" >&2
    grep -E 'ERROR|SUMMARY|terminate|what\(\)' "$log" | head -5 >&2 || true
  fi
  return $rc
}

failed=()
for t in "${run_list[@]}"; do
  fuzz "$t" "$seconds" || failed+=("$t")
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "failed: ${failed[*]}" >&2
  exit 1
fi
