#!/usr/bin/env bash
# Real-video benchmark of the whole job (`video3dgs reconstruct`, real COLMAP) on DAVIS sequences.
# For each sequence (default: blackswan horsejump-high from ../shared/data):
#   full   every frame, at --scale S (default 0.5)
#   first  the first clip only (frames 0..k-1), full resolution
# both with --preset P (default 3k), and prints one JSON line per run: {"bench":"video","sequence":..,
# "run":..,"scale":..,"preset":..,"train_seconds_recorded":..,"report":<report.json>}. A scale or preset
# other than the defaults gets folders of its own (OUT/SEQ/full-scale1-balanced), so runs of different
# settings never resume from each other.
# Runs resume (--resume): an interrupted benchmark continues where it stopped, and a finished one is not
# retrained, so the report's seconds.train (this run's wall time) is about 0 on a rerun. The training
# cost is train_seconds_recorded (the sum of the clips' train_seconds; also report.seconds.train_recorded):
# each clip's train_seconds is the figure recorded when the clip was trained (OUT/train/clip_NNN.done),
# which --resume keeps, as seconds.sfm_recorded / clips[].sfm_seconds_recorded do for SfM.
# --status runs nothing: for each run it prints the summary if the run has finished, else one line per
# finished clip, {"bench":"video","sequence":..,"run":..,"partial":true,"clip":N,"first":..,"last":..,
# "iterations":..,"psnr":..,"ssim":..,"train_seconds":..,"model_bytes":..} (OUT/train/clip_NNN.done; a
# clip of an earlier schedule stays there until retrained: check first/last).
#
# --variant NAME --args "ARGS" runs a variant of the job: ARGS go to every `reconstruct` (for example
# --args "--no-sfm-masks"), the runs live in OUT/SEQ/RUN-NAME and their lines carry "variant":"NAME".
#
# Usage: benchmarks/bench_video.sh [--data DIR] [--out DIR] [--threads N] [--runs "full first"]
#                                  [--scale S] [--preset P] [--variant NAME --args "ARGS"] [--cli PATH]
#                                  [--status] [sequence ...]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
data="$root/../shared/data"
out="$root/out/bench_video"
threads=0
runs="full first"
cli=""
status=0
variant=""
extra=""
scale=0.5
preset=3k
k=10
seqs=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --data) data="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --threads) threads="$2"; shift 2 ;;
    --runs) runs="$2"; shift 2 ;;
    --cli) cli="$2"; shift 2 ;;
    --status) status=1; shift ;;
    --variant) variant="$2"; shift 2 ;;
    --args) extra="$2"; shift 2 ;;
    --scale) scale="$2"; shift 2 ;;
    --preset) preset="$2"; shift 2 ;;
    -h|--help) sed -n '2,25p' "$0"; exit 0 ;;
    *) seqs+=("$1"); shift ;;
  esac
done
[[ ${#seqs[@]} -gt 0 ]] || seqs=(blackswan horsejump-high)
if [[ -n "$extra" && -z "$variant" ]]; then echo "--args needs --variant NAME (the runs' folder suffix)" >&2; exit 2; fi
[[ "$variant" =~ ^[A-Za-z0-9_.-]*$ ]] || { echo "--variant: letters, digits, '.', '_' and '-' only" >&2; exit 2; }
[[ "$scale" =~ ^(0?\.[0-9]*[1-9][0-9]*|1(\.0*)?)$ ]] || { echo "--scale: a number in (0, 1], got '$scale'" >&2; exit 2; }
scale="$(awk -v s="$scale" 'BEGIN { print s + 0 }')"  # 1.0 -> 1, .5 -> 0.5: a JSON number and one folder name
[[ "$preset" =~ ^[A-Za-z0-9]+$ ]] || { echo "--preset: a preset name (video3dgs reconstruct --help), got '$preset'" >&2; exit 2; }
read -r -a extra_args <<< "$extra"
run_scale() {  # run: the scale it trains at
  if [[ "$1" == full ]]; then echo "$scale"; else echo 1; fi
}
run_dir() {  # sequence run: the default settings keep the folders of earlier versions
  local tag=""
  [[ "$2" == full && "$scale" != 0.5 ]] && tag="-scale$scale"
  [[ "$preset" != 3k ]] && tag="$tag-$preset"
  echo "$out/$1/$2$tag${variant:+-$variant}"
}

# JSON lines are made by jq (installed by scripts/setup.sh). `head` is the part every line starts with.
head_json() {  # sequence run
  jq -cn --arg s "$1" --arg r "$2" --arg v "$variant" --argjson scale "$(run_scale "$2")" --arg p "$preset" \
    '{bench: "video", sequence: $s, run: $r, scale: $scale, preset: $p} + (if $v == "" then {} else {variant: $v} end)'
}
summary() {  # sequence run report.json: train_seconds_recorded is the sum of the clips' train_seconds (kept from clip_NNN.done when resumed)
  jq -c --argjson head "$(head_json "$1" "$2")" '$head + {train_seconds_recorded: ([.clips[].train_seconds] | add // 0), report: .}' "$3"
}
partial() {  # sequence run dir: one line per finished clip of an unfinished run (clip_NNN.done, JSON since 0.2)
  local f c bytes
  for f in "$3"/train/clip_*.done; do
    [[ -f "$f" ]] || continue
    c="$(basename "$f" .done)"
    bytes="$(stat -c %s "$3/model/$c.model" 2>/dev/null || echo null)"
    jq -c --argjson head "$(head_json "$1" "$2")" --argjson clip "$((10#${c#clip_}))" --argjson bytes "$bytes" \
      '$head + {partial: true, clip: $clip} + del(.key) + {model_bytes: $bytes}' "$f" 2>/dev/null \
      || echo "[bench_video] $f: not JSON (written by version 0.1), skipped" >&2
  done
}
if [[ $status -eq 1 ]]; then
  for s in "${seqs[@]}"; do
    for r in $runs; do
      dir="$(run_dir "$s" "$r")"
      if [[ -f "$dir/report.json" ]]; then
        summary "$s" "$r" "$dir/report.json"
      else
        partial "$s" "$r" "$dir"
      fi
    done
  done
  exit 0
fi
if [[ -z "$cli" ]]; then
  source "$root/scripts/setup.sh"
  ensure_packages
  build="$VIDEO3DGS_ROOT/build/release"
  mkdir -p "$build"
  configure_and_build "$build" -DVIDEO3DGS_BUILD_EXAMPLES=ON -- video3dgs_cli >&2
  cli="$build/bin/video3dgs"
fi

for s in "${seqs[@]}"; do
  frames="$data/$s/frames"
  masks="$data/$s/masks"
  if [[ ! -d "$frames" ]]; then
    echo "[bench_video] skipped $s: $frames not found" >&2
    continue
  fi
  mask_args=()
  [[ -d "$masks" ]] && mask_args=(--masks "$masks")
  for r in $runs; do
    dir="$(run_dir "$s" "$r")"
    mkdir -p "$dir"
    case "$r" in
      full)
        "$cli" reconstruct --frames "$frames" "${mask_args[@]}" --out "$dir" --scale "$scale" --preset "$preset" \
          --threads "$threads" -k "$k" --resume "${extra_args[@]}" >&2 ;;
      first)
        # The first k frames (symlinks) as a video of its own: one clip.
        in="$out/$s/first_input"
        mkdir -p "$in/frames" "$in/masks"
        mapfile -t fs < <(ls "$frames" | sort -V | head -n "$k")
        for f in "${fs[@]}"; do ln -sf "$frames/$f" "$in/frames/$f"; done
        m_args=()
        if [[ -d "$masks" ]]; then
          for f in "${fs[@]}"; do
            m="$(ls "$masks" | grep -E "^${f%.*}\.[A-Za-z]+$" | head -n 1)"
            [[ -n "$m" ]] && ln -sf "$masks/$m" "$in/masks/$m"
          done
          m_args=(--masks "$in/masks")
        fi
        "$cli" reconstruct --frames "$in/frames" "${m_args[@]}" --out "$dir" --scale 1 --preset "$preset" \
          --threads "$threads" -k "$k" --resume "${extra_args[@]}" >&2 ;;
      *) echo "unknown run '$r' (full, first)" >&2; exit 2 ;;
    esac
    summary "$s" "$r" "$dir/report.json"
  done
done
