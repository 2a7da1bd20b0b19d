/* core_main.c - runs the core's unit tests; exits 1 when one failed. */
#include <stdlib.h>

#include "core_check.h"

int check_failures;

void check_fail(const char *file, int line, const char *what, long long got, long long want) {
    check_failures++;
    fprintf(stderr, "%s:%d: FAILED %s (got %lld, want %lld)\n", file, line, what, got, want);
}

int main(void) {
    test_wire();
    test_protocol();
    test_rules();
    test_carrier();
    test_run();
    test_board_ranges();
    test_random();
    if (check_failures) {
        fprintf(stderr, "core tests: %d checks FAILED\n", check_failures);
        return EXIT_FAILURE;
    }
    printf("core tests: all passed\n");
    return EXIT_SUCCESS;
}
