#!/usr/bin/env python3
"""Prints fmu_src/contact.c's SEG_SHALLOW: the segment area t - sin t cos t of half-angle t over
y^3, y = sin(t/2), as a polynomial in s = 8 w - 1 for w = y^2 = h / 2R in [0, 1/4].

With dseg/dy = 16 y^2 sqrt(1 - y^2), seg = y^3 H(w), H(w) = 16 sum_n (-1)^n C(1/2, n) w^n / (2n + 3),
a series with exact rational coefficients that converges as 4^-n on [0, 1/4].  The polynomial
interpolates H at the Chebyshev nodes of that interval, in 60-digit decimal arithmetic, and is
converted to powers of s there; the script prints the doubles nearest its coefficients and, on
stderr, the largest relative error of the rounded polynomial evaluated in doubles.

    .venv/bin/python scripts/segment_polynomial.py [DEGREE]     # 13, as contact.c uses
"""
import sys
from decimal import Decimal, getcontext
from fractions import Fraction

getcontext().prec = 60
W1 = Decimal(1) / 4          # the interval [0, W1] of w: depths up to R/2
TAYLOR_TERMS = 120           # 4^-120: far below the 60 digits


def taylor_coefficients():
    coefficients, binom = [], Fraction(1)              # (-1)^n C(1/2, n)
    for n in range(TAYLOR_TERMS):
        coefficients.append(16 * binom / (2 * n + 3))
        binom *= -(Fraction(1, 2) - n) / (n + 1)
    return [Decimal(c.numerator) / Decimal(c.denominator) for c in coefficients]


TAYLOR = taylor_coefficients()


def segment_ratio(w):
    """H(w) = seg / y^3 by its series."""
    total = Decimal(0)
    for c in reversed(TAYLOR):
        total = total * w + c
    return total


def cosine(x):
    term = total = Decimal(1)
    k = 0
    while abs(term) > Decimal(10) ** -58:
        k += 2
        term = -term * x * x / (k * (k - 1))
        total += term
    return total


def pi():
    # Machin's formula: pi = 16 atan(1/5) - 4 atan(1/239)
    def atan_inverse(n):
        x, total, k, power = Decimal(1) / n, Decimal(0), 0, Decimal(1) / n
        while power > Decimal(10) ** -62:
            total += (-1) ** k * power / (2 * k + 1)
            power /= n * n
            k += 1
        return total
    return 16 * atan_inverse(5) - 4 * atan_inverse(239)


def coefficients(degree):
    n = degree + 1
    p = pi()
    nodes = [cosine(p * (j + Decimal("0.5")) / n) for j in range(n)]
    values = [segment_ratio(W1 / 2 * (1 + x)) for x in nodes]
    cheb = [sum(values[j] * cosine(p * k * (j + Decimal("0.5")) / n) for j in range(n)) * 2 / n for k in range(n)]
    cheb[0] /= 2
    chebyshev_t = [[Decimal(1)], [Decimal(0), Decimal(1)]]     # T_k in powers of s
    for k in range(2, n):
        t = [Decimal(0)] + [2 * v for v in chebyshev_t[k - 1]]
        for i, v in enumerate(chebyshev_t[k - 2]):
            t[i] -= v
        chebyshev_t.append(t)
    powers = [Decimal(0)] * n
    for k in range(n):
        for i, v in enumerate(chebyshev_t[k]):
            powers[i] += cheb[k] * v
    return [float(c) for c in powers]


def main():
    degree = int(sys.argv[1]) if len(sys.argv) > 1 else 13
    c = coefficients(degree)
    worst = Decimal(0)
    for i in range(2001):
        s = -1 + 2 * i / 2000
        value = 0.0
        for ci in reversed(c):
            value = value * s + ci
        exact = segment_ratio(W1 / 2 * (1 + Decimal(s)))
        worst = max(worst, abs((Decimal(value) - exact) / exact))
    print(f"degree {degree}: largest relative error in doubles {float(worst):.2e}", file=sys.stderr)
    print(f"static const double SEG_SHALLOW[{degree + 1}] = {{")
    for ci in c:
        print(f"    {ci!r},")
    print("};")


if __name__ == "__main__":
    main()
