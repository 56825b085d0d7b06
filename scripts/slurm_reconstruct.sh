#!/usr/bin/env bash
# `video3dgs reconstruct` on a Slurm cluster: MC-COLMAP as one job, the clips as a job array (one task
# per clip), the render/report step as a job that starts when every task has succeeded. OUT must be on a
# file system every node sees. Same result as one `video3dgs reconstruct` with the same arguments.
#
# Usage: scripts/slurm_reconstruct.sh [--cli PATH] [--cpus N] [--mem SIZE] [--time HH:MM:SS]
#                                     [--partition P] -- RECONSTRUCT_ARGS...   (without --resume)
# The MC-COLMAP step runs here, before submitting (it decides the number of clips; a rerun reuses the
# finished COLMAP attempts). Each array task runs `reconstruct --resume --clips $SLURM_ARRAY_TASK_ID`
# with --requeue: a preempted task restarts from its clip's checkpoint; a finished clip is skipped.
# Prints the two job ids; `sacct -j ID` follows them, and OUT/report.json appears at the end.
set -euo pipefail
cli="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/build/release/bin/video3dgs"
cpus=2
mem=8G
time_limit=04:00:00
partition=()
while [ $# -gt 0 ]; do
  case "$1" in
    --cli) cli="$2"; shift 2 ;;
    --cpus) cpus="$2"; shift 2 ;;
    --mem) mem="$2"; shift 2 ;;
    --time) time_limit="$2"; shift 2 ;;
    --partition) partition=(--partition "$2"); shift 2 ;;
    --) shift; break ;;
    *) echo "slurm_reconstruct.sh: unknown option $1 (RECONSTRUCT_ARGS go after --)" >&2; exit 2 ;;
  esac
done
command -v sbatch > /dev/null || { echo "slurm_reconstruct.sh: sbatch not found (Slurm client tools)" >&2; exit 2; }
command -v jq > /dev/null || { echo "slurm_reconstruct.sh: jq is not installed (apt-get install jq)" >&2; exit 2; }
args=("$@")
quoted="$(printf '%q ' "$cli" reconstruct "${args[@]}" --resume)"  # give --threads N to match --cpus
clips="$("$cli" reconstruct "${args[@]}" --resume --sfm-only | jq '.clips | length')"
echo "[slurm_reconstruct] $clips clips" >&2
train=$(sbatch --parsable --job-name=video3dgs-clips --array="0-$((clips - 1))" --cpus-per-task="$cpus" --mem="$mem" \
  --time="$time_limit" --requeue "${partition[@]}" --wrap "$quoted --clips \$SLURM_ARRAY_TASK_ID")
combine=$(sbatch --parsable --job-name=video3dgs-combine --dependency="afterok:$train" --cpus-per-task="$cpus" --mem="$mem" \
  --time="$time_limit" "${partition[@]}" --wrap "$quoted")
echo "clips: job $train (array 0-$((clips - 1))); render and report: job $combine"
