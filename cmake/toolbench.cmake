# Shared settings for project targets.

if(TOOLBENCH_SANITIZE)
  # UBSan without the checks that cost most to compile in template-heavy code (Eigen, CGAL, PCL)
  # and that ASan or x86 already cover: null (ASan reports the SEGV), object-size (ASan's bounds),
  # alignment, pointer-overflow and vptr. With them control/skills.cpp took 115 s to compile at
  # -O1 instead of 47 s (release: 36 s), and the sanitizer stage ran past CI's 90 minutes.
  # -O1 with line tables (-g1), after and so over the build type's flags: -O2 -g doubled the
  # compile time for nothing a sanitizer's stack trace needs (use RelWithDebInfo, not Debug:
  # CGAL's debug-mode checks make the generator tests 20x slower).
  add_compile_options(-O1 -g1
                      -fsanitize=address,undefined -fno-sanitize=vptr,alignment,null,pointer-overflow,object-size
                      -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
  add_link_options(-fsanitize=address,undefined)
  # Under ASan, Eigen stops trusting glibc's 16-byte malloc alignment and switches to its own
  # aligned allocator, while Debian's PCL (built without ASan) keeps plain malloc: a PCL cloud
  # allocated in libpcl and freed in our code then reads a header that is not there. ASan's
  # malloc is 16-byte aligned on x86_64 too, so keep Eigen's normal (ABI-compatible) setting.
  add_compile_definitions(EIGEN_MALLOC_ALREADY_ALIGNED=1)
endif()

# toolbench_target_defaults(<target>): warnings and include root for a project target.
function(toolbench_target_defaults target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic)
  if(TOOLBENCH_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()

# toolbench_add_test(<name> LABEL <label> [COST <seconds>] SOURCES <files...> LIBS <libs...>)
# COST: the expected run time of each discovered test. CTest starts the costliest tests first;
# on a fresh clone it has no timings of its own, and a long test started last leaves a core idle.
function(toolbench_add_test name)
  cmake_parse_arguments(T "" "LABEL;COST" "SOURCES;LIBS" ${ARGN})
  if(NOT T_COST)
    set(T_COST 0)
  endif()
  add_executable(${name} ${T_SOURCES})
  toolbench_target_defaults(${name})
  target_link_libraries(${name} PRIVATE ${T_LIBS} GTest::gmock GTest::gtest_main)
  gtest_discover_tests(${name} PROPERTIES LABELS ${T_LABEL} COST ${T_COST} DISCOVERY_TIMEOUT 60)
endfunction()
