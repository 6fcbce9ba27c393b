# Install-time script (install(SCRIPT) in apps/daemon/CMakeLists.txt): installs
# config/errsep.service into <prefix>/lib/systemd/system with ExecStart= and the documentation
# path pointing where THIS install puts the binary and the example configs, so the installed unit
# always starts the installed daemon (config/errsep.service names the default /usr/local layout).
# ERRSEP_UNIT_IN, ERRSEP_BINDIR and ERRSEP_DATADIR are set by the install(CODE) before it;
# CMAKE_INSTALL_PREFIX is the prefix of this install (cmake --install --prefix included).
foreach(_v ERRSEP_UNIT_IN ERRSEP_BINDIR ERRSEP_DATADIR)
  if(NOT DEFINED ${_v})
    message(FATAL_ERROR "install_unit.cmake: ${_v} not set")
  endif()
endforeach()
if(IS_ABSOLUTE "${ERRSEP_BINDIR}")
  set(_bin "${ERRSEP_BINDIR}")
else()
  set(_bin "${CMAKE_INSTALL_PREFIX}/${ERRSEP_BINDIR}")
endif()
if(IS_ABSOLUTE "${ERRSEP_DATADIR}")
  set(_data "${ERRSEP_DATADIR}")
else()
  set(_data "${CMAKE_INSTALL_PREFIX}/${ERRSEP_DATADIR}")
endif()

file(READ "${ERRSEP_UNIT_IN}" _unit)
string(FIND "${_unit}" "ExecStart=/usr/local/bin/errsep-daemon " _at)
if(_at LESS 0)
  message(FATAL_ERROR "${ERRSEP_UNIT_IN}: no 'ExecStart=/usr/local/bin/errsep-daemon ' line to "
                      "point at the installed binary")
endif()
# Unit-file syntax (systemd.service(5), systemd.unit(5)): '%' starts a specifier ('%%' is a
# literal '%'); a command path with white space must be quoted; Documentation= is a URI (spaces
# percent-encoded, then '%' doubled as above).
string(REPLACE "%" "%%" _exec "${_bin}/errsep-daemon")
if(_exec MATCHES "[ \t]")
  set(_exec "\"${_exec}\"")
endif()
string(REPLACE "%" "%25" _doc "${_data}/errsep/")
string(REPLACE " " "%20" _doc "${_doc}")
string(REPLACE "%" "%%" _doc "${_doc}")
string(REPLACE "ExecStart=/usr/local/bin/errsep-daemon " "ExecStart=${_exec} " _unit "${_unit}")
string(REPLACE "Documentation=file:/usr/local/share/errsep/" "Documentation=file:${_doc}" _unit
               "${_unit}")
# The comments (install instructions) name the plain paths.
string(REPLACE "/usr/local/bin/errsep-daemon" "${_bin}/errsep-daemon" _unit "${_unit}")
string(REPLACE "/usr/local/share/errsep/" "${_data}/errsep/" _unit "${_unit}")

# lib/systemd/system under the prefix (not CMAKE_INSTALL_LIBDIR, which is lib/<multiarch> on
# Debian): /usr/local/lib/systemd/system and /usr/lib/systemd/system are systemd's unit paths.
set(_dest "$ENV{DESTDIR}${CMAKE_INSTALL_PREFIX}/lib/systemd/system")
file(MAKE_DIRECTORY "${_dest}")
file(WRITE "${_dest}/errsep.service" "${_unit}")
message(STATUS "Installing: ${_dest}/errsep.service (ExecStart=${_bin}/errsep-daemon)")
list(APPEND CMAKE_INSTALL_MANIFEST_FILES "${_dest}/errsep.service")
