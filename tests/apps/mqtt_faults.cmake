# A real Mosquitto broker (stopped and restarted by the test), two errsep-devsim + errsep-daemon
# pairs on loopback (~20 s).  Skipped (SKIPPED:) where mosquitto, its clients, openssl or
# python3-jsonschema are missing.
add_dependencies(${test_target} errsep-daemon errsep-devsim)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/mqtt_faults: "
                     PROPERTIES TIMEOUT 240 LABELS apps EXTRA_LABEL mqtt SKIP_REGULAR_EXPRESSION "SKIPPED:")
