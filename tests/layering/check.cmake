# cmake -DMODULE=fem -DDIR=<module folder> -DALLOWED=fem,core [-DINJECT=<header>] -DWORK=<dir>
#   -P check.cmake
# Runs the configure-time layering check on a module's folder. With INJECT, the folder is copied
# to WORK first and one source that includes caps/<INJECT> is added (the check must refuse it).
cmake_minimum_required(VERSION 3.20)
include(${CMAKE_CURRENT_LIST_DIR}/../../cmake/CapsLayering.cmake)
string(REPLACE "," ";" ALLOWED "${ALLOWED}")
if(INJECT)
  file(REMOVE_RECURSE "${WORK}/${MODULE}")
  file(COPY "${DIR}/" DESTINATION "${WORK}/${MODULE}")
  file(WRITE "${WORK}/${MODULE}/src/reaches_up.cpp" "#include \"caps/${INJECT}\"\n")
  set(DIR "${WORK}/${MODULE}")
endif()
caps_check_includes(${MODULE} "${DIR}" "${ALLOWED}")
message(STATUS "layering: ${MODULE} includes only ${ALLOWED}")
