# Starts errsep-devsim, errsep-daemon, errsep-scan and errsep-report: build them with the test.
add_dependencies(${test_target} errsep-daemon errsep-devsim errsep-scan errsep-report)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/daemon_displacement: "
                     PROPERTIES TIMEOUT 120 LABELS apps)
