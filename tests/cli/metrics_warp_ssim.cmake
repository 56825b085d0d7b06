# `video3dgs metrics --warp-ssim --source S` on the FateZero jeep -> Porsche edit (8 frames, 512x512):
# the source video is more consistent through its own flow than the zero-shot edit, and the option
# errors exit non-zero.
cmake_minimum_required(VERSION 3.20)
include("${CMAKE_CURRENT_LIST_DIR}/lib/run.cmake")
shared_data_or_skip(pair edits/fatezero_car-turn_porsche edits/fatezero_car-turn_porsche/edited/00007.png)

function(run_metrics expect_ok out_var)
  execute_process(COMMAND "${CLI}" metrics ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(expect_ok AND NOT rc EQUAL 0)
    message(FATAL_ERROR "video3dgs metrics ${ARGN}: exit ${rc}\n${out}\n${err}")
  endif()
  if(NOT expect_ok AND rc EQUAL 0)
    message(FATAL_ERROR "video3dgs metrics ${ARGN}: succeeded, expected an error\n${out}")
  endif()
  set(${out_var} "${out}${err}" PARENT_SCOPE)
endfunction()

run_metrics(TRUE out "${pair}/source" "${pair}/edited" --warp-ssim --source "${pair}/source")
message(STATUS "${out}")
string(JSON wa GET "${out}" warp_ssim_a)
string(JSON wb GET "${out}" warp_ssim_b)
if(NOT wa GREATER wb OR wa GREATER 1.0 OR wb LESS 0.2)
  message(FATAL_ERROR "expected 1 >= warp_ssim(source) > warp_ssim(edited) > 0.2, got ${wa} and ${wb}")
endif()

run_metrics(FALSE out "${pair}/source" "${pair}/edited" --warp-ssim)
if(NOT out MATCHES "option.warp_ssim")
  message(FATAL_ERROR "missing --source: expected [option.warp_ssim], got ${out}")
endif()
run_metrics(FALSE out "${pair}/source" "${pair}/edited" --warp-ssim --source "${pair}/source" --flow-forward "${pair}/source")
if(NOT out MATCHES "option.warp_ssim")
  message(FATAL_ERROR "one flow folder: expected [option.warp_ssim], got ${out}")
endif()
