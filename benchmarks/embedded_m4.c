/* The embedded target's benchmark on a Cortex-M4F under QEMU (benchmarks/embedded.py): steps a
 * model and counts the instructions its steps take, by QEMU's -icount clock (shift=0: one
 * virtual nanosecond per instruction) read through the SysTick timer, which QEMU clocks from
 * the virtual time.  The ticks per instruction are calibrated in the same run on a loop of a
 * known count of instructions.  Prints "calib INSNS TICKS", "empty TICKS" (a measurement of
 * nothing) and "steps N TICKS" through semihosting.
 *   BGC_MODEL=NAME BGC_HEADER='"NAME.h"': a model of bgc's embedded target;
 *   BGC_CASADI=FUNCTION BGC_N=N BGC_HEADER='"FUNCTION.h"': a CasADi-generated step
 *     FUNCTION(arg, res, iw, w, mem) of N states, its initial state in BGC_X0, its work
 *     arrays of BGC_NW reals and BGC_NIW ints.
 * Built with tests/embedded_m4/startup.c and mps2_an386.ld. */
#include <stdio.h>
#include BGC_HEADER

#define SYST_CSR (*(volatile unsigned long *)0xE000E010UL)
#define SYST_RVR (*(volatile unsigned long *)0xE000E014UL)
#define SYST_CVR (*(volatile unsigned long *)0xE000E018UL)
#define MASK 0xFFFFFFUL
#define BATCH 10 /* steps per reading: well inside the 24-bit counter */

static unsigned long now(void)
{
    return SYST_CVR & MASK;
}

static void spin(unsigned long n) /* 2 n instructions: subs, bne */
{
    __asm volatile("1:\n\tsubs %0, %0, #1\n\tbne 1b" : "+r"(n) : : "cc");
}

#define BGC_CAT2(a, b) a##b
#define BGC_CAT(a, b) BGC_CAT2(a, b)

int main(void)
{
    unsigned long a, b, total = 0;
    long k, steps = BGC_STEPS;
    int j, rc = 0;
#ifdef BGC_CASADI
    static BGC_REAL x[BGC_N] = BGC_X0, x1[BGC_N];
    static BGC_REAL work[BGC_NW + 1];
    static int iwork[BGC_NIW + 1];
    const BGC_REAL *arg[1];
    BGC_REAL *res[1];
#else
#define API(x) BGC_CAT(BGC_MODEL, x)
    API(_state) s;
    API(_params) p;
    API(_inputs) u = { { 0 } };
    API(_outputs) y;
#endif
    SYST_RVR = MASK;
    SYST_CVR = 0;
    SYST_CSR = 5; /* enabled, the processor's clock, no interrupt */
    a = now();
    spin(1000000UL);
    b = now();
    printf("calib %lu %lu\n", 2000000UL, (a - b) & MASK);
    a = now();
    b = now();
    printf("empty %lu\n", (a - b) & MASK);
#ifndef BGC_CASADI
    API(_params_default)(&p);
    API(_init)(&s, &p);
#endif
    for (k = 0; k < steps && rc == 0; k += BATCH) {
        a = now();
        for (j = 0; j < BATCH && rc == 0; j++) {
#ifdef BGC_CASADI
            arg[0] = (k + j) % 2 ? x1 : x;
            res[0] = (k + j) % 2 ? x : x1;
            rc = BGC_CASADI(arg, res, iwork, work, 0);
#else
            rc = API(_step)(&s, &p, &u, &y);
#endif
        }
        b = now();
        total += (a - b) & MASK;
    }
    printf("steps %ld %lu\n", k, total);
    return rc;
}
