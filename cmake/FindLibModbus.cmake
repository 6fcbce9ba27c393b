# FindLibModbus.cmake -- libmodbus through pkg-config; IMPORTED target LibModbus::LibModbus.
find_package(PkgConfig REQUIRED)
pkg_check_modules(PC_LIBMODBUS QUIET IMPORTED_TARGET libmodbus)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(LibModbus
  REQUIRED_VARS PC_LIBMODBUS_FOUND VERSION_VAR PC_LIBMODBUS_VERSION
  REASON_FAILURE_MESSAGE "install Debian's libmodbus-dev")
if(LibModbus_FOUND AND NOT TARGET LibModbus::LibModbus)
  add_library(LibModbus::LibModbus INTERFACE IMPORTED)
  target_link_libraries(LibModbus::LibModbus INTERFACE PkgConfig::PC_LIBMODBUS)
endif()
