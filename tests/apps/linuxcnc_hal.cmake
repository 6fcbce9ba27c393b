# errsep's LinuxCNC HAL file in the real LinuxCNC (headless, started by the test itself).  Where
# LinuxCNC is absent the test prints "SKIPPED: ..." and ctest reports it skipped, never passed.
# One LinuxCNC (one HAL) per machine at a time, and its 1 kHz servo thread and task loop on a
# non-realtime kernel must not starve the timing-sensitive tests that would run beside it:
# RUN_SERIAL (about 15 s alone).
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "apps/linuxcnc_hal: "
                     PROPERTIES TIMEOUT 300 LABELS apps SKIP_REGULAR_EXPRESSION "SKIPPED:"
                                RUN_SERIAL TRUE)
