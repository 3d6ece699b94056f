# Sanitizer and fuzzing builds (issue 12), switched on by two cache options:
#
#   LOOPSFM_SANITIZE=ON  AddressSanitizer + UndefinedBehaviorSanitizer for everything built
#                        (library, tests, tools), with gcc or clang. A UB finding halts the
#                        program (-fno-sanitize-recover), so it fails the test that hit it.
#   LOOPSFM_FUZZ=ON      clang only: the readers' fuzz targets in tests/fuzz become libFuzzer
#                        binaries (label `fuzz`); everything else is compiled with the
#                        fuzzer's coverage instrumentation and ASan + UBSan.
#
# Without either, tests/fuzz links each target with a replay main that runs the committed
# corpus (label `unit`). Use a build folder of its own for each: build-sanitize, build-fuzz.

option(LOOPSFM_SANITIZE "Build with AddressSanitizer and UndefinedBehaviorSanitizer" OFF)
option(LOOPSFM_FUZZ "Build the tests/fuzz targets as libFuzzer binaries (clang only)" OFF)
set(LOOPSFM_FUZZ_SECONDS 60 CACHE STRING
    "How long each libFuzzer target runs under ctest -L fuzz (-max_total_time)")

set(loopsfm_sanitizers "")
if(LOOPSFM_SANITIZE OR LOOPSFM_FUZZ)
  set(loopsfm_sanitizers address,undefined)
endif()

if(LOOPSFM_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "LOOPSFM_FUZZ needs clang (libFuzzer); configure with "
                        "-DCMAKE_CXX_COMPILER=clang++")
  endif()
  # Coverage for the fuzzer everywhere; only the fuzz targets link libFuzzer's main.
  add_compile_options(-fsanitize=fuzzer-no-link)
endif()

if(loopsfm_sanitizers)
  # For the whole suite, line tables (-g1) are enough for the reports' stack traces and
  # compile much faster; the few fuzzed modules get full debug information.
  set(debug_info -g1)
  if(LOOPSFM_FUZZ)
    set(debug_info -g)
  endif()
  add_compile_options(-fsanitize=${loopsfm_sanitizers} -fno-sanitize-recover=undefined
                      -fno-omit-frame-pointer ${debug_info})
  add_link_options(-fsanitize=${loopsfm_sanitizers} -fno-sanitize-recover=undefined)
endif()
if(LOOPSFM_SANITIZE AND NOT LOOPSFM_FUZZ)
  # -O1 (ASan's recommendation) after the build type's -O3: the whole suite compiles in a
  # fraction of the time and still runs fast enough.
  add_compile_options(-O1)
endif()
