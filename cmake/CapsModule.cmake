# caps_add_module(<name> [DEPENDS <lower caps modules>] [SOURCES <files>] [LIBS <third-party targets>])
# Builds the library caps::<name>. A dependency must be a lower layer that was already added,
# so the module graph cannot contain a cycle (the order is CAPS_MODULES in the top CMakeLists).
# Its sources and headers may include only caps/<m>/ of itself and of the modules it depends on,
# directly or through them (caps_check_includes, cmake/CapsLayering.cmake): checked here, at
# configure time.
include(${CMAKE_CURRENT_LIST_DIR}/CapsLayering.cmake)
function(caps_add_module name)
  cmake_parse_arguments(ARG "" "" "DEPENDS;SOURCES;LIBS" ${ARGN})
  add_library(caps_${name} ${ARG_SOURCES})
  add_library(caps::${name} ALIAS caps_${name})
  target_include_directories(caps_${name} PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include)
  target_compile_options(caps_${name} PRIVATE -Wall -Wextra)
  # The sanitized fuzzing tree (CAPS_FUZZ) compiles the modules that no fuzz target reads its
  # input through and no sanitized test program runs (CAPS_UNSANITIZED_MODULES) without
  # sanitizers or coverage: fuzz_request and fuzz_server link them only because caps::app does,
  # and they compile in less than half the time (docs/reliability.md, "CI time").
  if(CAPS_FUZZ AND name IN_LIST CAPS_UNSANITIZED_MODULES)
    target_compile_options(caps_${name} PRIVATE -fno-sanitize=all)
  endif()
  caps_unity_build(caps_${name})
  foreach(dep IN LISTS ARG_DEPENDS)
    if(NOT TARGET caps::${dep})
      message(FATAL_ERROR "${name} -> ${dep} is not a lower layer (add ${dep} before ${name})")
    endif()
    target_link_libraries(caps_${name} PUBLIC caps::${dep})
  endforeach()
  set(allowed ${name})
  foreach(dep IN LISTS ARG_DEPENDS)
    get_property(below GLOBAL PROPERTY CAPS_LAYERS_${dep})
    list(APPEND allowed ${dep} ${below})
  endforeach()
  list(REMOVE_DUPLICATES allowed)
  set_property(GLOBAL PROPERTY CAPS_LAYERS_${name} ${allowed})
  caps_check_includes(${name} "${CMAKE_CURRENT_SOURCE_DIR}" "${allowed}")
  if(ARG_LIBS)
    target_link_libraries(caps_${name} PRIVATE ${ARG_LIBS})
  endif()
endfunction()

# caps_unity_build(<target>): with CAPS_UNITY_BUILD, the target's sources are compiled
# CAPS_UNITY_BATCH_SIZE at a time as one translation unit, so the headers they share (Eigen,
# nlohmann/json, the caps headers) are parsed, and their inline functions optimized, once per
# batch instead of once per file (docs/reliability.md, "CI time").
function(caps_unity_build target)
  if(CAPS_UNITY_BUILD)
    set_target_properties(${target} PROPERTIES UNITY_BUILD ON
                          UNITY_BUILD_BATCH_SIZE ${CAPS_UNITY_BATCH_SIZE})
  endif()
endfunction()
