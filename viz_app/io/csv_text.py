"""The track file's rows as CSV text, compiled (numba): floats in their shortest round-trip
form, formatted as pyarrow's CSV writer formats them, byte for byte.

pyarrow's writer spends ~180 ns on each float (double-conversion's shortest form); a file of
10⁶ plots × 7 methods has 1.1·10⁸ non-zero floats, so formatting was most of ``radarviz
track``'s time. Here the shortest digits come from Ulf Adams' Ryū algorithm (PLDI 2018,
"Ryū: fast float-to-string conversion"): the shortest decimal in the rounding interval of the
double, from two 64 × 128-bit products with tabulated powers of five, exact, no big integers
at run time. The tables are computed at import with Python's integers.

Layout, as pyarrow's (``tests/test_track_compiled.py`` compares the bytes on millions of
doubles): with the digits d₁…dₙ and the decimal exponent X of d₁.d₂…dₙ × 10^X,

* −6 ≤ X ≤ 9: positional: "123.456", "100", "0.00001" (no trailing ".0");
* otherwise scientific: "1.5e+10", "1e-7", "1.2345678901234568e+20";
* "0" for 0.0, "-0" for −0.0, a "-" before negatives.

Non-finite numbers are never written (the tracks are checked first); the kernel writes
"nan" / "inf" only so that nothing is undefined.
"""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")
#: The per-number helpers, inlined into their callers by numba itself (a call per number
#: otherwise costs as much as the digits).
_inline = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")

_POW5_INV_BITCOUNT = 125
_POW5_BITCOUNT = 125


def _tables() -> tuple[np.ndarray, np.ndarray]:
    """Ryū's DOUBLE_POW5_INV_SPLIT (342 × [lo, hi]) and DOUBLE_POW5_SPLIT (326 × [lo, hi])."""
    mask = (1 << 64) - 1
    inv = np.zeros((342, 2), dtype=np.uint64)
    for i in range(342):
        p = 5**i
        j = p.bit_length() - 1 + _POW5_INV_BITCOUNT
        v = (1 << j) // p + 1
        inv[i] = (v & mask, v >> 64)
    fwd = np.zeros((326, 2), dtype=np.uint64)
    for i in range(326):
        p = 5**i
        shift = p.bit_length() - _POW5_BITCOUNT
        v = p >> shift if shift > 0 else p << -shift
        fwd[i] = (v & mask, v >> 64)
    return inv, fwd


POW5_INV_SPLIT, POW5_SPLIT = _tables()

#: "00" "01" … "99" as bytes: two digits per division.
_DIGITS = np.frombuffer("".join(f"{i:02d}" for i in range(100)).encode(), dtype=np.uint8).copy()
_U32 = np.uint64(0xFFFFFFFF)
_S32 = np.uint64(32)
_S64 = np.uint64(64)


@intrinsic
def _umul128(typingctx, a, b):
    # (lo, hi) of the 128-bit product of two uint64: LLVM's i128 multiply, one machine
    # instruction on 64-bit targets (numba has no 128-bit integer type of its own)
    sig = types.UniTuple(types.uint64, 2)(types.uint64, types.uint64)

    def codegen(context, builder, signature, args):
        i128 = ir.IntType(128)
        p = builder.mul(builder.zext(args[0], i128), builder.zext(args[1], i128))
        lo = builder.trunc(p, ir.IntType(64))
        hi = builder.trunc(builder.lshr(p, ir.Constant(i128, 64)), ir.IntType(64))
        return context.make_tuple(builder, signature.return_type, (lo, hi))

    return sig, codegen


@_inline
def _mul_shift64(m, mul_lo, mul_hi, j):
    # ((m × mul) >> j) for the 128-bit mul, j > 64
    lo1, hi1 = _umul128(m, mul_hi)
    _, hi0 = _umul128(m, mul_lo)
    s = hi0 + lo1
    if s < hi0:
        hi1 += np.uint64(1)
    dist = np.uint64(j - 64)
    return (hi1 << (_S64 - dist)) | (s >> dist)


@_inline
def _pow5_factor(v) -> int:
    count = 0
    five = np.uint64(5)
    while v % five == np.uint64(0):
        v //= five
        count += 1
    return count


@_inline
def _shortest(mantissa, exponent):
    # Ryū's d2d: the shortest decimal (digits as an integer, exponent e10) that rounds back
    # to the double with IEEE mantissa bits ``mantissa`` and biased exponent ``exponent``
    one, two, four, ten = np.uint64(1), np.uint64(2), np.uint64(4), np.uint64(10)
    if exponent == 0:
        e2 = 1 - 1023 - 52 - 2
        m2 = mantissa
    else:
        e2 = exponent - 1023 - 52 - 2
        m2 = (one << np.uint64(52)) | mantissa
    accept_bounds = (m2 & one) == np.uint64(0)
    mv = four * m2
    mm_shift = np.uint64(1) if (mantissa != np.uint64(0) or exponent <= 1) else np.uint64(0)
    vm_tz = False
    vr_tz = False
    if e2 >= 0:
        q = ((e2 * 78913) >> 18) - (1 if e2 > 3 else 0)
        e10 = q
        k = _POW5_INV_BITCOUNT + (((q * 1217359) >> 19) + 1) - 1
        i = -e2 + q + k
        lo, hi = POW5_INV_SPLIT[q, 0], POW5_INV_SPLIT[q, 1]
        vr = _mul_shift64(four * m2, lo, hi, i)
        vp = _mul_shift64(four * m2 + two, lo, hi, i)
        vm = _mul_shift64(four * m2 - one - mm_shift, lo, hi, i)
        if q <= 21:
            if mv % np.uint64(5) == np.uint64(0):
                vr_tz = _pow5_factor(mv) >= q
            elif accept_bounds:
                vm_tz = _pow5_factor(mv - one - mm_shift) >= q
            else:
                vp -= np.uint64(1) if _pow5_factor(mv + two) >= q else np.uint64(0)
    else:
        q = ((-e2 * 732923) >> 20) - (1 if -e2 > 1 else 0)
        e10 = q + e2
        i = -e2 - q
        k = (((i * 1217359) >> 19) + 1) - _POW5_BITCOUNT
        j = q - k
        lo, hi = POW5_SPLIT[i, 0], POW5_SPLIT[i, 1]
        vr = _mul_shift64(four * m2, lo, hi, j)
        vp = _mul_shift64(four * m2 + two, lo, hi, j)
        vm = _mul_shift64(four * m2 - one - mm_shift, lo, hi, j)
        if q <= 1:
            vr_tz = True
            if accept_bounds:
                vm_tz = mm_shift == one
            else:
                vp -= one
        elif q < 63:
            vr_tz = (mv & ((one << np.uint64(q)) - one)) == np.uint64(0)
    removed = 0
    last = np.uint64(0)
    if vm_tz or vr_tz:
        while vp // ten > vm // ten:
            vm_tz = vm_tz and vm % ten == np.uint64(0)
            vr_tz = vr_tz and last == np.uint64(0)
            last = vr % ten
            vr //= ten
            vp //= ten
            vm //= ten
            removed += 1
        if vm_tz:
            while vm % ten == np.uint64(0):
                vr_tz = vr_tz and last == np.uint64(0)
                last = vr % ten
                vr //= ten
                vp //= ten
                vm //= ten
                removed += 1
        if vr_tz and last == np.uint64(5) and vr % two == np.uint64(0):
            last = np.uint64(4)  # round half to even
        up = (vr == vm and (not accept_bounds or not vm_tz)) or last >= np.uint64(5)
        out = vr + (one if up else np.uint64(0))
    else:
        round_up = False
        hundred = np.uint64(100)
        if vp // hundred > vm // hundred:
            round_up = vr % hundred >= np.uint64(50)
            vr //= hundred
            vp //= hundred
            vm //= hundred
            removed += 2
        while vp // ten > vm // ten:
            round_up = vr % ten >= np.uint64(5)
            vr //= ten
            vp //= ten
            vm //= ten
            removed += 1
        out = vr + (one if (vr == vm or round_up) else np.uint64(0))
    return out, e10 + removed


@_inline
def write_double(bits, buf, pos: int) -> int:
    """Write the double whose IEEE bits are ``bits`` (uint64) at buf[pos:] (the module
    docstring's layout); returns the new end."""
    sign = (bits >> np.uint64(63)) != np.uint64(0)
    mantissa = bits & ((np.uint64(1) << np.uint64(52)) - np.uint64(1))
    exponent = int((bits >> np.uint64(52)) & np.uint64(0x7FF))
    if exponent == 0x7FF and mantissa != np.uint64(0):
        buf[pos], buf[pos + 1], buf[pos + 2] = 110, 97, 110  # "nan"
        return pos + 3
    if sign:
        buf[pos] = 45  # "-"
        pos += 1
    if exponent == 0x7FF:
        buf[pos], buf[pos + 1], buf[pos + 2] = 105, 110, 102  # "inf"
        return pos + 3
    if exponent == 0 and mantissa == np.uint64(0):
        buf[pos] = 48
        return pos + 1
    digits, e10 = _shortest(mantissa, exponent)
    n = _decimal_length(digits)
    x = e10 + n - 1  # exponent of d₁.d₂…dₙ
    if -6 <= x <= 9:
        if x < 0:  # "0.00d₁…dₙ"
            buf[pos] = 48
            buf[pos + 1] = 46
            pos += 2
            for _ in range(-x - 1):
                buf[pos] = 48
                pos += 1
            _write_digits(digits, n, buf, pos)
            return pos + n
        if n <= x + 1:  # an integer: its digits, then zeros
            _write_digits(digits, n, buf, pos)
            for a in range(n, x + 1):
                buf[pos + a] = 48
            return pos + x + 1
        # d₁…d_{x+1} "." …dₙ: the digits written one place on, the integer part moved back
        _write_digits(digits, n, buf, pos + 1)
        for a in range(x + 1):
            buf[pos + a] = buf[pos + a + 1]
        buf[pos + x + 1] = 46
        return pos + n + 1
    # d₁ "." d₂…dₙ "e±X": likewise, d₁ moved back over the point's place
    _write_digits(digits, n, buf, pos + 1)
    buf[pos] = buf[pos + 1]
    if n > 1:
        buf[pos + 1] = 46
        pos += n + 1
    else:
        pos += 1
    buf[pos] = 101  # "e"
    buf[pos + 1] = 43 if x >= 0 else 45
    pos += 2
    ax = x if x >= 0 else -x
    if ax >= 100:
        buf[pos] = 48 + ax // 100
        pos += 1
    if ax >= 10:
        buf[pos] = 48 + (ax // 10) % 10
        pos += 1
    buf[pos] = 48 + ax % 10
    return pos + 1


@_inline
def _write_digits(v, n: int, buf, pos: int) -> None:
    # The n decimal digits of v at buf[pos : pos + n], two at a time from the least
    # significant (Ryū's table)
    at = pos + n
    hundred = np.uint64(100)
    while v >= hundred:
        c = int(v % hundred) * 2
        v //= hundred
        at -= 2
        buf[at] = _DIGITS[c]
        buf[at + 1] = _DIGITS[c + 1]
    if v >= np.uint64(10):
        c = int(v) * 2
        buf[at - 2] = _DIGITS[c]
        buf[at - 1] = _DIGITS[c + 1]
    else:
        buf[at - 1] = 48 + int(v)


@_inline
def _decimal_length(v) -> int:
    # Decimal digits of v (1 ≤ v < 10¹⁷): most shortest forms have 15–17, tested first
    if v >= np.uint64(10_000_000_000_000_000):
        return 17
    if v >= np.uint64(1_000_000_000_000_000):
        return 16
    if v >= np.uint64(100_000_000_000_000):
        return 15
    n = 1
    p = np.uint64(10)
    while v >= p:
        p *= np.uint64(10)
        n += 1
    return n


@_jit
def format_doubles(bits, buf) -> int:
    """Every double of ``bits`` (N,) (the uint64 view of a float64 array) followed by a
    newline into ``buf`` (for the tests)."""
    pos = 0
    for i in range(bits.shape[0]):
        pos = write_double(bits[i], buf, pos)
        buf[pos] = 10
        pos += 1
    return pos


@_jit
def format_track_rows(times, target, label_cells, text, text_start, x, P, state_of, cov_of, buf):
    """The CSV rows of a block of tracks into ``buf``, straight from the states; returns
    their length in bytes.

    ``times`` (B,), ``x`` (B·M, n) and ``P`` (B·M, n·n) are the uint64 views of float64
    arrays (row r = plot r // M, method r % M, M = ``x.shape[0] // times.shape[0]``). Row r:
    times[r // M]; with ``label_cells`` > 0 the pre-quoted cell k = target[r // M]
    (text[text_start[k] : text_start[k + 1]]); the method's cell k = label_cells + r % M;
    then x[r, state_of[c]] for each state column c and P[r, cov_of[c]] for each covariance
    column (0 where the index is −1: a component the state does not have); separated by
    commas, ended by a newline."""
    pos = 0
    rows = x.shape[0]
    m = rows // times.shape[0]
    zero = np.uint64(0)
    t_at, t_len = 0, 0
    for r in range(rows):
        b = r // m
        if r % m == 0:  # a plot's first row: its time formatted, the other rows copy it
            t_at = pos
            pos = write_double(times[b], buf, pos)
            t_len = pos - t_at
        else:
            for a in range(t_len):
                buf[pos + a] = buf[t_at + a]
            pos += t_len
        for c in range(2 if label_cells > 0 else 1):
            buf[pos] = 44
            pos += 1
            k = target[b] if c == 0 and label_cells > 0 else label_cells + r % m
            for a in range(text_start[k], text_start[k + 1]):
                buf[pos] = text[a]
                pos += 1
        for c in range(state_of.shape[0]):
            buf[pos] = 44
            pos += 1
            k = state_of[c]
            pos = write_double(x[r, k] if k >= 0 else zero, buf, pos)
        for c in range(cov_of.shape[0]):
            buf[pos] = 44
            pos += 1
            k = cov_of[c]
            pos = write_double(P[r, k] if k >= 0 else zero, buf, pos)
        buf[pos] = 10
        pos += 1
    return pos


@_jit
def track_columns_into(x, P, state_of, cov_of, out) -> None:
    """The state and covariance columns of a block of tracks into ``out`` (C, R) float64:
    out[c, r] = x[r, state_of[c]] for the state columns, then P[r, cov_of[c]] (0 where the
    index is −1); ``x`` (R, n), ``P`` (R, n·n) float64 (``format_track_rows``' columns, for
    the Parquet file)."""
    ns = state_of.shape[0]
    for r in range(x.shape[0]):
        for c in range(ns):
            k = state_of[c]
            out[c, r] = x[r, k] if k >= 0 else 0.0
        for c in range(cov_of.shape[0]):
            k = cov_of[c]
            out[ns + c, r] = P[r, k] if k >= 0 else 0.0


@_jit
def first_bad_row(x, P) -> int:
    """The first row r of a block of tracks (``x`` (R, n), ``P`` (R, n·n) float64) with a
    non-finite entry or a negative variance P[r, i·n + i], or −1 (the writer's check before
    any number is written)."""
    n = x.shape[1]
    for r in range(x.shape[0]):
        for i in range(n):
            if not np.isfinite(x[r, i]) or not P[r, i * n + i] >= 0.0:
                return r
        for k in range(P.shape[1]):
            if not np.isfinite(P[r, k]):
                return r
    return -1
