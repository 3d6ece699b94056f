# loopsfm_add_module(NAME SOURCES ... DEPS ...)
#   One static library per module under src/loopsfm/NAME, linked as loopsfm::NAME.
#   DEPS names lower-layer modules (loopsfm_<dep>) or external targets.
function(loopsfm_add_module name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  set(target loopsfm_${name})
  add_library(${target} STATIC ${ARG_SOURCES})
  target_include_directories(${target} PUBLIC ${PROJECT_SOURCE_DIR}/src)
  target_link_libraries(${target} PUBLIC ${ARG_DEPS})
  add_library(loopsfm::${name} ALIAS ${target})
endfunction()

# loopsfm_add_test(NAME SOURCES ... DEPS ... [LABELS unit|e2e] [TIMEOUT s])
#   A GoogleTest executable registered with ctest; label defaults to "unit".
function(loopsfm_add_test name)
  if(NOT LOOPSFM_BUILD_TESTS)
    return()
  endif()
  cmake_parse_arguments(ARG "" "TIMEOUT" "SOURCES;DEPS;LABELS" ${ARGN})
  if(NOT ARG_LABELS)
    set(ARG_LABELS unit)
  endif()
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 600)
  endif()
  if(LOOPSFM_SANITIZE)
    # ASan + UBSan at -O1 run the mapper tests several times slower.
    math(EXPR ARG_TIMEOUT "${ARG_TIMEOUT} * 5")
  endif()
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main)
  target_compile_definitions(${name} PRIVATE
    LOOPSFM_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    LOOPSFM_BINARY_DIR="${PROJECT_BINARY_DIR}")
  add_test(NAME ${name} COMMAND ${name})
  set_tests_properties(${name} PROPERTIES LABELS "${ARG_LABELS}" TIMEOUT ${ARG_TIMEOUT}
    WORKING_DIRECTORY ${PROJECT_BINARY_DIR})
endfunction()

# loopsfm_link_allocator(TARGET)
#   Links TARGET with the allocator the build chose (CMakeLists.txt: mimalloc, or none) and
#   defines LOOPSFM_WITH_MIMALLOC for its sources. Linked ahead of libc, mimalloc's malloc and
#   free serve the whole process (Ceres, OpenCV, TBB), even where TARGET calls none of its
#   functions, so the link must not be dropped as unneeded.
function(loopsfm_link_allocator target)
  if(loopsfm_allocator STREQUAL "mimalloc")
    target_link_libraries(${target} PRIVATE -Wl,--push-state,--no-as-needed mimalloc
                          -Wl,--pop-state)
    target_compile_definitions(${target} PRIVATE LOOPSFM_WITH_MIMALLOC)
  endif()
endfunction()
