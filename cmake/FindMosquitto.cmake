# FindMosquitto.cmake -- libmosquitto (MQTT client) through pkg-config; IMPORTED target
# Mosquitto::Mosquitto.
find_package(PkgConfig REQUIRED)
pkg_check_modules(PC_MOSQUITTO QUIET IMPORTED_TARGET libmosquitto)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(Mosquitto
  REQUIRED_VARS PC_MOSQUITTO_FOUND VERSION_VAR PC_MOSQUITTO_VERSION
  REASON_FAILURE_MESSAGE "install Debian's libmosquitto-dev")
if(Mosquitto_FOUND AND NOT TARGET Mosquitto::Mosquitto)
  add_library(Mosquitto::Mosquitto INTERFACE IMPORTED)
  target_link_libraries(Mosquitto::Mosquitto INTERFACE PkgConfig::PC_MOSQUITTO)
endif()
