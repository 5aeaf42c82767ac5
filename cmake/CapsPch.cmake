# Precompiled headers for the test programs (docs/benchmarks.md, "Build and test time").
# Every test program is one source that parses GoogleTest, Eigen and a dozen standard headers
# before its own code: about 2 s of CPU each with GCC 12. With CAPS_PCH those headers
# are compiled once into a precompiled header that the test programs reuse (REUSE_FROM), in two
# flavours, as a precompiled header is only valid for the same macro definitions:
#   caps_test_pch       GoogleTest, Eigen, the standard library (the module tests);
#   caps_test_pch_json  the same and nlohmann/json with JSON_DIAGNOSTICS=1 (the app, cli and
#                       server tests, which link nlohmann_json::nlohmann_json).
# The code compiled is the same: the headers are the ones each test includes itself (a test
# still includes what it uses; CAPS_PCH=OFF checks that). The precompiled header comes before a
# test's first line, so a test must not define a macro meant to change those headers (none
# does). ccache caches the precompiled header and the sources that use it only with the
# sloppiness pch_defines,time_macros (its manual, "Precompiled headers"; without it they are
# "uncacheable"): caps_test_pch_launcher gives these targets a launcher that sets it when the
# build's launcher is ccache.
option(CAPS_PCH "Precompiled GoogleTest/Eigen/json headers for the test programs" ON)

set(CAPS_TEST_PCH_HEADERS
  <gtest/gtest.h> <Eigen/Dense> <Eigen/Geometry>
  <algorithm> <array> <cmath> <cstdio> <cstdlib> <cstring> <filesystem> <fstream>
  <functional> <map> <memory> <random> <set> <sstream> <string> <vector>)

# caps_test_pch_target(<name> <like> [JSON]): a program of its own (so that its compile options,
# -fPIE among them, are the test programs'; its main is GoogleTest's) whose precompiled header the
# test programs reuse. It takes the compile definitions of the test program <like>: a precompiled
# header is rejected by GCC, and refused by clang, when a macro it saw differs.
function(caps_test_pch_target name like)
  set(src ${CMAKE_CURRENT_BINARY_DIR}/${name}.cpp)
  if(NOT EXISTS ${src})
    file(WRITE ${src} "// the precompiled header's own program (its main is GoogleTest's)\n")
  endif()
  add_executable(${name} ${src})
  get_target_property(defs ${like} COMPILE_DEFINITIONS)
  if(defs)
    target_compile_definitions(${name} PRIVATE ${defs})
  endif()
  target_link_libraries(${name} PRIVATE GTest::gtest_main Eigen3::Eigen)
  set(headers ${CAPS_TEST_PCH_HEADERS})
  if(ARGN STREQUAL "JSON")
    target_link_libraries(${name} PRIVATE nlohmann_json::nlohmann_json)
    list(APPEND headers <nlohmann/json.hpp>)
  endif()
  target_precompile_headers(${name} PRIVATE ${headers})
endfunction()

# caps_test_pch_launcher(<targets>): with ccache as the compiler launcher, compile <targets>
# through `env CCACHE_SLOPPINESS=pch_defines,time_macros ccache`.
function(caps_test_pch_launcher)
  if(CMAKE_CXX_COMPILER_LAUNCHER MATCHES "(^|/)ccache$")
    set_target_properties(${ARGN} PROPERTIES CXX_COMPILER_LAUNCHER
      "env;CCACHE_SLOPPINESS=pch_defines,time_macros;${CMAKE_CXX_COMPILER_LAUNCHER}")
  endif()
endfunction()
