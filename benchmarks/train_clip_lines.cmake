# Helpers of the cmake scripts that check bench_train_clip's JSON lines (include() this file).
# A 24-iteration synthetic run that densifies, deforms and raises the SH degree: the checks' run.
set(small_run --iterations 24 --frames 2 --width 32 --height 24 --every 100 --threads 1 --warmup 8 --densify-from 4
              --densify-until 16 --sh-interval 8)
function(same_keys a b what)  # the JSON lines a and b agree on each key after `what`
  foreach(key IN LISTS ARGN)
    string(JSON va GET "${a}" ${key})
    string(JSON vb GET "${b}" ${key})
    if(NOT va STREQUAL vb)
      message(FATAL_ERROR "${key}: ${va} vs ${vb} (${what})")
    endif()
  endforeach()
endfunction()
function(result_line out var)  # the "result" JSON line of a run's output
  string(REGEX MATCH "{\"bench\":\"train_clip\",\"kind\":\"result\"[^\n]*" line "${out}")
  if(NOT line)
    message(FATAL_ERROR "no result line in:\n${out}")
  endif()
  set(${var} "${line}" PARENT_SCOPE)
endfunction()
function(run_bench var)  # runs ${BENCH} with the given arguments; its output into var, a failure fatal
  execute_process(COMMAND "${BENCH}" ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "bench_train_clip ${ARGN} failed (${rc}): ${err}")
  endif()
  set(${var} "${out}" PARENT_SCOPE)
endfunction()
