# The ENOSPC case mounts a tmpfs in a user+mount namespace; where it cannot, it says SKIPPED.
errsep_discover_tests(${test_target} EXTRA_ARGS --warn NoTests TEST_PREFIX "io/atomic_file: "
                     PROPERTIES TIMEOUT 60 LABELS io SKIP_REGULAR_EXPRESSION "SKIPPED:")
