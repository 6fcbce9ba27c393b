# The fault tests run the simulator in-process; one of them also starts build/apps/errsep-devsim.
add_dependencies(${test_target} errsep-devsim)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "drivers/modbus_faults: "
                     PROPERTIES TIMEOUT 60 LABELS drivers)
