# The app tests run the executable: build it with the test.  The figure case prints "SKIPPED: ..."
# when gnuplot is missing, and ctest reports it as skipped (SKIP_REGULAR_EXPRESSION).
add_dependencies(${test_target} errsep-plan)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/plan_app: "
                     PROPERTIES TIMEOUT 300 LABELS apps SKIP_REGULAR_EXPRESSION "SKIPPED:")
