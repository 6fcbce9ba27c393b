# errsep-refine runs as a user would run it: build it with the test.
add_dependencies(${test_target} errsep-refine)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/refine_app: "
                     PROPERTIES TIMEOUT 120 LABELS apps)
