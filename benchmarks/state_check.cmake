# bench_train_clip --save-state / --resume: saving the training state leaves the run as it was, and a
# run resumed from the state saved after iteration 12 ends where the uninterrupted run ends (the same
# figures, counts and model bytes), reporting where it resumed.
#   cmake -DBENCH=path/to/bench_train_clip -DWORK_DIR=dir -P state_check.cmake
cmake_minimum_required(VERSION 3.20)
include("${CMAKE_CURRENT_LIST_DIR}/train_clip_lines.cmake")
set(args ${small_run})
file(MAKE_DIRECTORY "${WORK_DIR}")
set(state "${WORK_DIR}/after_12.state")
file(REMOVE "${state}")
run_bench(plain ${args})
run_bench(saving ${args} --save-state "${state}" --save-state-at 12)
if(NOT EXISTS "${state}")
  message(FATAL_ERROR "--save-state wrote no ${state}")
endif()
run_bench(resumed ${args} --resume "${state}")
result_line("${plain}" a)
result_line("${saving}" b)
result_line("${resumed}" c)
set(keys iterations psnr ssim psnr_frg psnr_bkg psnr_per_frame frg bkg model_bytes pruned split cloned)
same_keys("${a}" "${b}" "without a saved state vs with one" ${keys})
same_keys("${a}" "${c}" "uninterrupted vs resumed after iteration 12" ${keys})
string(JSON at GET "${c}" resumed_at)
string(JSON at0 GET "${a}" resumed_at)
if(NOT at EQUAL 12 OR NOT at0 EQUAL 0)
  message(FATAL_ERROR "resumed_at: ${at} (resumed run), ${at0} (plain run); expected 12 and 0")
endif()
# A state iteration outside the run is an error naming the option.
execute_process(COMMAND "${BENCH}" ${args} --save-state "${WORK_DIR}/never.state" --save-state-at 30
                RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
if(rc EQUAL 0 OR NOT err MATCHES "\\[option\\.range\\] --save-state-at")
  message(FATAL_ERROR "--save-state-at 30 in a 24-iteration run: exit ${rc}, ${err}")
endif()
message(STATUS "resumed after 12: ${c}")
