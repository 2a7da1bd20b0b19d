/* rx.c - the receive splitter (docs/amp-protocol.md 2.1): candidate frames between 0x00 bytes; a
 * run over AMP_MAX_ENCODED bytes is discarded up to the next 0x00 and counted as one bad frame. */
#include "amp_core.h"

void amp_receive(amp_t *amp, const uint8_t *data, size_t n, uint64_t now_us) {
    for (size_t i = 0; i < n; i++) {
        uint8_t byte = data[i];
        if (byte == 0) {
            if (amp->rx_len > 0) {
                amp_advance(amp, now_us);
                amp_on_candidate(amp, amp->rx, amp->rx_len);
            }
            amp->rx_len = 0;
            amp->rx_discarding = 0;
        } else if (!amp->rx_discarding) {
            if (amp->rx_len == AMP_MAX_ENCODED) {
                amp->rx_len = 0;
                amp->rx_discarding = 1;
                amp_advance(amp, now_us);
                amp_on_candidate(amp, NULL, 0);
            } else {
                amp->rx[amp->rx_len++] = byte;
            }
        }
    }
}

void amp_on_candidate(amp_t *amp, const uint8_t *encoded, size_t n) {
    uint8_t body[AMP_MAX_ENCODED];
    amp_frame_t frame;
    if (encoded == NULL || amp_frame_decode(encoded, n, body, &frame) != 0) {
        amp->counters.frames_bad++; /* 2.3 steps 1-2: never acted on, no watchdog reset, no ACK */
        return;
    }
    amp_on_frame(amp, &frame);
}
