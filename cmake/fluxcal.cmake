# Small helpers shared by every folder.

# fluxcal_add_library(NAME SOURCES... DEPS ...)
#   Declares fluxcal_<NAME> with the project root as include directory, so
#   headers are included as "io/recording_set.h".
function(fluxcal_add_library name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_library(fluxcal_${name} STATIC ${ARG_SOURCES})
  target_include_directories(fluxcal_${name} PUBLIC ${PROJECT_SOURCE_DIR} ${PROJECT_BINARY_DIR})
  target_link_libraries(fluxcal_${name} PUBLIC ${ARG_DEPS})
endfunction()

# fluxcal_add_test(NAME SOURCES... DEPS ...)
#   One GoogleTest binary per library (tests/<lib>/), registered with ctest.
#   FLUXCAL_SOURCE_DIR and FLUXCAL_SHARED_DIR let tests find the repository
#   and the shared specs/examples beside it.
function(fluxcal_add_test name)
  cmake_parse_arguments(ARG "" "TIMEOUT" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main)
  target_compile_definitions(${name} PRIVATE
    FLUXCAL_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    FLUXCAL_SHARED_DIR="${PROJECT_SOURCE_DIR}/../shared")
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 600)
  endif()
  add_test(NAME ${name} COMMAND ${name})
  set_tests_properties(${name} PROPERTIES TIMEOUT ${ARG_TIMEOUT})
endfunction()
