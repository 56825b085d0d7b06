# `video3dgs sfm` (MC-COLMAP alone) with the real COLMAP on a small generated video: clips.json and the
# per-clip models, a second run that writes the same bytes, a re-run that reuses every attempt, the
# mask options (--no-masks, --min-mask-area, --masked-fallback-after, --no-full-frame-fallback),
# --join-tail and bad input. Skips when colmap is not installed.
#
# Video: 12 frames of 96x72 with masks covering ~24 % of the frame (video3dgs synthetic-video). By
# default SfM runs on the whole frames first (min_mask_area 1); the method's rule (--min-mask-area 0.1)
# runs it on the masked frames; 2 clips (0-9, 2-11). COLMAP takes a few seconds per clip here.
cmake_minimum_required(VERSION 3.20)
include("${CMAKE_CURRENT_LIST_DIR}/lib/run.cmake")
start_test(colmap)
set(video "${WORK_DIR}/video")

run(0 o e synthetic-video --out "${video}" --frames 12 --width 96 --height 72 --threads 2)

# clips.json: the figures of every clip and of every attempt; `masked` says which pass made the model.
function(read_clips dir)
  file(READ "${dir}/clips.json" doc)
  string(JSON n GET "${doc}" frames)
  string(JSON nclips LENGTH "${doc}" clips)
  string(JSON masks GET "${doc}" masks)
  string(JSON fallback GET "${doc}" full_frame_fallback)
  string(JSON min_area GET "${doc}" min_mask_area)
  string(JSON fallback_after GET "${doc}" masked_fallback_after)
  if(NOT n EQUAL 12 OR nclips LESS 1)
    message(FATAL_ERROR "${dir}/clips.json: unexpected ${doc}")
  endif()
  math(EXPR last "${nclips} - 1")
  set(masked_all "")
  set(reused_all "")
  foreach(c RANGE ${last})
    string(JSON ok GET "${doc}" clips ${c} succeeded)
    string(JSON reg GET "${doc}" clips ${c} registered)
    string(JSON first GET "${doc}" clips ${c} first)
    string(JSON lastf GET "${doc}" clips ${c} last)
    string(JSON model GET "${doc}" clips ${c} model)
    math(EXPR size "${lastf} - ${first} + 1")
    if(NOT ok OR NOT reg EQUAL size OR NOT EXISTS "${dir}/${model}/images.bin" OR NOT EXISTS "${dir}/${model}/points3D.bin")
      message(FATAL_ERROR "${dir}: clip ${c} not reconstructed: ${doc}")
    endif()
    string(JSON ntries LENGTH "${doc}" clips ${c} tries)
    math(EXPR t "${ntries} - 1")
    string(JSON m GET "${doc}" clips ${c} tries ${t} masked)
    string(JSON r GET "${doc}" clips ${c} tries ${t} reused)
    list(APPEND masked_all "${m}")
    list(APPEND reused_all "${r}")
  endforeach()
  set(masks "${masks}" PARENT_SCOPE)
  set(fallback "${fallback}" PARENT_SCOPE)
  set(min_area "${min_area}" PARENT_SCOPE)
  set(fallback_after "${fallback_after}" PARENT_SCOPE)
  set(masked_all "${masked_all}" PARENT_SCOPE)
  set(reused_all "${reused_all}" PARENT_SCOPE)
  set(doc "${doc}" PARENT_SCOPE)
endfunction()

# 1. Defaults: whole frames first (the masks are given, and kept for the fallback), recorded with the rule.
set(out "${WORK_DIR}/default")
run(0 o e sfm --frames "${video}/frames" --masks "${video}/masks" --out "${out}" --threads 2)
read_clips("${out}")
if(NOT masks STREQUAL "ON" OR NOT fallback STREQUAL "ON" OR masked_all MATCHES "ON" OR reused_all MATCHES "ON"
   OR NOT min_area MATCHES "^1(\\.0*)?$" OR NOT fallback_after EQUAL 2)
  message(FATAL_ERROR "defaults: expected whole-frame SfM, fallback on, nothing reused, min_mask_area 1, masked_fallback_after 2: ${doc}")
endif()

# 1b. Reproducible by default: a second run into another folder writes the same clips.json and the
#     same model files byte for byte; the seconds are in timings.json.
set(out2 "${WORK_DIR}/default_again")
run(0 o e sfm --frames "${video}/frames" --masks "${video}/masks" --out "${out2}" --threads 2)
file(READ "${out}/clips.json" first_doc)
file(READ "${out2}/clips.json" second_doc)
if(NOT first_doc STREQUAL second_doc OR NOT first_doc MATCHES "\"deterministic\": true")
  message(FATAL_ERROR "two runs wrote different clips.json:\n${first_doc}\n${second_doc}")
endif()
file(GLOB_RECURSE models RELATIVE "${out}" "${out}/clip_*/sparse/0/*.bin")
list(LENGTH models nmodels)
if(nmodels LESS 3)
  message(FATAL_ERROR "expected model files under ${out}: ${models}")
endif()
foreach(f IN LISTS models)
  file(SHA256 "${out}/${f}" h1)
  file(SHA256 "${out2}/${f}" h2)
  if(NOT h1 STREQUAL h2)
    message(FATAL_ERROR "two runs wrote different ${f}")
  endif()
endforeach()
file(READ "${out2}/timings.json" times)
string(JSON secs GET "${times}" seconds)
string(JSON clip_secs GET "${times}" clips 0 seconds)
if(NOT secs GREATER 0 OR NOT clip_secs GREATER 0)
  message(FATAL_ERROR "timings.json: ${times}")
endif()

# 2. The same command again reuses every finished attempt (no COLMAP run) and says so.
run(0 o e sfm --frames "${video}/frames" --masks "${video}/masks" --out "${out}" --threads 2)
read_clips("${out}")
if(reused_all MATCHES "OFF" OR NOT e MATCHES "reused")
  message(FATAL_ERROR "re-run: expected every attempt reused:\n${e}\n${doc}")
endif()

# 3. --no-masks and a mask area threshold above the masks' area: whole frames.
foreach(variant "--no-masks" "--min-mask-area;0.5")
  string(MAKE_C_IDENTIFIER "${variant}" name)
  run(0 o e sfm --frames "${video}/frames" --masks "${video}/masks" --out "${WORK_DIR}/${name}" --threads 2 ${variant})
  read_clips("${WORK_DIR}/${name}")
  if(masked_all MATCHES "ON")
    message(FATAL_ERROR "${variant}: expected whole-frame SfM: ${doc}")
  endif()
endforeach()

# 4. The method's rule (masks first above 10 %) gives masked SfM; --no-full-frame-fallback is recorded.
run(0 o e sfm --frames "${video}/frames" --masks "${video}/masks" --out "${WORK_DIR}/no_fallback" --threads 2
    --min-mask-area 0.1 --masked-fallback-after 0 --no-full-frame-fallback)
read_clips("${WORK_DIR}/no_fallback")
if(NOT fallback STREQUAL "OFF" OR masked_all MATCHES "OFF" OR NOT fallback_after EQUAL 0)
  message(FATAL_ERROR "--min-mask-area 0.1 --no-full-frame-fallback: expected masked SfM, no fallback: ${doc}")
endif()

# 4b. --join-tail 2: the first clip, 0-9, would leave 2 frames and takes them in: one clip 0-11 (the
#     default schedule above has two), and clips.json records the setting.
run(0 o e sfm --frames "${video}/frames" --masks "${video}/masks" --out "${WORK_DIR}/join" --threads 2 --join-tail 2)
read_clips("${WORK_DIR}/join")
string(JSON nclips LENGTH "${doc}" clips)
string(JSON jfirst GET "${doc}" clips 0 first)
string(JSON jlast GET "${doc}" clips 0 last)
string(JSON jt GET "${doc}" join_tail)
if(NOT nclips EQUAL 1 OR NOT jfirst EQUAL 0 OR NOT jlast EQUAL 11 OR NOT jt EQUAL 2)
  message(FATAL_ERROR "--join-tail 2: expected one clip 0-11 and join_tail 2: ${doc}")
endif()

# 5. Bad input: an option out of range and a missing colmap fail with their ids; no frames folder is
#    refused by the argument check.
foreach(case "option.range;--min-mask-area;1.5" "option.range;--masked-fallback-after;-1" "option.range;--join-tail;-1"
             "colmap.missing;--colmap;${WORK_DIR}/no_such_colmap")
  list(GET case 0 id)
  list(SUBLIST case 1 -1 args)
  expect_error(${id} sfm --frames "${video}/frames" --masks "${video}/masks" --out "${WORK_DIR}/bad" --threads 2 ${args})
endforeach()
execute_process(COMMAND "${CLI}" sfm --frames "${WORK_DIR}/no_such_folder" --out "${WORK_DIR}/bad" RESULT_VARIABLE rc ERROR_VARIABLE e)
if(rc EQUAL 0)
  message(FATAL_ERROR "sfm accepted a missing --frames folder")
endif()

file(REMOVE_RECURSE "${WORK_DIR}")
