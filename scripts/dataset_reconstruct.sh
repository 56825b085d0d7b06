#!/usr/bin/env bash
# Reconstructs every sequence of a dataset in the DAVIS layout (DATA/<sequence>/frames/ and, when
# present, DATA/<sequence>/masks/) with `video3dgs reconstruct`, resumable, and writes one table:
#   OUT/table.jsonl   one JSON line per sequence ({"sequence", "frames", "width", "height", "clips",
#                     "psnr", "ssim", "seconds": total, "train_seconds": recorded, "model_bytes"}) and a
#                     last line {"sequence":"mean", ...} over the sequences
#   OUT/table.md      the same as a Markdown table
# A rerun reuses finished clips and COLMAP attempts (--resume), so an interrupted run continues.
#
# Usage: scripts/dataset_reconstruct.sh [--cli PATH] [--jobs N] DATA OUT [RECONSTRUCT_ARGS...]
#   --jobs N   sequences reconstructed at once through GNU parallel (default 1; give each one
#              --threads so that N x threads fits the cores). For one long video's clips on many
#              machines use scripts/parallel_reconstruct.sh or scripts/slurm_reconstruct.sh instead.
set -euo pipefail
cli="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/build/release/bin/video3dgs"
jobs=1
while [ $# -gt 0 ]; do
  case "$1" in
    --cli) cli="$2"; shift 2 ;;
    --jobs) jobs="$2"; shift 2 ;;
    *) break ;;
  esac
done
[ $# -ge 2 ] || { sed -n '2,14p' "$0" >&2; exit 2; }
data="$1"; out="$2"; shift 2
command -v jq > /dev/null || { echo "dataset_reconstruct.sh: jq is not installed (apt-get install jq)" >&2; exit 2; }
mkdir -p "$out"
seqs=()
for d in "$data"/*/; do
  [ -d "$d/frames" ] && seqs+=("$(basename "$d")")
done
[ ${#seqs[@]} -gt 0 ] || { echo "dataset_reconstruct.sh: no <sequence>/frames/ folder under $data" >&2; exit 2; }
one() {  # sequence: reconstruct it into OUT/<sequence> (log in OUT/<sequence>.log)
  local s="$1"; shift
  local masks=()
  [ -d "$data/$s/masks" ] && masks=(--masks "$data/$s/masks")
  "$cli" reconstruct --frames "$data/$s/frames" "${masks[@]}" --out "$out/$s" --resume --no-video "$@" \
    > /dev/null 2> "$out/$s.log" || { echo "[dataset] $s failed: see $out/$s.log" >&2; return 1; }
  echo "[dataset] $s done" >&2
}
export -f one
export cli data out
if [ "$jobs" -gt 1 ] && command -v parallel > /dev/null; then
  printf '%s\n' "${seqs[@]}" | parallel -q --jobs "$jobs" bash -c 'one "$@"' _ {} "$@"
else
  for s in "${seqs[@]}"; do one "$s" "$@"; done
fi
# The table, from each run's report.json and model files.
: > "$out/table.jsonl.tmp"
for s in "${seqs[@]}"; do
  bytes=$(cat "$out/$s"/model/clip_*.model | wc -c)
  jq -c --arg s "$s" --argjson bytes "$bytes" '{sequence: $s, frames, width, height, clips: (.clips | length), psnr, ssim,
    seconds: .seconds.total, train_seconds: .seconds.train_recorded, model_bytes: $bytes}' "$out/$s/report.json" >> "$out/table.jsonl.tmp"
done
jq -sc '{sequence: "mean", frames: (map(.frames) | add / length), psnr: (map(.psnr) | add / length),
  ssim: (map(.ssim) | add / length), seconds: (map(.seconds) | add / length), train_seconds: (map(.train_seconds) | add / length),
  model_bytes: (map(.model_bytes) | add / length)}' "$out/table.jsonl.tmp" >> "$out/table.jsonl.tmp"
mv "$out/table.jsonl.tmp" "$out/table.jsonl"
{
  echo "| sequence | frames | size | clips | PSNR (dB) | SSIM | seconds | training s | model MB |"
  echo "|---|---|---|---|---|---|---|---|---|"
  jq -r '"| \(.sequence) | \(.frames * 10 | round / 10) | \(if .width then "\(.width)x\(.height)" else "" end) | \(.clips // "") | \(.psnr * 100 | round / 100) | \(.ssim * 10000 | round / 10000) | \(.seconds | round) | \(.train_seconds | round) | \(.model_bytes / 1e6 | round) |"' "$out/table.jsonl"
} > "$out/table.md.tmp"
mv "$out/table.md.tmp" "$out/table.md"
cat "$out/table.md"
