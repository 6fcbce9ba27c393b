# The app tests run the executables: build them with the test.
add_dependencies(${test_target} errsep-separate-displacement errsep-budget)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/displacement_app: "
                     PROPERTIES TIMEOUT 120 LABELS apps)
