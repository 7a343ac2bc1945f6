"""Unit strings (`unit "N*m/rad"`): a small parser and the algebra of SI dimensions.

A unit is a scale and a vector of exponents of the SI base dimensions m, kg, s, A, K, mol, cd,
plus rad, which is dimensionless (two units that differ only in rad are the same dimension) but is
kept so that a display can say `rad/s`. Grammar (no spaces needed, none significant)::

    unit    := product
    product := power (('*' | '/') power)*
    power   := factor ('^' ['-'] DIGITS ['.' DIGITS])?   (`Pa^0.5`: exponents are fractions)
    factor  := '1' | SYMBOL | PREFIX SYMBOL | '(' product ')'

An unknown symbol is a `UnitError` with the offset of the symbol in the string and, where one
is close, the spelling of the unit meant.
"""
from __future__ import annotations

import difflib
from dataclasses import dataclass
from fractions import Fraction

BASE = ("m", "kg", "s", "A", "K", "mol", "cd", "rad")
_N = len(BASE)


@dataclass(frozen=True)
class Unit:
    """`scale` times the product of BASE[i] ** dims[i]."""

    dims: tuple[int, ...]
    scale: float = 1.0

    def __mul__(self, other: "Unit") -> "Unit":
        return Unit(tuple(a + b for a, b in zip(self.dims, other.dims)), self.scale * other.scale)

    def __truediv__(self, other: "Unit") -> "Unit":
        return Unit(tuple(a - b for a, b in zip(self.dims, other.dims)), self.scale / other.scale)

    def __pow__(self, k) -> "Unit":
        return Unit(tuple(a * k for a in self.dims), self.scale ** float(k))

    def same_dimension(self, other: "Unit") -> bool:
        """Equal exponents of the seven base dimensions (rad is dimensionless)."""
        return self.dims[:_N - 1] == other.dims[:_N - 1]

    def __str__(self) -> str:
        return show(self)


def _base(i: int) -> Unit:
    d = [Fraction(0)] * _N
    d[i] = Fraction(1)
    return Unit(tuple(d))


ONE = Unit((Fraction(0),) * _N)
m, kg, s, A, K, mol, cd, rad = (_base(i) for i in range(_N))

SYMBOLS: dict[str, Unit] = {
    "m": m, "kg": kg, "s": s, "A": A, "K": K, "mol": mol, "cd": cd, "rad": rad,
    "g": Unit(kg.dims, 1e-3), "sr": rad ** 2,
    "Hz": ONE / s, "N": kg * m / s ** 2, "Pa": kg / m / s ** 2, "J": kg * m ** 2 / s ** 2,
    "W": kg * m ** 2 / s ** 3, "C": A * s, "V": kg * m ** 2 / s ** 3 / A,
    "F": A ** 2 * s ** 4 / kg / m ** 2, "Ohm": kg * m ** 2 / s ** 3 / A ** 2,
    "S": A ** 2 * s ** 3 / kg / m ** 2, "Wb": kg * m ** 2 / s ** 2 / A, "T": kg / s ** 2 / A,
    "H": kg * m ** 2 / s ** 2 / A ** 2, "L": Unit((m ** 3).dims, 1e-3),
    "min": Unit(s.dims, 60.0), "h": Unit(s.dims, 3600.0), "bar": Unit((kg / m / s ** 2).dims, 1e5),
    "deg": Unit(rad.dims, 3.141592653589793 / 180.0),
}
SYMBOLS["\u03a9"] = SYMBOLS["Ohm"]
SYMBOLS["ohm"] = SYMBOLS["Ohm"]  # (as 20-sim and many a model spell it)

PREFIXES: dict[str, float] = {
    "p": 1e-12, "n": 1e-9, "u": 1e-6, "\u00b5": 1e-6, "m": 1e-3, "c": 1e-2, "d": 1e-1,
    "k": 1e3, "M": 1e6, "G": 1e9, "T": 1e12,
}


class UnitError(ValueError):
    """An ill-formed unit string; `offset` is where in the string, `length` how much."""

    def __init__(self, message: str, offset: int, length: int = 1):
        super().__init__(message)
        self.offset = offset
        self.length = max(1, length)


def parse(text: str) -> Unit:
    """The unit `text` denotes (`UnitError` if it is not one)."""
    p = _Parser(text)
    u = p.product()
    p.skip()
    if p.i < len(text):
        raise UnitError(f"unexpected '{text[p.i]}' in unit '{text}'", p.i)
    return u


def symbol(word: str) -> Unit | None:
    """A symbol with an optional SI prefix (`kN`, `mA`, `m`); None if it is none."""
    if word in SYMBOLS:
        return SYMBOLS[word]
    for pre, f in PREFIXES.items():
        rest = word[len(pre):]
        if word.startswith(pre) and rest in SYMBOLS and rest not in ("kg", "min", "h", "deg"):
            u = SYMBOLS[rest]
            return Unit(u.dims, u.scale * f)
    return None


class _Parser:
    def __init__(self, text: str):
        self.t = text
        self.i = 0

    def skip(self):
        while self.i < len(self.t) and self.t[self.i].isspace():
            self.i += 1

    def peek(self) -> str:
        self.skip()
        return self.t[self.i] if self.i < len(self.t) else ""

    def product(self) -> Unit:
        u = self.power()
        while self.peek() in ("*", "/") and self.peek():
            op = self.t[self.i]
            self.i += 1
            v = self.power()
            u = u * v if op == "*" else u / v
        return u

    def power(self) -> Unit:
        u = self.factor()
        if self.peek() == "^":
            self.i += 1
            self.skip()
            j = self.i
            if self.i < len(self.t) and self.t[self.i] == "-":
                self.i += 1
            while self.i < len(self.t) and (self.t[self.i].isdigit() or self.t[self.i] == "."):
                self.i += 1
            digits = self.t[j:self.i]
            try:
                k = Fraction(digits)
            except ValueError:
                raise UnitError(f"expected a number exponent after '^' in unit '{self.t}'", j) from None
            u = u ** k
        return u

    def factor(self) -> Unit:
        c = self.peek()
        if c == "(":
            self.i += 1
            u = self.product()
            if self.peek() != ")":
                raise UnitError(f"expected ')' in unit '{self.t}'", self.i)
            self.i += 1
            return u
        if c == "1":
            self.i += 1
            return ONE
        j = self.i
        while self.i < len(self.t) and (self.t[self.i].isalpha()):
            self.i += 1
        word = self.t[j:self.i]
        if not word:
            what = f"'{c}'" if c else "the end"
            raise UnitError(f"expected a unit at {what} in unit '{self.t}'", j)
        u = symbol(word)
        if u is None:
            close = difflib.get_close_matches(word, list(SYMBOLS), n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise UnitError(f"unknown unit '{word}'{hint}", j, len(word))
        return u


_SHOW = ("m", "kg", "s", "A", "K", "mol", "cd", "rad")


def show(u: Unit) -> str:
    """A canonical spelling in base units, numerator first (`kg*m^2/s^3`); scale not shown."""
    def part(i, e):
        return _SHOW[i] if e == 1 else f"{_SHOW[i]}^{e}" if e.denominator == 1 else \
            f"{_SHOW[i]}^{float(e)}"
    num = [part(i, e) for i, e in enumerate(u.dims) if e > 0]
    den = [part(i, -e) for i, e in enumerate(u.dims) if e < 0]
    text = "*".join(num) or "1"
    if den:
        text += "/" + ("/".join(den))
    return text
