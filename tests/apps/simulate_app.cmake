# errsep-simulate run as a user would, its truth fed to errsep-refine, its displacement scan to
# errsep-separate-displacement (built with the test).
add_dependencies(${test_target} errsep-simulate errsep-refine errsep-separate-displacement)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/simulate_app: "
                     PROPERTIES TIMEOUT 120 LABELS apps)
