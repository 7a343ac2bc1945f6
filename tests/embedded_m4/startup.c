/* A bare Cortex-M4F start for the embedded target's test under QEMU (machine mps2-an386):
 * the vector table, the FPU switched on, .bss zeroed, then the host harness's main
 * (tests/embedded_harness.c, its output through newlib's semihosting, librdimon), and
 * the run's end through exit(), which semihosting hands to QEMU as its exit status.
 * Built by tests/test_embedded.py with mps2_an386.ld. */
#include <stdlib.h>

extern unsigned long __bss_start__, __bss_end__, __stack_top;
extern void initialise_monitor_handles(void);
int main(int argc, char **argv);
void bgc_reset(void);
static void bgc_hang(void);

typedef void (*bgc_vector)(void);
__attribute__((section(".vectors"), used)) static const bgc_vector bgc_vectors[16] = {
    (bgc_vector)&__stack_top, bgc_reset, bgc_hang, bgc_hang, bgc_hang, bgc_hang, bgc_hang,
    0, 0, 0, 0, bgc_hang, bgc_hang, 0, bgc_hang, bgc_hang,
};

/* What newlib's exit() runs (its crti/crtn are not linked: -nostartfiles). */
void _init(void);
void _fini(void);
void _init(void)
{
}
void _fini(void)
{
}

static void bgc_hang(void)
{
    exit(99);
}

void bgc_reset(void)
{
    static char name[] = "harness";
    static char *argv[] = { name, 0 };
    unsigned long *p;
    *(volatile unsigned long *)0xE000ED88UL |= 0xFUL << 20; /* CPACR: CP10, CP11 full access */
    __asm volatile("dsb\n\tisb" ::: "memory");
    for (p = &__bss_start__; p < &__bss_end__; p++)
        *p = 0;
    initialise_monitor_handles();
    exit(main(1, argv));
}
