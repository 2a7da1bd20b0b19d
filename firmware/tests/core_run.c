/* core_run.c - amp_run's loop on the scripted board (core_hal.c): a session from HELLO to the
 * watchdog, bytes out through a UART that takes 16 at a time, carrier out, ADC in. */
#include <setjmp.h>
#include <string.h>

#include "core_hal.h"

static void script_frame(uint64_t at_us, uint8_t type, uint16_t seq, const uint8_t *payload, size_t n) {
    uint8_t line[AMP_MAX_ENCODED + 1];
    size_t length = amp_frame_encode(AMP_VERSION, type, seq, payload, n, line);
    for (size_t i = 0; i < length; i++) {
        hal_script.rx[hal_script.rx_count].at_us = at_us;
        hal_script.rx[hal_script.rx_count++].byte = line[i];
    }
}

void test_run(void) {
    static jmp_buf jump;
    memset(&hal_script, 0, sizeof hal_script);
    hal_script.board = &test_board;
    hal_script.end_us = 80000;
    hal_script.max_wait_us = 1000;
    hal_script.tx_per_call = 16;
    hal_script.output_room = 100;
    hal_script.jump = &jump;
    hal_script.fault_bits = AMP_FAULT_OVERTEMPERATURE;
    hal_script.fault_at_us = 70000;
    uint8_t p[4 + 2 * 256] = { 't' };
    put_u32(p + 12, 42);
    script_frame(1000, MSG_HELLO, 0, p, 16);
    put_u32(p, 31360000u);
    script_frame(1000, MSG_SET_CARRIER, 1, p, 4);
    put_u32(p, 16000);
    put_u32(p + 4, 0);
    put_u16(p + 8, 16);
    script_frame(2000, MSG_START, 2, p, 10);
    for (uint16_t f = 0; f < 4; f++) {
        put_u32(p, f * 256u);
        for (int i = 0; i < 256; i++)
            put_u16(p + 4 + 2 * i, 8000);
        script_frame(2000 + f * 1000u, MSG_ENVELOPE, (uint16_t)(3 + f), p, 4 + 512);
    }
    if (setjmp(jump) == 0)
        amp_run(); /* returns here by longjmp from hal_wait at end_us */
    CHECK_EQ(hal_script.inits, 1);
    CHECK(hal_script.kicks >= hal_script.waits);
    CHECK_EQ(hal_script.rx_at, hal_script.rx_count);
    /* what the host got: INFO, 2 ACKs, STATUS every 5 ms; the last says the watchdog tripped */
    size_t info = 0, acks = 0, statuses = 0, length = 0;
    uint8_t frame[AMP_MAX_ENCODED], body[AMP_MAX_ENCODED], last_status[STATUS_BYTES] = { 0 };
    for (size_t i = 0; i < hal_script.tx_count; i++) {
        if (hal_script.tx[i] != 0) {
            frame[length++] = hal_script.tx[i];
            continue;
        }
        amp_frame_t f;
        CHECK_EQ(amp_frame_decode(frame, length, body, &f), 0);
        length = 0;
        info += f.type == MSG_INFO;
        acks += f.type == MSG_ACK;
        if (f.type == MSG_STATUS) {
            statuses++;
            memcpy(last_status, f.payload, STATUS_BYTES);
        }
    }
    CHECK_EQ(info, 1);
    CHECK_EQ(acks, 2);
    CHECK(statuses >= 14);
    CHECK_EQ(get_u32(last_status + 12), 7);  /* frames_ok */
    CHECK_EQ(get_u32(last_status + 32), 1);  /* the watchdog tripped (38 ms after the last frame) */
    CHECK_EQ(last_status[10], AMP_FAULT);   /* the hardware fault at 70 ms */
    CHECK_EQ(last_status[11], AMP_FAULT_OVERTEMPERATURE);
    CHECK_EQ(hal_script.output_offs, 1);    /* the fault cut the board's queued output */
    CHECK(get_u32(last_status + 44) > 0);    /* voltage measured by then, from the ADC */
    CHECK(hal_script.output_count > 7000);   /* about 40 ms of 192 kHz carrier */
    CHECK(hal_script.adc_count == hal_script.output_count);
}
