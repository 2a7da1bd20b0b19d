/*
 * g4_irq.h - the board's interrupt handlers (board.c), which startup.c puts in the vector table
 * and the host register test calls directly.
 */
#ifndef TPAD_G4_IRQ_H
#define TPAD_G4_IRQ_H

void g4_dma1_ch1_irq(void); /* the DAC ring: a half was played (zero it) */
void g4_usart2_irq(void);   /* USART2: bytes received, room to send */
void g4_tim2_irq(void);     /* TIM2 compare: hal_wait's deadline */

#endif /* TPAD_G4_IRQ_H */
