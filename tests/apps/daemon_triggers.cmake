# In-process daemon tests (GPIO start input, schedule, straightness).  The real-chip case is its
# own ctest entry with SKIP_RETURN_CODE 77: without /dev/gpiochip* (or without a simulated chip
# that can make an edge) it exits 77 with the reason, so ctest reports it skipped, not passed.
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_SPEC "~[gpiochip]" TEST_PREFIX "apps/daemon_triggers: "
                     PROPERTIES TIMEOUT 60 LABELS apps)
add_test(NAME "apps/daemon_triggers: GPIO start input on a real gpiochip"
         COMMAND ${test_target} "[gpiochip]" --warn NoTests)
set_tests_properties("apps/daemon_triggers: GPIO start input on a real gpiochip"
                     PROPERTIES SKIP_RETURN_CODE 77 TIMEOUT 60 LABELS apps)
