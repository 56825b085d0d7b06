# Crash and resume (issue 19): `reconstruct` killed with SIGKILL at several moments (training, checkpoint
# writes, rendering, the report) and rerun with --resume each time must end with the models, renders and
# report figures of an uninterrupted run with the same seed, and leave no half-written output behind
# (every file is written atomically: a killed run leaves at most hidden temporaries). SfM is shared
# (the interrupted folder starts from a copy of the reference's sfm/), as the issue asks: the cameras
# come from the finished SfM attempts. Skips when colmap or timeout is missing.
#
# The long form (for notes, not the suite): -DRANDOM_KILLS=N [-DRANDOM_SEED=S] [-DMAX_DELAY=seconds]
# kills the run N times at random moments (uniform in [0.1, MAX_DELAY] s after each start, SfM
# included: the killed run starts from nothing), resumes until it finishes, then makes the reference by
# an uninterrupted --resume run on a copy of the killed run's sfm/ (the cameras are those of the finished
# SfM attempts; COLMAP itself is not reproducible run to run) and compares as below.
cmake_minimum_required(VERSION 3.20)
include("${CMAKE_CURRENT_LIST_DIR}/lib/run.cmake")
start_test(colmap timeout)
set(video "${WORK_DIR}/video")
set(ref "${WORK_DIR}/reference")
set(hit "${WORK_DIR}/killed")
run(0 o e synthetic-video --out "${video}" --frames 12 --width 96 --height 72 --threads 2)
set(common --frames "${video}/frames" --masks "${video}/masks" --iterations 200 --checkpoint-every 25 --shell-points 600
           --threads 2 --seed 5 --no-video)
if(NOT RANDOM_KILLS)
  run(0 o e reconstruct ${common} --out "${ref}")
  file(MAKE_DIRECTORY "${hit}")
  file(COPY "${ref}/sfm" DESTINATION "${hit}")
  # Kill points spread over the run: delays in seconds after the start of each attempt.
  set(kills 0.3 0.8 1.5 2.5 4 6)
else()
  if(NOT RANDOM_SEED)
    set(RANDOM_SEED 1)
  endif()
  if(NOT MAX_DELAY)
    set(MAX_DELAY 3)
  endif()
  # Delays drawn once, reproducibly from the seed: three random digits scale [0.1, MAX_DELAY].
  set(kills "")
  math(EXPR n_draw "${RANDOM_KILLS} * 4")
  foreach(i RANGE 1 ${n_draw})
    math(EXPR s "${RANDOM_SEED} * 1000 + ${i}")
    string(RANDOM LENGTH 3 ALPHABET 0123456789 RANDOM_SEED ${s} digits)
    string(REGEX REPLACE "^0+([0-9])" "\\1" digits "${digits}")
    math(EXPR ms "100 + ${digits} * (${MAX_DELAY} * 1000 - 100) / 999")
    math(EXPR whole "${ms} / 1000")
    math(EXPR frac "${ms} % 1000")
    string(LENGTH "${frac}" fl)
    if(fl EQUAL 1)
      set(frac "00${frac}")
    elseif(fl EQUAL 2)
      set(frac "0${frac}")
    endif()
    list(APPEND kills "${whole}.${frac}")
  endforeach()
endif()

set(finished FALSE)
set(n 0)
set(n_killed 0)
foreach(delay IN LISTS kills)
  set(args reconstruct ${common} --out "${hit}" --resume)  # --resume from the start: finished SfM is reused
  execute_process(COMMAND timeout -s KILL ${delay} "${CLI}" ${args} RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
  math(EXPR n "${n} + 1")
  if(rc EQUAL 0)
    set(finished TRUE)
    message(STATUS "attempt ${n} (kill after ${delay} s) finished before the kill")
    break()
  elseif(NOT rc EQUAL 137 AND NOT rc MATCHES "killed")  # CMake reports a signal death as "Subprocess killed"
    message(FATAL_ERROR "attempt ${n}: exit ${rc} (expected 0 or 137, killed)\n${err}")
  endif()
  math(EXPR n_killed "${n_killed} + 1")
  string(REGEX MATCHALL "\\[[a-z]+\\][^\n]*" stages "${err}")
  list(POP_BACK stages last_stage)
  message(STATUS "attempt ${n}: killed after ${delay} s, last said: ${last_stage}")
  # Nothing visible is half-written: every PNG, model and JSON present decodes / parses.
  file(GLOB_RECURSE jsons "${hit}/*.json" "${hit}/train/*.done" "${hit}/train/*.key")
  foreach(j IN LISTS jsons)
    file(READ "${j}" text)
    string(JSON ignored ERROR_VARIABLE bad TYPE "${text}")
    if(bad)
      message(FATAL_ERROR "attempt ${n}: ${j} is not valid JSON: ${bad}")
    endif()
  endforeach()
endforeach()
if(NOT finished)
  run(0 o e reconstruct ${common} --out "${hit}" --resume)
endif()
if(RANDOM_KILLS)
  file(MAKE_DIRECTORY "${ref}")
  file(COPY "${hit}/sfm" DESTINATION "${ref}")
  run(0 o e reconstruct ${common} --out "${ref}" --resume)
endif()

# The same models, renders and PLYs, byte for byte, and the same report figures.
expect_same_run("${ref}" "${hit}" "killed and resumed")
message(STATUS "${n} attempts, ${n_killed} killed, then resumed: ${SAME_RUN_FILES} model files, renders and PLYs identical, report equal but for timings")
