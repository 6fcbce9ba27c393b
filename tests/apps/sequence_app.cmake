# errsep-simulate and errsep-scan (against errsep-devsim, started by the test on an ephemeral
# loopback port) write scan sequences with an injected drift; errsep-refine, errsep-scan --refine
# and errsep-report find and print it (all built with the test).
add_dependencies(${test_target} errsep-simulate errsep-separate errsep-refine errsep-report errsep-scan
                 errsep-devsim)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/sequence_app: "
                     PROPERTIES TIMEOUT 180 LABELS apps EXTRA_LABEL modbus)
