/* core_hal.h - the scripted board of core_hal.c (tests of run.c). */
#ifndef CORE_HAL_H
#define CORE_HAL_H

#include <setjmp.h>

#include "core_check.h"

#define HAL_SCRIPT_RX 4096
#define HAL_SCRIPT_OUTPUT 200000
typedef struct {
    const hal_board_t *board;
    uint64_t now_us, end_us, max_wait_us, last_wait_us;
    jmp_buf *jump;                 /* hal_wait longjmps here once now_us >= end_us (NULL: never) */
    struct { uint64_t at_us; uint8_t byte; } rx[HAL_SCRIPT_RX];
    size_t rx_count, rx_at;
    uint8_t tx[65536];
    size_t tx_count, tx_per_call;
    size_t output_room;
    int16_t output[HAL_SCRIPT_OUTPUT];
    size_t output_count, adc_count;
    uint8_t fault_bits;
    uint64_t fault_at_us;
    unsigned inits, waits, kicks, output_offs;
} hal_script_t;
extern hal_script_t hal_script;

#endif
