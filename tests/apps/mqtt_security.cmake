# A real Mosquitto broker (with a TLS listener), one errsep-devsim + errsep-daemon
# pair on loopback (~10 s).  Skipped (SKIPPED:) where mosquitto, its clients, openssl or
# python3-jsonschema are missing.
add_dependencies(${test_target} errsep-daemon errsep-devsim)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/mqtt_security: "
                     PROPERTIES TIMEOUT 240 LABELS apps EXTRA_LABEL mqtt SKIP_REGULAR_EXPRESSION "SKIPPED:")
