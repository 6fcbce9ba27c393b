# errsep-scan end to end against the device simulator (both started by the test itself, on an
# ephemeral loopback port).  The apps must be built before the test runs.
add_dependencies(${test_target} errsep-scan errsep-devsim errsep-report)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/scan_end_to_end: "
                     PROPERTIES TIMEOUT 120 LABELS apps EXTRA_LABEL modbus)
