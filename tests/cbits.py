"""Doubles across a process boundary as bit patterns (hex words), for the tests that compare
the Python runtime with the C runtime to the bit: C_IO reads (rd) and writes (wr) one double
in a C harness."""

C_IO = r"""
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
static double rd(void)
{
    unsigned long long u;
    double d;
    if (scanf("%llx", &u) != 1) exit(9);
    memcpy(&d, &u, 8);
    return d;
}
static void wr(double d)
{
    unsigned long long u;
    memcpy(&u, &d, 8);
    printf("%llx ", u);
}
"""
