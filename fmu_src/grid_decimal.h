/*
 * The exact decimal-to-double conversion of the terrain reader: a grid
 * value's text, e.g. "0.003880" or Python's shortest round-trip
 * "-0.012345678901234567", to the double strtod gives in the C locale,
 * correctly rounded, without strtod (which costs several times as much a
 * value).  What the reader calls:
 *   plain_decimal: a value in the read buffer (the grid's bulk: the usual
 *     [-]digits.digits through grid_decimal, any other through
 *     scan_decimal);
 *   scan_decimal: the longest number at a place in a buffer;
 *   fast_decimal: a whole token.
 * Each returns NULL (fast_decimal 0) for what it does not take, which the
 * reader hands to strtod.  The byte at the buffer's end must stop a number
 * (the reader's NUL), and plain_decimal reads up to PLAIN_DECIMAL_REACH
 * bytes past a value's start, which the reader keeps inside its buffer.
 * Below them: the exact powers of ten, the 128-bit reciprocal and division
 * paths (reciprocal_decimal, long_decimal), and the digits read eight at a
 * time in 64-bit words (SWAR) or sixteen at a time with SSE2.
 *
 * A header of static functions, included by terrain_reader.c alone: the
 * reader's loop over the grid inlines plain_decimal (and grid_decimal and
 * reciprocal_decimal within it).  From a separate source file each value
 * would be a call, its registers saved and restored: a quarter more
 * instructions to load a grid of 17-digit values, where no link-time
 * optimisation inlines across files (an importer compiling the FMU's
 * sources, the sanitizer builds).
 */
#ifndef JUNO_GRID_DECIMAL_H
#define JUNO_GRID_DECIMAL_H

#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

/* scan_decimal inlined into its callers, and reciprocal_decimal into
 * grid_decimal: as calls, their registers are saved and restored for
 * every value they read (a tenth of the reading for scan_decimal). */
#if defined(__GNUC__)
#define SCAN_INLINE inline __attribute__((always_inline))
#else
#define SCAN_INLINE inline
#endif

/* Powers of ten that doubles hold exactly: 10^k = 2^k 5^k and 5^22 < 2^53. */
static const double pow10_exact[23] = {
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11,
    1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22
};

/* The same and their negatives, [k][1] = -10^k: a quotient's sign from
 * the divisor, without a test (m / -10^k = -(m / 10^k), also for m = 0). */
static const double signed_pow10_exact[23][2] = {
    {1e0, -1e0}, {1e1, -1e1}, {1e2, -1e2}, {1e3, -1e3}, {1e4, -1e4}, {1e5, -1e5},
    {1e6, -1e6}, {1e7, -1e7}, {1e8, -1e8}, {1e9, -1e9}, {1e10, -1e10}, {1e11, -1e11},
    {1e12, -1e12}, {1e13, -1e13}, {1e14, -1e14}, {1e15, -1e15}, {1e16, -1e16},
    {1e17, -1e17}, {1e18, -1e18}, {1e19, -1e19}, {1e20, -1e20}, {1e21, -1e21},
    {1e22, -1e22}
};

#if defined(__SIZEOF_INT128__) && defined(FLT_EVAL_METHOD) && FLT_EVAL_METHOD == 0
__extension__ typedef unsigned __int128 u128;   /* GCC and Clang; __extension__: not ISO C */

/* 5^0 .. 5^27 (5^27 < 2^63) */
static const uint64_t pow5[28] = {
    1u, 5u, 25u, 125u, 625u, 3125u, 15625u, 78125u, 390625u, 1953125u, 9765625u, 48828125u,
    244140625u, 1220703125u, 6103515625u, 30517578125u, 152587890625u, 762939453125u,
    3814697265625u, 19073486328125u, 95367431640625u, 476837158203125u, 2384185791015625u,
    11920928955078125u, 59604644775390625u, 298023223876953125u, 1490116119384765625u,
    7450580596923828125u
};

/* A normal double kept * 2^e2 (2^52 <= kept < 2^53), built from its fields
 * rather than by ldexp. */
static double double_from_parts(uint64_t kept, int e2)
{
    const uint64_t bits = ((uint64_t)(52 + e2 + 1023) << 52) | (kept & (((uint64_t)1 << 52) - 1));
    double v;
    memcpy(&v, &bits, sizeof v);
    return v;
}

/* 1/5^n for n = 1..27 as 128-bit fixed point: r = floor(2^s / 5^n) with s
 * chosen so that 2^127 <= r < 2^128 (s = 127 + the bit length of 5^n);
 * scale is the exponent field of 2^(129 - s - n), the power of two that
 * turns the top half of m r (m shifted to the top of a word) into m / 10^n. */
static const struct { uint64_t hi, lo; int scale; } recip5[28] = {
    {0u, 0u, 0},   /* n = 0 is never used: 10^0 is exact */
    {0xccccccccccccccccu, 0xccccccccccccccccu, 1021},
    {0xa3d70a3d70a3d70au, 0x3d70a3d70a3d70a3u, 1018},
    {0x83126e978d4fdf3bu, 0x645a1cac083126e9u, 1015},
    {0xd1b71758e219652bu, 0xd3c36113404ea4a8u, 1011},
    {0xa7c5ac471b478423u, 0x0fcf80dc33721d53u, 1008},
    {0x8637bd05af6c69b5u, 0xa63f9a49c2c1b10fu, 1005},
    {0xd6bf94d5e57a42bcu, 0x3d32907604691b4cu, 1001},
    {0xabcc77118461cefcu, 0xfdc20d2b36ba7c3du, 998},
    {0x89705f4136b4a597u, 0x31680a88f8953030u, 995},
    {0xdbe6fecebdedd5beu, 0xb573440e5a884d1bu, 991},
    {0xafebff0bcb24aafeu, 0xf78f69a51539d748u, 988},
    {0x8cbccc096f5088cbu, 0xf93f87b7442e45d3u, 985},
    {0xe12e13424bb40e13u, 0x2865a5f206b06fb9u, 981},
    {0xb424dc35095cd80fu, 0x538484c19ef38c94u, 978},
    {0x901d7cf73ab0acd9u, 0x0f9d37014bf60a10u, 975},
    {0xe69594bec44de15bu, 0x4c2ebe687989a9b3u, 971},
    {0xb877aa3236a4b449u, 0x09befeb9fad487c2u, 968},
    {0x9392ee8e921d5d07u, 0x3aff322e62439fcfu, 965},
    {0xec1e4a7db69561a5u, 0x2b31e9e3d06c32e5u, 961},
    {0xbce5086492111aeau, 0x88f4bb1ca6bcf584u, 958},
    {0x971da05074da7beeu, 0xd3f6fc16ebca5e03u, 955},
    {0xf1c90080baf72cb1u, 0x5324c68b12dd6338u, 951},
    {0xc16d9a0095928a27u, 0x75b7053c0f178293u, 948},
    {0x9abe14cd44753b52u, 0xc4926a9672793542u, 945},
    {0xf79687aed3eec551u, 0x3a83ddbd83f52204u, 941},
    {0xc612062576589ddau, 0x95364afe032a819du, 938},
    {0x9e74d1b791e07e48u, 0x775ea264cf55347du, 935},
};

/* (sign ? -1 : 1) m / 10^n correctly rounded for 1 <= m < 2^64,
 * 1 <= n <= 27, by a multiplication with recip5[n] instead of
 * long_decimal's 128-bit division, which costs several times more; sign
 * is 0 or the sign bit (2^63).  With w = m 2^z (top bit at bit 63) and
 * X = w 2^s / 5^n, m / 10^n = X 2^(-s-n-z).  P = w r falls short of X by
 * w (2^s / 5^n - r), more than 0 and less than 2^64, so t = floor(P / 2^64)
 * has X / 2^64 strictly between t and t + 2.  t's top bit is bit 126 or
 * 127 (P >= 2^63 2^127); the 53 bits from there down are the candidate,
 * the bits below it (rest, all but the top 53 of t's) set against half
 * their range decide the rounding:
 *   rest <= half - 2: X / 2^64 lies below the midpoint: the candidate;
 *   rest >= half: above it;
 *   rest = half - 1: too close to tell (an exact tie lands here, as P < X):
 *     returns 0 and the caller divides; otherwise *v is set and it returns 1.
 * The rest spans t's low word and the low bits of its high word hi: but
 * for rest = half - 1, which needs the low word all ones and is tested
 * only then, its top bit (the round bit, in hi) alone decides.  The
 * conversion of hi to double rounds the same way, to nearest at that bit,
 * once hi's lowest bit (nine or more places under the round bit) is set:
 * then no tie is left to round to even.  hi is halved first, so that it
 * converts as a signed integer, and the double times 2^(129-s-n-z)
 * (recip5's scale less z, with the sign) is the value: a product by a
 * power of two, exact, as the values lie far from the subnormals. */
static SCAN_INLINE int reciprocal_decimal(uint64_t m, int n, uint64_t sign, double *v)
{
    const int z = __builtin_clzll(m);
    const uint64_t w = m << z;
    /* t = w hi + floor(w lo / 2^64) in two words: the carry out of the low
     * word by hand, which compilers do not spill as they do a 128-bit sum */
    const u128 by_hi = (u128)w * recip5[n].hi;
    const uint64_t by_lo = (uint64_t)(((u128)w * recip5[n].lo) >> 64);
    const uint64_t lo = (uint64_t)by_hi + by_lo;
    const uint64_t hi = (uint64_t)(by_hi >> 64) + (lo < by_lo);
    const uint64_t scale_bits = sign | ((uint64_t)(recip5[n].scale - z) << 52);
    double scale;

    if (lo == UINT64_MAX) {
        const int below = 10 + (int)(hi >> 63);       /* bits of hi under the top 53 */
        if (((hi + 1) & (((uint64_t)1 << below) - 1)) == (uint64_t)1 << (below - 1))
            return 0;                                 /* rest = half - 1 */
    }
    memcpy(&scale, &scale_bits, sizeof scale);
    *v = (double)(int64_t)((hi >> 1) | 1) * scale;
    return 1;
}

/* m * 10^e10 correctly rounded (round half to even), for 1 <= m < 2^64 and
 * -27 <= e10 <= 27, with 128-bit integers: the digit strings fast_decimal's
 * division cannot take exactly (more than 2^53, e.g. the 17 significant
 * digits of a shortest round-trip double).  10^e10 = 5^e10 2^e10 and
 * 5^27 < 2^64:
 *   e10 >= 0: P = m 5^e10 < 2^127 exactly, rounded to 53 bits, times 2^e10;
 *   e10 < 0: reciprocal_decimal, or where it cannot tell the rounding,
 *            q = floor(m 2^s / 5^n) (n = -e10, s shifts m to the top of 128
 *            bits, so q has at least 64 bits) and its remainder as a sticky
 *            bit, q rounded to 53 bits, times 2^(-s-n).
 * Results lie between 1e-27 and 2^64 1e27, far from overflow and from the
 * subnormals, so the scaling by a power of two is exact.  Returns 0
 * outside that range (the caller then uses strtod). */
static int long_decimal(uint64_t m, int e10, double *v)
{
    u128 q;
    uint64_t p5, kept;
    int bits, shift, scale, sticky = 0;   /* __builtin_clzll: GCC and Clang, as __int128 */

    if (e10 < -27 || e10 > 27)
        return 0;
    if (e10 < 0) {
        if (reciprocal_decimal(m, -e10, 0, v))
            return 1;
    }
    p5 = pow5[e10 < 0 ? -e10 : e10];
    if (e10 >= 0) {
        q = (u128)m * p5;
        scale = e10;
    } else {
        const int s = 64 + __builtin_clzll(m);      /* m 2^s has its top bit at bit 127 */
        const u128 num = (u128)m << s;
        q = num / p5;
        sticky = num - q * p5 != 0;
        scale = e10 - s;
    }
    bits = (uint64_t)(q >> 64) != 0 ? 128 - __builtin_clzll((uint64_t)(q >> 64))
                                    : 64 - __builtin_clzll((uint64_t)q);   /* q >= 1 */
    if (bits <= 53) {
        *v = ldexp((double)(uint64_t)q, scale);
        return 1;
    }
    shift = bits - 53;
    kept = (uint64_t)(q >> shift);
    {
        const u128 rest = q & (((u128)1 << shift) - 1), half = (u128)1 << (shift - 1);
        if (rest > half || (rest == half && (sticky || (kept & 1))))
            kept++;
    }
    if (kept >> 53)                        /* rounded up to 2^53 */
        kept >>= 1, shift++;
    /* kept * 2^(scale + shift) with 2^52 <= kept < 2^53: a normal double
     * (the range above) */
    *v = double_from_parts(kept, scale + shift);
    return 1;
}
#else
/* Without 128-bit integers both decline (reciprocal_decimal returns 0 as
 * where it cannot tell): strtod reads those values. */
static int reciprocal_decimal(uint64_t m, int n, uint64_t sign, double *v)
{
    (void)m;
    (void)n;
    (void)sign;
    (void)v;
    return 0;
}

static int long_decimal(uint64_t m, int e10, double *v)
{
    (void)m;
    (void)e10;
    (void)v;
    return 0;
}
#endif

/* Eight digits at a time (little-endian SWAR, GCC and Clang; Lemire's
 * eight-digit test and parse_eight_digits_unrolled), on the eight bytes at
 * a place read as one word: byte 0 is the first character. */
#if defined(__GNUC__) && defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
#define DIGIT_RUN_SWAR 1

static uint64_t load_word(const char *p)
{
    uint64_t w;
    memcpy(&w, p, 8);                   /* any alignment */
    return w;
}

/* The two bytes at p, the first in the low byte. */
static uint16_t load_pair(const char *p)
{
    uint16_t w;
    memcpy(&w, p, 2);                   /* any alignment */
    return w;
}

/* 0x80 in the first byte of w that is not an ASCII digit and 0 in every
 * byte before it (the bytes after it may be flagged or not): a carry or
 * borrow between bytes starts only at a non-digit and moves to higher
 * bytes.  0 when all eight are digits. */
static uint64_t nondigit_flags(uint64_t w)
{
    return ((w + 0x4646464646464646u) | (w - 0x3030303030303030u)) & 0x8080808080808080u;
}

/* How many digits lead the word whose nondigit_flags are flags (not 0). */
static int leading_digit_count(uint64_t flags)
{
    return __builtin_ctzll(flags) >> 3;
}

/* The number eight digit values (0..9, one a byte) spell. */
static uint64_t eight_digit_values(uint64_t d)
{
    const uint64_t mask = 0x000000FF000000FFu;
    const uint64_t mul1 = 100 + (1000000ull << 32), mul2 = 1 + (10000ull << 32);
    d = d * 10 + (d >> 8);              /* pairs of digits */
    return (((d & mask) * mul1) + (((d >> 16) & mask) * mul2)) >> 32;
}

/* The number eight ASCII digits spell. */
static uint64_t eight_digits(uint64_t w)
{
    return eight_digit_values(w - 0x3030303030303030u);
}

/* ceil(2^32 / 10^(8-k)) for k = 1..8: multiplying a multiple of 10^(8-k)
 * below 10^8 by it and dropping 32 bits divides exactly (the excess is
 * under 10^8 / 2^32 < 1). */
static const uint64_t div10_8_minus[9] = {
    0u, 430u, 4295u, 42950u, 429497u, 4294968u, 42949673u, 429496730u, 4294967296u
};

/* The number the k (0..7) digits that lead w spell, where flags =
 * nondigit_flags(w) is not 0 and k = leading_digit_count(flags): the
 * bytes from the first flagged one on are cleared, so that the eight read
 * as digit values spell that number times 10^(8-k), which an exact
 * division by multiplication takes off (no shift by a variable count). */
static uint64_t leading_digits(uint64_t w, uint64_t flags, int k)
{
    const uint64_t before = ((flags & (0 - flags)) >> 7) - 1;   /* the bytes before the flagged one */
    return (eight_digit_values((w - 0x3030303030303030u) & before) * div10_8_minus[k]) >> 32;
}

/* A run of up to eight digits at p: the number of leading digits k (0..8)
 * into *k and their value (0 for none). */
static uint64_t digit_run(const char *p, int *k)
{
    const uint64_t w = load_word(p), flags = nondigit_flags(w);
    if (flags == 0) {
        *k = 8;
        return eight_digits(w);
    }
    *k = leading_digit_count(flags);
    return leading_digits(w, flags, *k);
}
#else
/* Elsewhere *k = 0, and the caller's byte loop reads the digits. */
#define DIGIT_RUN_SWAR 0
static uint64_t digit_run(const char *p, int *k)
{
    (void)p;
    *k = 0;
    return 0;
}
#endif

/* 10^0 .. 10^19 (10^19 < 2^64) */
static const uint64_t pow10_u64[20] = {
    1u, 10u, 100u, 1000u, 10000u, 100000u, 1000000u, 10000000u, 100000000u, 1000000000u,
    10000000000u, 100000000000u, 1000000000000u, 10000000000000u, 100000000000000u,
    1000000000000000u, 10000000000000000u, 100000000000000000u, 1000000000000000000u,
    10000000000000000000u
};

/* 10^(19-k) for k = 0..7: sixteen digits followed by k more stay below
 * 10^19 where the sixteen spell less than this (pow10_u64[19 - k] with
 * no subtraction to index it). */
static const uint64_t first16_limit[8] = {
    10000000000000000000u, 1000000000000000000u, 100000000000000000u, 10000000000000000u,
    1000000000000000u, 100000000000000u, 10000000000000u, 1000000000000u
};

/* The common decimal token [+-]digits[.digits][(e|E)[+-]digits] (the
 * bytes p..end; the byte at end is not a digit, point, sign or e) with at
 * most 19 significant digits, read without strtod.  Its digits m and
 * decimal exponent e give:
 *   m <= 2^53 and |e| <= 22: m * 10^e or m / 10^-e, one IEEE operation on
 *     two exact doubles, hence correctly rounded (Clinger 1990, the "fast
 *     path" of every correct strtod);
 *   otherwise, |e| <= 27: long_decimal, exact integer arithmetic.
 * Either way the value is strtod's.  scan_decimal reads the longest such
 * number at p (it stops at a byte that cannot continue it, at end at the
 * latest: the byte at end must be one, e.g. a NUL) and returns where it
 * stopped with *v set, or NULL for anything it does not take (more digits,
 * larger exponents, hexadecimal, inf, nan, malformed text), which the
 * caller hands to strtod; fast_decimal takes the token p..end whole.
 * Needs double arithmetic without extended precision (FLT_EVAL_METHOD 0,
 * e.g. SSE2), or the product could be rounded twice; elsewhere it always
 * declines. */
static SCAN_INLINE const char *scan_decimal(const char *p, const char *end, double *v)
{
#if defined(FLT_EVAL_METHOD) && FLT_EVAL_METHOD == 0
    const uint64_t max_exact = (uint64_t)1 << 53;
    uint64_t m = 0;
    int neg = 0, digits = 0, significant = 0, e10 = 0, k;
    double x;

    /* up to 19 significant digits (leading zeros do not count), so
     * m < 10^19 < 2^64; with more, m wraps and the token is declined */
    if (*p == '+' || *p == '-')
        neg = *p++ == '-';
    for (; *p == '0'; p++)
        digits++;
    /* runs of up to 8 digits, then any left near end (none: "0.25", ".5") */
    while ((unsigned)((unsigned char)*p - '0') <= 9u && end - p >= 8) {
        const uint64_t run = digit_run(p, &k);
        m = pow10_u64[k] * m + run, p += k, digits += k, significant += k;
        if (k < 8)
            break;
    }
    for (; (unsigned)((unsigned char)*p - '0') <= 9u; p++, digits++, significant++)
        m = 10 * m + (uint64_t)((unsigned char)*p - '0');
    if (*p == '.') {
        p++;
        if (m == 0)
            for (; *p == '0'; p++, e10--)
                digits++;
        while (end - p >= 8) {
            const uint64_t run = digit_run(p, &k);
            m = pow10_u64[k] * m + run, p += k, e10 -= k, digits += k, significant += k;
            if (k < 8)
                break;
        }
        for (; (unsigned)((unsigned char)*p - '0') <= 9u; p++, e10--, digits++, significant++)
            m = 10 * m + (uint64_t)((unsigned char)*p - '0');
    }
    if (significant > 19)
        return NULL;
    if (digits == 0)
        return NULL;
    if (*p == 'e' || *p == 'E') {
        int eneg = 0, edigits = 0, ev = 0;
        p++;
        if (*p == '+' || *p == '-')
            eneg = *p++ == '-';
        for (; *p >= '0' && *p <= '9'; p++, edigits++)
            if (ev < 1000)
                ev = 10 * ev + (*p - '0');
        if (edigits == 0)
            return NULL;
        e10 += eneg ? -ev : ev;
    }
    if (m == 0)
        x = 0.0;
    else if (m <= max_exact && e10 >= -22 && e10 <= 22)
        x = e10 < 0 ? (double)m / pow10_exact[-e10] : (double)m * pow10_exact[e10];
    else if (!long_decimal(m, e10, &x))
        return NULL;
    *v = neg ? -x : x;
    return p;
#else
    (void)p;
    (void)end;
    (void)v;
    return NULL;
#endif
}

/* The first sixteen digits after the point are read with SSE2 where the
 * compiler targets x86-64 (which always has it): one 16-byte check and one
 * conversion for what takes two words and three conversions otherwise.
 * JUNO_TERRAIN_NO_SSE2 keeps the word-at-a-time reading (the other
 * processors' path), so that it is built and tested here too. */
#if DIGIT_RUN_SWAR && defined(__SSE2__) && (defined(__x86_64__) || defined(_M_X64)) && \
    !defined(JUNO_TERRAIN_NO_SSE2)
#define DIGIT_RUN_SSE2 1
#include <emmintrin.h>
#else
#define DIGIT_RUN_SSE2 0
#endif

/* The bytes plain_decimal may read beyond p: its caller keeps more than
 * this many before the buffer's end. */
#if DIGIT_RUN_SSE2
#define PLAIN_DECIMAL_REACH 40
#else
#define PLAIN_DECIMAL_REACH 32
#endif

#if DIGIT_RUN_SSE2
/* The sixteen bytes at p minus '0': digits become 0..9, any other byte
 * 10 or more (wrapping below '0'). */
static SCAN_INLINE __m128i digit_values16(const char *p)
{
    return _mm_sub_epi8(_mm_loadu_si128((const __m128i *)(const void *)p), _mm_set1_epi8('0'));
}

/* A bit for each of the sixteen bytes of d (digit_values16) that is not a
 * digit: adding 118 with saturation sets the top bit of exactly those. */
static SCAN_INLINE unsigned nondigit_mask16(__m128i d)
{
    return (unsigned)_mm_movemask_epi8(_mm_adds_epu8(d, _mm_set1_epi8(118)));
}

/* 0xFF in the first k (0..16) bytes, 0 in the others: a window on
 * sixteen ones and sixteen zeros. */
static const unsigned char first_bytes_window[32] = {
    0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF
};

static SCAN_INLINE __m128i first_bytes(__m128i d, int k)
{
    return _mm_and_si128(d, _mm_loadu_si128((const __m128i *)(const void *)(first_bytes_window + 16 - k)));
}

/* The sixteen digit values of d (0..9 a byte) as eight numbers of two
 * digits (16-bit lanes): a lane holds d[2i] + 256 d[2i+1], and times
 * 2561 = 1 + 256 * 10 (modulo 2^16, where 256 * 10 * 256 d[2i+1]
 * vanishes) it holds d[2i] + 256 (10 d[2i] + d[2i+1]), the pair's number
 * in the high byte. */
static SCAN_INLINE __m128i digit_pairs(__m128i d)
{
    __m128i times = _mm_set1_epi16(2561);
    /* an empty asm that may change the factor, so that the compiler
     * multiplies (one instruction) rather than shifting and adding (four) */
    __asm__("" : "+x"(times));
    return _mm_srli_epi16(_mm_mullo_epi16(d, times), 8);
}

/* The numbers of eight digits that the first sixteen digit values of a
 * and of b spell, as four 32-bit lanes: a's first eight, a's next eight,
 * b's first eight, b's next eight.  Pairs become fours (madd: 100 x + y,
 * below 10^4, so that packing them to 16 bits keeps them), fours
 * become eights (10^4 x + y). */
static SCAN_INLINE __m128i eight_digit_lanes(__m128i a, __m128i b)
{
    const __m128i pairs_to_fours = _mm_set1_epi32((1 << 16) | 100);
    const __m128i fours_to_eights = _mm_set1_epi32((1 << 16) | 10000);
    const __m128i fours = _mm_packs_epi32(_mm_madd_epi16(digit_pairs(a), pairs_to_fours),
                                          _mm_madd_epi16(digit_pairs(b), pairs_to_fours));
    return _mm_madd_epi16(fours, fours_to_eights);
}

/* fraction_digits below, sixteen digits a step: the first sixteen checked
 * and converted at once, with digits 16 to 23 from the next sixteen bytes.
 * The same results (and -1 for the same fractions); reads frac[0..31]. */
static SCAN_INLINE int fraction_digits(const char *frac, uint64_t *m)
{
    const __m128i a = digit_values16(frac);
    const unsigned na = nondigit_mask16(a);
    __m128i b, eights;
    uint64_t first16;
    unsigned nb;
    int k;

    if (na != 0) {                      /* up to fifteen digits */
        uint64_t ab;
        k = __builtin_ctz(na);
        ab = (uint64_t)_mm_cvtsi128_si64(eight_digit_lanes(first_bytes(a, k), _mm_setzero_si128()));
        /* the digits spell their number times 10^(16-k): in the first
         * lane for k <= 8, in the second (the first lane whole) above */
        if (k <= 8) {
            *m = ((ab & 0xFFFFFFFFu) * div10_8_minus[k]) >> 32;
        } else {
            *m = (ab & 0xFFFFFFFFu) * pow10_u64[k - 8] + (((ab >> 32) * div10_8_minus[k - 8]) >> 32);
        }
        return k;
    }
    b = digit_values16(frac + 16);
    nb = nondigit_mask16(b);
    k = nb != 0 ? __builtin_ctz(nb) : 16;
    if (k > 7)                          /* more than 23 */
        return -1;
    eights = eight_digit_lanes(a, first_bytes(b, k));
    {
        const uint64_t ab = (uint64_t)_mm_cvtsi128_si64(eights);
        const uint64_t c = (uint32_t)_mm_cvtsi128_si32(_mm_srli_si128(eights, 8));
        first16 = (ab & 0xFFFFFFFFu) * 100000000u + (ab >> 32);
        if (first16 >= first16_limit[k])    /* first16 10^k + the rest would reach 10^19 */
            return -1;
        *m = first16 * pow10_u64[k] + ((c * div10_8_minus[k]) >> 32);
    }
    return 16 + k;
}
#elif DIGIT_RUN_SWAR
/* The digits after a decimal point at frac: their number nf (returned,
 * 0 to 23) and the number they spell (*m), or -1 where there are more
 * than 23 of them or more than 19 significant ones (m would wrap).  Read
 * as whole words of eight digits where they are whole, so that the usual
 * lengths take one word ("%.6f"), or two and a part (the 16 to 21 digits
 * of a shortest round-trip value after "0."), and no digit count per
 * word.  Reads frac[0..23] at most. */
static SCAN_INLINE int fraction_digits(const char *frac, uint64_t *m)
{
    const uint64_t a = load_word(frac), fa = nondigit_flags(a);
    uint64_t b, fb, c, fc, first16;
    int k;

    if (fa != 0) {                      /* up to seven digits */
        k = leading_digit_count(fa);
        *m = leading_digits(a, fa, k);
        return k;
    }
    b = load_word(frac + 8);
    c = load_word(frac + 16);
    fb = nondigit_flags(b);
    fc = nondigit_flags(c);             /* with fb: their constants loaded once */
    if (fb != 0) {                      /* 8 to 15 */
        k = leading_digit_count(fb);
        *m = eight_digits(a) * pow10_u64[k] + leading_digits(b, fb, k);
        return 8 + k;
    }
    if (fc == 0)
        return -1;
    k = leading_digit_count(fc);        /* 16 to 23 */
    first16 = eight_digits(a) * 100000000u + eight_digits(b);
    if (first16 >= first16_limit[k])    /* first16 10^k + the rest would reach 10^19 */
        return -1;
    *m = first16 * pow10_u64[k] + leading_digits(c, fc, k);
    return 16 + k;
}

#endif

#if DIGIT_RUN_SWAR
/* The grids' usual values, [-]digits.digits with one to seven digits
 * before the point and at most 19 significant digits in all: "%.6f"'s
 * "0.003880" as much as the shortest round-trip "0.0038795912416837394"
 * that Python writes.  Returns where the number stops (before an exponent
 * too: the caller takes the value only where a token ends there) with *v
 * set, or NULL for any other shape (a '+', no digit before the point, more
 * digits), which scan_decimal reads.  The digits m and the exponent
 * -(fraction digits) are scan_decimal's, each conversion correctly rounded
 * (m / 10^k for k <= 15 and m <= 2^53, else reciprocal_decimal, and where
 * it cannot tell the division or long_decimal), hence the same value.
 * Reads p[0..PLAIN_DECIMAL_REACH] at most: the
 * integer digits from p + 1 at the latest, the fraction's 24 bytes (32
 * with SSE2) from p + 9. */
static SCAN_INLINE const char *grid_decimal(const char *p, double *v)
{
    const uint64_t max_exact = (uint64_t)1 << 53;
    const uint16_t zero_point = '0' | ('.' << 8);      /* "0." as load_pair reads it */
    const int neg = *p == '-';
    const char *const t = p + neg;
    const char *frac;
    uint64_t m, fm;
    int ki, nf;
    double x, tie;   /* tie: long_decimal's, apart so that x need not live in memory */

    /* "0.25": no integer digits to add; the usual case of terrain heights
     * in metres, laid out as the straight path */
    if (__builtin_expect(load_pair(t) == zero_point, 1)) {
        m = 0;
        frac = t + 2;
    } else if ((unsigned)((unsigned char)t[0] - '0') <= 9u && t[1] == '.') {   /* "1.25" */
        m = (uint64_t)((unsigned char)t[0] - '0');
        frac = t + 2;
    } else {
        m = digit_run(t, &ki);
        if (ki == 0 || ki == 8 || t[ki] != '.')
            return NULL;
        frac = t + ki + 1;
    }
    nf = fraction_digits(frac, &fm);
    if (nf < 0)
        return NULL;
    if (m != 0) {                       /* m 10^nf + fm, below 10^19 */
        if (nf > 18 || m >= pow10_u64[19 - nf])
            return NULL;
        fm += m * pow10_u64[nf];
    }
    /* the sign goes into the divisor or the scale, not tested again.  More
     * than 15 digits after the point (shortest round-trip values: 16 to 19
     * significant digits, below 2^53 or above it value by value) take the
     * reciprocal whatever m is, so that a grid of them takes one way: a
     * choice by m's size, unpredictable from one value to the next, costs
     * the processor more than the reciprocal costs over the division.  The
     * reciprocal gets nf >= 1: with no digits after the point fm is the
     * integer part, below 10^7 */
    if (nf <= 15 && fm <= max_exact)
        *v = (double)fm / signed_pow10_exact[nf][neg];
    else if (fm != 0 && reciprocal_decimal(fm, nf, (uint64_t)neg << 63, &x))
        *v = x;
    else if (fm <= max_exact && nf <= 22)
        *v = (double)fm / signed_pow10_exact[nf][neg];
    else if (fm == 0)
        *v = neg ? -0.0 : 0.0;
    else if (long_decimal(fm, -nf, &tie))
        *v = neg ? -tie : tie;
    else
        return NULL;
    return frac + nf;
}
#endif

/* scan_decimal as a call, for the values grid_decimal declines: inlined
 * beside it, its registers would crowd the read loop's (more of them
 * saved to memory and loaded back for every value). */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static const char *scan_decimal_apart(const char *p, const char *end, double *v)
{
    return scan_decimal(p, end, v);
}

/* scan_decimal with a shortcut for the grids' usual values (grid_decimal),
 * where double arithmetic has no extended precision (as scan_decimal
 * needs) and the eight-digit words can be read. */
static SCAN_INLINE const char *plain_decimal(const char *p, const char *end, double *v)
{
#if defined(FLT_EVAL_METHOD) && FLT_EVAL_METHOD == 0 && DIGIT_RUN_SWAR
    const char *const q = grid_decimal(p, v);
    if (q != NULL)
        return q;
#endif
    {
        double x;   /* apart from *v, so that *v need not live in memory */
        const char *const q = scan_decimal_apart(p, end, &x);
        if (q != NULL)
            *v = x;
        return q;
    }
}

/* The token p..end as a whole, by scan_decimal. */
static int fast_decimal(const char *p, const char *end, double *v)
{
    return scan_decimal(p, end, v) == end;
}

#endif /* JUNO_GRID_DECIMAL_H */
