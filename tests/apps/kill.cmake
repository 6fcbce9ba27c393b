# Kills errsep-scan (which starts errsep-devsim) and errsep-daemon: build them with the test.
add_dependencies(${test_target} errsep-scan errsep-devsim errsep-daemon)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/kill: "
                     PROPERTIES TIMEOUT 150 LABELS apps)
