/* pty.c - a new pseudo-terminal for the host build (pty.h). */
#include "pty.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <unistd.h>

/* Raw mode, as Python's tty.setraw: 8 bits, no echo, no line editing, no translation, no signals. */
static int make_raw(int fd)
{
    struct termios mode;
    if (tcgetattr(fd, &mode) != 0)
        return -1;
    mode.c_iflag &= ~(tcflag_t)(BRKINT | ICRNL | INPCK | ISTRIP | IXON);
    mode.c_oflag &= ~(tcflag_t)OPOST;
    mode.c_cflag &= ~(tcflag_t)(CSIZE | PARENB);
    mode.c_cflag |= CS8;
    mode.c_lflag &= ~(tcflag_t)(ECHO | ICANON | IEXTEN | ISIG);
    mode.c_cc[VMIN] = 1;
    mode.c_cc[VTIME] = 0;
    return tcsetattr(fd, TCSAFLUSH, &mode);
}

int pty_open(pty_t *pty, char *error, size_t error_size)
{
    const char *name;
    pty->master = pty->slave = -1;
    pty->master = posix_openpt(O_RDWR | O_NOCTTY);
    if (pty->master < 0 || grantpt(pty->master) != 0 || unlockpt(pty->master) != 0 ||
        (name = ptsname(pty->master)) == NULL || strlen(name) >= sizeof pty->name)
        goto failed;
    strcpy(pty->name, name);
    pty->slave = open(pty->name, O_RDWR | O_NOCTTY);
    if (pty->slave < 0 || make_raw(pty->slave) != 0)
        goto failed;
    int flags = fcntl(pty->master, F_GETFL);
    if (flags < 0 || fcntl(pty->master, F_SETFL, flags | O_NONBLOCK) != 0)
        goto failed;
    return 0;
failed:
    snprintf(error, error_size, "cannot open a pty (%s)", strerror(errno));
    pty_close(pty);
    return -1;
}

void pty_discard_output(pty_t *pty)
{
    if (pty->slave >= 0)
        tcflush(pty->slave, TCIFLUSH); /* what the host's end has not read yet */
}

void pty_close(pty_t *pty)
{
    if (pty->master >= 0)
        close(pty->master);
    if (pty->slave >= 0)
        close(pty->slave);
    pty->master = pty->slave = -1;
}
