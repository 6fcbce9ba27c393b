# Starts errsep-devsim and errsep-daemon: build them with the test.
add_dependencies(${test_target} errsep-daemon errsep-devsim)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/daemon_kill: "
                     PROPERTIES TIMEOUT 90 LABELS apps)
