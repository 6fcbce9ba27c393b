# A real Mosquitto broker on loopback, SIGSTOPped for a moment (~5 s).  Skipped (SKIPPED:) where
# mosquitto, its clients, openssl or python3-jsonschema are missing.
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "service/plant_publisher: "
                     PROPERTIES TIMEOUT 120 LABELS service EXTRA_LABEL mqtt SKIP_REGULAR_EXPRESSION "SKIPPED:")
