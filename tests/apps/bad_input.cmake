# Runs every app that reads raw scans on impossible values: build them with the test.
add_dependencies(${test_target} errsep-separate errsep-refine errsep-report
                 errsep-separate-displacement)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/bad_input: "
                     PROPERTIES TIMEOUT 120 LABELS apps)
