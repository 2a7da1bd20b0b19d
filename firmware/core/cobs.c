/* cobs.c - COBS (docs/amp-protocol.md 2.1): blocks of a code byte c (1..255) and c - 1 non-zero
 * bytes; a 0x00 follows each block with c < 255 except the last. */
#include "amp_core.h"

size_t amp_cobs_encode(const uint8_t *in, size_t n, uint8_t *out) {
    size_t code_at = 0, length = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < n; i++) {
        if (in[i] != 0) {
            out[length++] = in[i];
            code++;
        }
        if (in[i] == 0 || code == 0xFFu) {
            out[code_at] = code;
            code = 1;
            code_at = length++;
            if (in[i] != 0 && i + 1 == n) /* a full block ends the body: no empty block after it */
                return code_at;
        }
    }
    out[code_at] = code;
    return length;
}

long amp_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap) {
    size_t length = 0, i = 0;
    while (i < n) {
        uint8_t code = in[i++];
        if (code == 0 || (size_t)(code - 1u) > n - i || length + (code - 1u) > cap)
            return -1;
        for (uint8_t k = 1; k < code; k++) {
            if (in[i] == 0)
                return -1;
            out[length++] = in[i++];
        }
        if (code < 0xFFu && i < n) {
            if (length == cap)
                return -1;
            out[length++] = 0;
        }
    }
    return (long)length;
}
