# errsep-simulate writes scan sequences with an injected drift; errsep-refine and errsep-report
# read them (all built with the test).
add_dependencies(${test_target} errsep-simulate errsep-refine errsep-report)
catch_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/sequence_app: "
                     PROPERTIES TIMEOUT 120 LABELS apps)
