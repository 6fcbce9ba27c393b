# Starts errsep-devsim and errsep-daemon: build them with the test.
add_dependencies(${test_target} errsep-daemon errsep-devsim)
catch_discover_tests(${test_target} TEST_PREFIX "apps/daemon_disk: "
                     PROPERTIES TIMEOUT 90 LABELS apps SKIP_REGULAR_EXPRESSION "SKIPPED:")
