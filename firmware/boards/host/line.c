/* line.c - the pty as the firmware receives it, through the line faults (line.h). */
#include "line.h"

#include <math.h>
#include <unistd.h>

static uint64_t to_us(double s)
{
    return (uint64_t)ceil(s * 1e6);
}

void line_init(line_t *line, pty_t *pty, const options_t *plan)
{
    line->pty = pty;
    line->plan = plan;
    line->rng = plan->seed;
    line->disconnect_us = plan->disconnect_at_s < 0.0 ? UINT64_MAX : to_us(plan->disconnect_at_s);
    line->bytes_head = line->bytes_tail = line->chunks_head = line->chunks_tail = 0;
    line->last_rx_us = UINT64_MAX;
}

/* A uniform draw in [0, 1) (splitmix64). */
static double draw(line_t *line)
{
    uint64_t z = (line->rng += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return (double)((z ^ (z >> 31)) >> 11) / 9007199254740992.0;
}

/* Drop and corrupt `data` in place (one pair of draws per byte, in order); returns the bytes kept. */
static size_t line_faults(line_t *line, uint8_t *data, size_t n)
{
    double drop = line->plan->drop_rate, corrupt = line->plan->corrupt_rate;
    size_t kept = 0;
    if (drop == 0.0 && corrupt == 0.0)
        return n;
    for (size_t i = 0; i < n; i++) {
        double dropped = draw(line), flipped = draw(line);
        uint8_t byte = data[i];
        if (flipped < corrupt)
            byte ^= (uint8_t)(1u << (unsigned)(flipped / corrupt * 8.0));
        if (dropped >= drop)
            data[kept++] = byte;
    }
    return kept;
}

int line_disconnected(const line_t *line, uint64_t now_us)
{
    return now_us >= line->disconnect_us;
}

int line_reading(const line_t *line, uint64_t now_us)
{
    if (line->pty->master < 0 || line_disconnected(line, now_us))
        return 0;
    for (size_t i = 0; i < line->plan->stalls; i++) {
        uint64_t from = to_us(line->plan->stall_at_s[i]), to = to_us(line->plan->stall_at_s[i] + line->plan->stall_for_s[i]);
        if (now_us >= from && now_us < to)
            return 0;
    }
    return 1;
}

/* Read what the pty holds (up to `cap`), through drop and corrupt. */
static size_t receive(line_t *line, uint8_t *data, size_t cap, uint64_t now_us)
{
    if (cap == 0 || !line_reading(line, now_us))
        return 0;
    ssize_t got = read(line->pty->master, data, cap);
    if (got <= 0)
        return 0; /* nothing waiting (EAGAIN); the firmware keeps its own slave open, so no end of file */
    line->last_rx_us = now_us;
    return line_faults(line, data, (size_t)got);
}

size_t line_read(line_t *line, uint8_t *data, size_t cap, uint64_t now_us)
{
    if (line->plan->delay_s == 0.0)
        return receive(line, data, cap, now_us);
    /* Hold what arrives for delay_s, in the queue's free room, then hand on what is due. */
    static uint8_t incoming[65536];
    uint32_t room = LINE_MAX_DELAYED_BYTES - (line->bytes_head - line->bytes_tail);
    size_t got = line->chunks_head - line->chunks_tail < LINE_MAX_DELAYED_CHUNKS
                     ? receive(line, incoming, room < sizeof incoming ? room : sizeof incoming, now_us)
                     : 0;
    if (got > 0) {
        for (size_t i = 0; i < got; i++)
            line->bytes[(line->bytes_head + i) % LINE_MAX_DELAYED_BYTES] = incoming[i];
        line->bytes_head += (uint32_t)got;
        uint32_t slot = line->chunks_head++ % LINE_MAX_DELAYED_CHUNKS;
        line->chunks[slot].release_us = now_us + to_us(line->plan->delay_s);
        line->chunks[slot].length = (uint32_t)got;
    }
    size_t given = 0;
    while (given < cap && line->chunks_tail != line->chunks_head) {
        uint32_t slot = line->chunks_tail % LINE_MAX_DELAYED_CHUNKS;
        if (line->chunks[slot].release_us > now_us)
            break;
        while (given < cap && line->chunks[slot].length > 0) {
            data[given++] = line->bytes[line->bytes_tail++ % LINE_MAX_DELAYED_BYTES];
            line->chunks[slot].length--;
        }
        if (line->chunks[slot].length == 0)
            line->chunks_tail++;
    }
    return given;
}

uint64_t line_next_event_us(const line_t *line, uint64_t now_us)
{
    uint64_t next = line->disconnect_us > now_us ? line->disconnect_us : UINT64_MAX;
    if (line->chunks_tail != line->chunks_head) {
        uint64_t release = line->chunks[line->chunks_tail % LINE_MAX_DELAYED_CHUNKS].release_us;
        next = release < next ? release : next;
    }
    for (size_t i = 0; i < line->plan->stalls; i++) {
        uint64_t from = to_us(line->plan->stall_at_s[i]), to = to_us(line->plan->stall_at_s[i] + line->plan->stall_for_s[i]);
        if (from > now_us && from < next)
            next = from;
        if (to > now_us && to < next)
            next = to;
    }
    return next;
}
