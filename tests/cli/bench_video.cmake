# benchmarks/bench_video.sh's contract, with a stand-in for `video3dgs` that records its arguments and
# writes a report.json of two clips (12.5 + 7.5 s of training): which `reconstruct` options each run
# gets (--scale, --preset, --resume, extra --args), which folder it writes (the defaults keep the folders
# of earlier versions; another scale or preset gets its own), the JSON line (scale, preset,
# train_seconds_recorded, the report), --status, and bad --scale / --preset refused with exit 2 before
# any run. The real job on DAVIS is what the script measures (docs/performance.md), not what this checks.
cmake_minimum_required(VERSION 3.20)
include("${CMAKE_CURRENT_LIST_DIR}/lib/run.cmake")
start_test(bash jq)
get_filename_component(script "${CMAKE_CURRENT_LIST_DIR}/../../benchmarks/bench_video.sh" ABSOLUTE)
set(data "${WORK_DIR}/data")
set(out "${WORK_DIR}/out")
set(calls "${WORK_DIR}/calls.txt")
set(fake "${WORK_DIR}/fake-video3dgs")
file(WRITE "${fake}" "#!/usr/bin/env bash
# stand-in for video3dgs reconstruct: one line of arguments per call, then OUT/report.json
echo \"$* |\" >> '${calls}'
while [ $# -gt 0 ]; do [ \"$1\" = --out ] && out=\"$2\"; shift; done
mkdir -p \"$out\"
echo '{\"clips\":[{\"train_seconds\":12.5},{\"train_seconds\":7.5}],\"psnr\":30}' > \"$out/report.json\"
")
file(CHMOD "${fake}" PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE)
foreach(i RANGE 0 11)
  string(LENGTH "${i}" n)
  math(EXPR pad "5 - ${n}")
  string(REPEAT "0" ${pad} zeros)
  file(WRITE "${data}/seq/frames/${zeros}${i}.jpg" "")
  file(WRITE "${data}/seq/masks/${zeros}${i}.png" "")
endforeach()

# bench(expect_rc out_var args...): the script with the stand-in, its stdout in out_var.
function(bench expect_rc out_var)
  execute_process(COMMAND "${BASH_EXE}" "${script}" --data "${data}" --out "${out}" --cli "${fake}" --threads 2 ${ARGN}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE o ERROR_VARIABLE e)
  if(NOT rc EQUAL expect_rc)
    message(FATAL_ERROR "bench_video.sh ${ARGN}: exit ${rc}, expected ${expect_rc}\n${o}\n${e}")
  endif()
  set(${out_var} "${o}" PARENT_SCOPE)
endfunction()

# check_line(line run scale preset): the line's fields.
function(check_line line run scale preset)
  foreach(pair "run;${run}" "scale;${scale}" "preset;${preset}" "sequence;seq" "train_seconds_recorded;20")
    list(GET pair 0 key)
    list(GET pair 1 want)
    string(JSON got GET "${line}" ${key})
    if(NOT got STREQUAL want)
      message(FATAL_ERROR "${key}: expected ${want}, got ${got} in ${line}")
    endif()
  endforeach()
  string(JSON psnr GET "${line}" report psnr)
  if(NOT psnr EQUAL 30)
    message(FATAL_ERROR "the report is not in the line: ${line}")
  endif()
endfunction()

# expect_call(n text...): the n-th recorded call (0-based; "ARGS |") contains each text.
function(expect_call n)
  file(STRINGS "${calls}" lines)
  list(GET lines ${n} line)
  foreach(text IN LISTS ARGN)
    string(FIND "${line}" "${text}" at)
    if(at LESS 0)
      message(FATAL_ERROR "call ${n}: expected '${text}' in\n${line}")
    endif()
  endforeach()
endfunction()

# The defaults: the full video at half size and the first clip at full size, both 3k, in the folders
# earlier versions used.
bench(0 o seq)
json_lines(lines "${o}" 2 "default runs")
list(GET lines 0 full)
list(GET lines 1 first)
check_line("${full}" full 0.5 3k)
check_line("${first}" first 1 3k)
expect_call(0 "reconstruct --frames ${data}/seq/frames --masks ${data}/seq/masks --out ${out}/seq/full --scale 0.5 --preset 3k --threads 2 -k 10 --resume |")
expect_call(1 "reconstruct --frames ${out}/seq/first_input/frames --masks ${out}/seq/first_input/masks --out ${out}/seq/first --scale 1 --preset 3k ")
file(GLOB linked "${out}/seq/first_input/frames/*")
list(LENGTH linked nlinked)
if(NOT nlinked EQUAL 10)
  message(FATAL_ERROR "the first clip: expected 10 frames linked, got ${nlinked}")
endif()

# Issue 16's whole videos: full size with the default preset, in folders of their own; 1.0 is 1.
bench(0 o --runs full --scale 1 --preset balanced seq)
json_lines(lines "${o}" 1 "full size")
check_line("${lines}" full 1 balanced)
expect_call(2 " --out ${out}/seq/full-scale1-balanced --scale 1 --preset balanced ")
bench(0 o --runs full --scale 1.0 --preset balanced --variant v --args "--budget 1" seq)
check_line("${o}" full 1 balanced)
expect_call(3 " --out ${out}/seq/full-scale1-balanced-v --scale 1 --preset balanced " " --resume --budget 1 |")
string(JSON variant GET "${o}" variant)
if(NOT variant STREQUAL "v")
  message(FATAL_ERROR "variant: expected v, got ${variant}")
endif()
bench(0 o --runs first --preset fast seq)
check_line("${o}" first 1 fast)
expect_call(4 " --out ${out}/seq/first-fast --scale 1 --preset fast ")

# --status runs nothing and prints the finished runs' lines.
bench(0 o --status --runs full --scale 1 --preset balanced seq)
check_line("${o}" full 1 balanced)
file(STRINGS "${calls}" all)
list(LENGTH all ncalls)
if(NOT ncalls EQUAL 5)
  message(FATAL_ERROR "--status ran the job (${ncalls} calls)")
endif()

# Bad settings: exit 2, nothing run.
foreach(bad "--scale;0" "--scale;1.5" "--scale;abc" "--scale;-0.5" "--preset;a b")
  bench(2 o ${bad} seq)
endforeach()
file(STRINGS "${calls}" all)
list(LENGTH all ncalls)
if(NOT ncalls EQUAL 5)
  message(FATAL_ERROR "a refused setting ran the job (${ncalls} calls)")
endif()
