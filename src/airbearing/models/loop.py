"""Long recurrences ``z_{k+1} = f(z_k, v_k, consts)`` evaluated in compiled chunks.

``f.mapaccum(name, n, [0], [0])`` builds a CasADi graph with one node per step:
for a 1 h run at 20 Hz (72,000 steps) building it, evaluating it in the virtual
machine and converting its outputs to NumPy each cost about 0.3-0.5 s. A
:class:`ChunkedLoop` compiles one chunk of ``K`` steps once per structure (C,
cached on disk by :func:`airbearing.models.compiled.compiled`) and calls it
``ceil(n / K)`` times on NumPy memory directly (``Function.buffer``): no graph
of ``n`` nodes, no conversion.
"""

from __future__ import annotations

import numpy as np

from airbearing.models.compiled import compiled

__all__ = ["CHUNK", "ChunkedLoop"]

#: Steps per compiled chunk (the graph and the C code grow with it; the Python
#: overhead per chunk, ~50 us, is shared by this many steps).
CHUNK = 250


class ChunkedLoop:
    """``step.mapaccum(n)`` as compiled chunks: ``(z0, V, *consts) -> (Z, ROWS)``.

    Parameters
    ----------
    step : casadi.Function
        ``(z, v, *consts) -> (z_next, *rows)``: input 0 and output 0 are the carried
        state (same shape, a column), input 1 is one column of per-step data, the
        other inputs are held for the whole run; every output is a column.
    n : int
        Steps.
    chunk : int
        Steps per compiled chunk.

    Calling it returns NumPy arrays ``Z (nz, n)`` (``z_1 .. z_n``) and one
    ``(n_out_i, n)`` array per further output, the same values as the ``mapaccum``.
    """

    def __init__(self, step, n: int, chunk: int = CHUNK) -> None:
        import casadi as ca

        if n < 1:
            raise ValueError(f"n = {n}: expected at least one step")
        for i in range(step.n_out()):
            if step.size2_out(i) != 1:
                raise ValueError(f"{step.name()} output {i} is not a column")
        self.n = int(n)
        self.K = K = int(chunk)  # n itself would give every run length its own library
        self.step = step
        z = ca.MX.sym("z", step.sparsity_in(0))
        V = ca.MX.sym("V", step.size1_in(1), K)
        consts = [ca.MX.sym(step.name_in(i), step.sparsity_in(i)) for i in range(2, step.n_in())]
        outs = step.mapaccum(f"{step.name()}_acc", K, [0], [0])(z, V, *consts)
        fn = ca.Function(f"{step.name()}_x{K}", [z, V, *consts], outs)
        self.fn = compiled(fn)

    def __call__(self, z0, V, *consts):
        n, K, step = self.n, self.K, self.step
        nz, nv = step.size1_in(0), step.size1_in(1)
        z0 = np.ascontiguousarray(np.asarray(z0, dtype=float).reshape(-1))
        if z0.size != nz:
            raise ValueError(f"z0 has {z0.size} entries, expected {nz}")
        # column k of V is step k; rows of Vt are contiguous columns (CasADi is column-major)
        Vt = np.asarray(V, dtype=float)
        Vt = np.ascontiguousarray(Vt.T if Vt.shape == (nv, n) else Vt.reshape(n, nv))
        cs = []
        for i, c in enumerate(consts, start=2):
            a = np.asarray(c, dtype=float)
            # a dense input is column-major: pass the transpose's C-order memory
            cs.append(np.ascontiguousarray(a.T if a.ndim == 2 else a.reshape(-1)))
            if cs[-1].size != step.numel_in(i):
                raise ValueError(f"input {step.name_in(i)} has {a.size} entries")
        outs = [np.empty((n, step.size1_out(i))) for i in range(step.n_out())]
        buf, evaluate = self.fn.buffer()
        for i, c in enumerate(cs, start=2):
            buf.set_arg(i, memoryview(c))
        q, r = divmod(n, K)
        z = z0
        for j in range(q):
            a, b = j * K, (j + 1) * K
            buf.set_arg(0, memoryview(z))
            buf.set_arg(1, memoryview(Vt[a:b]))
            for i, o in enumerate(outs):
                buf.set_res(i, memoryview(o[a:b]))
            evaluate()
            z = np.ascontiguousarray(outs[0][b - 1])
        if r:
            # the last, partial chunk: pad with the last column (finite, discarded)
            vpad = np.empty((K, nv))
            vpad[:r] = Vt[q * K :]
            vpad[r:] = Vt[-1]
            tmp = [np.empty((K, o.shape[1])) for o in outs]
            buf.set_arg(0, memoryview(z))
            buf.set_arg(1, memoryview(vpad))
            for i, o in enumerate(tmp):
                buf.set_res(i, memoryview(o))
            evaluate()
            for o, t in zip(outs, tmp, strict=True):
                o[q * K :] = t[:r]
        return tuple(o.T for o in outs)
