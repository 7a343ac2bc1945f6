/* Hand-written Dormand-Prince 5(4) for the Baumgarte-stabilised pendulum (Favre & Scavarda
 * 1998, eq. 12): the baseline that bgc's generated C program is measured against.
 *
 * A straightforward, competent DOPRI5 in the manner of Hairer's dopri5.f:
 *   - the Dormand-Prince tableau, FSAL (6 right-hand-side evaluations per step);
 *   - error norm sqrt(mean((err_i / sk_i)^2)), sk_i = atol + rtol * max(|y0_i|, |y1_i|);
 *   - Hairer's step controller: safety 0.9, facmin 0.2, facmax 10, with his Lund
 *     stabilisation h_new = h * err^(-(0.2 - 0.75 beta)) * err_old^beta, beta = 0.04, and
 *     no growth right after a rejection (-DHW_BETA=0 gives the plain controller
 *     h * safety * err^(-1/5), the one SciPy's RK45 uses);
 *   - Hairer's initial step guess (hinit, 2 evaluations: f(t0, y0) and one trial);
 *   - dense output with Hairer's continuous extension (contd5), so the output grid never
 *     shortens a step; only the last step is cut to land on t_end.
 *
 * Build:  cc -O2 -std=c99 handwritten_dopri5.c -o handwritten_dopri5 -lm
 * Run:    ./handwritten_dopri5 [--t-end T] [--dt DT] [--rtol R] [--atol A] > out.csv
 * CSV on stdout: t,x,y,rod.lambda,rod.residual (%.17g);
 * "stats: steps=N rejected=N rhs=N" on stderr.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define N 4 /* state: px, py, x, y */
#ifndef HW_BETA
#define HW_BETA 0.04
#endif

static const double M = 1.0, L = 1.0, G = 9.81, THETA0 = 0.5, ALPHA = 5.0, BETA = 5.0;

static long n_rhs = 0;

/* B of eq. (12): y g + xd^2 + yd^2 + 2 alpha (x xd + y yd) + beta^2 (x^2 + y^2 - l^2) / 2 */
static double bracket(const double *s)
{
    double xd = s[0] / M, yd = s[1] / M, x = s[2], y = s[3];
    double r2 = x * x + y * y;
    return y * G + xd * xd + yd * yd + 2.0 * ALPHA * (x * xd + y * yd)
           + BETA * BETA * (r2 - L * L) / 2.0;
}

static void rhs(double t, const double *s, double *ds)
{
    (void)t;
    double x = s[2], y = s[3];
    double k = bracket(s) / (x * x + y * y);
    n_rhs++;
    ds[0] = M * (-x * k);
    ds[1] = M * (G - y * k);
    ds[2] = s[0] / M;
    ds[3] = s[1] / M;
}

static void write_row(double t, const double *s)
{
    double x = s[2], y = s[3], r2 = x * x + y * y;
    double lambda = M / (2.0 * r2) * bracket(s);
    printf("%.17g,%.17g,%.17g,%.17g,%.17g\n", t, x, y, lambda, r2 - L * L);
}

/* Dormand-Prince coefficients */
static const double C2 = 1.0 / 5, C3 = 3.0 / 10, C4 = 4.0 / 5, C5 = 8.0 / 9;
static const double A21 = 1.0 / 5;
static const double A31 = 3.0 / 40, A32 = 9.0 / 40;
static const double A41 = 44.0 / 45, A42 = -56.0 / 15, A43 = 32.0 / 9;
static const double A51 = 19372.0 / 6561, A52 = -25360.0 / 2187, A53 = 64448.0 / 6561,
                    A54 = -212.0 / 729;
static const double A61 = 9017.0 / 3168, A62 = -355.0 / 33, A63 = 46732.0 / 5247,
                    A64 = 49.0 / 176, A65 = -5103.0 / 18656;
static const double A71 = 35.0 / 384, A73 = 500.0 / 1113, A74 = 125.0 / 192,
                    A75 = -2187.0 / 6784, A76 = 11.0 / 84;
static const double E1 = 71.0 / 57600, E3 = -71.0 / 16695, E4 = 71.0 / 1920,
                    E5 = -17253.0 / 339200, E6 = 22.0 / 525, E7 = -1.0 / 40;
static const double D1 = -12715105075.0 / 11282082432.0, D3 = 87487479700.0 / 32700410799.0,
                    D4 = -10690763975.0 / 1880347072.0, D5 = 701980252875.0 / 199316789632.0,
                    D6 = -1453857185.0 / 822651844.0, D7 = 69997945.0 / 29380423.0;

static double sum_sq(const double *v, const double *sk)
{
    double sum = 0.0;
    for (int i = 0; i < N; i++)
        sum += (v[i] / sk[i]) * (v[i] / sk[i]);
    return sum;
}

/* Hairer's hinit for order 5; f0 = f(t0, y0) is given, one more evaluation is made. */
static double initial_step(double t0, const double *y0, const double *f0, double hmax,
                           double rtol, double atol)
{
    double sk[N], y1[N], f1[N], df[N];
    for (int i = 0; i < N; i++)
        sk[i] = atol + rtol * fabs(y0[i]);
    double dny = sum_sq(y0, sk), dnf = sum_sq(f0, sk); /* Hairer's norms here: no mean */
    double h0 = (dny <= 1e-10 || dnf <= 1e-10) ? 1e-6 : 0.01 * sqrt(dny / dnf);
    h0 = fmin(h0, hmax);
    for (int i = 0; i < N; i++)
        y1[i] = y0[i] + h0 * f0[i];
    rhs(t0 + h0, y1, f1);
    for (int i = 0; i < N; i++)
        df[i] = f1[i] - f0[i];
    double d2 = sqrt(sum_sq(df, sk)) / h0;
    double der12 = fmax(fabs(d2), sqrt(dnf));
    double h1 = der12 <= 1e-15 ? fmax(1e-6, h0 * 1e-3) : pow(0.01 / der12, 1.0 / 5.0);
    return fmin(fmin(100.0 * h0, h1), hmax);
}

static int parse_args(int argc, char **argv, double *t_end, double *dt, double *rtol,
                      double *atol)
{
    for (int i = 1; i < argc; i++) {
        double *target = !strcmp(argv[i], "--t-end") ? t_end
                         : !strcmp(argv[i], "--dt")  ? dt
                         : !strcmp(argv[i], "--rtol") ? rtol
                         : !strcmp(argv[i], "--atol") ? atol
                                                      : NULL;
        if (target == NULL || i + 1 >= argc) {
            fprintf(stderr, "usage: %s [--t-end T] [--dt DT] [--rtol R] [--atol A]\n", argv[0]);
            return 0;
        }
        *target = strtod(argv[++i], NULL);
    }
    return 1;
}

int main(int argc, char **argv)
{
    double t0 = 0.0, t_end = 100.0, dt = 0.01, rtol = 1e-8, atol = 1e-10;
    if (!parse_args(argc, argv, &t_end, &dt, &rtol, &atol))
        return 2;
    static char buffer[1 << 16];
    setvbuf(stdout, buffer, _IOFBF, sizeof buffer);

    const double safety = 0.9, facmin = 0.2, facmax = 10.0, hmax = t_end - t0;
    const double expo = 0.2 - 0.75 * HW_BETA;
    double err_old = 1e-4;
    double y[N] = {0.0, 0.0, L * sin(THETA0), L * cos(THETA0)};
    double k1[N], k2[N], k3[N], k4[N], k5[N], k6[N], k7[N], ys[N], y1[N], err[N], sk[N];
    double r1[N], r2[N], r3[N], r4[N], r5[N]; /* continuous extension */
    long steps = 0, rejected = 0, next = 1;
    long n_out = (long)ceil((t_end - t0) / dt - 1e-6); /* rows t0 + k dt, k < n_out; t_end */

    printf("t,x,y,rod.lambda,rod.residual\n");
    write_row(t0, y);
    rhs(t0, y, k1);
    double t = t0, h = initial_step(t0, y, k1, hmax, rtol, atol);
    int last_rejected = 0;

    while (t < t_end) {
        int last = t + 1.01 * h >= t_end;
        if (last)
            h = t_end - t;
        for (int i = 0; i < N; i++) ys[i] = y[i] + h * A21 * k1[i];
        rhs(t + C2 * h, ys, k2);
        for (int i = 0; i < N; i++) ys[i] = y[i] + h * (A31 * k1[i] + A32 * k2[i]);
        rhs(t + C3 * h, ys, k3);
        for (int i = 0; i < N; i++) ys[i] = y[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
        rhs(t + C4 * h, ys, k4);
        for (int i = 0; i < N; i++)
            ys[i] = y[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
        rhs(t + C5 * h, ys, k5);
        for (int i = 0; i < N; i++)
            ys[i] = y[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i]
                                + A65 * k5[i]);
        rhs(t + h, ys, k6);
        for (int i = 0; i < N; i++)
            y1[i] = y[i] + h * (A71 * k1[i] + A73 * k3[i] + A74 * k4[i] + A75 * k5[i]
                                + A76 * k6[i]);
        rhs(t + h, y1, k7);
        for (int i = 0; i < N; i++) {
            err[i] = h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i]
                          + E7 * k7[i]);
            sk[i] = atol + rtol * fmax(fabs(y[i]), fabs(y1[i]));
        }
        double e = sqrt(sum_sq(err, sk) / N);
        if (!isfinite(e)) {
            fflush(stdout);
            fprintf(stderr, "error: non-finite state at t = %.17g\n", t);
            return 1;
        }
        double err_pow = pow(e, expo); /* e = 0 gives fac = facmax */
        double fac = fmax(facmin, fmin(facmax, safety / (err_pow / pow(err_old, HW_BETA))));
        if (e > 1.0) {
            rejected++;
            last_rejected = 1;
            h *= fmax(facmin, fmin(1.0, safety / err_pow));
            if (t + h == t) {
                fflush(stdout);
                fprintf(stderr, "error: step size underflow at t = %.17g\n", t);
                return 1;
            }
            continue;
        }
        steps++;
        err_old = fmax(e, 1e-4);
        if (last_rejected)
            fac = fmin(fac, 1.0);
        last_rejected = 0;
        for (int i = 0; i < N; i++) {
            double ydiff = y1[i] - y[i], bspl = h * k1[i] - ydiff;
            r1[i] = y[i];
            r2[i] = ydiff;
            r3[i] = bspl;
            r4[i] = ydiff - h * k7[i] - bspl;
            r5[i] = h * (D1 * k1[i] + D3 * k3[i] + D4 * k4[i] + D5 * k5[i] + D6 * k6[i]
                         + D7 * k7[i]);
        }
        double t_new = last ? t_end : t + h;
        for (; next <= n_out; next++) {
            double to = next == n_out ? t_end : t0 + next * dt, yo[N];
            if (to > t_new)
                break;
            double th = (to - t) / h, th1 = 1.0 - th;
            for (int i = 0; i < N; i++)
                yo[i] = r1[i] + th * (r2[i] + th1 * (r3[i] + th * (r4[i] + th1 * r5[i])));
            write_row(to, yo);
        }
        memcpy(y, y1, sizeof y);
        memcpy(k1, k7, sizeof k1);
        t = t_new;
        h = fmin(h * fac, hmax);
    }
    fflush(stdout);
    fprintf(stderr, "stats: steps=%ld rejected=%ld rhs=%ld\n", steps, rejected, n_rhs);
    return 0;
}
