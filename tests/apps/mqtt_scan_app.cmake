# A real Mosquitto broker (stopped and restarted by the test), errsep-scan three times on its embedded
# simulator (~10 s).  Skipped (SKIPPED:) where mosquitto, its clients, openssl or
# python3-jsonschema are missing.
add_dependencies(${test_target} errsep-scan errsep-devsim)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/mqtt_scan_app: "
                     PROPERTIES TIMEOUT 240 LABELS apps EXTRA_LABEL mqtt SKIP_REGULAR_EXPRESSION "SKIPPED:")
