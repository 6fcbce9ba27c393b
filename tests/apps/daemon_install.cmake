# `cmake --install` into a temporary prefix: needs every installed target built first.
get_property(_install_apps GLOBAL PROPERTY ERRSEP_APPS)
add_dependencies(${test_target} ${_install_apps})
string(REPLACE ";" "," _install_apps_csv "${_install_apps}")
target_compile_definitions(${test_target} PRIVATE
  ERRSEP_CMAKE_COMMAND="${CMAKE_COMMAND}"
  ERRSEP_INSTALLED_APPS="${_install_apps_csv}"
  ERRSEP_INSTALL_BINDIR="${CMAKE_INSTALL_BINDIR}"
  ERRSEP_INSTALL_DATADIR="${CMAKE_INSTALL_DATADIR}")
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/daemon_install: "
                     PROPERTIES TIMEOUT 120 LABELS apps SKIP_REGULAR_EXPRESSION "SKIPPED:")
