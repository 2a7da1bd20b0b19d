/* frame.c - a frame's body (docs/amp-protocol.md 2.2, 2.3 steps 1-2): header, payload, CRC. */
#include "amp_core.h"

#define HEADER_BYTES 4u
#define CRC_BYTES 2u

int amp_frame_decode(const uint8_t *encoded, size_t n, uint8_t *body, amp_frame_t *frame) {
    long length = amp_cobs_decode(encoded, n, body, AMP_MAX_ENCODED);
    if (length < (long)AMP_MIN_BODY || length > (long)AMP_MAX_BODY)
        return -1;
    size_t crc_at = (size_t)length - CRC_BYTES;
    if (amp_crc16(body, crc_at) != get_u16(body + crc_at))
        return -1;
    frame->version = body[0];
    frame->type = body[1];
    frame->seq = get_u16(body + 2);
    frame->payload = body + HEADER_BYTES;
    frame->payload_bytes = crc_at - HEADER_BYTES;
    return 0;
}

size_t amp_frame_encode(uint8_t version, uint8_t type, uint16_t seq, const uint8_t *payload,
                        size_t payload_bytes, uint8_t *out) {
    uint8_t body[AMP_MAX_BODY];
    body[0] = version;
    body[1] = type;
    put_u16(body + 2, seq);
    for (size_t i = 0; i < payload_bytes; i++)
        body[HEADER_BYTES + i] = payload[i];
    size_t crc_at = HEADER_BYTES + payload_bytes;
    put_u16(body + crc_at, amp_crc16(body, crc_at));
    size_t length = amp_cobs_encode(body, crc_at + CRC_BYTES, out);
    out[length] = 0;
    return length + 1;
}
