# Clips as jobs (scripts/parallel_reconstruct.sh over GNU parallel on localhost): the same video and
# seed reconstructed by one process and by MC-COLMAP + two parallel clip workers + a combining run must
# give byte-identical models and renders, and the same report apart from timings. SfM is shared (the
# second output folder starts from a copy of the first one's sfm/), as the method's clips are fixed by
# it. Skips when colmap or parallel is not installed.
cmake_minimum_required(VERSION 3.20)
include("${CMAKE_CURRENT_LIST_DIR}/lib/run.cmake")
start_test(colmap parallel jq)
set(video "${WORK_DIR}/video dir")  # a space in every path: the recipe must quote
set(one "${WORK_DIR}/one process")
set(many "${WORK_DIR}/workers")
run(0 o e synthetic-video --out "${video}" --frames 12 --width 96 --height 72 --threads 2)
set(common --frames "${video}/frames" --masks "${video}/masks" --iterations 60 --shell-points 600 --threads 1 --seed 7 --no-video)

run(0 o e reconstruct ${common} --out "${one}")
file(MAKE_DIRECTORY "${many}")
file(COPY "${one}/sfm" DESTINATION "${many}")

get_filename_component(root "${CMAKE_CURRENT_LIST_DIR}/../.." ABSOLUTE)
execute_process(COMMAND bash "${root}/scripts/parallel_reconstruct.sh" --cli "${CLI}" --jobs 2 -- ${common} --out "${many}"
                RESULT_VARIABLE rc OUTPUT_VARIABLE report ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "parallel_reconstruct.sh failed (${rc}):\n${err}")
endif()
message(STATUS "${err}")
if(NOT err MATCHES "\\[parallel_reconstruct\\] 2 clips, 2 at a time")
  message(FATAL_ERROR "expected 2 clips in 2 jobs:\n${err}")
endif()

# Byte-identical models and renders.
file(GLOB models RELATIVE "${one}" "${one}/model/*")
file(GLOB renders RELATIVE "${one}" "${one}/renders/*.png")
list(LENGTH models nm)
list(LENGTH renders nr)
if(NOT nm EQUAL 3 OR NOT nr EQUAL 12)
  message(FATAL_ERROR "expected 2 clip models + manifest and 12 renders, got ${models} ${renders}")
endif()
expect_same_run("${one}" "${many}" "workers")
# The combining run reused both clips.
file(READ "${many}/report.json" r2)
foreach(c 0 1)
  string(JSON reused GET "${r2}" clips ${c} reused)
  if(NOT reused STREQUAL "ON")
    message(FATAL_ERROR "the combining run retrained clip ${c}")
  endif()
endforeach()
message(STATUS "workers == one process: ${nm} model files, ${nr} renders, report equal but for timings")

# Bad ranges fail with their id before any work.
foreach(bad "x" "3:1" "-1:2" "1:2:3")
  run(2 o e reconstruct ${common} --out "${WORK_DIR}/bad" --clips "${bad}")
  if(NOT e MATCHES "\\[option\\.range\\] --clips")
    message(FATAL_ERROR "--clips ${bad}: expected [option.range] --clips, got\n${e}")
  endif()
endforeach()
run(2 o e reconstruct ${common} --out "${WORK_DIR}/bad" --clips 0:1 --sfm-only)
if(EXISTS "${WORK_DIR}/bad")
  message(FATAL_ERROR "a refused worker wrote ${WORK_DIR}/bad")
endif()

# The Slurm recipe's submissions, with a stand-in `sbatch` that records its arguments (the recipe was
# run on a real single-node Slurm once; see docs/cli.md): one array task per clip, requeued on
# preemption, and the combining job after every task succeeded.
file(MAKE_DIRECTORY "${WORK_DIR}/bin")
file(WRITE "${WORK_DIR}/bin/sbatch" "#!/bin/sh\necho \"$*\" >> \"${WORK_DIR}/sbatch.log\"\necho 4$(wc -l < \"${WORK_DIR}/sbatch.log\")\n")
file(CHMOD "${WORK_DIR}/bin/sbatch" PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE)
execute_process(COMMAND "${CMAKE_COMMAND}" -E env "PATH=${WORK_DIR}/bin:$ENV{PATH}"
                        bash "${root}/scripts/slurm_reconstruct.sh" --cli "${CLI}" --cpus 1 -- ${common} --out "${many}"
                RESULT_VARIABLE rc OUTPUT_VARIABLE o ERROR_VARIABLE e)
file(READ "${WORK_DIR}/sbatch.log" submitted)
if(NOT rc EQUAL 0 OR NOT o MATCHES "clips: job 41 \\(array 0-1\\); render and report: job 42"
   OR NOT submitted MATCHES "--array=0-1 [^\n]*--requeue[^\n]*--clips \\$SLURM_ARRAY_TASK_ID\n"
   OR NOT submitted MATCHES "\n[^\n]*--dependency=afterok:41 [^\n]*--resume")
  message(FATAL_ERROR "slurm_reconstruct.sh (${rc}):\n${o}\n${e}\nsbatch saw:\n${submitted}")
endif()
message(STATUS "slurm_reconstruct.sh submits:\n${submitted}")
