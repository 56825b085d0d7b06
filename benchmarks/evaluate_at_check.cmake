# bench_train_clip --evaluate-at: a checkpoint's evaluation leaves the training as it was (the result
# line of a run with checkpoints equals that of the same run without them), and the checkpoint after
# the last iteration reports the result's figures.
#   cmake -DBENCH=path/to/bench_train_clip -P evaluate_at_check.cmake
cmake_minimum_required(VERSION 3.20)
include("${CMAKE_CURRENT_LIST_DIR}/train_clip_lines.cmake")
set(args ${small_run})
run_bench(plain ${args})
run_bench(checked ${args} --evaluate-at 8,16,24)
result_line("${plain}" a)
result_line("${checked}" b)
same_keys("${a}" "${b}" "without checkpoints vs with them" psnr ssim psnr_frg psnr_bkg frg bkg model_bytes pruned split cloned)
string(REGEX MATCHALL "\"kind\":\"checkpoint\",\"iteration\":[0-9]+" iters "${checked}")
list(LENGTH iters n)
if(NOT n EQUAL 3)
  message(FATAL_ERROR "expected checkpoints at 8, 16 and 24, got: ${iters}")
endif()
string(REGEX MATCH "{\"bench\":\"train_clip\",\"kind\":\"checkpoint\",\"iteration\":24,[^\n]*" last "${checked}")
same_keys("${last}" "${b}" "the last checkpoint vs the result" psnr ssim psnr_frg psnr_bkg frg bkg)
message(STATUS "checkpoints: ${iters}; result ${b}")
