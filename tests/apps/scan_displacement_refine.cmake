# errsep-scan --method displacement --refine against the device simulator it starts itself, then
# errsep-report on its folder: build them with the test.
add_dependencies(${test_target} errsep-scan errsep-devsim errsep-report errsep-separate-displacement)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX
                     "apps/scan_displacement_refine: " PROPERTIES TIMEOUT 120 LABELS apps EXTRA_LABEL modbus)
