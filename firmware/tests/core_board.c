/* core_board.c - amp_init against hal.h's ranges: every limit of every constant, each side of it, and
 * what a refused board does (answers, makes no output). */
#include <string.h>

#include "core_check.h"

static session_t s;

typedef struct {
    const char *what;
    hal_board_t board;
    int want; /* amp_init's answer */
} board_case_t;

/* test_board's figures, carriers from 1 kHz (the 16 kHz rate's are below 8 kHz). */
#define BOARD(rate, full, max, low, high, measures, uv, na) \
    { "case", rate, full, max, low, high, 2000u, measures, uv, na }

static const board_case_t cases[] = {
    { "rate 0 (protocol only)", BOARD(0u, 125000u, 100000u, 1000000u, 80000000u, 0u, 0u, 0u), AMP_BOARD_OK },
    { "rate 16000", BOARD(16000u, 125000u, 100000u, 1000000u, 7000000u, 7u, 1u, 1u), AMP_BOARD_OK },
    { "rate 192000", BOARD(192000u, 125000u, 100000u, 1000000u, 80000000u, 7u, 1u, 1u), AMP_BOARD_OK },
    { "rate 400000", BOARD(400000u, 125000u, 100000u, 1000000u, 80000000u, 7u, 1u, 1u), AMP_BOARD_OK },
    { "rate at its most", BOARD(AMP_MAX_OUTPUT_RATE_HZ, 125000u, 100000u, 1000000u, 80000000u, 7u, 1u, 1u),
      AMP_BOARD_OK },
    { "rate 8000", BOARD(8000u, 125000u, 100000u, 1000000u, 3000000u, 0u, 0u, 0u), AMP_BOARD_OUTPUT_RATE },
    { "rate 200000 (of 8000, not 16000)", BOARD(200000u, 125000u, 100000u, 1000000u, 80000000u, 0u, 0u, 0u),
      AMP_BOARD_OUTPUT_RATE },
    { "rate 192001", BOARD(192001u, 125000u, 100000u, 1000000u, 80000000u, 0u, 0u, 0u), AMP_BOARD_OUTPUT_RATE },
    { "rate one step past its most", BOARD(AMP_MAX_OUTPUT_RATE_HZ + 16000u, 125000u, 100000u, 1000000u, 80000000u,
      0u, 0u, 0u), AMP_BOARD_OUTPUT_RATE },
    { "rate 4294960000 (of 16000)", BOARD(4294960000u, 125000u, 100000u, 1000000u, 80000000u, 0u, 0u, 0u),
      AMP_BOARD_OUTPUT_RATE },
    { "full scale 0", BOARD(192000u, 0u, 0u, 1000000u, 80000000u, 0u, 0u, 0u), AMP_BOARD_FULL_SCALE },
    { "full scale 1 mV", BOARD(192000u, 1u, 1u, 1000000u, 80000000u, 0u, 0u, 0u), AMP_BOARD_OK },
    { "full scale 1000 V", BOARD(192000u, 1000000u, 1000000u, 1000000u, 80000000u, 0u, 0u, 0u), AMP_BOARD_OK },
    { "full scale 1000.001 V", BOARD(192000u, 1000001u, 1000u, 1000000u, 80000000u, 0u, 0u, 0u),
      AMP_BOARD_FULL_SCALE },
    { "full scale 2**32 - 1", BOARD(192000u, 0xFFFFFFFFu, 1000u, 1000000u, 80000000u, 0u, 0u, 0u),
      AMP_BOARD_FULL_SCALE },
    { "max 0", BOARD(192000u, 125000u, 0u, 1000000u, 80000000u, 0u, 0u, 0u), AMP_BOARD_MAX_MV },
    { "max at full scale", BOARD(192000u, 125000u, 125000u, 1000000u, 80000000u, 0u, 0u, 0u), AMP_BOARD_OK },
    { "max above full scale", BOARD(192000u, 125000u, 125001u, 1000000u, 80000000u, 0u, 0u, 0u), AMP_BOARD_MAX_MV },
    { "measures 8", BOARD(192000u, 125000u, 100000u, 1000000u, 80000000u, 8u, 1u, 1u), AMP_BOARD_MEASURES },
    { "current without na per lsb", BOARD(192000u, 125000u, 100000u, 1000000u, 80000000u, 1u, 1u, 0u),
      AMP_BOARD_MEASURES },
    { "voltage without uv per lsb", BOARD(192000u, 125000u, 100000u, 1000000u, 80000000u, 2u, 0u, 1u),
      AMP_BOARD_MEASURES },
    { "phase alone", BOARD(192000u, 125000u, 100000u, 1000000u, 80000000u, 4u, 0u, 0u), AMP_BOARD_OK },
    { "per lsb at 2**32 - 1", BOARD(192000u, 125000u, 100000u, 1000000u, 80000000u, 7u, 0xFFFFFFFFu, 0xFFFFFFFFu),
      AMP_BOARD_OK },
    { "carriers min above max", BOARD(192000u, 125000u, 100000u, 30000000u, 20000000u, 0u, 0u, 0u),
      AMP_BOARD_CARRIERS },
    { "carriers within one step, none a multiple", BOARD(192000u, 125000u, 100000u, 30000001u, 30000009u, 0u, 0u, 0u),
      AMP_BOARD_CARRIERS },
    { "carriers one", BOARD(192000u, 125000u, 100000u, 30000000u, 30000000u, 0u, 0u, 0u), AMP_BOARD_OK },
    { "carriers near 2**32 (the minimum rounds past it)", BOARD(0u, 125000u, 100000u, 0xFFFFFFFFu, 0xFFFFFFFFu, 0u,
      0u, 0u), AMP_BOARD_CARRIERS },
    { "carriers from half the output rate", BOARD(192000u, 125000u, 100000u, 96000000u, 99000000u, 0u, 0u, 0u),
      AMP_BOARD_CARRIERS },
    { "carriers just below half the output rate", BOARD(192000u, 125000u, 100000u, 95999990u, 99000000u, 0u, 0u, 0u),
      AMP_BOARD_OK },
};

/* A refused board: INFO says max_mv 0 and no carrier; START is refused; nothing is made or measured. */
static void check_refused(const hal_board_t *board) {
    session_init(&s, board, 0);
    host_hello(&s, 7, 0);
    take_sent(&s);
    CHECK_EQ(count_sent(&s, MSG_INFO), 1);
    const uint8_t *info = s.sent[0].payload;
    CHECK_EQ(get_u32(info + 48), 0); /* carrier_min_mhz */
    CHECK_EQ(get_u32(info + 52), 0); /* carrier_max_mhz */
    CHECK_EQ(get_u32(info + 64), 0); /* max_mv */
    CHECK_EQ(info[80], 0);           /* measures */
    host_set_carrier(&s, 30000000u, 0);
    host_start(&s, 16000u, 0, 16, 0);
    take_sent(&s);
    CHECK_EQ(last_ack(&s, NULL, NULL), AMP_NO_CARRIER);
    static int16_t out[4096];
    amp_advance(&s.amp, 200000);
    CHECK_EQ(amp_synthesize(&s.amp, out, 4096), 0);
    CHECK_EQ(counters_of(&s.amp).envelope_uv, 0);
    CHECK_EQ(amp_limit_uv(&s.amp, 1000000), 0); /* the clamp is 0 V */
}

void test_board_ranges(void) {
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        const board_case_t *c = &cases[i];
        int got = amp_init(&s.amp, &c->board, "T", 0);
        if (got != c->want)
            fprintf(stderr, "  board case: %s\n", c->what);
        CHECK_EQ(got, c->want);
        if (c->want == AMP_BOARD_OK) {
            CHECK_EQ(s.amp.max_mv, c->board.max_mv);
            CHECK_EQ(s.amp.board->output_rate_hz, c->board.output_rate_hz);
            CHECK(s.amp.carrier_min_mhz <= s.amp.carrier_max_mhz);
        } else {
            check_refused(&c->board);
        }
    }
    /* a problem for each code, in words */
    for (int code = AMP_BOARD_OK; code <= AMP_BOARD_CARRIERS; code++)
        for (int other = AMP_BOARD_OK; other < code; other++)
            CHECK(strcmp(amp_board_problem(code), amp_board_problem(other)) != 0);
    /* output_rate / envelope rate whole: 400 kHz makes 25 and 50 outputs per sample, no drift */
    hal_board_t g4 = test_board;
    g4.output_rate_hz = 400000u;
    session_init(&s, &g4, 0);
    session_running(&s, 0, 0, 1000);
    amp_advance(&s.amp, 1000);
    static int16_t out[8192];
    CHECK_EQ(amp_synthesize(&s.amp, out, 8192), 17u * 25u); /* the samples due at 0 .. 1000 us */
    printf("  board: %zu cases of hal.h's ranges\n", sizeof cases / sizeof *cases);
}
