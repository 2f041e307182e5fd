/* Start-up code of the C example (Cortex-M4F): the vector table, the reset
 * handler (FPU on, .data copied, .bss zeroed, semihosting output set
 * up, then main; C has no constructors to run), and the SysTick instruction counter. */
#include <stdint.h>
#include <stdlib.h>

#include "board.h"

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _estack;
extern int main(void);
extern void initialise_monitor_handles(void);

#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)
#define SCB_ICSR (*(volatile uint32_t *)0xE000ED04u)
#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)
#define SYST_RELOAD 0x00FFFFFFu
#define ICSR_PENDSTSET (1u << 26)

void Reset_Handler(void);
void SysTick_Handler(void);

static void Fault_Handler(void) {
    /* No recovery in an example: stop where a debugger can see it. */
    for (;;) {
    }
}

/* The vector table: the initial stack pointer, then the exception
 * handlers in ARMv7-M order (reset, NMI, faults, SVCall, PendSV, SysTick). */
struct vector_table {
    void *initial_sp;
    void (*handlers[15])(void);
};

__attribute__((section(".vectors"), used)) static const struct vector_table vectors = {
    &_estack,
    {Reset_Handler, Fault_Handler, Fault_Handler, Fault_Handler, Fault_Handler, Fault_Handler, 0, 0, 0,
     0, Fault_Handler, Fault_Handler, 0, Fault_Handler, SysTick_Handler},
};

void Reset_Handler(void) {
    /* Full access to CP10/CP11 before any floating-point instruction. */
    SCB_CPACR |= 0xFu << 20;
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

/* SysTick wraps counted by its exception. */
static volatile uint32_t wraps;

void SysTick_Handler(void) { wraps++; }

void instructions_start(void) {
    SYST_CSR = 0;
    SYST_RVR = SYST_RELOAD;
    SYST_CVR = 0;
    /* Processor clock, exception on wrap, enabled. */
    SYST_CSR = 0x7u;
    /* The counter holds 0 until its first tick loads the reload value. */
    while (SYST_CVR == 0) {
    }
    wraps = 0;
}

uint64_t instructions_now(void) {
    for (;;) {
        uint32_t w = wraps;
        uint32_t current = SYST_CVR;
        uint32_t pending = (SCB_ICSR & ICSR_PENDSTSET) ? 1u : 0u;
        uint32_t again = SYST_CVR;
        /* Retry if the exception ran or the counter wrapped between reads. */
        if (wraps != w || again > current) {
            continue;
        }
        uint64_t ticks = (uint64_t)(w + pending) * (SYST_RELOAD + 1u) + (SYST_RELOAD - current);
        return ticks * INSTRUCTIONS_PER_TICK;
    }
}
