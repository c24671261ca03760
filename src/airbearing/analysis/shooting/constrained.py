"""The constrained shooting NLP: continuity between windows and inequalities on ``theta``.

The same weighted residual, scaling and Gauss-Newton Hessian as the unconstrained
solver of :mod:`.functions`, with constraints ``g = [c; h(theta)]``:

- ``c = 0``: the continuity defects of the linked pairs of consecutive windows (the end
  state of window ``j`` equals the start state of window ``j + 1``, in noise units,
  :func:`.problem_functions._link_function`), so the windows of one segment form one trajectory;
- ``h(theta) >= 0``: any CasADi Function of the free parameters (e.g. the principal
  minors of a pseudo-inertia), with its exact Jacobian and Hessian.

The Hessian of the Lagrangian is ``lambda_f J^T J`` plus the exact Hessian of
``lambda_h . h`` (constrained Gauss-Newton, Bock's multiple shooting: the continuity
defects' second derivatives are left out). :func:`null_space_basis` turns the linearised
continuity constraints into the basis the covariance is computed in.
"""

from __future__ import annotations

import hashlib

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from airbearing.analysis.shooting.function_cache import borrowed
from airbearing.analysis.shooting.functions import (
    _Call,
    _problem_functions,
    delta_layout,
    evaluate,
    ipopt_options,
    layout_key,
    scale_columns,
)

__all__ = ["Inequality", "null_space_basis"]


class Inequality:
    """``h(theta) >= 0`` with its Jacobian and the Hessian of ``lam . h`` (CasADi VM).

    Parameters
    ----------
    fn : casadi.Function
        One input, the ``k`` free parameters (the fit's ``theta``, SI units); one output,
        the ``m`` constraint values.
    """

    def __init__(self, fn: ca.Function) -> None:
        k = fn.size1_in(0)
        th = ca.SX.sym("theta", k)
        h = fn(th)
        lam = ca.SX.sym("lam", h.shape[0])
        self.k, self.m = k, h.shape[0]
        self.fn = ca.Function("h", [th], [h])
        self.jac = ca.Function("h_jac", [th], [h, ca.jacobian(h, th)])
        self.hess = ca.Function("h_hess", [th, lam], [ca.hessian(ca.dot(lam, h), th)[0]])

    def value(self, theta) -> np.ndarray:
        """``h(theta)``."""
        return self.fn(theta).full().ravel()


class _LinkedOracle:
    """Residual, defects and their Jacobians at the last iterate (one compiled evaluation)."""

    def __init__(self, fr, fj, n_p: int, K: int, n_v: int, link: bool) -> None:
        self.fr, self.fj, self.link = fr, fj, link
        self.n_p, self.K, self.n_v = n_p, K, n_v
        self.z = self.r = self.J = self.c = self.Jc = None
        self.ineq, self.rows = None, np.zeros(0, dtype=int)

    def set(self, p_base, S, scale, data, rows, ineq) -> None:
        """The data of the next solve: parameters, scaling, linked defect rows, inequality."""
        self.pb, self.S, self.scale, self.data = p_base, S, scale, data
        self.rows, self.ineq, self.z = rows, ineq, None

    def release(self) -> None:
        """Forget the last iterate (its Jacobian is large on long logs; the cached solver
        keeps this oracle)."""
        self.z = self.r = self.J = None
        if hasattr(self, "Jc"):
            self.c = self.Jc = None

    def _g(self, z, c):
        g = [c[self.rows]]
        if self.ineq is not None:
            g.append(self.ineq.value((z * self.scale)[: self.ineq.k]))
        return np.concatenate(g)

    def r_g(self, z):
        if self.z is None or not np.array_equal(z, self.z):
            out = evaluate(self.fr, z * self.scale, self.pb, self.S, self.data)
            r, c = out if self.link else (out[0], np.zeros(0))
            self.z, self.J = z.copy(), None
            self.r, self.c = r, c
        return self.r, self._g(z, self.c)

    def derivatives(self, z):
        if self.z is None or self.J is None or not np.array_equal(z, self.z):
            out = self.fj(z * self.scale, self.pb, self.S, self.data)
            r, J, c, Jc = out if self.link else (*out, np.zeros(0), sp.csc_matrix((0, self.n_v)))
            self.z = z.copy()
            self.r, self.c = r, c
            self.J = scale_columns(J, self.scale)
            self.Jc = scale_columns(Jc[self.rows], self.scale) if self.rows.size else None
        return self.r, self.J

    def jac_g(self, z):
        """``(g, Jg)`` with ``Jg`` scipy CSC: the continuity rows, then the inequalities'."""
        self.derivatives(z)
        blocks = [] if self.Jc is None else [self.Jc]
        if self.ineq is not None:
            k = self.ineq.k
            _, hj = self.ineq.jac((z * self.scale)[:k])
            Jh = np.zeros((self.ineq.m, self.n_v))
            Jh[:, :k] = hj.full() * self.scale[:k]
            blocks.append(sp.csc_matrix(Jh))
        return self._g(z, self.c), sp.vstack(blocks, format="csc")


def _values(M, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """The entries of sparse ``M`` at ``(rows, cols)`` (a fixed pattern's order)."""
    return np.asarray(sp.csr_matrix(M)[rows, cols]).ravel()


def _spy(P: sp.csc_matrix) -> tuple:
    """``(casadi.Sparsity, rows, cols)`` of a scipy pattern (CSC, sorted)."""
    P = sp.csc_matrix(P)
    P.sort_indices()
    spy = ca.Sparsity(P.shape[0], P.shape[1], P.indptr.tolist(), P.indices.tolist())
    return spy, P.indices.copy(), np.repeat(np.arange(P.shape[1]), np.diff(P.indptr))


def _linked_patterns(wj, rows: np.ndarray, K: int, n_ineq: int):
    """Sparsity of the constraint Jacobian (the linked pairs' defect rows, then ``n_ineq``
    rows on the ``K`` parameter slots) and of the Hessian's upper triangle (``J^T J``, the
    parameter block dense for the inequalities): the window states couple only through
    their neighbours, so IPOPT's factorisation stays linear in the number of windows."""
    ones = wj.pattern()
    n_v = wj.shape[1]
    blocks = []
    if rows.size:
        spy = wj.defect_sparsity()
        C = sp.csc_matrix(
            (np.ones(spy.nnz()), np.asarray(spy.row()), np.asarray(spy.colind())),
            shape=(spy.size1(), spy.size2()),
        )
        blocks.append(C[rows])
    if n_ineq:
        Jh = np.zeros((n_ineq, n_v))
        Jh[:, :K] = 1.0
        blocks.append(sp.csc_matrix(Jh))
    G = sp.vstack(blocks, format="csc") if blocks else sp.csc_matrix((0, n_v))
    H = (ones.T @ ones).tocsc()
    if K:
        H = H + sp.csc_matrix(
            (np.ones(K * K), (np.repeat(np.arange(K), K), np.tile(np.arange(K), K))),
            shape=(n_v, n_v),
        )
    return _spy(G), _spy(sp.triu(H, format="csc"))


def _build_linked_solver(model, L, nw, K, outputs, substeps, jit, link, rows, n_ineq, max_iter):
    """IPOPT on ``z = v / scale`` with the continuity rows ``rows`` (of the defects of
    every consecutive pair) and ``n_ineq`` inequalities."""
    fr, wj, _ = _problem_functions(model, L, nw, K, outputs, substeps, jit, link)
    rows = np.asarray(rows, dtype=int)
    n_link = rows.size
    nd = sum(delta_layout(model, outputs))
    n_v = K + nd * nw
    ng = n_link + n_ineq
    o = _LinkedOracle(fr, wj, model.n_p, K, n_v, link)
    dv, one = ca.Sparsity.dense(n_v, 1), ca.Sparsity.dense(1, 1)
    dg = ca.Sparsity.dense(ng, 1)
    (jg, g_rows, g_cols), (h_spy, h_rows, h_cols) = _linked_patterns(wj, rows, K, n_ineq)

    def f(z):
        r, _ = o.r_g(z)
        return [0.5 * float(r @ r)]

    def g(z):
        return [o.r_g(z)[1]]

    def grad(z, _par):
        r, J = o.derivatives(z)
        return [0.5 * float(r @ r), np.asarray(J.T @ r).ravel()]

    def jac_g(z, _par):
        gz, Jg = o.jac_g(z)
        return [gz, ca.DM(jg, _values(Jg, g_rows, g_cols))]

    def hess(z, _par, lam_f, lam_g):
        _, J = o.derivatives(z)
        H = lam_f[0] * (J.T @ J)
        if o.ineq is not None:
            k = o.ineq.k
            s = o.scale[:k]
            Hh = o.ineq.hess((z * o.scale)[:k], lam_g[n_link:]).full()
            ij = (np.repeat(np.arange(k), k), np.tile(np.arange(k), k))
            H = H + sp.csc_matrix((np.ravel(Hh * np.outer(s, s)), ij), shape=H.shape)
        return [ca.DM(h_spy, _values(H, h_rows, h_cols))]

    # f and g know their first derivatives (CasADi asks for them once)
    f_jac = _Call(
        "jac_sf", [n_v, 1], [ca.Sparsity.dense(1, n_v)], lambda z, _f: [grad(z, 0)[1][None, :]]
    )
    g_jac = _Call("jac_sg", [n_v, ng], [jg], lambda z, _g: jac_g(z, 0)[1:])
    F = _Call("shoot_f", [n_v], [one], f, lambda name: f_jac)
    G = _Call("shoot_g", [n_v], [dg], g, lambda name: g_jac)
    GF = _Call("shoot_grad_f", [n_v, 0], [one, dv], grad)
    JG = _Call("shoot_jac_g", [n_v, 0], [dg, jg], jac_g)
    H = _Call("shoot_hess_l", [n_v, 0, 1, ng], [h_spy], hess)
    z = ca.MX.sym("z", n_v)
    solver = ca.nlpsol(
        "output_error_linked",
        "ipopt",
        {"x": z, "f": F(z), "g": G(z)},
        {
            "grad_f": GF,
            "jac_g": JG,
            "hess_lag": H,
            **ipopt_options(max_iter),
        },
    )
    return solver, (F, G, GF, JG, H, f_jac, g_jac, o)


def linked_solver(model, L, nw, K, outputs, substeps, jit, link, rows, n_ineq, max_iter):
    """``with linked_solver(...) as (solver, keep)``: :func:`_build_linked_solver`'s, lent
    by the one bounded cache (:func:`.function_cache.borrowed`; ``rows``: the continuity
    rows, part of the key since they set the constraints' sparsity)."""
    rows = np.asarray(rows, dtype=int)
    key = ("linked", layout_key(model, outputs), L, nw, K, outputs, substeps, jit, link,
           hashlib.sha1(rows.tobytes()).hexdigest(), rows.size, n_ineq, max_iter)  # fmt: skip
    return borrowed(
        key,
        lambda: _build_linked_solver(
            model, L, nw, K, outputs, substeps, jit, link, rows, n_ineq, max_iter
        ),
    )


def null_space_basis(Jc, k: int, nd: int | None = None) -> np.ndarray:
    """A basis ``N`` of the directions that keep the linearised continuity ``Jc dv = 0``.

    ``dv = N w`` with ``w = [dtheta; free initial-state directions]``: the first ``k``
    rows of ``N`` are ``[I 0]``, so ``theta`` keeps its coordinates and the remaining
    columns of ``J N`` are nuisance (eliminated by :func:`.problem.theta_errors`, whose
    Schur complement does not depend on which basis of the nuisance directions is used).

    Each defect sets the next window's start, so the continuity's columns of the windows
    that continue another are a square, block-bidiagonal matrix ``C_l``: the free directions
    are the initial states of each segment's first window and the parameters, and the
    others follow by one sparse LU solve, ``dv_l = -C_l^-1 (C_f dv_f + C_t dtheta)``, linear
    in the number of windows. When ``C_l`` is singular (a defect that does not set the next
    start), the orthonormal basis of a dense SVD.

    Parameters
    ----------
    Jc : ndarray or scipy sparse (m, k + n_delta)
        Jacobian of the linked defects in ``[theta; vec(delta)]`` (full row rank in delta:
        each defect sets the next window's start).
    k : int
        Number of parameters.
    nd : int, optional
        Entries of each window's initial state (the rows of each pair's defects, in order);
        None: the dense SVD.
    """
    n = Jc.shape[1]
    if Jc.shape[0] == 0:
        return np.eye(n)
    C = sp.csc_matrix(Jc, dtype=float)
    Ct, Cd = C[:, :k], C[:, k:]
    later = _continued_columns(Cd, nd)
    if later is not None:
        free = np.setdiff1d(np.arange(Cd.shape[1]), later)

        try:
            with np.errstate(all="ignore"):
                lu = splu(sp.csc_matrix(Cd[:, later]))
                rhs = sp.hstack([Cd[:, free], Ct], format="csc").toarray()
                X = -lu.solve(rhs)
        except RuntimeError:  # exactly singular
            X = None
        if X is not None and np.all(np.isfinite(X)):
            N = np.zeros((n, k + free.size))
            N[np.arange(k), np.arange(k)] = 1.0
            N[k + free, k + np.arange(free.size)] = 1.0
            N[k + later, k:] = X[:, : free.size]
            N[k + later, :k] = X[:, free.size :]
            return N
    return _dense_null_space_basis(C.toarray(), k)


def _continued_columns(Cd, nd: int | None):
    """The columns of ``Cd`` (defects by window states, ``nd`` rows per linked pair, in
    order) of the windows whose start each pair's defects set (the pair's last window); None
    when they do not make a square block."""
    m = Cd.shape[0]
    if not nd or m % nd:
        return None
    Cr = sp.csr_matrix(Cd)
    if np.any(np.diff(Cr.indptr) == 0):
        return None
    last = np.maximum.reduceat(Cr.indices, Cr.indptr[:-1])
    window = last.reshape(-1, nd).max(axis=1) // nd
    later = (window[:, None] * nd + np.arange(nd)).ravel()
    if np.unique(later).size != m or later.max() >= Cd.shape[1]:
        return None
    return later


def _dense_null_space_basis(Jc: np.ndarray, k: int) -> np.ndarray:
    """:func:`null_space_basis` through a dense SVD (orthonormal free directions)."""
    n = Jc.shape[1]
    Ct, Cd = Jc[:, :k], Jc[:, k:]
    import scipy.linalg as sla  # only the linked fits need it (0.25 s to import)

    Zd = sla.null_space(Cd)
    P = -np.linalg.lstsq(Cd, Ct, rcond=None)[0] if k else np.zeros((n - k, 0))
    top = np.hstack([np.eye(k), np.zeros((k, Zd.shape[1]))])
    return np.vstack([top, np.hstack([P, Zd])])
