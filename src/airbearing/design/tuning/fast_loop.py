"""NumPy copies of a Loop's python-control pieces: frequency responses, the closed loop
and its step response, in milliseconds per candidate (the search's workhorse)."""

from __future__ import annotations

import numpy as np

__all__: list[str] = []


def _mats(sys) -> tuple:
    return tuple(np.asarray(m, dtype=float) for m in (sys.A, sys.B, sys.C, sys.D))


def _freq(A, B, C, D, x) -> np.ndarray:
    """``C (x I - A)^-1 B + D`` at the points ``x`` (z values), shape (p, m, len(x))."""
    n = A.shape[0]
    if n == 0:
        return np.repeat(D[:, :, None].astype(complex), x.size, axis=2)
    M = x[:, None, None] * np.eye(n) - A[None]
    X = np.linalg.solve(M, np.broadcast_to(B, (x.size,) + B.shape))
    return np.moveaxis(np.einsum("ij,kjl->kil", C, X) + D[None], 0, -1)


def _assemble(P, K, Dl, nmeas: int, nch: int) -> tuple:
    """Closed loop of plant ``P`` (inputs: channels then disturbances; outputs: the used
    measurements first), controller ``K`` (inputs: measurements then references) and
    delay ``Dl`` (commands to channels), as matrices.

    States ``[plant, controller, delay]``; inputs ``[disturbances, references]``; outputs
    ``[plant outputs, channels]`` (the order of :meth:`Loop.closed_loop`'s pieces).
    """
    Ap, Bp, Cp, Dp = P
    Ac, Bc, Cc, Dc = K
    Ad, Bd, Cd, Dd = Dl
    npl, nc, nd = Ap.shape[0], Ac.shape[0], Ad.shape[0]
    n = npl + nc + nd
    ip, ic, idl = slice(0, npl), slice(npl, npl + nc), slice(npl + nc, n)
    Bpu, Bpw, Dpu, Dpw = Bp[:, :nch], Bp[:, nch:], Dp[:, :nch], Dp[:, nch:]
    Cm, Dmu, Dmw = Cp[:nmeas], Dpu[:nmeas], Dpw[:nmeas]
    Bcy, Bcr, Dcy, Dcr = Bc[:, :nmeas], Bc[:, nmeas:], Dc[:, :nmeas], Dc[:, nmeas:]
    # channels u = Ux x + Uw w + Ur r (solving the algebraic loop when there is no delay)
    Mx = np.zeros((nch, n))
    Mx[:, ip], Mx[:, ic], Mx[:, idl] = Dd @ Dcy @ Cm, Dd @ Cc, Cd
    Minv = np.linalg.inv(np.eye(nch) - Dd @ Dcy @ Dmu)
    Ux, Uw, Ur = Minv @ Mx, Minv @ (Dd @ Dcy @ Dmw), Minv @ (Dd @ Dcr)
    # measurements y = Yx x + Yw w + Yr r; commands v = Vx x + Vw w + Vr r
    Yx = Dmu @ Ux
    Yx[:, ip] += Cm
    Yw, Yr = Dmu @ Uw + Dmw, Dmu @ Ur
    Vx = Dcy @ Yx
    Vx[:, ic] += Cc
    Vw, Vr = Dcy @ Yw, Dcy @ Yr + Dcr
    A = np.zeros((n, n))
    A[ip] = Bpu @ Ux
    A[ip, ip] += Ap
    A[ic] = Bcy @ Yx
    A[ic, ic] += Ac
    A[idl] = Bd @ Vx
    A[idl, idl] += Ad
    Bw = np.vstack([Bpu @ Uw + Bpw, Bcy @ Yw, Bd @ Vw])
    Br = np.vstack([Bpu @ Ur, Bcy @ Yr + Bcr, Bd @ Vr])
    Cy = Dpu @ Ux
    Cy[:, ip] += Cp
    C = np.vstack([Cy, Ux])
    D = np.hstack([np.vstack([Dpu @ Uw + Dpw, Uw]), np.vstack([Dpu @ Ur, Ur])])
    return A, np.hstack([Bw, Br]), C, D


def _step_response(A, b, C, d, n: int) -> np.ndarray:
    """Outputs ``y_k = C x_k + d`` for k < n (shape (outputs, n)), ``x_0 = 0``,
    ``x_{k+1} = A x_k + b``, by doubling: ``x_{k+m} = A^m x_k + x_m`` fills samples
    m..2m-1 from 0..m-1 in one product. The long products are ``np.einsum`` loops, not
    threaded BLAS, which on a busy machine waits for its threads far longer than the
    product takes."""
    X = np.empty((n, A.shape[0]))  # time first: contiguous rows
    x = np.zeros(A.shape[0])
    m = min(32, n)
    for k in range(m):
        X[k] = x
        x = A @ x + b
    Am = np.linalg.matrix_power(A, m)
    while m < n:  # x holds x_m, Am holds A^m
        Am[np.abs(Am) < 1e-150] = 0.0  # no subnormal numbers: they are 100 times slower
        e = min(2 * m, n)
        np.einsum("kj,ij->ki", X[: e - m], Am, out=X[m:e])
        X[m:e] += x
        x = Am @ x + x
        Am = Am @ Am
        m = e
    return np.einsum("ij,kj->ik", C, X) + d[:, None]
