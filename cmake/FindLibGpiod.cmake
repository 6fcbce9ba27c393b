# FindLibGpiod.cmake -- libgpiod 1.6 (C API) through pkg-config; IMPORTED target LibGpiod::LibGpiod.
find_package(PkgConfig REQUIRED)
pkg_check_modules(PC_LIBGPIOD QUIET IMPORTED_TARGET libgpiod)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(LibGpiod
  REQUIRED_VARS PC_LIBGPIOD_FOUND VERSION_VAR PC_LIBGPIOD_VERSION
  REASON_FAILURE_MESSAGE "install Debian's libgpiod-dev")
if(LibGpiod_FOUND AND NOT TARGET LibGpiod::LibGpiod)
  add_library(LibGpiod::LibGpiod INTERFACE IMPORTED)
  target_link_libraries(LibGpiod::LibGpiod INTERFACE PkgConfig::PC_LIBGPIOD)
endif()
