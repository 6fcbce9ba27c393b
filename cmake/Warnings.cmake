# Warnings live in an INTERFACE target that every errsep target links privately.
# -Werror is switched on by CI (ERRSEP_WERROR=ON), never hard-coded.
add_library(errsep_warnings INTERFACE)
target_compile_options(errsep_warnings INTERFACE -Wall -Wextra -Wpedantic -Wshadow
                       -Wnon-virtual-dtor -Wcast-align)
if(ERRSEP_WERROR)
  target_compile_options(errsep_warnings INTERFACE -Werror)
endif()
