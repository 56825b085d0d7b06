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

# start_test(program ...): finds each program (its path in <PROGRAM>_EXE, e.g. COLMAP_EXE), ends the
# calling script with "[skipped] <program> is not installed" when one is missing, and empties WORK_DIR.
# A macro, so that its return() ends the calling script.
macro(start_test)
  foreach(_program ${ARGN})
    string(TOUPPER "${_program}_EXE" _var)
    find_program(${_var} ${_program})
    if(NOT ${_var})
      message("[skipped] ${_program} is not installed")
      return()
    endif()
  endforeach()
  file(REMOVE_RECURSE "${WORK_DIR}")
  file(MAKE_DIRECTORY "${WORK_DIR}")
endmacro()
