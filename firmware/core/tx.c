/* tx.c - the bytes queued for the host: a ring of whole frames, bounded; never blocks. */
#include "amp_core.h"

static void tx_put(amp_t *amp, const uint8_t *data, size_t n) {
    for (size_t i = 0; i < n; i++)
        amp->tx[(amp->tx_head + i) & (AMP_TX_BYTES - 1u)] = data[i];
    amp->tx_head += (uint32_t)n;
}

void amp_send(amp_t *amp, uint8_t type, const uint8_t *payload, size_t payload_bytes) {
    uint8_t encoded[AMP_MAX_ENCODED + 1u];
    size_t n = amp_frame_encode(AMP_VERSION, type, amp->tx_seq, payload, payload_bytes, encoded);
    amp->tx_seq++;
    if (n > AMP_TX_BYTES - (amp->tx_head - amp->tx_tail)) {
        amp->counters.tx_dropped++; /* the host does not read: drop this frame whole */
        return;
    }
    tx_put(amp, encoded, n);
}

void amp_tx_discard(amp_t *amp) {
    amp->tx_tail = amp->tx_head;
    if (amp->tx_mid_frame) { /* the host has part of a frame: end it, so that it is discarded */
        static const uint8_t delimiter = 0;
        tx_put(amp, &delimiter, 1);
    }
}

size_t amp_transmit(amp_t *amp, uint8_t *out, size_t cap) {
    size_t n = 0;
    while (n < cap && amp->tx_tail != amp->tx_head) {
        out[n++] = amp->tx[amp->tx_tail & (AMP_TX_BYTES - 1u)];
        amp->tx_tail++;
    }
    if (n > 0)
        amp->tx_mid_frame = out[n - 1] != 0;
    return n;
}
