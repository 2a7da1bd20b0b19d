/* main.c - the micro:bit's firmware: the core's loop on this board's hal.h (hal_init inside). */
#include "amp.h"

int main(void)
{
    amp_run();
    return 0;
}
