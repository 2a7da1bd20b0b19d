/* pty.h - the host build's serial line: a new pseudo-terminal (as amp emulate's Port.open_pty). */
#ifndef TPAD_HOST_PTY_H
#define TPAD_HOST_PTY_H

#include <stddef.h>

typedef struct {
    int master;      /* the firmware's end: read and written without blocking; -1 when closed */
    int slave;       /* kept open, so that a host closing the port does not end the line */
    char name[64];   /* what a host opens (/dev/pts/N) */
} pty_t;

/* A new pty, the slave in raw mode; 0, or -1 with one line in `error`. */
int pty_open(pty_t *pty, char *error, size_t error_size);

/* Drop the bytes written for the host and not read yet (a HELLO: they are stale). */
void pty_discard_output(pty_t *pty);

void pty_close(pty_t *pty);

#endif /* TPAD_HOST_PTY_H */
