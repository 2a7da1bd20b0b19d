/* crc16.c - CRC-16/IBM-3740 (docs/amp-protocol.md 2.2): poly 0x1021, init 0xFFFF, no reflection,
 * no final XOR; check value of "123456789" 0x29B1. */
#include "amp_core.h"

uint16_t amp_crc16(const uint8_t *data, size_t n) {
    uint16_t crc = 0xFFFFu;
    for (size_t i = 0; i < n; i++) {
        crc ^= (uint16_t)(data[i] << 8);
        for (int bit = 0; bit < 8; bit++)
            crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
    }
    return crc;
}
