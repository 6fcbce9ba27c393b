# errsep-scan --refine against the device simulator (both started by the test, ephemeral loopback
# port), compared with errsep-refine on the same raw file; the report errsep-scan makes after it.
# The PDF case needs Chromium and pdftoppm: its own ctest entry with SKIP_RETURN_CODE 77, so a
# machine without them reports it as skipped (with the reason in its output).
add_dependencies(${test_target} errsep-scan errsep-devsim errsep-refine errsep-report)
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_SPEC "~[chromium]" TEST_PREFIX "apps/scan_refine: "
                     PROPERTIES TIMEOUT 120 LABELS apps EXTRA_LABEL modbus)
add_test(NAME "apps/scan_refine: the scan's report.pdf renders to a page that is not blank"
         COMMAND ${test_target} "[chromium]" --warn NoTests)
set_tests_properties("apps/scan_refine: the scan's report.pdf renders to a page that is not blank"
                     PROPERTIES SKIP_RETURN_CODE 77 TIMEOUT 240 LABELS apps EXTRA_LABEL modbus)
