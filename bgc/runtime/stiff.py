# bgc/runtime/stiff.py -- a part of the Python runtime (runtime.py's header says how the parts
# make one module); its C twin is stiff.c: the stiff families, Rosenbrock (_Rosenbrock) and
# Radau IIA (_Radau), and what they solve with: sums of stages (_combine), complex arithmetic,
# the dense LU factorisations and the sparse LU of a large sparse model.

# ================================================================== stiff ===
# The stiff families: Rosenbrock methods in Hairer's transformed form (RODAS's design, any
# tableau of the family) and Radau IIA with 3, 5 or 7 stages, of fixed or variable order
# (RADAU5's and RADAU's design), as bgc_run_rosenbrock and bgc_run_radau in the C runtime (see
# there).  Byte parity: every floating-point operation is the C runtime's, in C's order, so
# both backends write the same bytes whatever BLAS or SIMD kernels numpy picks.  Hence no
# numpy.sum, dot, @ or linalg here: sums run in C's sequence (_seq_sum, a subtract.accumulate),
# the LU factorisations and solves are bgc_stiff_lu's and bgc_stiff_zlu's (row-vectorised
# where C's loops are element-wise independent), and complex arithmetic is done on real and
# imaginary parts as the C runtime's bgc_cmul and bgc_cdiv write it out: products (ac - bd) +
# i(ad + bc) with Annex G's recovery of infinities (libgcc's __muldc3), quotients as GCC 12's
# libgcc __divdc3.


def _stiff_norm(s, v, w):
    """bgc_stiff_norm: sqrt(mean((v_i / w_i)^2)) over the states the error control weighs (0
    without states) and the component with the largest share (the first; -1 if every share
    is NaN)."""
    if _N == 0:
        return 0.0, -1
    E = _error_states(s)
    with numpy.errstate(all="ignore"):
        q = v[:E] / w[:E]
        q = q * q
    return math.sqrt(_seq_sum(q) / E), _worst(q)


def _combine(weights, K, count):
    """sum_j weights[j] K[j] over j < count with a nonzero weight, left to right, for numpy
    vectors K[j] (the stiff solvers)."""
    acc = numpy.zeros(_N)  # C's acc = 0.0, then acc += a K_j
    for j in range(count):
        a = weights[j]
        if a != 0.0:
            acc = acc + a * K[j]
    return acc


# ---------------------------------------------------------------- complex arithmetic
# A complex number is a pair of floats (or of float arrays): real and imaginary part.

_RBIG = sys.float_info.max / 2
_RMIN = sys.float_info.min
_RMIN2 = sys.float_info.epsilon
_RMINSCAL = 1.0 / sys.float_info.epsilon
_RMAX2 = _RBIG * _RMIN2


def _box(v):
    """Annex G's boxing of an infinite part: +-1 if v is infinite, else +-0."""
    return math.copysign(1.0 if math.isinf(v) else 0.0, v)


def _muldc3(a, b, c, d):
    """(a + ib)(c + id) as libgcc's __muldc3 (gcc's inline product where not both parts are
    NaN), on floats."""
    ac, bd, ad, bc = a * c, b * d, a * d, b * c
    x, y = ac - bd, ad + bc
    if x != x and y != y:  # recover infinities that came out as NaN + iNaN
        recalc = False
        if math.isinf(a) or math.isinf(b):
            a, b = _box(a), _box(b)
            c = math.copysign(0.0, c) if c != c else c
            d = math.copysign(0.0, d) if d != d else d
            recalc = True
        if math.isinf(c) or math.isinf(d):
            c, d = _box(c), _box(d)
            a = math.copysign(0.0, a) if a != a else a
            b = math.copysign(0.0, b) if b != b else b
            recalc = True
        if not recalc and any(math.isinf(v) for v in (ac, bd, ad, bc)):
            a, b, c, d = (math.copysign(0.0, v) if v != v else v for v in (a, b, c, d))
            recalc = True
        if recalc:
            x = math.inf * (a * c - b * d)
            y = math.inf * (a * d + b * c)
    return x, y


def _divdc3(a, b, c, d):
    """(a + ib) / (c + id) as libgcc's __divdc3 (GCC 12's: Smith's method with scaling), on
    floats; where Python would raise on a division by zero, on numpy.float64 values (IEEE)."""
    try:
        return _divdc3_of(a, b, c, d)
    except ZeroDivisionError:
        with numpy.errstate(all="ignore"):
            x, y = _divdc3_of(*(numpy.float64(v) for v in (a, b, c, d)))
        return float(x), float(y)


def _divdc3_of(a, b, c, d):
    if abs(c) < abs(d):
        if abs(d) >= _RBIG:
            a, b, c, d = a / 2, b / 2, c / 2, d / 2
        if abs(d) < _RMIN2 or _tiny(a, b, d):
            a, b, c, d = a * _RMINSCAL, b * _RMINSCAL, c * _RMINSCAL, d * _RMINSCAL
        ratio = c / d
        denom = (c * ratio) + d
        if abs(ratio) > _RMIN:
            x, y = ((a * ratio) + b) / denom, ((b * ratio) - a) / denom
        else:
            x, y = ((c * (a / d)) + b) / denom, ((c * (b / d)) - a) / denom
    else:
        if abs(c) >= _RBIG:
            a, b, c, d = a / 2, b / 2, c / 2, d / 2
        if abs(c) < _RMIN2 or _tiny(a, b, c):
            a, b, c, d = a * _RMINSCAL, b * _RMINSCAL, c * _RMINSCAL, d * _RMINSCAL
        ratio = d / c
        denom = (d * ratio) + c
        if abs(ratio) > _RMIN:
            x, y = ((b * ratio) + a) / denom, (b - (a * ratio)) / denom
        else:
            x, y = (a + (d * (b / c))) / denom, (b - (d * (a / c))) / denom
    if x != x and y != y:  # recover infinities and zeros that came out as NaN + iNaN
        if c == 0.0 and d == 0.0 and (a == a or b == b):
            x, y = math.copysign(math.inf, c) * a, math.copysign(math.inf, c) * b
        elif (math.isinf(a) or math.isinf(b)) and math.isfinite(c) and math.isfinite(d):
            a, b = _box(a), _box(b)
            x, y = math.inf * (a * c + b * d), math.inf * (b * c - a * d)
        elif (math.isinf(c) or math.isinf(d)) and math.isfinite(a) and math.isfinite(b):
            c, d = _box(c), _box(d)
            x, y = 0.0 * (a * c + b * d), 0.0 * (b * c - a * d)
    return x, y


def _tiny(a, b, big):
    """__divdc3's test for scaling up a small numerator (big: the divisor's larger part)."""
    return ((abs(a) < _RMIN and abs(b) < _RMAX2 and abs(big) < _RMAX2)
            or (abs(b) < _RMIN and abs(a) < _RMAX2 and abs(big) < _RMAX2))


def _each(f, mask, x, y, *args):
    """x, y with f(*args_i) at the elements where mask holds (the rare cases of the vector
    complex operations, done one by one)."""
    args = numpy.broadcast_arrays(*args)
    x, y = numpy.array(x, dtype=float), numpy.array(y, dtype=float)
    for i in zip(*numpy.nonzero(mask)):
        x[i], y[i] = f(*(float(v[i]) for v in args))
    return x, y


def _cmul(a, b, c, d):
    """(a + ib)(c + id) element-wise (arrays or floats): gcc's inline product, __muldc3 where
    both parts are NaN."""
    x, y = a * c - b * d, a * d + b * c
    bad = (x != x) & (y != y)
    return _each(_muldc3, bad, x, y, a, b, c, d) if bad.any() else (x, y)


def _cdiv(a, b, c, d):
    """(a + ib) / (c + id) for arrays a, b and floats c, d: __divdc3 without scaling (a
    divisor of moderate size) vectorised, _divdc3 element by element otherwise."""
    one = abs(c) < abs(d)  # scaled by d: ratio c / d
    big = abs(d) if one else abs(c)
    if not _RMIN2 <= big < _RBIG:
        return _each(_divdc3, numpy.ones(numpy.shape(a), bool), a, a, a, b, c, d)
    ratio = c / d if one else d / c
    normal = abs(ratio) > _RMIN  # else (a real or imaginary divisor) the other order
    if one:
        denom = (c * ratio) + d
        if normal:
            x, y = ((a * ratio) + b) / denom, ((b * ratio) - a) / denom
        else:
            x, y = ((c * (a / d)) + b) / denom, ((c * (b / d)) - a) / denom
    else:
        denom = (d * ratio) + c
        if normal:
            x, y = ((b * ratio) + a) / denom, (b - (a * ratio)) / denom
        else:
            x, y = (a + (d * (b / c))) / denom, (b - (d * (a / c))) / denom
    aa, ab = numpy.abs(a), numpy.abs(b)
    odd = (x != x) & (y != y)
    if big < _RMAX2:
        odd |= ((aa < _RMIN) & (ab < _RMAX2)) | ((ab < _RMIN) & (aa < _RMAX2))
    return _each(_divdc3, odd, x, y, a, b, c, d) if odd.any() else (x, y)


# ---------------------------------------------------------------- dense linear algebra
# bgc_stiff_lu and bgc_stiff_zlu: partial pivoting on the first largest |a_ik| (|re| + |im|
# for complex), rows whose multiplier is zero left alone, a column without a nonzero pivot
# singular (None); the elimination of row i, a_ij - l a_kj for j > k, is element-wise in C
# and done here for all rows i at once.  The solves: all the row swaps, the column-oriented
# forward substitution (vectorised), the back substitution's row sums in C's order.


def _pivot(size):
    """C's pivot search over a column's sizes from the diagonal: from |a_kk|, the first entry
    larger than the largest so far (a NaN is never larger, and a NaN |a_kk| stays)."""
    if len(size) < 2 or size[0] != size[0]:
        return 0
    rest = numpy.where(size[1:] == size[1:], size[1:], -1.0)
    i = int(numpy.argmax(rest))
    return i + 1 if rest[i] > size[0] else 0


# A small matrix is factored and solved in plain floats, line by line as the C loops read:
# the same operations (Python's float arithmetic is IEEE double, and a pivot is never zero),
# without a numpy call per row, which on a few states costs more than the arithmetic.
_SMALL_LU = 12


def _lu_small(a):
    """bgc_stiff_lu on the rows of a (lists of floats, factored in place)."""
    n = len(a)
    piv = []
    for k in range(n):
        ak = a[k]
        big, p = abs(ak[k]), k
        for i in range(k + 1, n):
            if abs(a[i][k]) > big:
                big, p = abs(a[i][k]), i
        piv.append(p)
        if big == 0.0:
            return None
        if p != k:
            a[k], a[p] = a[p], a[k]
            ak = a[k]
        for i in range(k + 1, n):
            ai = a[i]
            lower = ai[k] / ak[k]
            ai[k] = lower
            if lower != 0.0:
                for j in range(k + 1, n):
                    ai[j] -= lower * ak[j]
    return piv


def _lu_solve_small(lu, piv, b):
    """bgc_stiff_lu_solve on lists."""
    n = len(b)
    for k in range(n):
        p = piv[k]
        b[k], b[p] = b[p], b[k]
    for k in range(n):
        bk = b[k]
        if bk != 0.0:
            for i in range(k + 1, n):
                b[i] -= lu[i][k] * bk
    for k in range(n - 1, -1, -1):
        row = lu[k]
        acc = b[k]
        for i in range(k + 1, n):
            acc -= row[i] * b[i]
        b[k] = acc / row[k]
    return b


def _zlu_small(ar, ai):
    """bgc_stiff_zlu on the rows of ar + i ai (lists of floats, factored in place)."""
    n = len(ar)
    piv = []
    for k in range(n):
        big, p = abs(ar[k][k]) + abs(ai[k][k]), k
        for i in range(k + 1, n):
            size = abs(ar[i][k]) + abs(ai[i][k])
            if size > big:
                big, p = size, i
        piv.append(p)
        if big == 0.0:
            return None
        if p != k:
            ar[k], ar[p] = ar[p], ar[k]
            ai[k], ai[p] = ai[p], ai[k]
        akr, aki = ar[k], ai[k]
        for i in range(k + 1, n):
            rr, ri = ar[i], ai[i]
            lr, li = _divdc3(rr[k], ri[k], akr[k], aki[k])
            rr[k], ri[k] = lr, li
            if lr != 0.0 or li != 0.0:
                for j in range(k + 1, n):
                    pr, pi = _muldc3(lr, li, akr[j], aki[j])
                    rr[j] -= pr
                    ri[j] -= pi
    return piv


def _zlu_solve_small(lur, lui, piv, br, bi):
    """bgc_stiff_zlu_solve on lists."""
    n = len(br)
    for k in range(n):
        p = piv[k]
        br[k], br[p] = br[p], br[k]
        bi[k], bi[p] = bi[p], bi[k]
    for k in range(n):
        xr, xi = br[k], bi[k]
        if xr != 0.0 or xi != 0.0:
            for i in range(k + 1, n):
                pr, pi = _muldc3(lur[i][k], lui[i][k], xr, xi)
                br[i] -= pr
                bi[i] -= pi
    for k in range(n - 1, -1, -1):
        rr, ri = lur[k], lui[k]
        xr, xi = br[k], bi[k]
        for i in range(k + 1, n):
            pr, pi = _muldc3(rr[i], ri[i], br[i], bi[i])
            xr -= pr
            xi -= pi
        br[k], bi[k] = _divdc3(xr, xi, rr[k], ri[k])
    return br, bi


class _SmallLU:
    """The factors of a small matrix as lists (what _lu returns as its "pivots" then carries
    them), so that each solve runs in plain floats too."""

    __slots__ = ("piv", "rows", "imag")

    def __init__(self, piv, rows, imag=None):
        self.piv, self.rows, self.imag = piv, rows, imag

    def __getitem__(self, k):
        return self.piv[k]

    def __len__(self):
        return len(self.piv)


def _lu(a):
    """bgc_stiff_lu on a (n x n, factored in place): the pivots, or None if singular."""
    if isinstance(a, _SparseMatrix):
        return a.piv
    n = a.shape[0]
    if n <= _SMALL_LU:
        rows = a.tolist()
        piv = _lu_small(rows)
        a[:, :] = rows
        return None if piv is None else _SmallLU(piv, rows)
    piv = []
    with numpy.errstate(all="ignore"):
        for k in range(n):
            size = numpy.abs(a[k:, k])
            p = k + _pivot(size)
            piv.append(p)
            if size[p - k] == 0.0:
                return None
            if k + 1 == n:
                break
            if p != k:
                a[[k, p]] = a[[p, k]]
            lower = a[k + 1:, k] / a[k, k]
            a[k + 1:, k] = lower
            rows = numpy.nonzero(lower != 0.0)[0]
            if len(rows) == n - k - 1:
                a[k + 1:, k + 1:] -= lower[:, None] * a[k, k + 1:]
            elif len(rows):
                a[rows + k + 1, k + 1:] -= lower[rows, None] * a[k, k + 1:]
    return piv


def _lu_solve(lu, piv, b):
    """bgc_stiff_lu_solve: A^-1 b (a new vector) from _lu's factors (under the caller's
    numpy.errstate, as _zlu_solve)."""
    if isinstance(lu, _SparseMatrix):
        return lu.solve(b)
    if isinstance(piv, _SmallLU):
        return numpy.array(_lu_solve_small(piv.rows, piv.piv, numpy.asarray(b, dtype=float)
                                           .tolist()))
    b = numpy.array(b, dtype=float)
    n = len(b)
    for k in range(n):
        p = piv[k]
        b[k], b[p] = b[p], b[k]
    for k in range(n - 1):
        bk = b[k]
        if bk != 0.0:
            b[k + 1:] -= lu[k + 1:, k] * bk
    for k in range(n - 1, -1, -1):
        b[k] = _seq_minus(b[k], lu[k, k + 1:] * b[k + 1:]) / lu[k, k]
    return b


def _zlu(ar, ai):
    """bgc_stiff_zlu on ar + i ai (factored in place): the pivots, or None if singular."""
    n = ar.shape[0]
    if n <= _SMALL_LU:
        rows, imag = ar.tolist(), ai.tolist()
        piv = _zlu_small(rows, imag)
        ar[:, :], ai[:, :] = rows, imag
        return None if piv is None else _SmallLU(piv, rows, imag)
    piv = []
    with numpy.errstate(all="ignore"):
        for k in range(n):
            size = numpy.abs(ar[k:, k]) + numpy.abs(ai[k:, k])
            p = k + _pivot(size)
            piv.append(p)
            if size[p - k] == 0.0:
                return None
            if k + 1 == n:
                break
            if p != k:
                ar[[k, p]], ai[[k, p]] = ar[[p, k]], ai[[p, k]]
            lr, li = _cdiv(ar[k + 1:, k], ai[k + 1:, k], float(ar[k, k]), float(ai[k, k]))
            ar[k + 1:, k], ai[k + 1:, k] = lr, li
            rows = numpy.nonzero((lr != 0.0) | (li != 0.0))[0]
            if len(rows):
                pr, pi = _cmul(lr[rows, None], li[rows, None], ar[k, k + 1:], ai[k, k + 1:])
                ar[rows + k + 1, k + 1:] -= pr
                ai[rows + k + 1, k + 1:] -= pi
    return piv


def _zlu_solve(lur, lui, piv, br, bi):
    """bgc_stiff_zlu_solve: A^-1 (br + i bi) (new vectors) from _zlu's factors."""
    if isinstance(lur, _SparseMatrix):
        return lur.zsolve(br, bi)
    if isinstance(piv, _SmallLU):
        xr, xi = _zlu_solve_small(piv.rows, piv.imag, piv.piv,
                                  numpy.asarray(br, dtype=float).tolist(),
                                  numpy.asarray(bi, dtype=float).tolist())
        return numpy.array(xr), numpy.array(xi)
    br, bi = numpy.array(br, dtype=float), numpy.array(bi, dtype=float)
    n = len(br)
    for k in range(n):
        p = piv[k]
        br[k], br[p] = br[p], br[k]
        bi[k], bi[p] = bi[p], bi[k]
    for k in range(n - 1):
        xr, xi = float(br[k]), float(bi[k])
        if xr != 0.0 or xi != 0.0:
            pr, pi = _cmul(lur[k + 1:, k], lui[k + 1:, k], xr, xi)
            br[k + 1:] -= pr
            bi[k + 1:] -= pi
    for k in range(n - 1, -1, -1):
        xr, xi = float(br[k]), float(bi[k])
        if k + 1 < n:
            pr, pi = _cmul(lur[k, k + 1:], lui[k, k + 1:], br[k + 1:], bi[k + 1:])
            xr, xi = float(_seq_minus(xr, pr)), float(_seq_minus(xi, pi))
        br[k], bi[k] = _divdc3(xr, xi, float(lur[k, k]), float(lui[k, k]))
    return br, bi


# A large sparse model's iteration matrices (_JAC_LU, bgc_splu in the C runtime): the values
# of L + U in the plan's positions, factored row by row in the plan's order with the C
# runtime's operations in its order (bgc_splu_factor ... bgc_smat_zsolve), each row's updates
# element-wise; a pivot that fails its test sends the matrix to the dense LU above.


class _SparseLU:
    """The plan (bgc/sparse.py, IterationPlan) as arrays, with each row's parts cut out once."""

    def __init__(self, perm, rowptr, cols, diag, jpos, dpos):
        self.n = len(perm)
        self.perm = numpy.array(perm, dtype=numpy.intp)
        self.cols = numpy.array(cols, dtype=numpy.intp)
        self.jpos = numpy.array(jpos, dtype=numpy.intp)
        self.dpos = numpy.array(dpos, dtype=numpy.intp)
        self.nnz = len(cols)
        self.rowptr, self.diag = list(rowptr), list(diag)
        # per row i: its positions, its L part (positions, columns), its U part after the
        # diagonal (positions, columns)
        self.row = [slice(rowptr[i], rowptr[i + 1]) for i in range(self.n)]
        self.lower = [slice(rowptr[i], diag[i]) for i in range(self.n)]
        self.lcols = [list(cols[rowptr[i]:diag[i]]) for i in range(self.n)]
        self.upper = [slice(diag[i] + 1, rowptr[i + 1]) for i in range(self.n)]
        self.ucols = [self.cols[diag[i] + 1:rowptr[i + 1]] for i in range(self.n)]
        # J's structural entries (the model part binds _JAC_COLUMNS first): where each
        # column starts, and each entry's row and column
        self.colstart, start = [], 0
        for rows in _JAC_COLUMNS:
            self.colstart.append(start)
            start += len(rows)
        self.jrows = numpy.array([i for rows in _JAC_COLUMNS for i in rows], dtype=numpy.intp)
        self.jcols = numpy.array([j for j, rows in enumerate(_JAC_COLUMNS) for _ in rows],
                                 dtype=numpy.intp)


def _splu_factor(pl, a):
    """bgc_splu_factor: a (the values) factored in place; False if a pivot fails its test."""
    w = numpy.zeros(pl.n)
    cols, diag = pl.cols, pl.diag
    for i in range(pl.n):
        row = pl.row[i]
        w[cols[row]] = a[row]
        size = numpy.abs(a[row])
        scale = max(0.0, float(numpy.max(numpy.where(size == size, size, 0.0))))
        for k in pl.lcols[i]:
            lower = float(w[k]) / float(a[diag[k]])
            if not abs(lower) <= 10.0:
                return False
            w[k] = lower
            u = pl.upper[k]
            if u.stop > u.start:
                w[pl.ucols[k]] -= lower * a[u]
        a[row] = w[cols[row]]
        pivot = float(a[diag[i]])
        if not abs(pivot) > 1e-14 * scale or not math.isfinite(pivot):
            return False
    return True


def _splu_solve(pl, a, b):
    """bgc_splu_solve: a new vector (states' order)."""
    w = numpy.empty(pl.n)
    bp = numpy.asarray(b, dtype=float)[pl.perm]
    cols, diag = pl.cols, pl.diag
    for i in range(pl.n):
        lo = pl.lower[i]
        w[i] = _seq_minus(bp[i], a[lo] * w[cols[lo]]) if lo.stop > lo.start else bp[i]
    for i in range(pl.n - 1, -1, -1):
        u = pl.upper[i]
        acc = _seq_minus(w[i], a[u] * w[pl.ucols[i]]) if u.stop > u.start else w[i]
        w[i] = acc / a[diag[i]]
    out = numpy.empty(pl.n)
    out[pl.perm] = w
    return out


def _splu_zfactor(pl, ar, ai):
    """bgc_splu_zfactor on ar + i ai."""
    wr, wi = numpy.zeros(pl.n), numpy.zeros(pl.n)
    cols, diag = pl.cols, pl.diag
    for i in range(pl.n):
        row = pl.row[i]
        wr[cols[row]], wi[cols[row]] = ar[row], ai[row]
        size = numpy.abs(ar[row]) + numpy.abs(ai[row])
        scale = max(0.0, float(numpy.max(numpy.where(size == size, size, 0.0))))
        for k in pl.lcols[i]:
            dk = diag[k]
            lr, li = _divdc3(float(wr[k]), float(wi[k]), float(ar[dk]), float(ai[dk]))
            if not abs(lr) + abs(li) <= 10.0:
                return False
            wr[k], wi[k] = lr, li
            u = pl.upper[k]
            if u.stop > u.start:
                pr, pi = _cmul(lr, li, ar[u], ai[u])
                uc = pl.ucols[k]
                wr[uc] -= pr
                wi[uc] -= pi
        ar[row], ai[row] = wr[cols[row]], wi[cols[row]]
        size = abs(float(ar[diag[i]])) + abs(float(ai[diag[i]]))
        if not size > 1e-14 * scale or not math.isfinite(size):
            return False
    return True


def _splu_zsolve(pl, ar, ai, br, bi):
    """bgc_splu_zsolve: new vectors."""
    wr, wi = numpy.empty(pl.n), numpy.empty(pl.n)
    pr0, pi0 = numpy.asarray(br, dtype=float)[pl.perm], numpy.asarray(bi, dtype=float)[pl.perm]
    cols, diag = pl.cols, pl.diag
    for i in range(pl.n):
        lo = pl.lower[i]
        if lo.stop > lo.start:
            c = cols[lo]
            pr, pi = _cmul(ar[lo], ai[lo], wr[c], wi[c])
            wr[i], wi[i] = _seq_minus(pr0[i], pr), _seq_minus(pi0[i], pi)
        else:
            wr[i], wi[i] = pr0[i], pi0[i]
    for i in range(pl.n - 1, -1, -1):
        u = pl.upper[i]
        xr, xi = float(wr[i]), float(wi[i])
        if u.stop > u.start:
            c = pl.ucols[i]
            pr, pi = _cmul(ar[u], ai[u], wr[c], wi[c])
            xr, xi = float(_seq_minus(xr, pr)), float(_seq_minus(xi, pi))
        wr[i], wi[i] = _divdc3(xr, xi, float(ar[diag[i]]), float(ai[diag[i]]))
    outr, outi = numpy.empty(pl.n), numpy.empty(pl.n)
    outr[pl.perm], outi[pl.perm] = wr, wi
    return outr, outi


class _SparseMatrix:
    """An iteration matrix on the sparse path (bgc_smat): alpha I - J (plus i beta I when
    complex) from J's structural values, factored by factor() (False: singular), sparse or,
    after a failed pivot test, dense."""

    __slots__ = ("re", "im", "piv", "dense")

    def __init__(self, Jv, alpha, beta=None):
        pl = _JAC_LU
        self.re = numpy.zeros(pl.nnz)
        self.re[pl.jpos] = -Jv
        self.re[pl.dpos] += alpha
        self.im = None
        if beta is not None:
            self.im = numpy.zeros(pl.nnz)
            self.im[pl.dpos] += beta
        self.piv, self.dense = None, False
        self._factor(Jv, alpha, beta)

    def _factor(self, Jv, alpha, beta):
        pl = _JAC_LU
        with numpy.errstate(all="ignore"):
            ok = (_splu_factor(pl, self.re) if self.im is None
                  else _splu_zfactor(pl, self.re, self.im))
        if ok:
            self.piv = True
            return
        self.dense = True
        self.re = numpy.zeros((_N, _N))
        self.re[pl.jrows, pl.jcols] = -Jv
        self.re[numpy.diag_indices(_N)] += alpha
        if beta is None:
            self.piv = _lu(self.re)
        else:
            self.im = numpy.zeros((_N, _N))
            self.im[numpy.diag_indices(_N)] += beta
            self.piv = _zlu(self.re, self.im)

    def solve(self, b):
        if self.dense:
            return _lu_solve(self.re, self.piv, b)
        with numpy.errstate(all="ignore"):
            return _splu_solve(_JAC_LU, self.re, b)

    def zsolve(self, br, bi):
        if self.dense:
            return _zlu_solve(self.re, self.im, self.piv, br, bi)
        with numpy.errstate(all="ignore"):
            return _splu_zsolve(_JAC_LU, self.re, self.im, br, bi)


def _real_matrix(J, diagonal):
    """-J with `diagonal` added to its diagonal, as the C runtime forms it (on the sparse path
    factored at once: _lu returns its outcome)."""
    if _JAC_LU is not None:
        return _SparseMatrix(J, diagonal)
    E = -J
    E[numpy.diag_indices(_N)] += diagonal
    return E


def _stiff_fail_singular(name, t, h):
    return _Failure("at t = %.17g: %s: the iteration matrix is singular (h = %.3g)"
                    % (t, name, h), t)


def _stiff_jacobian(run, t, y):
    """J at (t, y): dense, or on the sparse path its structural values (bgc_jacobian_values)."""
    J = numpy.zeros((_N, _N)) if _JAC_LU is None else numpy.zeros(_JAC_LU.jpos.shape[0])
    run.st["jac"] += 1
    try:
        _jacobian_into(t, y.tolist(), run.p, run.w, J, _JAC_LU is not None)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    return J


def _stiff_start(run, t, y):
    """f(t, y) at the start of a run or after an accepted step: a failure ends the run."""
    run.st["rhs"] += 1
    try:
        f0 = run.f(t, y)
    except _BlockFailure as failure:
        raise _block_failed(failure) from None
    i = _first_nonfinite(f0)
    if i >= 0:
        raise _fail(t, "derivative of state", STATES[i])
    return f0


def _first_step(run, y, f0):
    """The first step of an adaptive run: the earlier run's (bounded by the span), else
    HINIT."""
    hmax = _hmax(run.s)
    return min(run.h, hmax) if run.h > 0.0 else _initial_step(run, run.m["q"], y, f0, hmax)


# ---------------------------------------------------------------- Rosenbrock methods


class _Rosenbrock(_Family):
    """Rosenbrock methods as Hairer's RODAS (bgc_family_rosenbrock in the C runtime)."""

    def __init__(self, run):
        self.run, self.m = run, run.m
        self.accepted_steps, self.nsing = 0, 0
        self.hacc, self.erracc = 0.0, 1.0
        self.ft = numpy.zeros(_N)
        self.f0 = self.J = self.K = self.y = self.y1 = None

    def _point(self, t, y):
        """f, df/dt and J at a new point."""
        run = self.run
        self.f0 = _stiff_start(run, t, y)
        if not _AUTONOMOUS:
            delta = math.sqrt(_EPS * max(1e-5, abs(t)))
            run.st["rhs"] += 1
            try:
                self.ft = (run.f(t + delta, y) - self.f0) / delta
            except _BlockFailure as failure:
                raise _block_failed(failure) from None
        self.J = _stiff_jacobian(run, t, y)

    def start(self, y):
        self._point(self.run.t, y)
        return None if self.run.fixed else _first_step(self.run, y, self.f0)

    def _stages(self, t, h, tph, y, E, piv):
        m, run = self.m, self.run
        c, d, a, C = m["c"], m["d"], m["a"], m["C"]
        K = [None] * m["stages"]
        with numpy.errstate(all="ignore"):
            for i in range(m["stages"]):
                if i == 0:
                    rhs = self.f0.copy()
                else:
                    run.st["rhs"] += 1
                    rhs = run.f(tph if c[i] == 1.0 else t + c[i] * h, y + _combine(a[i], K, i))
                rhs = rhs + _combine(C[i], K, i) / h
                if not _AUTONOMOUS and d[i] != 0.0:
                    rhs = rhs + h * d[i] * self.ft
                K[i] = _lu_solve(E, piv, rhs)
                run.st["solves"] += 1
        return K

    def step(self, t, h, tph, y):
        run, m, st = self.run, self.m, self.run.st
        fixed = run.fixed
        st["lu"] += 1
        E = _real_matrix(self.J, 1.0 / (m["gamma"] * h))
        piv = _lu(E)
        if piv is None:
            if fixed or self.nsing + 1 == 5:
                raise _stiff_fail_singular(run.name, t, h)
            self.nsing += 1
            return _RETRY, None, h * 0.5, (-3, "", None)
        try:
            K = self._stages(t, h, tph, y, E, piv)
        except _BlockFailure as failure:  # an algebraic block failed in a stage
            if fixed:
                raise _block_failed(failure) from None
            return _RETRY, None, h * 0.5, (-2, "", failure)
        stages = m["stages"]
        with numpy.errstate(all="ignore"):
            y1 = y + _combine(m["m"], K, stages)
            err, worst = _stiff_norm(run.s, _combine(m["e"], K, stages), _weights(run.s, y, y1))
        self.worst = worst if worst >= 0 else self.worst
        i = _first_nonfinite(y1)
        if err != err or err == math.inf or i >= 0:
            if fixed:
                raise _fail(tph, "state", STATES[max(i, 0)])
            bad, bad_kind = i, "state"
            for j in range(1, stages):
                if bad >= 0:
                    break
                bad, bad_kind = _first_nonfinite(K[j]), "derivative of state"
            return _RETRY, None, h * 0.5, (bad, bad_kind, None)
        if fixed:
            err = 0.0

        # Gustafsson's predictive controller (rodas.f)
        safe, fac_min, fac_max, expo = m["safe"], m["fac_min"], m["fac_max"], 1.0 / m["q"]
        fac = max(1.0 / fac_max, min(1.0 / fac_min, err ** expo / safe))
        hnew = h / fac
        if err > 1.0:
            return _REJECT, None, hnew, None
        if self.accepted_steps > 0:
            facgus = (self.hacc / h) * (err * err / self.erracc) ** expo / safe
            facgus = max(1.0 / fac_max, min(1.0 / fac_min, facgus))
            fac = max(fac, facgus)
            hnew = h / fac
        self.hacc, self.erracc = h, max(1e-2, err)
        self.accepted_steps += 1
        self.nsing = 0
        self.K, self.y, self.y1 = K, y, y1
        return _ACCEPT, y1, hnew, None

    def dense(self):
        """y(theta) = (1 - theta) y0 + theta (y1 + (1 - theta) (q_1 + theta (q_2 + ...)))."""
        y, y1, K = self.y, self.y1, self.K
        q = []
        for row in self.m["H"]:  # every weight, zeros too, as bgc_ros_prepare
            acc = numpy.zeros(_N)
            for w, k in zip(row, K):
                acc = acc + w * k
            q.append(acc)

        def at(theta):
            s1 = 1.0 - theta
            acc = q[-1]
            for qr in q[-2::-1]:
                acc = qr + theta * acc
            return s1 * y + theta * (y1 + s1 * acc)
        return at

    def after(self, tph, y1, last):
        if not last:
            self._point(tph, y1)
        return False


# ---------------------------------------------------------------- Radau IIA (RADAU5)


def _radau_poly(c, Z):
    """The collocation polynomial through (0, 0) and (c_i, Z_i) in Newton's form:
    u(theta) = theta (b_1 + (theta - c_1) (b_2 + ... + (theta - c_{s-1}) b_s)); b: s x N."""
    x = (0.0,) + tuple(c)
    d = [numpy.zeros(_N)] + [Z[i] for i in range(len(c))]
    s = len(c)
    with numpy.errstate(all="ignore"):
        for j in range(1, s + 1):  # divided differences, in place
            for k in range(s, j - 1, -1):
                d[k] = (d[k] - d[k - 1]) / (x[k] - x[k - j])
    return d[1:]


def _radau_mul(M, V):
    """bgc_radau_mul for every component: M (ns x ns) times the stages V (ns x N), each
    M_i0 V_0 + M_i1 V_1 + ... in this order (all rows i at once)."""
    acc = numpy.multiply.outer(M[:, 0], V[0])
    for j in range(1, len(M)):
        acc += numpy.multiply.outer(M[:, j], V[j])
    return acc


def _radau_u(c, b, theta):
    k = len(b) - 1
    acc = b[k]
    while k > 0:
        k -= 1
        acc = b[k] + (theta - c[k]) * acc
    return theta * acc


class _RadauUse:
    """What follows from a stage set (see bgc_radau_configure in the C runtime)."""

    def __init__(self, m, s, k):
        rd = m["radau"][k]
        self.ns, self.c, self.gamma = rd["s"], rd["c"], rd["gamma"]
        self.alpha, self.beta, self.e = rd["alpha"], rd["beta"], rd["e"]
        self.T, self.Ti = numpy.array(rd["T"]), numpy.array(rd["Ti"])
        self.pairs = (self.ns - 1) // 2
        self.nit = 7 + 5 * ((self.ns - 3) // 2)
        expm = (self.ns + 1) / (2.0 * self.ns)
        en = 1.0 / expm - 1.0
        self.rtol = 0.1 * s.rtol ** expm
        self.atol = self.rtol * (s.atol / s.rtol)
        self.fnewt = max(10.0 * _EPS / self.rtol,
                         min(0.03, math.sqrt(self.rtol) if en == 0.5 else self.rtol ** en))
        self.cfac = m["safe"] * (1 + 2 * self.nit)
        self.expo = 1.0 / (self.ns + 1)


_THET = 0.001  # recompute J when Newton contracted more slowly than this


class _Radau(_Family):
    """Radau IIA after Hairer's RADAU5 and RADAU, fixed or variable order (bgc_family_radau
    in the C runtime)."""

    def __init__(self, run):
        m, s = run.m, run.s
        self.run, self.m = run, m
        self.nsets = len(m["radau"])
        self.variable = self.nsets > 1 and not run.fixed
        self.k_set, self.since = 0, 0
        for k, rd in enumerate(m["radau"]):
            if self.variable and 2 * rd["s"] - 1 == s.order0:
                self.k_set, self.since = k, 10  # going on from an earlier run at its order
        self.change = self.unexp = self.unexn = self.recheck = False
        self.u = _RadauUse(m, s, self.k_set)
        self.hfact = self.hold = self.hacc = 0.0
        self.erracc = 1.0
        self.faccon, self.theta, self.thetat = 1.0, _THET, 0.0
        self.thqold, self.dynold, self.hhfac = 1.0, 1.0, 0.5
        self.reject = self.caljac = False
        self.first = self.needjac = True
        self.accepted_steps, self.nsing, self.newt = 0, 0, 0
        self.J = self.E1 = self.piv1 = self.f0 = self.scal = None
        self.Ec = []  # per complex pair: the factors' real and imaginary parts, the pivots
        self.b = [numpy.zeros(_N)] * self.u.ns
        self.zlast = numpy.zeros(_N)
        self.Z = self.W = self.y = self.dc = None

    def start(self, y):
        run, u = self.run, self.u
        self.f0 = _stiff_start(run, run.t, y)
        self.scal = u.atol + u.rtol * numpy.abs(y)
        return None if run.fixed else _first_step(run, y, self.f0)

    def _order(self, h, y):
        """The order, whenever the matrices are to be factored (variable order only)."""
        hquot = h / self.hold if self.hold > 0.0 else 0.0
        nxt = self.k_set
        self.since += 1
        self.thetat = min(10.0, max(self.theta, 0.5 * self.thetat))
        if (self.newt > 1 and self.thetat <= 0.002 and 0.8 < hquot < 1.2 and self.since > 10
                and self.k_set + 1 < self.nsets):
            nxt = self.k_set + 1
        if (self.thetat >= 0.8 or self.unexp or self.unexn) and self.k_set > 0:
            nxt = self.k_set - 1
        self.unexp = self.unexn = self.recheck = False
        if nxt != self.k_set:
            self.k_set = nxt
            self.u = u = _RadauUse(self.m, self.run.s, nxt)
            self.since, self.change, self.hfact = 1, True, 0.0
            self.scal = u.atol + u.rtol * numpy.abs(y)

    def _factor(self, fac1, alphn, betan):
        """gamma/h I - J and (alpha_k + i beta_k)/h I - J, factored; False if one is singular.
        C adds alpha_k + beta_k _Complex_I, i.e. (alpha_k + beta_k 0) + i (0 + beta_k), to
        -J."""
        st = self.run.st
        st["lu"] += 1
        self.E1 = _real_matrix(self.J, fac1)
        self.piv1 = _lu(self.E1)
        self.Ec = []
        if self.piv1 is None:
            return False
        for k in range(self.u.pairs):
            st["lu"] += 1
            if _JAC_LU is not None:
                E = _SparseMatrix(self.J, alphn[k] + betan[k] * 0.0, betan[k])
                if E.piv is None:
                    return False
                self.Ec.append((E, None, E.piv))
                continue
            Er = _real_matrix(self.J, alphn[k] + betan[k] * 0.0)
            Ei = numpy.zeros((_N, _N))
            Ei[numpy.diag_indices(_N)] += betan[k]
            pv = _zlu(Er, Ei)
            if pv is None:
                return False
            self.Ec.append((Er, Ei, pv))
        return True

    def _newton(self, t, h, tph, y, fac1, alphn, betan):
        """The simplified Newton iteration from the last step's collocation polynomial: 0
        converged (self.Z), else (1, why) a stage failed, 2 no convergence, 3 too slow
        (self.hhfac: the step that would converge)."""
        run, u, st = self.run, self.u, self.run.st
        c, ns, scal = u.c, u.ns, self.scal
        if self.first or self.change:
            Z, W = numpy.zeros((ns, _N)), numpy.zeros((ns, _N))
        else:
            q = h / self.hold
            with numpy.errstate(all="ignore"):
                Z = numpy.array([_radau_u(c, self.b, 1.0 + c[i] * q) - self.zlast
                                 for i in range(ns)])
                W = _radau_mul(u.Ti, Z)
        self.newt = 0
        self.faccon = max(self.faccon, _EPS) ** 0.8
        self.theta = _THET
        while True:
            if self.newt >= u.nit:
                return 2, None
            F = numpy.empty((ns, _N))
            try:
                for i in range(ns):
                    st["rhs"] += 1
                    F[i] = run.f(tph if i == ns - 1 else t + c[i] * h, y + Z[i])
                    j = _first_nonfinite(F[i])
                    if j >= 0:
                        return 1, (j, "derivative of state", None)
            except _BlockFailure as failure:
                return 1, (-2, "", failure)
            with numpy.errstate(all="ignore"):
                G = _radau_mul(u.Ti, F)
                dW = numpy.empty((ns, _N))
                dW[0] = _lu_solve(self.E1, self.piv1, G[0] - fac1 * W[0])
                for k in range(u.pairs):
                    w2, w3 = W[2 * k + 1], W[2 * k + 2]
                    g2 = G[2 * k + 1] - (alphn[k] * w2 - betan[k] * w3)
                    g3 = G[2 * k + 2] - (betan[k] * w2 + alphn[k] * w3)
                    # C's g2 + g3 _Complex_I: (g2 + g3 0) + i g3
                    dW[2 * k + 1], dW[2 * k + 2] = _zlu_solve(*self.Ec[k], g2 + g3 * 0.0, g3)
                st["solves"] += 1 + u.pairs
                self.newt += 1
                # per component dW_0^2 + dW_1^2 + ... (in units of scal), then over them
                part = dW[0] / scal
                part = part * part
                for i in range(1, ns):
                    q = dW[i] / scal
                    part = part + q * q
                dyno = math.sqrt(_seq_sum(part) / (ns * _N)) if _N else 0.0
            if dyno != dyno or dyno == math.inf:
                return 2, None
            newt = self.newt
            if 1 < newt < u.nit:
                thq = dyno / self.dynold
                self.theta = thq if newt == 2 else math.sqrt(thq * self.thqold)
                self.thqold = thq
                theta = self.theta
                if theta < 0.99:
                    self.faccon = theta / (1.0 - theta)
                    dyth = self.faccon * dyno * theta ** (u.nit - 1 - newt) / u.fnewt
                    if dyth >= 1.0 and not run.fixed:  # a smaller step converges sooner
                        qnewt = max(1e-4, min(20.0, dyth))
                        self.hhfac = 0.8 * qnewt ** (-1.0 / (4.0 + u.nit - 1 - newt))
                        return 3, None
                else:
                    return 2, None
            self.dynold = max(dyno, _EPS)
            with numpy.errstate(all="ignore"):
                W = W + dW
                Z = _radau_mul(u.T, W)
            self.Z = Z
            # converged, the contraction measured in this step (never after one iteration)
            if newt > 1 and self.faccon * dyno <= u.fnewt:
                return 0, None

    def _error(self, t, h, y):
        """The error estimate, refined once with f(t, y + err) on the first step and after a
        rejection."""
        run, u, Z = self.run, self.u, self.Z
        ns = u.ns
        with numpy.errstate(all="ignore"):
            f2 = u.e[0] * Z[0]
            for j in range(1, ns):
                f2 = f2 + u.e[j] * Z[j]
            f2 = f2 / h
            cont = _lu_solve(self.E1, self.piv1, f2 + self.f0)
            run.st["solves"] += 1
            wt = u.atol + u.rtol * _c_max(numpy.abs(y), numpy.abs(y + Z[ns - 1]))
            err, worst = _stiff_norm(run.s, cont, wt)
            err = max(err, 1e-10)
            if err >= 1.0 and (self.first or self.reject):  # refined: f at y + err
                run.st["rhs"] += 1
                try:
                    f1 = run.f(t, y + cont)
                except _BlockFailure:
                    f1 = None
                if f1 is not None:
                    cont = _lu_solve(self.E1, self.piv1, f1 + f2)
                    run.st["solves"] += 1
                    err, worst = _stiff_norm(run.s, cont, wt)
                    err = max(err, 1e-10)
        self.worst = worst if worst >= 0 else self.worst
        return err

    def _retry(self, hnew, why):
        """A failed attempt: retried smaller, with a fresh Jacobian unless this one is."""
        self.reject = True
        self.needjac = not self.caljac
        return _RETRY, None, hnew, why

    def _fixed_failure(self, t, h, failed, why):
        """Newton's failure on a fixed step: once more with a fresh Jacobian, else the end."""
        if failed == 1:
            bad, bad_kind, failure = why
            if bad == -2:
                raise _block_failed(failure)
            raise _fail(t, bad_kind, STATES[bad])
        if not self.caljac:
            self.needjac = True
            return _AGAIN, None, h, None
        raise _Failure("at t = %.17g: %s: the Newton iteration does not converge with the "
                       "fixed step h = %.3g" % (t, self.run.name, h), t)

    def _control(self, h, err, y):
        """Step control: Gustafsson's, the safety factor scaled by the Newton iterations."""
        m, u = self.m, self.u
        safe, fac_min, fac_max = m["safe"], m["fac_min"], m["fac_max"]
        fac = min(safe, u.cfac / (self.newt + 2 * u.nit))
        quot = max(1.0 / fac_max, min(1.0 / fac_min, err ** u.expo / fac))
        hnew = h / quot
        if not err < 1.0:
            self.reject = True
            self.needjac = not self.caljac
            return _REJECT, None, 0.1 * h if self.first else hnew, None
        self.first = False
        self.accepted_steps += 1
        if self.accepted_steps > 1 and not self.change:
            facgus = (self.hacc / h) * (err * err / self.erracc) ** u.expo / fac
            facgus = max(1.0 / fac_max, min(1.0 / fac_min, facgus))
            quot = max(quot, facgus)
            hnew = h / quot
        self.change = False
        self.hacc, self.erracc = h, max(1e-2, err)
        Z = self.Z
        y1 = y + Z[u.ns - 1]
        self.b, self.dc, self.y = _radau_poly(u.c, Z), u.c, y
        self.zlast, self.hold = Z[u.ns - 1], h
        self.reject = self.caljac = False
        self.nsing = 0
        return _ACCEPT, y1, hnew, None

    def step(self, t, h, tph, y):
        run = self.run
        if self.needjac:
            self.J = _stiff_jacobian(run, t, y)
            self.needjac, self.caljac, self.hfact = False, True, 0.0
        if self.variable and (h != self.hfact or self.recheck):
            self._order(h, y)
        u = self.u
        fac1 = u.gamma / h
        alphn = [a / h for a in u.alpha]
        betan = [bb / h for bb in u.beta]
        if h != self.hfact:
            if not self._factor(fac1, alphn, betan):
                self.hfact = 0.0
                if run.fixed or self.nsing + 1 == 5:
                    raise _stiff_fail_singular(run.name, t, h)
                self.nsing += 1
                self.unexp = True
                return self._retry(h * 0.5, (-3, "", None))
            self.hfact = h
        failed, why = self._newton(t, h, tph, y, fac1, alphn, betan)
        if failed and run.fixed:
            return self._fixed_failure(t, h, failed, why)
        if failed:
            if failed == 3:
                self.unexn = self.hhfac <= 0.5
            else:
                self.unexp = True
            return self._retry(h * (self.hhfac if failed == 3 else 0.5),
                               why if failed == 1 else (-4, "", None))
        err = 0.0
        if not run.fixed:
            err = self._error(t, h, y)
            if err != err or err == math.inf:
                self.unexp = True
                return self._retry(h * 0.5, (-1, "", None))
        return self._control(h, err, y)

    def dense(self):
        y, c, b = self.y, self.dc, self.b
        return lambda theta: y + _radau_u(c, b, theta)

    def after(self, tph, y1, last):
        """The new point: its weights and f (after the run's last step, the order to go on
        with)."""
        run, u = self.run, self.u
        if last:
            if not run.fixed:
                run.st["order_next"] = 2 * u.ns - 1
            return False
        self.scal = u.atol + u.rtol * numpy.abs(y1)
        run.st["rhs"] += 1
        try:
            self.f0 = run.f(tph, y1)
        except _BlockFailure as failure:
            raise _block_failed(failure) from None
        return False

    def next_h(self, h, hnew):
        """h is kept (and the factorisations with it) while the controller asks for at most
        20 % more and Newton converged fast; J is recomputed when it converged slowly."""
        if self.theta <= _THET and 1.0 <= hnew / h <= 1.2:
            hnew = h
            if self.variable:
                self.since += 1
                if self.since >= 10 and self.k_set + 1 < self.nsets:
                    self.recheck = True  # ... but look at the order now and then
        self.needjac = self.theta > _THET
        return hnew
