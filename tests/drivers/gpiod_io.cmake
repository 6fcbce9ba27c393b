# libgpiod driver tests.  The real-chip case is its own ctest entry with SKIP_RETURN_CODE 77: on a
# machine without /dev/gpiochip* it exits 77 with the reason, so ctest reports it skipped.
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_SPEC "~[gpiochip]" TEST_PREFIX "drivers/gpiod_io: "
                     PROPERTIES TIMEOUT 60 LABELS drivers)
add_test(NAME "drivers/gpiod_io: a real gpiochip opens and reports its lines"
         COMMAND ${test_target} "[gpiochip]" --warn NoTests)
set_tests_properties("drivers/gpiod_io: a real gpiochip opens and reports its lines"
                     PROPERTIES SKIP_RETURN_CODE 77 TIMEOUT 60 LABELS drivers)
