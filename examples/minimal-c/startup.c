/* Start-up code (Cortex-M4F): the vector table and the reset handler,
 * which turns the FPU on, copies .data from flash, zeroes .bss, sets up
 * newlib's semihosting output and runs main (C has no constructors). */
#include <stdint.h>
#include <stdlib.h>

/* From link.ld. */
extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _estack;
extern int main(void);
extern void initialise_monitor_handles(void); /* newlib's rdimon */

void Reset_Handler(void) {
    /* Full access to the FPU (CP10, CP11) before any float instruction. */
    *(volatile uint32_t *)0xE000ED88u |= 0xFu << 20;
    __asm__ volatile("dsb\n\tisb");
    for (uint32_t *src = &_sidata, *dst = &_sdata; dst < &_edata;) {
        *dst++ = *src++;
    }
    for (uint32_t *dst = &_sbss; dst < &_ebss;) {
        *dst++ = 0;
    }
    initialise_monitor_handles();
    exit(main());
}

/* Any fault: stop where a debugger can see it. */
static void Fault_Handler(void) {
    for (;;) {
    }
}

/* The vector table: the initial stack pointer, then reset, NMI,
 * HardFault, MemManage, BusFault, UsageFault (ARMv7-M order); this
 * firmware enables no other exception. */
__attribute__((section(".vectors"), used)) static const struct {
    void *initial_sp;
    void (*handlers[6])(void);
} vectors = {&_estack, {Reset_Handler, Fault_Handler, Fault_Handler, Fault_Handler, Fault_Handler, Fault_Handler}};
