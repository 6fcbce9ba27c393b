# A Modbus TCP server not written here (python3-pymodbus), started before and stopped after the
# tests of ${test_target} by a ctest fixture.  When pymodbus cannot be imported the start step
# still succeeds but writes "skip <reason>" to the port file; each test then prints
# "SKIPPED: ..." and ctest reports it as skipped (SKIP_REGULAR_EXPRESSION), never as passed.
set(_pm_dir "${CMAKE_CURRENT_BINARY_DIR}/pymodbus_server")
set(_pm_script "${PROJECT_SOURCE_DIR}/tests/support/pymodbus_server.py")
add_test(NAME "drivers/modbus_pymodbus: (start pymodbus server)"
         COMMAND /usr/bin/python3 "${_pm_script}" start --dir "${_pm_dir}")
add_test(NAME "drivers/modbus_pymodbus: (stop pymodbus server)"
         COMMAND /usr/bin/python3 "${_pm_script}" stop --dir "${_pm_dir}")
set_tests_properties("drivers/modbus_pymodbus: (start pymodbus server)" PROPERTIES
  FIXTURES_SETUP errsep_pymodbus_server TIMEOUT 30 LABELS drivers)
set_tests_properties("drivers/modbus_pymodbus: (stop pymodbus server)" PROPERTIES
  FIXTURES_CLEANUP errsep_pymodbus_server TIMEOUT 30 LABELS drivers)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "drivers/modbus_pymodbus: "
  PROPERTIES FIXTURES_REQUIRED errsep_pymodbus_server
             ENVIRONMENT "ERRSEP_PYMODBUS_DIR=${_pm_dir}"
             SKIP_REGULAR_EXPRESSION "SKIPPED:"
             TIMEOUT 60 LABELS drivers)
