# Measure - compensate - verify end to end: errsep-scan, errsep-report and errsep-devsim on an
# ephemeral loopback port, all started by the test.  The apps must be built first.
add_dependencies(${test_target} errsep-scan errsep-devsim errsep-report)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/verify_app: "
                     PROPERTIES TIMEOUT 180 LABELS apps EXTRA_LABEL modbus)
