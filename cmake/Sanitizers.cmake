# ERRSEP_SANITIZE=address,undefined  (or thread) instruments every target.
set(ERRSEP_SANITIZE "" CACHE STRING "Comma-separated sanitizers: address,undefined or thread")
if(ERRSEP_SANITIZE)
  string(REPLACE "," ";" _sans "${ERRSEP_SANITIZE}")
  foreach(_s IN LISTS _sans)
    if(NOT _s MATCHES "^(address|undefined|thread|leak)$")
      message(FATAL_ERROR "ERRSEP_SANITIZE: unknown sanitizer '${_s}'")
    endif()
  endforeach()
  # -O1 (after the build type's -O2, so it wins): the sanitizers' recommended level, and it compiles
  # the Eigen-heavy core about a third faster (displacement_refine.cpp: 116 s -> 77 s under ASan),
  # which CI's time limit needs more than the instrumented binaries' speed.
  add_compile_options(-O1 -fsanitize=${ERRSEP_SANITIZE} -fno-omit-frame-pointer -fno-sanitize-recover=all)
  add_link_options(-fsanitize=${ERRSEP_SANITIZE})
endif()
