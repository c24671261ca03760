"""CasADi Functions evaluated straight into NumPy arrays: one buffer per Function and
thread (:func:`function_buffer`), every output's nonzeros in new arrays (:func:`evaluate`).
"""

from __future__ import annotations

import threading

import casadi as ca
import numpy as np

#: Bytes of work vectors above which a Function's buffer is made for each call and let go
#: with it instead of kept (:func:`function_buffer`).
KEPT_WORK_BYTES = 16 * 2**20


def function_buffer(fn: ca.Function):
    """``fn.buffer()`` made once per Function and thread, then reused; made anew for each
    call when its work vectors exceed :data:`KEPT_WORK_BYTES`.

    Making a buffer allocates the Function's work vectors: for a window Jacobian of 50 Hz
    pieces about 10 ms, as much as a residual evaluation, and IPOPT's line search evaluates
    thousands of times per search. The caller sets every argument and result pointer
    before each run, so a reused buffer holds nothing of the last call. The functions of
    all the windows of a long log have work vectors of some 0.4 kB per row (the residual,
    the continuity defects: 40-70 MB each on 100,001 rows, one per slot count), and a
    long search evaluates them tens of times, not thousands: kept, they held a few hundred
    MB at the search's peak.
    """
    if 8 * fn.sz_w() + 8 * fn.sz_iw() > KEPT_WORK_BYTES:
        return fn.buffer()
    cache = getattr(fn, "_airbearing_buffers", None)
    if cache is None:
        cache = {}
        try:
            fn._airbearing_buffers = cache
        except AttributeError:  # pragma: no cover - a Function that takes no attribute
            return fn.buffer()
    key = threading.get_ident()
    if key not in cache:
        cache[key] = fn.buffer()
    return cache[key]


def evaluate(fn: ca.Function, *args, keep: bool = True) -> list:
    """The nonzeros of every output of ``fn(*args)``, written by CasADi straight into new
    NumPy arrays (:meth:`casadi.Function.buffer`).

    A call through ``fn(...)`` converts every input to a DM and every output back, element
    by element through Python lists: on an hour of samples that costs several times the
    compiled evaluation itself and a transient Python list of every Jacobian entry (32 bytes
    each). Same values as the call.

    Parameters
    ----------
    fn : casadi.Function or object
        Dense inputs; or an object with its own ``evaluate(*args)`` (the functions of all
        windows run window by window, :class:`~.problem_functions.WindowResidual`).
    *args : array-like
        One per input, its entries in column-major (Fortran) order.
    keep : bool
        Run in the buffer kept with ``fn`` (:func:`function_buffer`); False: in one made
        for this call and let go with it (a function evaluated seldom, on many rows).

    Returns
    -------
    list of ndarray
        Per output, its nonzeros in CasADi's column-major order (:func:`csc_of` makes a
        sparse one a matrix).
    """
    if not isinstance(fn, ca.Function):
        return fn.evaluate(*args)
    buf, run = function_buffer(fn) if keep else fn.buffer()
    held = []
    for i, a in enumerate(args):
        x = np.ascontiguousarray(np.asarray(a, dtype=float).reshape(-1, order="F"))
        if x.size != fn.nnz_in(i):  # pragma: no cover - programming error
            raise ValueError(f"{fn.name()}: input {i} has {x.size} entries, not {fn.nnz_in(i)}")
        held.append(x)
        buf.set_arg(i, memoryview(x))
    out = [np.empty(fn.nnz_out(i)) for i in range(fn.n_out())]
    for i, o in enumerate(out):
        buf.set_res(i, memoryview(o))
    run()
    if buf.ret() != 0:
        raise RuntimeError(f"{fn.name()}: evaluation failed (return code {buf.ret()})")
    return out
