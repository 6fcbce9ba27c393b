add_dependencies(${test_target} errsep-daemon)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/daemon_unit: "
                     PROPERTIES TIMEOUT 60 LABELS apps SKIP_REGULAR_EXPRESSION "SKIPPED:")
