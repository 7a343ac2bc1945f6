#ifndef BGC_NO_MAIN
#include <errno.h>
#if defined(__linux__)
#include <sys/prctl.h> /* PR_SET_PDEATHSIG: bgc_die_with_parent */
#include <unistd.h>    /* getppid */
#endif
/* ================================================================ CSV === */

/* Numbers are written exactly as printf("%.17g") writes them (NaN as "nan"), in integer
   arithmetic: |v| = M 2^q (M < 2^53) times 10^m, a 128-bit mantissa from bgc_pow10 rounded
   down, is one 192-bit product whose integer part is v's 17 significant digits and whose
   next 64 bits, the fraction, are off by less than 1/8 of their last place.  That decides
   the rounding to nearest unless the fraction lies within that error of one half (exact
   ties, about one value in 2^63 otherwise): snprintf writes those, and subnormals,
   infinities and |v| outside 1e-40..1e40 (the range of the table).  Compile with
   -DBGC_PLAIN_PRINTF to always use snprintf. */
#define BGC_FMT_SIZE 32 /* bgc_fmt17 writes at most 26 bytes (it stores whole words) */
static unsigned long bgc_fmt_slow_count; /* snprintf fallbacks, for tests */

static int bgc_fmt_printf(char *buf, double v)
{
    bgc_fmt_slow_count++;
    if (v != v) {
        memcpy(buf, "nan", 4);
        return 3;
    }
    return snprintf(buf, BGC_FMT_SIZE, "%.17g", v);
}

#if !defined(BGC_PLAIN_PRINTF) && FLT_RADIX == 2 && DBL_MANT_DIG == 53 && DBL_MAX_EXP == 1024 \
    && ULLONG_MAX == 0xffffffffffffffffULL
typedef unsigned long long bgc_u64;

#if defined(__SIZEOF_INT128__) && !defined(BGC_NO_INT128)
__extension__ typedef unsigned __int128 bgc_u128;
/* a * b = (returned) 2^64 + *lo. */
static inline bgc_u64 bgc_mul64(bgc_u64 a, bgc_u64 b, bgc_u64 *lo)
{
    const bgc_u128 prod = (bgc_u128)a * b;
    *lo = (bgc_u64)prod;
    return (bgc_u64)(prod >> 64);
}
#else
/* a * b = (returned) 2^64 + *lo, from 32-bit halves (C99 has no 128-bit integer). */
static inline bgc_u64 bgc_mul64(bgc_u64 a, bgc_u64 b, bgc_u64 *lo)
{
    const bgc_u64 mask = 0xffffffffULL, a0 = a & mask, a1 = a >> 32, b0 = b & mask, b1 = b >> 32;
    const bgc_u64 p00 = a0 * b0, p01 = a0 * b1, p10 = a1 * b0;
    const bgc_u64 mid = (p00 >> 32) + (p01 & mask) + (p10 & mask);
    *lo = (mid << 32) | (p00 & mask);
    return a1 * b1 + (p01 >> 32) + (p10 >> 32) + (mid >> 32);
}
#endif

/* 10^m = (hi 2^64 + lo) 2^e2 rounded down, 2^127 <= hi 2^64 + lo < 2^128, for m in
   BGC_POW10_MIN..BGC_POW10_MAX. */
#define BGC_POW10_MIN (-24)
#define BGC_POW10_MAX 56
static const struct bgc_pow10_entry {
    bgc_u64 hi, lo;
    int e2;
} bgc_pow10[] = {
    { 0x9abe14cd44753b52ULL, 0xc4926a9672793542ULL, -207 }, /* 1e-24 */
    { 0xc16d9a0095928a27ULL, 0x75b7053c0f178293ULL, -204 }, /* 1e-23 */
    { 0xf1c90080baf72cb1ULL, 0x5324c68b12dd6338ULL, -201 }, /* 1e-22 */
    { 0x971da05074da7beeULL, 0xd3f6fc16ebca5e03ULL, -197 }, /* 1e-21 */
    { 0xbce5086492111aeaULL, 0x88f4bb1ca6bcf584ULL, -194 }, /* 1e-20 */
    { 0xec1e4a7db69561a5ULL, 0x2b31e9e3d06c32e5ULL, -191 }, /* 1e-19 */
    { 0x9392ee8e921d5d07ULL, 0x3aff322e62439fcfULL, -187 }, /* 1e-18 */
    { 0xb877aa3236a4b449ULL, 0x09befeb9fad487c2ULL, -184 }, /* 1e-17 */
    { 0xe69594bec44de15bULL, 0x4c2ebe687989a9b3ULL, -181 }, /* 1e-16 */
    { 0x901d7cf73ab0acd9ULL, 0x0f9d37014bf60a10ULL, -177 }, /* 1e-15 */
    { 0xb424dc35095cd80fULL, 0x538484c19ef38c94ULL, -174 }, /* 1e-14 */
    { 0xe12e13424bb40e13ULL, 0x2865a5f206b06fb9ULL, -171 }, /* 1e-13 */
    { 0x8cbccc096f5088cbULL, 0xf93f87b7442e45d3ULL, -167 }, /* 1e-12 */
    { 0xafebff0bcb24aafeULL, 0xf78f69a51539d748ULL, -164 }, /* 1e-11 */
    { 0xdbe6fecebdedd5beULL, 0xb573440e5a884d1bULL, -161 }, /* 1e-10 */
    { 0x89705f4136b4a597ULL, 0x31680a88f8953030ULL, -157 }, /* 1e-9 */
    { 0xabcc77118461cefcULL, 0xfdc20d2b36ba7c3dULL, -154 }, /* 1e-8 */
    { 0xd6bf94d5e57a42bcULL, 0x3d32907604691b4cULL, -151 }, /* 1e-7 */
    { 0x8637bd05af6c69b5ULL, 0xa63f9a49c2c1b10fULL, -147 }, /* 1e-6 */
    { 0xa7c5ac471b478423ULL, 0x0fcf80dc33721d53ULL, -144 }, /* 1e-5 */
    { 0xd1b71758e219652bULL, 0xd3c36113404ea4a8ULL, -141 }, /* 1e-4 */
    { 0x83126e978d4fdf3bULL, 0x645a1cac083126e9ULL, -137 }, /* 1e-3 */
    { 0xa3d70a3d70a3d70aULL, 0x3d70a3d70a3d70a3ULL, -134 }, /* 1e-2 */
    { 0xccccccccccccccccULL, 0xccccccccccccccccULL, -131 }, /* 1e-1 */
    { 0x8000000000000000ULL, 0x0000000000000000ULL, -127 }, /* 1e0 */
    { 0xa000000000000000ULL, 0x0000000000000000ULL, -124 }, /* 1e1 */
    { 0xc800000000000000ULL, 0x0000000000000000ULL, -121 }, /* 1e2 */
    { 0xfa00000000000000ULL, 0x0000000000000000ULL, -118 }, /* 1e3 */
    { 0x9c40000000000000ULL, 0x0000000000000000ULL, -114 }, /* 1e4 */
    { 0xc350000000000000ULL, 0x0000000000000000ULL, -111 }, /* 1e5 */
    { 0xf424000000000000ULL, 0x0000000000000000ULL, -108 }, /* 1e6 */
    { 0x9896800000000000ULL, 0x0000000000000000ULL, -104 }, /* 1e7 */
    { 0xbebc200000000000ULL, 0x0000000000000000ULL, -101 }, /* 1e8 */
    { 0xee6b280000000000ULL, 0x0000000000000000ULL, -98 }, /* 1e9 */
    { 0x9502f90000000000ULL, 0x0000000000000000ULL, -94 }, /* 1e10 */
    { 0xba43b74000000000ULL, 0x0000000000000000ULL, -91 }, /* 1e11 */
    { 0xe8d4a51000000000ULL, 0x0000000000000000ULL, -88 }, /* 1e12 */
    { 0x9184e72a00000000ULL, 0x0000000000000000ULL, -84 }, /* 1e13 */
    { 0xb5e620f480000000ULL, 0x0000000000000000ULL, -81 }, /* 1e14 */
    { 0xe35fa931a0000000ULL, 0x0000000000000000ULL, -78 }, /* 1e15 */
    { 0x8e1bc9bf04000000ULL, 0x0000000000000000ULL, -74 }, /* 1e16 */
    { 0xb1a2bc2ec5000000ULL, 0x0000000000000000ULL, -71 }, /* 1e17 */
    { 0xde0b6b3a76400000ULL, 0x0000000000000000ULL, -68 }, /* 1e18 */
    { 0x8ac7230489e80000ULL, 0x0000000000000000ULL, -64 }, /* 1e19 */
    { 0xad78ebc5ac620000ULL, 0x0000000000000000ULL, -61 }, /* 1e20 */
    { 0xd8d726b7177a8000ULL, 0x0000000000000000ULL, -58 }, /* 1e21 */
    { 0x878678326eac9000ULL, 0x0000000000000000ULL, -54 }, /* 1e22 */
    { 0xa968163f0a57b400ULL, 0x0000000000000000ULL, -51 }, /* 1e23 */
    { 0xd3c21bcecceda100ULL, 0x0000000000000000ULL, -48 }, /* 1e24 */
    { 0x84595161401484a0ULL, 0x0000000000000000ULL, -44 }, /* 1e25 */
    { 0xa56fa5b99019a5c8ULL, 0x0000000000000000ULL, -41 }, /* 1e26 */
    { 0xcecb8f27f4200f3aULL, 0x0000000000000000ULL, -38 }, /* 1e27 */
    { 0x813f3978f8940984ULL, 0x4000000000000000ULL, -34 }, /* 1e28 */
    { 0xa18f07d736b90be5ULL, 0x5000000000000000ULL, -31 }, /* 1e29 */
    { 0xc9f2c9cd04674edeULL, 0xa400000000000000ULL, -28 }, /* 1e30 */
    { 0xfc6f7c4045812296ULL, 0x4d00000000000000ULL, -25 }, /* 1e31 */
    { 0x9dc5ada82b70b59dULL, 0xf020000000000000ULL, -21 }, /* 1e32 */
    { 0xc5371912364ce305ULL, 0x6c28000000000000ULL, -18 }, /* 1e33 */
    { 0xf684df56c3e01bc6ULL, 0xc732000000000000ULL, -15 }, /* 1e34 */
    { 0x9a130b963a6c115cULL, 0x3c7f400000000000ULL, -11 }, /* 1e35 */
    { 0xc097ce7bc90715b3ULL, 0x4b9f100000000000ULL, -8 }, /* 1e36 */
    { 0xf0bdc21abb48db20ULL, 0x1e86d40000000000ULL, -5 }, /* 1e37 */
    { 0x96769950b50d88f4ULL, 0x1314448000000000ULL, -1 }, /* 1e38 */
    { 0xbc143fa4e250eb31ULL, 0x17d955a000000000ULL, 2 }, /* 1e39 */
    { 0xeb194f8e1ae525fdULL, 0x5dcfab0800000000ULL, 5 }, /* 1e40 */
    { 0x92efd1b8d0cf37beULL, 0x5aa1cae500000000ULL, 9 }, /* 1e41 */
    { 0xb7abc627050305adULL, 0xf14a3d9e40000000ULL, 12 }, /* 1e42 */
    { 0xe596b7b0c643c719ULL, 0x6d9ccd05d0000000ULL, 15 }, /* 1e43 */
    { 0x8f7e32ce7bea5c6fULL, 0xe4820023a2000000ULL, 19 }, /* 1e44 */
    { 0xb35dbf821ae4f38bULL, 0xdda2802c8a800000ULL, 22 }, /* 1e45 */
    { 0xe0352f62a19e306eULL, 0xd50b2037ad200000ULL, 25 }, /* 1e46 */
    { 0x8c213d9da502de45ULL, 0x4526f422cc340000ULL, 29 }, /* 1e47 */
    { 0xaf298d050e4395d6ULL, 0x9670b12b7f410000ULL, 32 }, /* 1e48 */
    { 0xdaf3f04651d47b4cULL, 0x3c0cdd765f114000ULL, 35 }, /* 1e49 */
    { 0x88d8762bf324cd0fULL, 0xa5880a69fb6ac800ULL, 39 }, /* 1e50 */
    { 0xab0e93b6efee0053ULL, 0x8eea0d047a457a00ULL, 42 }, /* 1e51 */
    { 0xd5d238a4abe98068ULL, 0x72a4904598d6d880ULL, 45 }, /* 1e52 */
    { 0x85a36366eb71f041ULL, 0x47a6da2b7f864750ULL, 49 }, /* 1e53 */
    { 0xa70c3c40a64e6c51ULL, 0x999090b65f67d924ULL, 52 }, /* 1e54 */
    { 0xd0cf4b50cfe20765ULL, 0xfff4b4e3f741cf6dULL, 55 }, /* 1e55 */
    { 0x82818f1281ed449fULL, 0xbff8f10e7a8921a4ULL, 59 }, /* 1e56 */
};

/* floor(log10(2^e)) for |e| <= 1650 (the constant is Ryu's). */
static int bgc_floor_log10_pow2(int e)
{
    return e >= 0 ? (int)(((unsigned long)e * 78913UL) >> 18)
                  : -(int)((((unsigned long)-e * 78913UL) >> 18) + 1);
}

/* floor(mant 2^q 10^m) and (in *frac) the next 64 bits, for mant < 2^53 and a result in
   [2^53, 2^60); the fraction is short by less than 1/8 of its last place. */
static inline bgc_u64 bgc_scaled(bgc_u64 mant, int q, int m, bgc_u64 *frac)
{
    const struct bgc_pow10_entry *p = &bgc_pow10[m - BGC_POW10_MIN];
    bgc_u64 w0, w1, w2, mid_lo;
    const bgc_u64 mid = bgc_mul64(mant, p->lo, &w0);
    int shift;
    w2 = bgc_mul64(mant, p->hi, &mid_lo);
    w1 = mid + mid_lo;
    w2 += w1 < mid; /* the product is w2 2^128 + w1 2^64 + w0 */
    shift = -(q + p->e2) - 64; /* 56..63: the binary point lies that far into w1 */
    *frac = (w1 << (64 - shift)) | (w0 >> shift);
    return (w2 << (64 - shift)) | (w1 >> shift);
}

/* The 8 digits of v < 10^8, all at once, as the word whose byte i (bits 8i..8i+7) is the
   character of digit i: v splits into two 4-digit lanes, each into two 2-digit lanes, each
   of those into two digits (the multiply-shifts divide exactly in these ranges). */
static inline bgc_u64 bgc_digits8(bgc_u64 v)
{
    const bgc_u64 high4 = (v * 109951163U) >> 40; /* v / 10000 */
    const bgc_u64 quads = high4 | (v - 10000U * high4) << 32;
    const bgc_u64 top2 = ((quads * 10486U) >> 20) & 0x0000007f0000007fULL; /* quads / 100 */
    const bgc_u64 pairs = (quads - 100U * top2) << 16 | top2;
    const bgc_u64 top1 = ((pairs * 103U) >> 10) & 0x000f000f000f000fULL; /* pairs / 10 */
    return ((pairs - 10U * top1) << 8 | top1) | 0x3030303030303030ULL;
}

/* Byte i of w into o[i], i < 8: one store where the bytes of a word are in that order
   (the test is a constant that compilers fold). */
static inline void bgc_store8(char *o, bgc_u64 w)
{
    const bgc_u64 one = 1;
    char first;
    int i;
    memcpy(&first, &one, 1);
    if (first == 1) {
        memcpy(o, &w, 8);
        return;
    }
    for (i = 0; i < 8; i++)
        o[i] = (char)(w >> (8 * i));
}

/* The %g layout of the 17 digits of d (10^16 <= d < 10^17) with decimal exponent x: fixed
   for -4 <= x < 17, else e-style.  The digits stay in registers (never stored and read
   back); whole words are stored, so it writes up to o[24]. */
static inline char *bgc_layout(char *o, bgc_u64 d, int x)
{
    const bgc_u64 high9 = d / 100000000U, low8 = d - 100000000U * high9;
    const bgc_u64 lead = high9 / 100000000U;
    const bgc_u64 w1 = bgc_digits8(high9 - 100000000U * lead), w2 = bgc_digits8(low8);
    int nd = 17, ax; /* significant digits without the trailing zeros */
    if ((w2 >> 56) == '0') /* the last digit */
        for (d /= 10U, nd--; d % 10U == 0; d /= 10U)
            nd--;
    o[0] = (char)('0' + lead);
    if (x >= 0 && x < 17) { /* digits 0..x, and '.' and digits x+1..nd-1 if nd > x + 1 */
        bgc_store8(o + 1, w1);
        bgc_store8(o + 9, w2);
        if (nd <= x + 1)
            return o + x + 1;
        if (x == 0) {
            bgc_store8(o + 2, w1);
            bgc_store8(o + 10, w2);
        } else if (x < 8) { /* digits x+1.. are w1:w2 shifted down by x bytes */
            bgc_store8(o + x + 2, w1 >> (8 * x) | w2 << (64 - 8 * x));
            bgc_store8(o + x + 10, w2 >> (8 * x));
        } else {
            bgc_store8(o + x + 2, w2 >> (8 * x - 64));
        }
        o[x + 1] = '.';
        return o + nd + 1;
    }
    if (x < 0 && x >= -4) { /* "0.", -x - 1 zeros, the digits */
        const char lead_char = o[0];
        memcpy(o, "0.000", 5);
        o += 1 - x;
        o[0] = lead_char;
        bgc_store8(o + 1, w1);
        bgc_store8(o + 9, w2);
        return o + nd;
    }
    o[1] = '.';
    bgc_store8(o + 2, w1);
    bgc_store8(o + 10, w2);
    o += nd > 1 ? nd + 1 : 1;
    ax = x < 0 ? -x : x;
    *o++ = 'e';
    *o++ = x < 0 ? '-' : '+';
    if (ax >= 100) {
        *o++ = (char)('0' + ax / 100);
        ax %= 100;
    }
    o[0] = (char)('0' + ax / 10);
    o[1] = (char)('0' + ax % 10);
    return o + 2;
}

/* Writes v into buf (>= BGC_FMT_SIZE bytes) as printf("%.17g", v); returns the length. */
static int bgc_fmt17(char *buf, double v)
{
    const bgc_u64 half = 1ULL << 63, ten17 = 100000000000000000ULL;
    bgc_u64 bits, mant, d, frac;
    char *o = buf;
    int e2, x, m;
    memcpy(&bits, &v, sizeof bits);
    e2 = (int)((bits >> 52) & 0x7ff); /* biased binary exponent */
    if (e2 == 0 || e2 == 0x7ff) {
        if (v != 0.0)
            return bgc_fmt_printf(buf, v); /* subnormal, inf or nan */
        if (signbit(v))
            *o++ = '-';
        *o++ = '0';
        *o = '\0';
        return (int)(o - buf);
    }
    mant = (bits & 0xfffffffffffffULL) | (1ULL << 52);
    x = bgc_floor_log10_pow2(e2 - 1023); /* floor(log10|v|) or one less */
    m = 16 - x;
    if (m - 1 < BGC_POW10_MIN || m > BGC_POW10_MAX)
        return bgc_fmt_printf(buf, v);
    d = bgc_scaled(mant, e2 - 1075, m, &frac);
    if (d >= ten17) {
        x++;
        d = bgc_scaled(mant, e2 - 1075, --m, &frac);
    }
    if (frac - (half - 1) <= 1)
        return bgc_fmt_printf(buf, v); /* too close to a tie to decide */
    d += frac >> 63; /* rounded to nearest */
    if (d == ten17) {
        d /= 10;
        x++;
    }
    *o = '-';
    o = bgc_layout(o + (bits >> 63), d, x);
    *o = '\0';
    return (int)(o - buf);
}
#else
static int bgc_fmt17(char *buf, double v)
{
    return bgc_fmt_printf(buf, v);
}
#endif

typedef struct bgc_writer {
    FILE *file;
    size_t len;
    int failed; /* a write failed: the errno it gave (-1 if none was set) */
    char buf[1 << 16];
} bgc_writer;

static bgc_writer bgc_out;

static void bgc_flush(bgc_writer *w)
{
    errno = 0;
    if (w->len && fwrite(w->buf, 1, w->len, w->file) != w->len && !w->failed)
        w->failed = errno ? errno : -1;
    w->len = 0;
}

static void bgc_put_number(bgc_writer *w, double v)
{
    if (sizeof w->buf - w->len < BGC_FMT_SIZE + 2)
        bgc_flush(w);
    w->len += (size_t)bgc_fmt17(w->buf + w->len, v);
}

/* --progress: a line "bgc-progress T T0 T_END" on stderr at the first row, then as the rows
   pass at most ten a second of processor time (bgc simulate draws them as a bar); off by
   default.  The clock is read once per thousandth of the time span at most. */
static struct bgc_progress {
    int on, lines;
    double t0, t_end, next;
    clock_t last;
} bgc_progress;

static void bgc_progress_row(double t)
{
    clock_t now;
    if (t < bgc_progress.next)
        return;
    bgc_progress.next = t + (bgc_progress.t_end - bgc_progress.t0) / 1000.0;
    now = clock();
    if (bgc_progress.lines && (double)(now - bgc_progress.last) < 0.1 * CLOCKS_PER_SEC)
        return;
    bgc_progress.lines++;
    bgc_progress.last = now;
    fprintf(stderr, "bgc-progress %.17g %.17g %.17g\n", t, bgc_progress.t0, bgc_progress.t_end);
}

static int bgc_csv_row(void *ctx, double t, const double *x, const double *y)
{
    bgc_writer *w = (bgc_writer *)ctx;
    int j;
    (void)x;
    if (bgc_progress.on)
        bgc_progress_row(t);
    bgc_put_number(w, t);
    for (j = 0; j < BGC_NUM_OUTPUTS; j++) {
        w->buf[w->len++] = ',';
        bgc_put_number(w, y[j]);
    }
    w->buf[w->len++] = '\n';
    return w->failed ? BGC_ERR_RUNTIME : 0;
}

static void bgc_csv_header(FILE *f)
{
    int j;
    fputs("t", f);
    for (j = 0; j < BGC_NUM_OUTPUTS; j++) {
        fputc(',', f);
        fputs(bgc_output_names[j], f);
    }
    fputc('\n', f);
}

/* ======================================================== command line === */

/* The event log (--events FILE): a header t,event,change, then a row per change at an event
   (a field with a comma, a quote or a line break quoted as CSV quotes it). */
static struct {
    const char *path;
    FILE *file;
    int failed;
} bgc_event_log = { NULL, NULL, 0 };

static void bgc_csv_field(FILE *f, const char *text)
{
    const char *c;
    if (strpbrk(text, ",\"\r\n") == NULL) {
        fputs(text, f);
        return;
    }
    fputc('"', f);
    for (c = text; *c; c++) {
        if (*c == '"')
            fputc('"', f);
        fputc(*c, f);
    }
    fputc('"', f);
}

static int bgc_log_event(void *ctx, double t, const char *what, const char *change)
{
    FILE *f = (FILE *)ctx;
    fprintf(f, "%.17g,", t);
    bgc_csv_field(f, what);
    fputc(',', f);
    bgc_csv_field(f, change);
    if (fputc('\n', f) == EOF) {
        bgc_event_log.failed = errno ? errno : -1;
        return BGC_ERR_RUNTIME;
    }
    return 0;
}



/* The inputs' data (--input FILE): a CSV file with a header row, a column t (non-decreasing:
   a repeated t is a jump, never three in a row) and a column per input given (named as
   bgc_input_name gives), a number in every field. */
static struct {
    const char *path;
    bgc_input_series *series; /* one per input */
    double *values; /* the file's numbers, column by column */
} bgc_input_file = { NULL, NULL, NULL };

/* The next comma-separated field of *line, its spaces trimmed ('\0'-terminated in place). */
static char *bgc_next_field(char **line)
{
    char *start = *line, *end, *comma = strchr(start, ',');
    if (comma) {
        *comma = '\0';
        *line = comma + 1;
    } else {
        *line = NULL;
    }
    while (*start == ' ' || *start == '\t')
        start++;
    end = start + strlen(start);
    while (end > start && (end[-1] == ' ' || end[-1] == '\t' || end[-1] == '\r'))
        *--end = '\0';
    return start;
}

/* The whole of the open file f as one '\0'-terminated string (its length in *size); NULL
   (message written) when out of memory.  Closes f. */
static char *bgc_read_text(const char *path, FILE *f, size_t *size)
{
    char *text = NULL;
    size_t cap = 0, got;
    *size = 0;
    do {
        if (*size + 4096 + 1 > cap) {
            char *more = (char *)realloc(text, cap = 2 * cap + 4096 + 1);
            if (!more) {
                free(text);
                fclose(f);
                fprintf(stderr, "error: out of memory reading '%s'\n", path);
                return NULL;
            }
            text = more;
        }
        got = fread(text + *size, 1, 4096, f);
        *size += got;
    } while (got > 0);
    fclose(f);
    text[*size] = '\0';
    return text;
}

/* The header line of --input's file: column[k] the input that column k gives (-2: none, the
   column t), *tcol the column t.  The number of columns, or -1 (message written). */
static int bgc_input_header(const char *path, char *line, int *column, int *tcol)
{
    int ncol = 0, k, j;
    *tcol = -1;
    while (line && ncol < 256) {
        const char *field = bgc_next_field(&line);
        column[ncol] = -2;
        if (strcmp(field, "t") == 0) {
            if (*tcol >= 0)
                goto twice;
            *tcol = ncol;
        } else {
            for (j = 0; j < BGC_NUM_INPUTS; j++)
                if (strcmp(field, bgc_input_name(j)) == 0)
                    break;
            if (j == BGC_NUM_INPUTS) {
                fprintf(stderr, "error: %s: '%s' is not an input of the model (its inputs:", path,
                        field);
                for (j = 0; j < BGC_NUM_INPUTS; j++)
                    fprintf(stderr, "%s %s", j ? "," : "", bgc_input_name(j));
                fprintf(stderr, "%s)\n", BGC_NUM_INPUTS ? "" : " none");
                return -1;
            }
            for (k = 0; k < ncol; k++)
                if (column[k] == j)
                    goto twice;
            if (bgc_input_file.series[j].n > 0) {
                fprintf(stderr, "error: %s: input '%s' is given twice\n", path, field);
                return -1;
            }
            column[ncol] = j;
        }
        ncol++;
    }
    if (*tcol < 0) {
        fprintf(stderr, "error: %s: the header has no column 't'\n", path);
        return -1;
    }
    if (line) {
        fprintf(stderr, "error: %s: more than 256 columns\n", path);
        return -1;
    }
    return ncol;
twice:
    fprintf(stderr, "error: %s: a column is named twice in the header\n", path);
    return -1;
}

/* The rows of data after the header (body: its lines, each '\0'-terminated, up to end) into
   v, row by row, cols numbers each, t in column tcol; the number of rows, or -1 (message
   written). */
static int bgc_input_rows(const char *path, char *body, const char *end, int cols, int tcol,
                          double *v)
{
    char *line, *next;
    long line_no = 1;
    int rows = 0, k;
    for (line = body; line && line < end; line = next) {
        char *rest = line;
        next = line + strlen(line) + 1;
        line_no++;
        if (strspn(line, " \t\r") == strlen(line))
            continue;
        for (k = 0; k < cols; k++) {
            char *field, *stop;
            double x;
            if (!rest) {
                fprintf(stderr, "error: %s:%ld: this row has %d fields, the header %d\n", path,
                        line_no, k, cols);
                return -1;
            }
            field = bgc_next_field(&rest);
            x = strtod(field, &stop);
            if (stop == field || *stop != '\0' || !isfinite(x)) {
                fprintf(stderr, "error: %s:%ld: '%s' is not a finite number\n", path, line_no,
                        field);
                return -1;
            }
            v[(size_t)rows * (size_t)cols + (size_t)k] = x;
        }
        if (rest) {
            fprintf(stderr, "error: %s:%ld: this row has more fields than the header (%d)\n",
                    path, line_no, cols);
            return -1;
        }
        if (rows > 0 && v[(size_t)rows * cols + tcol] < v[(size_t)(rows - 1) * cols + tcol]) {
            fprintf(stderr, "error: %s:%ld: t decreases here (t does not decrease from row to "
                    "row; a repeated t is a jump)\n", path, line_no);
            return -1;
        }
        if (rows > 1 && v[(size_t)rows * cols + tcol] == v[(size_t)(rows - 1) * cols + tcol]
            && v[(size_t)rows * cols + tcol] == v[(size_t)(rows - 2) * cols + tcol]) {
            fprintf(stderr, "error: %s:%ld: the same t a third time here (a jump is two rows of "
                    "the same t)\n", path, line_no);
            return -1;
        }
        rows++;
    }
    if (rows == 0)
        fprintf(stderr, "error: %s: no rows of data\n", path);
    return rows > 0 ? rows : -1;
}

/* The inputs' series from the rows of data v (row-major, rows x cols): the values transposed
   into bgc_input_file.values, so that each column is an array; 0, or -1 (message written). */
static int bgc_input_columns(const char *path, const double *v, int rows, int cols,
                             const int *column, int tcol)
{
    double *cm = (double *)malloc(sizeof(double) * (size_t)rows * (size_t)cols);
    int r, k;
    if (!cm) {
        fprintf(stderr, "error: out of memory reading '%s'\n", path);
        return -1;
    }
    for (r = 0; r < rows; r++)
        for (k = 0; k < cols; k++)
            cm[(size_t)k * rows + r] = v[(size_t)r * cols + k];
    bgc_input_file.values = cm;
    for (k = 0; k < cols; k++)
        if (column[k] >= 0) {
            bgc_input_series *s = &bgc_input_file.series[column[k]];
            s->n = rows;
            s->t = cm + (size_t)tcol * rows;
            s->u = cm + (size_t)k * rows;
        }
    return 0;
}

/* Reads --input's file into bgc_input_file.series; 0, or BGC_ERR_USAGE with a message. */
static int bgc_read_inputs(void)
{
    const char *path = bgc_input_file.path;
    FILE *f = fopen(path, "rb");
    char *text, *line, *next, *body;
    size_t size;
    int column[256], tcol, rows = 0, cols, rc = BGC_ERR_USAGE;
    double *v;
    if (!f) {
        fprintf(stderr, "error: cannot read the input file '%s': %s\n", path, strerror(errno));
        return BGC_ERR_USAGE;
    }
    if (!bgc_input_file.series)
        bgc_input_file.series = (bgc_input_series *)calloc((size_t)BGC_DIM(BGC_NUM_INPUTS),
                                                           sizeof *bgc_input_file.series);
    if (!bgc_input_file.series) {
        fclose(f);
        fprintf(stderr, "error: out of memory reading '%s'\n", path);
        return BGC_ERR_USAGE;
    }
    text = bgc_read_text(path, f, &size);
    if (!text)
        return BGC_ERR_USAGE;
    body = strchr(text, '\n');
    if (body)
        *body++ = '\0';
    cols = bgc_input_header(path, text, column, &tcol);
    if (cols < 0) {
        free(text);
        return BGC_ERR_USAGE;
    }
    for (line = body; line; line = next) { /* the lines cut apart, the rows of data counted */
        next = strchr(line, '\n');
        if (next)
            *next++ = '\0';
        if (strspn(line, " \t\r") != strlen(line))
            rows++;
    }
    v = (double *)malloc(sizeof(double) * (size_t)BGC_DIM(rows * cols));
    if (!v) {
        free(text);
        fprintf(stderr, "error: out of memory reading '%s'\n", path);
        return BGC_ERR_USAGE;
    }
    rows = bgc_input_rows(path, body, text + size + 1, cols, tcol, v);
    free(text);
    if (rows > 0 && bgc_input_columns(path, v, rows, cols, column, tcol) == 0)
        rc = 0;
    free(v);
    return rc;
}

static const char bgc_usage[] =
    " [--t-end T] [--dt DT] [--solver NAME] [--rtol R] [--atol A]\n"
    "       [--step H] [--max-steps N] [-p NAME=VALUE ...] [--stats] [--progress]\n"
    "       [--project-initial | --allow-inconsistent]\n"
    "       [--max-step H] [--error-states N] [--event-rows] [--events FILE] [--input FILE]\n"
    "       [--batch FILE|- [--metric KIND:OUTPUT ...] [--trajectories DIR]]\n";

static void bgc_print_usage(FILE *f)
{
    fprintf(f, "usage: %s%s", bgc_ident, bgc_usage);
}

static void bgc_help(void)
{
    bgc_settings s;
    bgc_params p;
    int j;
    bgc_settings_default(&s);
    bgc_params_defaults(&p, NULL);
    bgc_print_usage(stdout);
    printf("Simulates the model and writes CSV (t and the outputs) to stdout.\n"
           "  --t-end T          end time (%.17g; the start time is %.17g)\n"
           "  --dt DT            output interval (%.17g)\n"
           "  --solver NAME      the solver (%s), one of those listed below\n"
           "  --rtol R           relative tolerance of the adaptive solvers (%.17g)\n"
           "  --atol A           absolute tolerance of the adaptive solvers (%.17g)\n"
           "  --step H           step of the fixed-step solvers (default: dt)\n"
           "  --max-steps N      the most steps between two output times (%ld; 0: no limit)\n"
           "  --max-step H       every solver's largest step (default: no bound)\n"
           "  --error-states N   the error control weighs the first N states only (0: all)\n"
           "  --event-rows       two rows at each event: its left and right limits\n"
           "  --events FILE      the event log: t,event,change, a row per change\n"
           "  --input FILE       the inputs' data: CSV, a column t and one per input\n"
           "  -p NAME=VALUE      set a parameter; derived parameters follow\n"
           "  --project-initial  project the initial state onto the constraints\n"
           "  --allow-inconsistent  start from an initial state that violates the constraints\n"
           "                     (the correctors pull it back): neither refused nor projected\n"
           "  --stats            print the solver's counters to stderr\n"
           "  --progress         report the progress on stderr: lines bgc-progress T T0 T_END\n"
           "  --batch FILE       one run per line of FILE (- for stdin): NAME=VALUE words;\n"
           "                     writes a CSV row per run: run,status,metrics,steps,rejected,\n"
           "                     rhs,cpu,message\n"
           "  --metric K:OUTPUT  with --batch: a column, K one of final, max, min, maxabs, rms\n"
           "  --trajectories DIR with --batch: each run's CSV also to DIR/run-NNNNNN.csv\n",
           s.t_end, s.t0, s.dt, bgc_solver_names[s.solver], s.rtol, s.atol, s.max_steps);
    printf("solvers:\n");
    for (j = 0; j < BGC_NUM_SOLVERS; j++)
        printf("  %-8s %s\n", bgc_methods[j].name, bgc_methods[j].summary);
    if (BGC_NUM_PARAMS > 0)
        printf("parameters (NAME = default):\n");
    for (j = 0; j < BGC_NUM_PARAMS; j++)
        printf("  %s = %.17g\n", bgc_param_names[j], *bgc_param_ref(&p, j));
}

/* A decimal number (digits, sign, '.', exponent: no hex, inf or nan), finite. */
static int bgc_parse_number(const char *option, const char *text, double *out)
{
    char *end;
    if (*text != '\0' && strspn(text, "0123456789+-.eE") == strlen(text)) {
        *out = strtod(text, &end);
        if (*end == '\0' && isfinite(*out))
            return 0;
    }
    fprintf(stderr, "error: invalid value for %s: '%s'\n", option, text);
    return -1;
}

static int bgc_parse_param(const char *text, bgc_params *p, int *given)
{
    const char *eq = strrchr(text, '=');
    char name[256];
    size_t len = eq ? (size_t)(eq - text) : 0;
    int j;
    double v;
    if (!eq || len == 0 || len >= sizeof name) {
        fprintf(stderr, "error: -p expects NAME=VALUE, got '%s'\n", text);
        return -1;
    }
    memcpy(name, text, len);
    name[len] = '\0';
    j = bgc_param_index(name);
    if (j < 0) {
        fprintf(stderr, "error: unknown parameter '%s'\n", name);
        return -1;
    }
    if (bgc_parse_number(name, eq + 1, &v))
        return -1;
    *bgc_param_ref(p, j) = v;
    given[j] = 1;
    return 0;
}

static int bgc_parse_solver(const char *text, int *solver)
{
    int k = bgc_solver_index(text);
    if (k >= 0) {
        *solver = k;
        return 0;
    }
    fprintf(stderr, "error: unknown solver '%s' (expected %s)\n", text, BGC_SOLVER_LIST);
    return -1;
}

/* Applies option `name` (one that takes a value) to the run. */
static int bgc_apply_option(const char *name, const char *value, bgc_settings *s, bgc_params *p,
                            int *given)
{
    if (strcmp(name, "-p") == 0)
        return bgc_parse_param(value, p, given);
    if (strcmp(name, "--solver") == 0)
        return bgc_parse_solver(value, &s->solver);
    if (strcmp(name, "--max-steps") == 0) {
        double n;
        if (bgc_parse_number(name, value, &n))
            return -1;
        if (n >= 0.0 && n <= 1e15 && n == floor(n)) {
            s->max_steps = (long)n;
            return 0;
        }
        fprintf(stderr, "error: --max-steps must be a whole number from 0 (no limit) to 1e15\n");
        return -1;
    }
    if (strcmp(name, "--error-states") == 0) {
        double n;
        if (bgc_parse_number(name, value, &n))
            return -1;
        if (n >= 0.0 && n <= BGC_NUM_STATES && n == floor(n)) {
            s->error_states = (long)n;
            return 0;
        }
        fprintf(stderr, "error: --error-states must be a whole number from 0 (all) to %d\n",
                BGC_NUM_STATES);
        return -1;
    }
    if (strcmp(name, "--max-step") == 0) {
        if (bgc_parse_number(name, value, &s->hmax))
            return -1;
        if (s->hmax > 0.0)
            return 0;
        fprintf(stderr, "error: --max-step must be positive\n");
        return -1;
    }
    if (strcmp(name, "--events") == 0) {
        bgc_event_log.path = value;
        return 0;
    }
    if (strcmp(name, "--input") == 0) {
        bgc_input_file.path = value;
        return bgc_read_inputs() ? -1 : 0;
    }
    if (strcmp(name, "--step") == 0) {
        if (bgc_parse_number(name, value, &s->step))
            return -1;
        if (s->step > 0.0)
            return 0;
        fprintf(stderr, "error: --step must be positive\n");
        return -1;
    }
    return bgc_parse_number(name, value, strcmp(name, "--t-end") == 0 ? &s->t_end
                                         : strcmp(name, "--dt") == 0  ? &s->dt
                                         : strcmp(name, "--rtol") == 0 ? &s->rtol
                                                                      : &s->atol);
}

/* -1 to run, else the exit status: 0 after --help, 2 after a usage error.  *project: 1 with
   --project-initial, 2 with --allow-inconsistent (they exclude each other). */
static int bgc_parse_args(int argc, char **argv, bgc_settings *s, bgc_params *p, int *given,
                          int *project, int *stats)
{
    static const char *const with_value[] = { "--t-end", "--dt", "--solver", "--rtol",
                                              "--atol", "--step", "--max-steps", "-p",
                                              "--max-step", "--events", "--input",
                                              "--error-states" };
    int i, k;
    for (i = 1; i < argc; i++) {
        const char *arg = argv[i], *eq = strncmp(arg, "--", 2) == 0 ? strchr(arg, '=') : NULL;
        const size_t len = eq ? (size_t)(eq - arg) : strlen(arg);
        const char *value;
        if (strcmp(arg, "-h") == 0 || strcmp(arg, "--help") == 0) {
            bgc_help();
            return 0;
        }
        if (strcmp(arg, "--progress") == 0) {
            bgc_progress.on = 1;
            continue;
        }
        if (strcmp(arg, "--project-initial") == 0 || strcmp(arg, "--allow-inconsistent") == 0) {
            const int mode = arg[2] == 'p' ? 1 : 2;
            if (*project && *project != mode) {
                fprintf(stderr, "error: --project-initial and --allow-inconsistent exclude each "
                        "other\n");
                return BGC_ERR_USAGE;
            }
            *project = mode;
            continue;
        }
        if (strcmp(arg, "--stats") == 0) {
            *stats = 1;
            continue;
        }
        if (strcmp(arg, "--event-rows") == 0) {
            s->event_rows = 1;
            continue;
        }
        for (k = 0; k < BGC_COUNT(with_value); k++)
            if (strlen(with_value[k]) == len && strncmp(arg, with_value[k], len) == 0)
                break;
        if (k == BGC_COUNT(with_value)) {
            fprintf(stderr, "error: unknown option '%s'\n", arg);
            bgc_print_usage(stderr);
            return BGC_ERR_USAGE;
        }
        value = eq ? eq + 1 : (i + 1 < argc ? argv[++i] : NULL);
        if (!value) {
            fprintf(stderr, "error: option '%s' needs a value\n", arg);
            bgc_print_usage(stderr);
            return BGC_ERR_USAGE;
        }
        if (bgc_apply_option(with_value[k], value, s, p, given))
            return BGC_ERR_USAGE;
    }
    return -1;
}

/* The run's settings from the command line (and the parameters it sets), checked: -1 to
   run, else the exit status (as bgc_parse_args). */
static int bgc_settings_from_args(int argc, char **argv, bgc_settings *s, bgc_params *p,
                                  int *given, int *project, int *stats)
{
    char msg[1024];
    int rc;
    bgc_settings_default(s);
    rc = bgc_parse_args(argc, argv, s, p, given, project, stats);
    if (rc < 0 && bgc_check_settings(s, msg, sizeof msg)) {
        fprintf(stderr, "error: %s\n", msg);
        return BGC_ERR_USAGE;
    }
    return rc;
}

/* SIGINT, SIGTERM: the run stops at its next step, as a failure, its rows written. */
static void bgc_on_signal(int sig)
{
    bgc_request_stop(sig);
}

/* Started by bgc (BGC_PARENT_PID in the environment: bgc's process id), the program dies
   with it instead of running on as an orphan when bgc is killed: on Linux, the kernel sends
   it SIGKILL when its parent ends (and it ends at once if the parent did before).  Run by
   anything else, or elsewhere, this does nothing. */
static void bgc_die_with_parent(void)
{
#if defined(__linux__) && defined(PR_SET_PDEATHSIG) && defined(SIGKILL)
    const char *parent = getenv("BGC_PARENT_PID");
    if (parent == NULL || *parent == '\0')
        return;
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if ((long)getppid() != strtol(parent, NULL, 10))
        raise(SIGKILL);
#endif
}

/* The write error's message: "cannot write the output: REASON" (bgc simulate reads it). */
static void bgc_write_failed(int err)
{
    fprintf(stderr, "error: cannot write the output: %s\n",
            err > 0 ? strerror(err) : "write error");
}

static int bgc_batch_main(int argc, char **argv); /* --batch: below (batch.c) */

int main(int argc, char **argv)
{
    bgc_settings s;
    bgc_params p;
    bgc_stats st = { 0, 0, 0, 0, 0, 0, 0, 0.0, 0.0, 0.0, 0, 0, 0 };
    int given[BGC_DIM(BGC_NUM_PARAMS)] = { 0 };
    double x0[BGC_DIM(BGC_NUM_STATES)] = { 0.0 };
    char msg[1024];
    int project = 0, stats = 0, rc, i;

    bgc_die_with_parent();
    rc = bgc_batch_main(argc, argv);
    if (rc >= 0)
        return rc;
    rc = bgc_settings_from_args(argc, argv, &s, &p, given, &project, &stats);
    if (rc >= 0)
        return rc;
    bgc_params_defaults(&p, given);
    for (i = 0; i < BGC_NUM_PARAMS; i++)
        if (!isfinite(*bgc_param_ref(&p, i))) {
            fprintf(stderr, "error: parameter '%s' is not finite\n", bgc_param_names[i]);
            return BGC_ERR_RUNTIME;
        }
    bgc_init(&p, x0);
    i = bgc_first_nonfinite(x0, BGC_NUM_STATES);
    if (i >= 0) {
        fprintf(stderr, "error: at t = %.17g: state '%s' is not finite\n", s.t0, bgc_state_names[i]);
        return BGC_ERR_RUNTIME;
    }
    if (project == 1 && bgc_project_initial(s.t0, x0, &p, msg, sizeof msg)) {
        fprintf(stderr, "error: %s\n", msg);
        return BGC_ERR_CONSTRAINT;
    }
    if ((project == 2 ? bgc_check_constraints_finite : bgc_check_constraints)(s.t0, x0, &p,
                                                                              stderr))
        return BGC_ERR_CONSTRAINT;

    s.inputs = bgc_input_file.series;
    if (bgc_event_log.path) {
        bgc_event_log.file = fopen(bgc_event_log.path, "w");
        if (!bgc_event_log.file) {
            fprintf(stderr, "error: cannot write the event log '%s': %s\n", bgc_event_log.path,
                    strerror(errno));
            return BGC_ERR_USAGE;
        }
        fputs("t,event,change\n", bgc_event_log.file);
        s.on_event = bgc_log_event;
        s.event_ctx = bgc_event_log.file;
    }
    signal(SIGINT, bgc_on_signal);
    signal(SIGTERM, bgc_on_signal);
    bgc_out.file = stdout;
    bgc_csv_header(stdout);
    bgc_progress.t0 = bgc_progress.next = s.t0;
    bgc_progress.t_end = s.t_end;
    rc = bgc_simulate(&s, &p, x0, bgc_csv_row, &bgc_out, &st, msg, sizeof msg);
    bgc_flush(&bgc_out);
    errno = 0;
    if (fflush(stdout) != 0 && !bgc_out.failed)
        bgc_out.failed = errno ? errno : -1;
    if (bgc_event_log.file && fclose(bgc_event_log.file) != 0 && !bgc_event_log.failed)
        bgc_event_log.failed = errno ? errno : -1;
    if (bgc_event_log.failed && !bgc_out.failed)
        bgc_out.failed = bgc_event_log.failed;
    if (bgc_out.failed) {
        bgc_write_failed(bgc_out.failed);
        return BGC_ERR_RUNTIME;
    }
    if (stats)
        bgc_print_stats(stderr, &st);
    if (rc) {
        fprintf(stderr, "error: %s\n", msg);
        return BGC_ERR_RUNTIME;
    }
    return 0;
}
#endif /* BGC_NO_MAIN */
