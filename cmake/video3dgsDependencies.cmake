# Finds what video3dgs::video3dgs links to. Used by the build tree and by the installed package config,
# so both see the same targets. Every dependency is looked up only if the consumer has not made it yet.
include(CMakeFindDependencyMacro)
if(NOT TARGET Eigen3::Eigen)
  find_dependency(Eigen3 3.3 NO_MODULE)
endif()
if(NOT TARGET Threads::Threads)
  set(THREADS_PREFER_PTHREAD_FLAG ON)
  find_dependency(Threads)
endif()
# stb_image: Debian's libstb-dev ships the headers under <prefix>/include/stb and the compiled
# implementations in libstb.a, so including our I/O headers never duplicates stb symbols.
if(NOT TARGET video3dgs::stb)
  find_path(VIDEO3DGS_STB_INCLUDE_DIR stb_image.h PATH_SUFFIXES stb)
  find_library(VIDEO3DGS_STB_LIBRARY NAMES stb)
  if(NOT VIDEO3DGS_STB_INCLUDE_DIR OR NOT VIDEO3DGS_STB_LIBRARY)
    message(FATAL_ERROR "video3dgs needs stb_image (headers and libstb): apt-get install libstb-dev")
  endif()
  add_library(video3dgs::stb UNKNOWN IMPORTED GLOBAL)
  set_target_properties(video3dgs::stb PROPERTIES
    IMPORTED_LOCATION "${VIDEO3DGS_STB_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${VIDEO3DGS_STB_INCLUDE_DIR}")
endif()
# libpng decodes every PNG (it returns the raw indices of palette PNGs, which stb_image cannot) and
# libjpeg every JPEG (stb_image's decoders are not meant for untrusted files);
# nlohmann/json writes the reports and state files.
if(NOT TARGET PNG::PNG)
  find_dependency(PNG)
endif()
if(NOT TARGET JPEG::JPEG)
  find_dependency(JPEG)
endif()
# zlib deflates the parts of compact model files (model/compact_io.hpp).
if(NOT TARGET ZLIB::ZLIB)
  find_dependency(ZLIB)
endif()
if(NOT TARGET nlohmann_json::nlohmann_json)
  find_dependency(nlohmann_json 3)
endif()
# SQLite reads and updates COLMAP databases (the colmap adapter's exact matcher, video3dgs::colmap).
if(NOT TARGET SQLite::SQLite3)
  find_dependency(SQLite3)
endif()
