# Shared by the CLI test scripts (tests/cli/*.cmake, run with cmake -P; this folder is not globbed).
# run(expect_rc out_var err_var args...): runs ${CLI} args..., fails the test unless it exits with
# expect_rc, and returns its stdout and stderr.
function(run expect_rc out_var err_var)
  execute_process(COMMAND "${CLI}" ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE o ERROR_VARIABLE e)
  if(NOT rc EQUAL expect_rc)
    message(FATAL_ERROR "video3dgs ${ARGN}: exit ${rc}, expected ${expect_rc}\n${o}\n${e}")
  endif()
  set(${out_var} "${o}" PARENT_SCOPE)
  set(${err_var} "${e}" PARENT_SCOPE)
endfunction()

# json_lines(out_var text n what): the non-empty lines of `text` (one JSON document each) as a list,
# failing unless there are `n`.
function(json_lines out_var text n what)
  string(REGEX MATCHALL "[^\n]+" lines "${text}")
  list(LENGTH lines count)
  if(NOT count EQUAL n)
    message(FATAL_ERROR "${what}: expected ${n} lines, got ${count}:\n${text}")
  endif()
  set(${out_var} "${lines}" PARENT_SCOPE)
endfunction()

# expect_error(id args...): runs ${CLI} args..., fails the test unless it exits 2 with [id] on stderr.
function(expect_error id)
  run(2 o e ${ARGN})
  string(REPLACE "." "\\." rx "${id}")
  if(NOT e MATCHES "\\[${rx}\\]")
    message(FATAL_ERROR "video3dgs ${ARGN}: expected [${id}], got\n${e}")
  endif()
  message(STATUS "ok [${id}]: ${e}")
endfunction()

# Missing test inputs (../shared/data, or a program scripts/setup.sh installs): without the environment
# flag VIDEO3DGS_REQUIRE_SHARED_DATA the script prints "[skipped] <why>" and ends (ctest reports the test
# as skipped: SKIP_REGULAR_EXPRESSION in examples/CMakeLists.txt); with VIDEO3DGS_REQUIRE_SHARED_DATA=1
# (.ci/run) it fails naming what is missing. $ENV{VIDEO3DGS_SHARED_DATA}, when set, replaces SHARED_DATA
# (as it does for the C++ tests, tests/test_data.hpp).
if(DEFINED ENV{VIDEO3DGS_SHARED_DATA})
  set(SHARED_DATA "$ENV{VIDEO3DGS_SHARED_DATA}")
endif()
set(_require "$ENV{VIDEO3DGS_REQUIRE_SHARED_DATA}")
if(_require AND NOT _require STREQUAL "0")
  set(REQUIRE_SHARED_DATA TRUE)
else()
  set(REQUIRE_SHARED_DATA FALSE)
endif()

# skip_test(why): "[skipped] why" and the end of the calling script, or a failure under the flag. A macro,
# so that its return() ends the calling script.
macro(skip_test why)
  if(REQUIRE_SHARED_DATA)
    message(FATAL_ERROR "${why} (required: VIDEO3DGS_REQUIRE_SHARED_DATA is set)")
  endif()
  message("[skipped] ${why}")
  return()
endmacro()

# shared_data_or_skip(var rel [file]): sets var to ${SHARED_DATA}/rel; skip_test()s when file (default:
# rel itself) does not exist below SHARED_DATA.
macro(shared_data_or_skip var rel)
  set(${var} "${SHARED_DATA}/${rel}")
  set(_probe "${SHARED_DATA}/${rel}")
  if(NOT "${ARGN}" STREQUAL "")
    set(_probe "${SHARED_DATA}/${ARGN}")
  endif()
  if(NOT EXISTS "${_probe}")
    skip_test("shared data ${rel} not found (looked for ${_probe})")
  endif()
endmacro()

# start_test(program ...): finds each program (its path in <PROGRAM>_EXE, e.g. COLMAP_EXE), ends the
# calling script through skip_test() ("<program> is not installed") when one is missing, and empties
# WORK_DIR. A macro, so that its return() ends the calling script.
macro(start_test)
  foreach(_program ${ARGN})
    string(TOUPPER "${_program}_EXE" _var)
    find_program(${_var} ${_program})
    if(NOT ${_var})
      skip_test("${_program} is not installed")
    endif()
  endforeach()
  file(REMOVE_RECURSE "${WORK_DIR}")
  file(MAKE_DIRECTORY "${WORK_DIR}")
endmacro()

# expect_same_run(a b what): output folders a and b of `reconstruct` hold byte-identical models, renders
# and PLYs, and equal report.json figures (all but timings); `what` names b in failures. Sets
# SAME_RUN_FILES to the number of files compared.
function(expect_same_run a b what)
  file(GLOB files RELATIVE "${a}" "${a}/model/*" "${a}/renders/*.png" "${a}/ply/*.ply")
  foreach(f IN LISTS files)
    file(SHA256 "${a}/${f}" ha)
    file(SHA256 "${b}/${f}" hb)
    if(NOT ha STREQUAL hb)
      message(FATAL_ERROR "${f} differs: ${a} vs ${b} (${what})")
    endif()
  endforeach()
  file(READ "${a}/report.json" r1)
  file(READ "${b}/report.json" r2)
  foreach(key psnr ssim psnr_mean_colour frames width height)
    string(JSON va GET "${r1}" ${key})
    string(JSON vb GET "${r2}" ${key})
    if(NOT va STREQUAL vb)
      message(FATAL_ERROR "report ${key}: ${va} vs ${vb} (${what})")
    endif()
  endforeach()
  string(JSON nc LENGTH "${r1}" clips)
  string(JSON nc2 LENGTH "${r2}" clips)
  if(NOT nc EQUAL nc2)
    message(FATAL_ERROR "report: ${nc} clips vs ${nc2} (${what})")
  endif()
  math(EXPR last "${nc} - 1")
  foreach(c RANGE ${last})
    foreach(key first last iterations psnr ssim gaussians_frg gaussians_bkg model_bytes sfm_points)
      string(JSON va GET "${r1}" clips ${c} ${key})
      string(JSON vb GET "${r2}" clips ${c} ${key})
      if(NOT va STREQUAL vb)
        message(FATAL_ERROR "clip ${c} ${key}: ${va} vs ${vb} (${what})")
      endif()
    endforeach()
  endforeach()
  list(LENGTH files n)
  set(SAME_RUN_FILES ${n} PARENT_SCOPE)
endfunction()
