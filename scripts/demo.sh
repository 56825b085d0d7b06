#!/usr/bin/env bash
# The main job: installs what is missing, builds the `video3dgs` tool, generates a synthetic video with
# foreground masks (30 frames of 160x120, a textured sphere moving in front of a textured dome, camera on
# an arc), reconstructs it end to end with the real COLMAP (`video3dgs reconstruct`: MC-COLMAP, 1000
# iterations per clip, every frame rendered) into out/demo/, and prints where to look. The sizes keep it
# well under 10 minutes on 2 cores. Each clip is also written compact (model/clip_NNN.compact, under
# 1 MB): --capacity auto sizes each clip's model from its pixels, frames, SfM points and viewpoints
# (for these 160x120 clips: 2^14-entry hash tables of 8 levels up to 128 cells, at most 165 Gaussians
# per SfM point, about 30k, in each set), trained at x3 the fields' learning rate (docs/performance.md,
# "The demo's clips under 1 MB"). Rerunning resumes (finished clips are reused).
#
# Usage: scripts/demo.sh [--input FRAMES_DIR [--masks MASKS_DIR]] [extra `video3dgs reconstruct` flags]
#   --input DIR   reconstruct any frame folder instead (the default preset, balanced, unless flags say otherwise)
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
input=""
masks=""
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --input) input="$2"; shift 2 ;;
    --masks) masks="$2"; shift 2 ;;
    *) extra+=("$1"); shift ;;
  esac
done
ensure_packages
build="$VIDEO3DGS_ROOT/build/release"
mkdir -p "$build"
configure_and_build "$build" -DVIDEO3DGS_BUILD_EXAMPLES=ON -- video3dgs_cli
cli="$build/bin/video3dgs"
out="$VIDEO3DGS_ROOT/out/demo"
mkdir -p "$out"
start=$(date +%s)
if [ -z "$input" ]; then
  echo "== generating the synthetic video into $out/input"
  "$cli" synthetic-video --out "$out/input" --frames 30 --width 160 --height 120
  args=(--frames "$out/input/frames" --masks "$out/input/masks" --iterations 1000 --shell-points 5000
        --capacity auto --deformation-lr 2.4e-3 --compact-preset small)
else
  args=(--frames "$input")
  [ -n "$masks" ] && args+=(--masks "$masks")
fi
echo "== video3dgs reconstruct ${args[*]} ${extra[*]:-} --out $out --resume"
"$cli" reconstruct "${args[@]}" --out "$out" --resume "${extra[@]}" > "$out/summary.json"
echo "== done in $(( $(date +%s) - start )) s. Look at:"
if [ -f "$out/compare.mp4" ]; then
  echo "   $out/compare.mp4      source | render | error heat map, as a video"
fi
echo "   $out/compare/         the same, one PNG per frame"
echo "   $out/renders/         the rendered frames"
echo "   $out/metrics.csv      per-frame PSNR / SSIM (plot: $out/metrics.png)"
echo "   $out/report.json      $(cat "$out/summary.json")"
