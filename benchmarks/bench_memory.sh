#!/usr/bin/env bash
# Peak memory of `video3dgs reconstruct` against the video's length (issue 19): for each frame count N,
# a generated N-frame video (synthetic-video, cached in OUT/video_N) is reconstructed with few iterations
# per clip under /usr/bin/time -v, and one JSON line is printed per run:
#   {"bench":"memory","frames":N,"width":W,"height":H,"sweep":S,"iterations":I,"peak_rss_mb":..,"wall_s":..,
#    "clips":..,"longest_clip":..,"psnr":..}
# Peak memory should follow the clip length and the frame size, not N. The videos sweep back and forth
# every --sweep frames (synthetic-video --sweep), so every N moves as much per frame and MC-COLMAP's
# clips have the same length (with one sweep over 1,000 frames SfM failed on 10-frame clips and grew
# them to up to 21 frames). SfM uses whole frames (--no-sfm-masks) and the generator's focal length
# (--focal): on these videos of ~140 features a frame COLMAP's focal estimate of the first clip varied
# from run to run (163 px, 3 px; the true one is 740 px), and with 3 px no later clip registered.
# Usage: benchmarks/bench_memory.sh [--cli PATH] [--out DIR] [--width 854] [--height 480]
#                                   [--iterations 20] [--threads 2] [--sweep 100] N [N ...]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cli="$root/build/release/bin/video3dgs"
out="$root/out/bench_memory"
width=854 height=480 iterations=20 threads=2 sweep=100
counts=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --cli) cli="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --width) width="$2"; shift 2 ;;
    --height) height="$2"; shift 2 ;;
    --iterations) iterations="$2"; shift 2 ;;
    --threads) threads="$2"; shift 2 ;;
    --sweep) sweep="$2"; shift 2 ;;
    -h|--help) sed -n '2,16p' "$0"; exit 0 ;;
    *) counts+=("$1"); shift ;;
  esac
done
[[ ${#counts[@]} -gt 0 ]] || { echo "bench_memory.sh: give at least one frame count" >&2; exit 2; }
[[ -x "$cli" ]] || { echo "bench_memory.sh: no video3dgs at $cli (build it, or pass --cli)" >&2; exit 2; }
command -v /usr/bin/time > /dev/null || [[ -x /usr/bin/time ]] || { echo "bench_memory.sh: needs /usr/bin/time (Debian package time)" >&2; exit 2; }
mkdir -p "$out"
for n in "${counts[@]}"; do
  video="$out/video_${n}_${width}x${height}_sweep${sweep}"
  [[ -f "$video/synthetic.json" ]] || { rm -rf "$video"; "$cli" synthetic-video --out "$video" --frames "$n" --width "$width" --height "$height" \
                                         --sweep "$sweep" --threads "$threads" > "$video.json" && mv "$video.json" "$video/synthetic.json"; }
  focal=$(jq .focal "$video/synthetic.json")
  run="$out/run_${n}_${width}x${height}_sweep${sweep}"
  rm -rf "$run"
  /usr/bin/time -v -o "$run.time" "$cli" reconstruct --frames "$video/frames" --masks "$video/masks" --out "$run" \
    --iterations "$iterations" --threads "$threads" --no-sfm-masks --focal "$focal" --no-video --no-compare > "$run.log" 2>&1
  rss_kb=$(sed -n 's/.*Maximum resident set size (kbytes): *//p' "$run.time")
  wall=$(sed -n 's/.*Elapsed (wall clock) time (h:mm:ss or m:ss): *//p' "$run.time" | awk -F: '{s=0; for(i=1;i<=NF;i++) s=s*60+$i; print s}')
  jq -c --argjson n "$n" --argjson w "$width" --argjson h "$height" --argjson it "$iterations" --argjson rss "$rss_kb" --argjson wall "$wall" --argjson sweep "$sweep" \
    '{bench:"memory",frames:$n,width:$w,height:$h,sweep:$sweep,iterations:$it,peak_rss_mb:($rss/1024|floor),wall_s:$wall,clips:(.clips|length),longest_clip:([.clips[]|.last-.first+1]|max),psnr:.psnr}' \
    "$run/report.json"
done
