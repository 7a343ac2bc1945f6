/* Host harness of the embedded C target (docs/embedded.md): steps a generated model and writes
 * its rows as CSV, "t,<outputs>" then one row per step from t0, numbers as printf("%.17g"),
 * the format of `bgc simulate`.  Built by tests/test_embedded.py:
 *   cc -std=c99 -DBGC_MODEL=NAME -DBGC_HEADER='"NAME.h"' embedded_harness.c NAME.o -lm
 *   ./a.out STEPS [NAME=VALUE ...]   (parameter overrides by name, then NAME_params_update)
 * With -DBGC_INPUT_SEQUENCE the inputs are set before each step to a sequence of samples
 * (the harness's s(k, j)); else they stay 0.
 * Exit status 0, or 3 with the fault code and time on stderr.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include BGC_HEADER

#ifndef BGC_STEPS
#define BGC_STEPS 10 /* the steps without an argument (a target without a command line) */
#endif
#define BGC_CAT2(a, b) a##b
#define BGC_CAT(a, b) BGC_CAT2(a, b)
#define API(x) BGC_CAT(BGC_MODEL, x)

static void row(double t, const API(_outputs) *y)
{
    int j;
    printf("%.17g", t);
    for (j = 0; j < API(_N_OUTPUTS); j++)
        printf(",%.17g", (double)y->y[j]);
    printf("\n");
}

static int set_param(API(_params) *p, const char *arg)
{
    const char *eq = strchr(arg, '=');
    API(_real) *fields = (API(_real) *)p; /* the parameter fields come first, in order */
    int j;
    if (!eq)
        return 1;
    for (j = 0; j < API(_N_PARAMS); j++)
        if (strlen(API(_param_names)[j]) == (size_t)(eq - arg)
            && strncmp(API(_param_names)[j], arg, (size_t)(eq - arg)) == 0) {
            fields[j] = (API(_real))strtod(eq + 1, NULL);
            return 0;
        }
    return 1;
}

int main(int argc, char **argv)
{
    API(_state) s;
    API(_params) p;
    API(_inputs) u;
    API(_outputs) y;
    long k, steps = argc > 1 ? strtol(argv[1], NULL, 10) : BGC_STEPS;
    int j, rc;
    memset(&u, 0, sizeof u);
    API(_params_default)(&p);
    for (j = 2; j < argc; j++)
        if (set_param(&p, argv[j])) {
            fprintf(stderr, "unknown parameter in '%s'\n", argv[j]);
            return 2;
        }
    API(_params_update)(&p);
    API(_init)(&s, &p);
    printf("t");
    for (j = 0; j < API(_N_OUTPUTS); j++)
        printf(",%s", API(_output_names)[j]);
    printf("\n");
    rc = API(_output)(&s, &p, &u, &y);
    if (rc == 0)
        row(API(_time)(&s), &y);
    for (k = 0; k < steps && rc == 0; k++) {
#ifdef BGC_INPUT_SEQUENCE
        /* the inputs' samples at the step's end t_(k+1): input j's s(k + 1, j), exact in
           binary, that the test writes as the rows of simulate's --input data */
        for (j = 0; j < API(_N_INPUTS); j++)
            u.u[j] = (API(_real))((double)(((k + 1) * 37 + 5 * j) % 11) * 0.25 - 1.0);
#endif
        rc = API(_step)(&s, &p, &u, &y);
        if (rc == 0)
            row(API(_time)(&s), &y);
    }
    if (rc) {
        fprintf(stderr, "fault %d at t = %.17g\n", rc, API(_time)(&s));
        return 3;
    }
    return 0;
}
