# The app tests run the executables: build them with the test.
add_dependencies(${test_target} errsep-separate)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/separate_app: "
                     PROPERTIES TIMEOUT 120 LABELS apps)
