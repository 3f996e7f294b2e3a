"""The track file's rows as CSV text, compiled (numba): floats in their shortest round-trip
form, formatted as pyarrow's CSV writer formats them, byte for byte.

pyarrow's writer spends ~180 ns on each float (double-conversion's shortest form); a file of
10⁶ plots × 7 methods has 1.1·10⁸ non-zero floats, so formatting was most of ``radarviz
track``'s time. Here the shortest digits come from Raffaello Giulietti's Schubfach algorithm
("The Schubfach way to render doubles"), exact and without big integers at run
time. Of the double v = c·2^q, it takes the decimal scale 10^k of v's last digits and
computes three numbers at once, each one 64 × 126-bit product with a tabulated 10^−k: 4·v,
and the ends of v's rounding interval, all × 10^−k, each rounded to odd (the integer part,
its last bit set where a fraction was cut; exact enough to decide every comparison below).
Within the interval lie one or two of s·10^k and (s + 1)·10^k (s = ⌊v·10^−k⌋), or one
multiple of 10^(k+1) (the interval is less than 10^(k+1) wide, so at most one): that
multiple where there is one (its trailing zeros are dropped later, which leaves the shortest
decimal), otherwise the one of s and s + 1 in the interval, the nearer to v where both are
(the even one on a tie). This is the shortest decimal that rounds back to v and of those the
nearest, as Ryū and double-conversion choose it: the same digits as pyarrow's. The table of
10^−k is computed at import with Python's integers.

The digits are written 17 at a time, whatever their number: the decimal scaled to
10^16 ≤ f < 10^17, split into its first digit and two halves of 8, each half turned into its
8 digits in one 64-bit word (split by 10 000 into lanes of 32 bits, those by 100 into lanes of
16, those by 10 into bytes, every split a multiply by a reciprocal and a shift on all lanes at
once; the two halves are independent chains) and stored at once. The trailing zeros are then
cut by counting the zero bytes at the top of the words, and the point of the positional layout
placed by storing the digits after it again one byte on.

Layout, as pyarrow's (``tests/test_track_compiled.py`` compares the bytes on millions of
doubles): with the digits d₁…dₙ and the decimal exponent X of d₁.d₂…dₙ × 10^X,

* −6 ≤ X ≤ 9: positional: "123.456", "100", "0.00001" (no trailing ".0");
* otherwise scientific: "1.5e+10", "1e-7", "1.2345678901234568e+20";
* "0" for 0.0, "-0" for −0.0, a "-" before negatives.

A number's bytes are stored 8 at a time, so up to 25 bytes from its start may be written
(the longest number's length) whatever its own length: the bytes past its end are written
over by what follows, and a buffer holds 25 bytes for each number besides its separator.

Non-finite numbers are never written (the tracks are checked first); the kernel writes
"nan" / "inf" only so that nothing is undefined.
"""

from __future__ import annotations

import sys

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")
#: The per-number helpers, each compiled once and always inlined into its callers by LLVM
#: (forceinline; a call per number would cost as much as the digits); numba's own inlining
#: (inline="always") typed them again at every call site, seconds of compiling on a first run.
_inline = numba.njit(cache=True, nogil=True, error_model="numpy", forceinline=True)

if sys.byteorder != "little":  # the 8-digit words put the first digit in the lowest byte
    raise ImportError("viz_app.io.csv_text writes digits for little-endian machines only")

#: The range of k (the decimal scale of a double's last digits) over all finite doubles.
_K_MIN, _K_MAX = -324, 292


def _g_table() -> np.ndarray:
    """Schubfach's g(k) = ⌊10^−k · 2^(125 − r)⌋ + 1 with r = ⌊log₂ 10^−k⌋ (2^125 ≤ g < 2^126,
    one more than the truncation even where it is exact, as the error bound wants), for
    k = −324 … 292, as rows [g₁, g₀] with g = g₁·2^63 + g₀."""
    mask = (1 << 63) - 1
    out = np.zeros((_K_MAX - _K_MIN + 1, 2), dtype=np.uint64)
    for k in range(_K_MIN, _K_MAX + 1):
        num, den = (10**-k, 1) if k <= 0 else (1, 10**k)
        r = num.bit_length() - den.bit_length()  # r or r − 1 is ⌊log₂(num / den)⌋
        if (num << max(-r, 0)) < (den << max(r, 0)):
            r -= 1
        shift = 125 - r
        g = (num << shift) // den if shift >= 0 else num >> -shift
        g += 1
        out[k - _K_MIN] = (g >> 63, g & mask)
    return out


G = _g_table()

#: 10⁰ … 10¹⁷: the scale that brings a decimal of n digits to 17.
_POW10 = np.array([10**i for i in range(18)], dtype=np.uint64)
#: ⌊log₁₀ 2 · 2⁴¹⌋, ⌊log₁₀(3/4) · 2⁴¹⌋ and ⌊log₂ 10 · 2³⁸⌋: ⌊log₁₀ 2^q⌋ = (q·C10) >> 41,
#: ⌊log₁₀(3/4 · 2^q)⌋ = (q·C10 + A10) >> 41 and ⌊log₂ 10^e⌋ = (e·C2) >> 38 over the
#: exponents of doubles (Giulietti's constants).
_C10, _A10, _C2 = 661971961083, -274743187321, 913124641741
_MASK63 = np.uint64((1 << 63) - 1)
_E4, _E8 = np.uint64(10_000), np.uint64(100_000_000)
#: "0" × 8 as one word, added to eight digit values to make them ASCII.
_ASCII8 = np.uint64(0x3030303030303030)
#: "0.000000": the start of a positional number below 1 (at most six zeros follow the point).
_POINT_ZEROS = np.uint64(int.from_bytes(b"0.000000", "little"))
_S8 = np.uint64(8)
#: "nan" and "inf" (the rest of the word is written over by what follows).
_NAN = np.uint64(int.from_bytes(b"nan", "little"))
_INF = np.uint64(int.from_bytes(b"inf", "little"))


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


@intrinsic
def _leading_zeros(typingctx, v):
    # the leading zero bits of a uint64 (LLVM's ctlz, one instruction; 64 for 0)
    sig = types.int64(types.uint64)

    def codegen(context, builder, signature, args):
        return builder.ctlz(args[0], ir.Constant(ir.IntType(1), 0))

    return sig, codegen


@intrinsic
def _address(typingctx, buf):
    # the address of an array's first byte, as an integer: the per-number writers take it
    # rather than the array, so that no reference count is taken and dropped per number (two
    # atomic operations, a third of a number's time before)
    sig = types.intp(buf)

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        return builder.ptrtoint(ary.data, context.get_value_type(types.intp))

    return sig, codegen


@intrinsic
def _put(typingctx, out, pos, byte):
    # one byte at out + pos (``out`` from _address; no bounds check, as numba's indexing)
    sig = types.void(types.intp, types.intp, types.uint8)

    def codegen(context, builder, signature, args):
        at = builder.add(args[0], args[1])
        builder.store(args[2], builder.inttoptr(at, ir.IntType(8).as_pointer()))
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def _put8(typingctx, out, pos, word):
    # word's 8 bytes at out + pos, lowest byte first: one unaligned store
    sig = types.void(types.intp, types.intp, types.uint64)

    def codegen(context, builder, signature, args):
        at = builder.add(args[0], args[1])
        builder.store(args[2], builder.inttoptr(at, ir.IntType(64).as_pointer()), align=1)
        return context.get_dummy_value()

    return sig, codegen


@_inline
def _rop(g1, g0, cp):
    # Schubfach's rounding to odd of cp·g·2^−127 (g = g1·2^63 + g0): its integer part, the
    # lowest bit set where the fraction is not 0
    _, x1 = _umul128(g0, cp)
    y0, y1 = _umul128(g1, cp)
    z = (y0 >> np.uint64(1)) + x1
    vbp = y1 + (z >> np.uint64(63))
    return vbp | (((z & _MASK63) + _MASK63) >> np.uint64(63))


@_inline
def _shortest(mantissa, exponent):
    # The shortest decimal (digits f, exponent k: f·10^k, f perhaps with trailing zeros) that
    # rounds back to the double with IEEE mantissa bits ``mantissa`` and biased exponent
    # ``exponent`` (not 0 with mantissa 0), the nearest to it of those: Schubfach
    one, two = np.uint64(1), np.uint64(2)
    if exponent != 0:
        c = (one << np.uint64(52)) | mantissa
        q = exponent - 1075
    else:
        c = mantissa
        q = -1074
    out = c & one  # an odd c: the interval's ends round to the neighbours, excluded
    cb = c << two
    cbr = cb + two
    if mantissa != np.uint64(0) or exponent <= 1:  # the neighbours equally far
        cbl = cb - two
        k = (q * _C10) >> 41
    else:  # a power of 2: the lower neighbour half as far
        cbl = cb - one
        k = (q * _C10 + _A10) >> 41
    h = np.uint64(q + ((-k * _C2) >> 38) + 2)  # 1 … 4
    g1, g0 = G[k - _K_MIN, 0], G[k - _K_MIN, 1]
    vb = _rop(g1, g0, cb << h)
    vbl = _rop(g1, g0, cbl << h)
    vbr = _rop(g1, g0, cbr << h)
    s = vb >> two
    t = s + one
    # a multiple of 10^(k+1) in the interval (at most one): the shorter one
    sp = (s // np.uint64(10)) * np.uint64(10)
    up_in = vbl + out <= sp << two
    wp_in = ((sp + np.uint64(10)) << two) + out <= vbr
    # otherwise s or s + 1, whichever is in; both: the nearer to 4·v·10^−k, the even on a tie
    u_in = vbl + out <= s << two
    w_in = (t << two) + out <= vbr
    mid = (s << two) + two
    # selects rather than branches (& and | rather than and and or, which branch): which case
    # holds varies from number to number
    odd = (s & one) != np.uint64(0)
    up = w_in & ((not u_in) | (vb > mid) | ((vb == mid) & odd))
    f = s + np.uint64(up)
    shorter = (s >= np.uint64(10)) & (up_in != wp_in)
    f = sp + np.uint64(10) * np.uint64(wp_in) if shorter else f
    return f, k


@_inline
def _eight_digits(v):
    # The 8 decimal digits of v < 10⁸ as the bytes of a uint64, the first in the lowest byte
    # (digit values 0–9): v split into two lanes of 4 digits (32 bits each), each lane into
    # two of 2 digits (16 bits), each of those into its 2 digits (a byte each), every split a
    # multiply by a reciprocal and a shift, all lanes at once
    hi = v // _E4
    merged = hi | ((v - hi * _E4) << np.uint64(32))
    top = ((merged * np.uint64(10486)) >> np.uint64(20)) & np.uint64(0x0000007F0000007F)
    hundreds = ((merged - np.uint64(100) * top) << np.uint64(16)) + top
    tens = ((hundreds * np.uint64(103)) >> np.uint64(10)) & np.uint64(0x000F000F000F000F)
    return tens + ((hundreds - np.uint64(10) * tens) << _S8)


@_inline
def write_double(bits, out: int, pos: int) -> int:
    """Write the double whose IEEE bits are ``bits`` (uint64) at ``pos`` of the buffer whose
    first byte is at address ``out`` (``_address(buf)``; the module docstring's layout, and
    bytes up to pos + 25 may be written); returns the new end."""
    sign = (bits >> np.uint64(63)) != np.uint64(0)
    mantissa = bits & ((np.uint64(1) << np.uint64(52)) - np.uint64(1))
    exponent = int((bits >> np.uint64(52)) & np.uint64(0x7FF))
    if exponent == 0x7FF and mantissa != np.uint64(0):
        _put8(out, pos, _NAN)
        return pos + 3
    _put(out, pos, 45)  # "-", kept by a negative number (no branch: the sign is as often either)
    pos += int(sign)
    if exponent == 0x7FF:
        _put8(out, pos, _INF)
        return pos + 3
    if exponent == 0 and mantissa == np.uint64(0):
        _put(out, pos, 48)
        return pos + 1
    f, k = _shortest(mantissa, exponent)
    # its digits: ⌊log₁₀ 2^b⌋ or one more for a number of b bits (1233 / 2¹² ≈ log₁₀ 2)
    n = ((64 - _leading_zeros(f)) * 1233) >> 12
    n += int(f >= _POW10[n])
    x = k + n - 1  # exponent of d₁.d₂…dₙ
    f *= _POW10[17 - n]  # 17 digits: d₁, then two words of 8
    hm = f // _E8
    lo = f - hm * _E8
    d1 = hm // _E8
    mid = hm - d1 * _E8
    a = _eight_digits(mid)
    b = _eight_digits(lo)
    # the significant digits: 17 less the trailing zeros, the zero bytes at the top of b, a
    if lo != np.uint64(0):
        n = 17 - (_leading_zeros(b) >> 3)
    elif mid != np.uint64(0):
        n = 9 - (_leading_zeros(a) >> 3)
    else:
        n = 1
    a += _ASCII8
    b += _ASCII8
    lead = 48 + int(d1)
    if -6 <= x <= 9:
        if x < 0:  # "0.00d₁…dₙ"
            _put8(out, pos, _POINT_ZEROS)
            at = pos + 1 - x
            _put(out, at, lead)
            _put8(out, at + 1, a)
            _put8(out, at + 9, b)
            return at + n
        _put(out, pos, lead)
        _put8(out, pos + 1, a)
        _put8(out, pos + 9, b)
        if n <= x + 1:  # an integer: its digits, the zeros among them
            return pos + x + 1
        # d₁…d_{x+1} "." …dₙ: the point over the digit after the integer part, the rest
        # of its word stored again one byte on (then the following word, if it is a)
        _put(out, pos + x + 1, 46)
        if x < 8:
            _put8(out, pos + x + 2, a >> np.uint64(8 * x))
            _put8(out, pos + 10, b)
        else:
            _put8(out, pos + x + 2, b >> np.uint64(8 * (x - 8)))
        return pos + n + 1
    # d₁ "." d₂…dₙ "e±X"
    _put(out, pos, lead)
    _put(out, pos + 1, 46)
    _put8(out, pos + 2, a)
    _put8(out, pos + 10, b)
    pos += n + 1 if n > 1 else 1
    _put(out, pos, 101)  # "e"
    _put(out, pos + 1, 43 if x >= 0 else 45)
    pos += 2
    ax = x if x >= 0 else -x
    if ax >= 100:
        _put(out, pos, 48 + ax // 100)
        pos += 1
    if ax >= 10:
        _put(out, pos, 48 + (ax // 10) % 10)
        pos += 1
    _put(out, pos, 48 + ax % 10)
    return pos + 1


@_jit
def format_doubles(bits, buf) -> int:
    """Every double of ``bits`` (N,) (the uint64 view of a float64 array) followed by a
    newline into ``buf`` (for the tests)."""
    out = _address(buf)
    pos = 0
    for i in range(bits.shape[0]):
        pos = write_double(bits[i], out, pos)
        _put(out, pos, 10)
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
    out = _address(buf)
    pos = 0
    rows = x.shape[0]
    m = rows // times.shape[0]
    zero = np.uint64(0)
    t_at, t_len = 0, 0
    for r in range(rows):
        b = r // m
        if r % m == 0:  # a plot's first row: its time formatted, the other rows copy it
            t_at = pos
            pos = write_double(times[b], out, pos)
            t_len = pos - t_at
        else:
            for a in range(t_len):
                buf[pos + a] = buf[t_at + a]
            pos += t_len
        for c in range(2 if label_cells > 0 else 1):
            _put(out, pos, 44)
            pos += 1
            k = target[b] if c == 0 and label_cells > 0 else label_cells + r % m
            for a in range(text_start[k], text_start[k + 1]):
                buf[pos] = text[a]
                pos += 1
        for c in range(state_of.shape[0]):
            _put(out, pos, 44)
            pos += 1
            k = state_of[c]
            pos = write_double(x[r, k] if k >= 0 else zero, out, pos)
        for c in range(cov_of.shape[0]):
            _put(out, pos, 44)
            pos += 1
            k = cov_of[c]
            pos = write_double(P[r, k] if k >= 0 else zero, out, pos)
        _put(out, pos, 10)
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
