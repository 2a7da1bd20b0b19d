/* buffer.c - the envelope buffer by stream index (docs/amp-protocol.md 3.1 ENVELOPE, A3): sample
 * `index` lives in slot index % AMP_BUFFER_SAMPLES (a power of two: it divides 2**32, so the slots
 * run on across the index's wrap), with a presence bit. */
#include "amp_core.h"

#define SLOT_MASK (AMP_BUFFER_SAMPLES - 1u)

void amp_buffer_clear(amp_t *amp) {
    for (uint32_t w = 0; w < AMP_BUFFER_SAMPLES / 32u; w++)
        amp->present[w] = 0;
}

/* Indices first .. first + count - 1 all in [play_index, play_index + size) mod 2**32 (count <= size). */
int amp_buffer_fits(uint32_t first, uint32_t count, uint32_t play_index) {
    return (uint32_t)(first - play_index) <= AMP_BUFFER_SAMPLES - count;
}

void amp_buffer_put(amp_t *amp, uint32_t first, const uint8_t *samples_le, uint32_t count) {
    for (uint32_t k = 0; k < count; k++) {
        uint32_t slot = (first + k) & SLOT_MASK;
        amp->buffer[slot] = (int16_t)get_u16(samples_le + 2u * k);
        amp->present[slot >> 5] |= 1u << (slot & 31u);
    }
}

/* The sample at `index`, removed: 1 and *sample, or 0 when missing. */
int amp_buffer_take(amp_t *amp, uint32_t index, int16_t *sample) {
    uint32_t slot = index & SLOT_MASK, bit = 1u << (slot & 31u);
    if (!(amp->present[slot >> 5] & bit))
        return 0;
    amp->present[slot >> 5] &= ~bit;
    *sample = amp->buffer[slot];
    return 1;
}

/* Samples present from play_index on, up to the first missing one (a word at a time). */
uint32_t amp_buffer_fill(const amp_t *amp, uint32_t play_index) {
    uint32_t fill = 0, slot = play_index & SLOT_MASK;
    while (fill < AMP_BUFFER_SAMPLES) {
        uint32_t shift = slot & 31u, run = 32u - shift;
        uint32_t bits = amp->present[slot >> 5] >> shift;
        uint32_t ones = 0;
        if (shift == 0 && bits == 0xFFFFFFFFu)
            ones = 32;
        else
            while (ones < run && (bits >> ones) & 1u)
                ones++;
        fill += ones;
        if (ones < run)
            break;
        slot = (slot + run) & SLOT_MASK;
    }
    return fill < AMP_BUFFER_SAMPLES ? fill : AMP_BUFFER_SAMPLES;
}
