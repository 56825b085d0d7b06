# `video3dgs trade` end to end: `video3dgs sfm` (the real COLMAP) on a small generated video, then a
# 2 x 2 sweep on its first clip (12 frames: clips 0-9 and 2-11) from that model (no SfM re-run): trade.csv / trade.json / runs/ / the
# two plots (with gnuplot), one JSON line per configuration, a re-run that reuses every result, and bad
# input refused with its id before any training. Skips when colmap is not installed.
cmake_minimum_required(VERSION 3.20)
include("${CMAKE_CURRENT_LIST_DIR}/lib/run.cmake")
start_test(colmap)
set(video "${WORK_DIR}/video")
set(out "${WORK_DIR}/trade out")

run(0 o e synthetic-video --out "${video}" --frames 12 --width 96 --height 72 --threads 2)
run(0 o e sfm --frames "${video}/frames" --masks "${video}/masks" --out "${WORK_DIR}/sfm" --threads 2)
file(READ "${WORK_DIR}/sfm/clips.json" clips)
string(JSON model GET "${clips}" clips 0 model)
string(JSON first GET "${clips}" clips 0 first)
string(JSON last GET "${clips}" clips 0 last)
set(sparse "${WORK_DIR}/sfm/${model}")
set(common --frames "${video}/frames" --masks "${video}/masks" --sparse "${sparse}" --first ${first} --last ${last}
           --shell-points 300 --threads 2 --iterations 40,80 --grid-levels 4,16 --log2-table 10)

function(check_lines text expect_reused)
  json_lines(lines "${text}" 4 "trade")
  foreach(line IN LISTS lines)
    string(JSON psnr GET "${line}" psnr)
    string(JSON bytes GET "${line}" compact_bytes)
    string(JSON reused GET "${line}" reused)
    if(psnr LESS 10 OR bytes LESS 1000 OR NOT reused STREQUAL "${expect_reused}")
      message(FATAL_ERROR "implausible or unexpected result (reused should be ${expect_reused}): ${line}")
    endif()
  endforeach()
endfunction()

run(0 o e trade ${common} --out "${out}")
check_lines("${o}" OFF)
foreach(f trade.csv trade.json)
  if(NOT EXISTS "${out}/${f}")
    message(FATAL_ERROR "${out}/${f} missing")
  endif()
endforeach()
file(STRINGS "${out}/trade.csv" rows)
list(LENGTH rows nrows)
if(NOT nrows EQUAL 5)
  message(FATAL_ERROR "trade.csv: expected a header and 4 rows, got ${nrows}")
endif()
file(GLOB runs "${out}/runs/*.json")
list(LENGTH runs nruns)
if(NOT nruns EQUAL 4)
  message(FATAL_ERROR "runs/: expected 4 result files, got ${nruns}")
endif()
find_program(GNUPLOT_EXE gnuplot)
if(GNUPLOT_EXE)
  foreach(png trade_time.png trade_bytes.png)
    file(READ "${out}/${png}" head LIMIT 8 HEX)
    if(NOT head STREQUAL "89504e470d0a1a0a")
      message(FATAL_ERROR "${out}/${png} is not a PNG (${head})")
    endif()
  endforeach()
endif()

# Resumed: every configuration read back, nothing trained.
run(0 o e trade ${common} --out "${out}")
check_lines("${o}" ON)

# Bad input, refused before any training.
expect_error(option.range trade --frames "${video}/frames" --sparse "${sparse}" --first 5 --last 50 --out "${WORK_DIR}/bad1")
expect_error(option.train trade --frames "${video}/frames" --sparse "${sparse}" --presets fastest --out "${WORK_DIR}/bad2")
# The first clip's model registers its frames only, not the video's last ones.
expect_error(io.incomplete trade --frames "${video}/frames" --sparse "${sparse}" --first 0 --last 11 --out "${WORK_DIR}/bad3")
message(STATUS "trade: 4 configurations trained, resumed, outputs present")
