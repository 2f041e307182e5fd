/* What the C example needs from its board (startup.c). */
#ifndef BOARD_H
#define BOARD_H

#include <stdint.h>

/* QEMU with -icount shift=0 runs one instruction per nanosecond and the
 * MPS2 SysTick counts at 25 MHz: one tick every 40 instructions. */
#define INSTRUCTIONS_PER_TICK 40u

/* Starts counting instructions (SysTick; owns it from now on). */
void instructions_start(void);
/* Instructions since instructions_start(), exact to one tick. */
uint64_t instructions_now(void);

#endif
