#!/usr/bin/env bash
# CXX_COMPILER_LAUNCHER of tests' video3dgs_header_check (VIDEO3DGS_HEADER_CHECK_COMPILER):
#   syntax_only_launcher.sh CHECKER CONFIGURED_COMPILER ARGS...
# checks the unit with `CHECKER -fsyntax-only ARGS...` instead of compiling it (the header check wants
# parsing and template instantiation, not code), then leaves the empty object file that the build
# expects at ARGS' `-o` path. The dependency file (-MD -MF) is written by the checker as usual.
set -euo pipefail
checker="$1"
shift 2
out=""
prev=""
for a in "$@"; do
  [[ "$prev" == "-o" ]] && out="$a"
  prev="$a"
done
"$checker" -fsyntax-only "$@"
if [[ -n "$out" ]]; then
  : > "$out"
fi
