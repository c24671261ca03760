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

import casadi as ca
import numpy as np

from airbearing.models.compiled import compiled

__all__ = ["CHUNK", "ChunkedLoop"]

#: Steps per compiled chunk (the graph and the C code grow with it; the Python
#: overhead per chunk, ~50 us, is shared by this many steps).
CHUNK = 250


class ChunkedLoop:
    """``step.mapaccum(n)`` as compiled chunks: ``(z0, *inputs) -> (Z, *ROWS)``.

    Parameters
    ----------
    step : casadi.Function
        ``(z, ...) -> (z_next, *rows)``: input 0 and output 0 are the carried state
        (same shape, a column); the inputs named by ``mapped`` take one column per
        step; the others are held for the whole run; every output is a column and
        every input dense.
    n : int
        Steps.
    chunk : int
        Steps per compiled chunk.
    mapped : tuple of int
        Inputs with one column per step (default: input 1).

    Calling it with ``(z0, ...)`` (mapped inputs as ``(rows, n)`` arrays) returns
    NumPy arrays ``Z (nz, n)`` (``z_1 .. z_n``) and one ``(n_out_i, n)`` array per
    further output: the same values as ``step.mapaccum(name, n, [0], [0])``.
    """

    def __init__(self, step, n: int, chunk: int = CHUNK, mapped: tuple = (1,)) -> None:
        if n < 1:
            raise ValueError(f"n = {n}: expected at least one step")
        for i in range(step.n_out()):
            if step.size2_out(i) != 1:
                raise ValueError(f"{step.name()} output {i} is not a column")
        for i in range(step.n_in()):
            if not step.sparsity_in(i).is_dense():
                raise ValueError(f"{step.name()} input {step.name_in(i)} is not dense")
        self.mapped = tuple(sorted(set(mapped)))
        if 0 in self.mapped or not all(0 < i < step.n_in() for i in self.mapped):
            raise ValueError(f"mapped inputs {mapped}: expected indices 1..{step.n_in() - 1}")
        for i in self.mapped:
            if step.size2_in(i) != 1:
                raise ValueError(f"{step.name()} input {step.name_in(i)} is not a column")
        self.n = int(n)
        self.K = K = int(chunk)  # n itself would give every run length its own library
        self.step = step
        args = [ca.MX.sym("z", step.sparsity_in(0))]
        for i in range(1, step.n_in()):
            if i in self.mapped:
                args.append(ca.MX.sym(step.name_in(i), step.size1_in(i), K))
            else:
                args.append(ca.MX.sym(step.name_in(i), step.sparsity_in(i)))
        outs = step.mapaccum(f"{step.name()}_acc", K, [0], [0]).call(args)
        self.fn = compiled(ca.Function(f"{step.name()}_x{K}", args, outs))

    def __call__(self, z0, *inputs):
        n, K, step = self.n, self.K, self.step
        if len(inputs) != step.n_in() - 1:
            raise ValueError(f"{step.name()} takes {step.n_in()} inputs, got {len(inputs) + 1}")
        nz = step.size1_in(0)
        z0 = np.ascontiguousarray(np.asarray(z0, dtype=float).reshape(-1))
        if z0.size != nz:
            raise ValueError(f"z0 has {z0.size} entries, expected {nz}")
        data = {}
        for i, a in enumerate(inputs, start=1):
            a = np.asarray(a, dtype=float)
            if i in self.mapped:
                rows = step.size1_in(i)
                if a.shape != (rows, n) and not (rows == 1 and a.shape == (n,)):
                    raise ValueError(
                        f"input {step.name_in(i)} has shape {a.shape}, expected ({rows}, {n})"
                    )
                # column k is step k; rows of the transpose are contiguous columns
                data[i] = np.ascontiguousarray(a.reshape(rows, n).T)
            else:
                # dense and column-major: the transpose's C-order memory
                data[i] = np.ascontiguousarray(a.T if a.ndim == 2 else a.reshape(-1))
                if data[i].size != step.numel_in(i):
                    raise ValueError(f"input {step.name_in(i)} has {a.size} entries")
        outs = [np.empty((n, step.size1_out(i))) for i in range(step.n_out())]
        buf, evaluate = self.fn.buffer()
        for i, c in data.items():
            if i not in self.mapped:
                buf.set_arg(i, memoryview(c))
        q, r = divmod(n, K)
        z = z0
        for j in range(q):
            a, b = j * K, (j + 1) * K
            buf.set_arg(0, memoryview(z))
            for i in self.mapped:
                buf.set_arg(i, memoryview(data[i][a:b]))
            for i, o in enumerate(outs):
                buf.set_res(i, memoryview(o[a:b]))
            evaluate()
            z = np.ascontiguousarray(outs[0][b - 1])
        if r:
            # the last, partial chunk: pad with the last column (finite, discarded)
            pads = {}
            for i in self.mapped:
                pads[i] = np.empty((K, data[i].shape[1]))
                pads[i][:r] = data[i][q * K :]
                pads[i][r:] = data[i][-1]
            tmp = [np.empty((K, o.shape[1])) for o in outs]
            buf.set_arg(0, memoryview(z))
            for i in self.mapped:
                buf.set_arg(i, memoryview(pads[i]))
            for i, o in enumerate(tmp):
                buf.set_res(i, memoryview(o))
            evaluate()
            for o, t in zip(outs, tmp, strict=True):
                o[q * K :] = t[:r]
        return tuple(o.T for o in outs)


#: Steps per chunk of :class:`ExpandedLoop` (its SX graph, built once per structure, grows
#: with it: about 0.1 s to build 250 steps of a 12-state linear loop).
EXPANDED_CHUNK = 250


class ExpandedLoop:
    """``step.mapaccum(n)`` as chunks of ``K`` steps expanded to one SX Function each,
    run in CasADi's virtual machine: no compiler, no Python loop per step.

    A ``mapaccum`` of MX calls costs about 15 us a step in the virtual machine, its
    expansion to SX about 2.5 us (a 12-state linear loop); the chunk is built once per
    step Function and reused for every run length and every input value. For runs of a
    few thousand steps with held inputs (matrices of a linear loop, a limit), where
    compiling (:class:`ChunkedLoop`) costs more than it saves.

    Parameters
    ----------
    step : casadi.Function
        SX ``(z, *held) -> (z_next, *rows)``: input 0 and output 0 are the carried state
        (a column), the held inputs are the same at every step, every output a column.
    chunk : int
        Steps per chunk.

    Calling it with ``(z0, n, *held)`` returns NumPy arrays ``Z (nz, n)`` (``z_1 .. z_n``)
    and one ``(n_out_i, n)`` array per further output: the values of
    ``step.mapaccum(name, n, [0], [0])`` with the held inputs repeated.
    """

    def __init__(self, step, chunk: int = EXPANDED_CHUNK) -> None:
        for i in range(step.n_out()):
            if step.size2_out(i) != 1:
                raise ValueError(f"{step.name()} output {i} is not a column")
        self.step, self.K = step, int(chunk)
        args = [ca.SX.sym(step.name_in(i), step.sparsity_in(i)) for i in range(step.n_in())]
        outs = step.mapaccum(f"{step.name()}_acc", self.K, [0], [0]).call(args)
        self.fn = ca.Function(f"{step.name()}_x{self.K}", args, outs).expand()

    def __call__(self, z0, n: int, *held):
        if n < 1:
            raise ValueError(f"n = {n}: expected at least one step")
        held = [ca.DM(np.asarray(h, dtype=float)) for h in held]
        z = ca.DM(np.asarray(z0, dtype=float).reshape(-1))
        parts = []
        for _ in range(-(-n // self.K)):
            outs = self.fn(z, *held)
            outs = outs if isinstance(outs, tuple) else (outs,)
            parts.append([np.asarray(o) for o in outs])
            z = outs[0][:, -1]
        return tuple(np.hstack(col)[:, :n] for col in zip(*parts, strict=True))
