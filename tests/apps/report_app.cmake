# errsep-report tests.  The Chromium render is its own ctest entry with SKIP_RETURN_CODE 77, so a
# machine without /usr/bin/chromium reports it as skipped (with the reason in its output).
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_SPEC "~[chromium]" TEST_PREFIX "apps/report_app: "
                     PROPERTIES TIMEOUT 120 LABELS apps)
add_test(NAME "apps/report_app: report of the simulated demo scan renders in headless Chromium"
         COMMAND ${test_target} "[chromium]" --warn NoTests)
set_tests_properties("apps/report_app: report of the simulated demo scan renders in headless Chromium"
                     PROPERTIES SKIP_RETURN_CODE 77 TIMEOUT 180 LABELS apps)
