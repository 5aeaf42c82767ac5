# caps_check_includes(<module> <dir> <allowed modules>): every `#include "caps/<m>/..."` in the
# module's sources and public headers must name a module in <allowed> (the module itself and
# every module below it in its DEPENDS, transitively). A configure-time error names the file,
# the line and what the module may use, so a layer cannot reach up (the FE core cannot include
# a plan) even where an include directory happens to be on the compiler's path.
function(caps_check_includes module dir allowed)
  file(GLOB_RECURSE files "${dir}/src/*.cpp" "${dir}/src/*.hpp" "${dir}/src/*.h"
                          "${dir}/include/*.hpp" "${dir}/include/*.h")
  list(SORT files)
  foreach(f IN LISTS files)
    file(STRINGS "${f}" lines REGEX "^[ \t]*#[ \t]*include[ \t]*[<\"]caps/[a-z_0-9]+/")
    foreach(line IN LISTS lines)
      string(REGEX MATCH "caps/([a-z_0-9]+)/" _ "${line}")
      if(NOT CMAKE_MATCH_1 IN_LIST allowed)
        string(STRIP "${line}" line)
        string(REPLACE ";" ", " may "${allowed}")
        message(FATAL_ERROR "layering: ${f}: '${line}': ${module} may include only caps/{${may}}/ "
                            "(a module uses only the layers below it; move the code up, or the "
                            "shared piece down)")
      endif()
    endforeach()
  endforeach()
endfunction()
