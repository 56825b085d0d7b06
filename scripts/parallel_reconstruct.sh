#!/usr/bin/env bash
# `video3dgs reconstruct` with the clips trained as GNU parallel jobs, on this machine's cores or on the
# machines of an --sshloginfile (which must see OUT at the same path, e.g. over NFS). Same result as one
# `video3dgs reconstruct` with the same arguments: the clips are trained by the same code with the same
# seeds, and SfM runs once.
#
# Usage: scripts/parallel_reconstruct.sh [--cli PATH] [--jobs N] [--sshloginfile FILE] -- RECONSTRUCT_ARGS...
#   RECONSTRUCT_ARGS: what `video3dgs reconstruct` takes (--frames, --out, ...), without --resume.
#   --jobs N: clips trained at once (default 1 per machine; give each job --threads so that
#   jobs x threads fits the cores).
# Steps: 1. MC-COLMAP once (`reconstruct --sfm-only`); 2. one `reconstruct --resume --clips C:C` job per
# clip of the schedule, through `parallel` (a rerun skips finished clips; a killed job's checkpoint is
# resumed); 3. `reconstruct --resume` renders every frame and writes report.json (printed on stdout).
set -euo pipefail
cli="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/build/release/bin/video3dgs"
jobs=1
login=()
while [ $# -gt 0 ]; do
  case "$1" in
    --cli) cli="$2"; shift 2 ;;
    --jobs) jobs="$2"; shift 2 ;;
    --sshloginfile) login=(--sshloginfile "$2"); shift 2 ;;
    --) shift; break ;;
    *) echo "parallel_reconstruct.sh: unknown option $1 (RECONSTRUCT_ARGS go after --)" >&2; exit 2 ;;
  esac
done
command -v parallel > /dev/null || { echo "parallel_reconstruct.sh: GNU parallel is not installed (apt-get install parallel)" >&2; exit 2; }
command -v jq > /dev/null || { echo "parallel_reconstruct.sh: jq is not installed (apt-get install jq)" >&2; exit 2; }
args=("$@")
# 1. The schedule (reuses finished COLMAP attempts when rerun).
clips="$("$cli" reconstruct "${args[@]}" --resume --sfm-only | jq '.clips | length')"
echo "[parallel_reconstruct] $clips clips, $jobs at a time" >&2
# 2. The clips (-q: every argument quoted for the shell parallel runs, so paths may hold spaces).
seq 0 $((clips - 1)) | parallel -q --halt now,fail=1 --jobs "$jobs" "${login[@]}" \
  "$cli" reconstruct "${args[@]}" --resume --clips '{}:{}' > /dev/null
# 3. Combine: every clip is finished, so this renders and reports.
"$cli" reconstruct "${args[@]}" --resume
