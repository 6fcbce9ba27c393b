# errsep-scan --refine against the device simulator (both started by the test, ephemeral loopback
# port), compared with errsep-refine on the same raw file.
add_dependencies(${test_target} errsep-scan errsep-devsim errsep-refine)
catch_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/scan_refine: "
                     PROPERTIES TIMEOUT 120 LABELS "apps;modbus")
