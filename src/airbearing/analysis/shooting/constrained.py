"""The constrained shooting NLP: continuity between windows and inequalities on ``theta``.

The same weighted residual, scaling and Gauss-Newton Hessian as the unconstrained
solver of :mod:`.functions`, with constraints ``g = [c; h(theta)]``:

- ``c = 0``: the continuity defects of the linked pairs of consecutive windows (the end
  state of window ``j`` equals the start state of window ``j + 1``, in noise units,
  :func:`.functions._link_function`), so the windows of one segment form one trajectory;
- ``h(theta) >= 0``: any CasADi Function of the free parameters (e.g. the principal
  minors of a pseudo-inertia), with its exact Jacobian and Hessian.

The Hessian of the Lagrangian is ``lambda_f J^T J`` plus the exact Hessian of
``lambda_h . h`` (constrained Gauss-Newton, Bock's multiple shooting: the continuity
defects' second derivatives are left out). :func:`null_space_basis` turns the linearised
continuity constraints into the basis the covariance is computed in.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

from airbearing.analysis.shooting.functions import (
    _cached,
    _Call,
    _problem_functions,
    delta_layout,
    ipopt_options,
    structure_key,
    to_csc,
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

    def _g(self, z, c):
        g = [c[self.rows]]
        if self.ineq is not None:
            g.append(self.ineq.value((z * self.scale)[: self.ineq.k]))
        return np.concatenate(g)

    def r_g(self, z):
        if self.z is None or not np.array_equal(z, self.z):
            out = self.fr(z * self.scale, self.pb, self.S, self.data)
            r, c = out if self.link else (out, ca.DM(0, 1))
            self.z, self.J = z.copy(), None
            self.r, self.c = r.full().ravel(), c.full().ravel()
        return self.r, self._g(z, self.c)

    def derivatives(self, z):
        if self.z is None or self.J is None or not np.array_equal(z, self.z):
            out = self.fj(z * self.scale, self.pb, self.S, self.data)
            r, J, c, Jc = out if self.link else (*out, ca.DM(0, 1), ca.DM(0, self.n_v))
            self.z = z.copy()
            self.r, self.c = r.full().ravel(), c.full().ravel()
            D = sp.diags(self.scale)
            self.J = to_csc(J) @ D
            self.Jc = (to_csc(Jc)[self.rows] @ D).toarray() if self.rows.size else None
        return self.r, self.J

    def jac_g(self, z):
        self.derivatives(z)
        blocks = [] if self.Jc is None else [self.Jc]
        if self.ineq is not None:
            k = self.ineq.k
            _, hj = self.ineq.jac((z * self.scale)[:k])
            Jh = np.zeros((self.ineq.m, self.n_v))
            Jh[:, :k] = hj.full() * self.scale[:k]
            blocks.append(Jh)
        return self._g(z, self.c), np.vstack(blocks)


def _build_linked_solver(model, L, nw, K, outputs, substeps, jit, link, n_link, n_ineq, max_iter):
    """IPOPT on ``z = v / scale`` with ``n_link`` continuity rows and ``n_ineq`` inequalities."""
    fr, fj, _ = _problem_functions(model, L, nw, K, outputs, substeps, jit, link)
    nd = sum(delta_layout(model, outputs))
    n_v = K + nd * nw
    ng = n_link + n_ineq
    o = _LinkedOracle(fr, fj, model.n_p, K, n_v, link)
    dv, one = ca.Sparsity.dense(n_v, 1), ca.Sparsity.dense(1, 1)
    dg, jg = ca.Sparsity.dense(ng, 1), ca.Sparsity.dense(ng, n_v)

    def f(z):
        r, _ = o.r_g(z)
        return [0.5 * float(r @ r)]

    def g(z):
        return [o.r_g(z)[1]]

    def grad(z, _par):
        r, J = o.derivatives(z)
        return [0.5 * float(r @ r), np.asarray(J.T @ r).ravel()]

    def jac_g(z, _par):
        return list(o.jac_g(z))

    def hess(z, _par, lam_f, lam_g):
        _, J = o.derivatives(z)
        H = lam_f[0] * (J.T @ J).toarray()
        if o.ineq is not None:
            k = o.ineq.k
            s = o.scale[:k]
            Hh = o.ineq.hess((z * o.scale)[:k], lam_g[n_link:]).full()
            H[:k, :k] += Hh * np.outer(s, s)
        return [np.triu(H)]

    # f and g know their first derivatives (CasADi asks for them once)
    f_jac = _Call(
        "jac_sf", [n_v, 1], [ca.Sparsity.dense(1, n_v)], lambda z, _f: [grad(z, 0)[1][None, :]]
    )
    g_jac = _Call("jac_sg", [n_v, ng], [jg], lambda z, _g: jac_g(z, 0)[1:])
    F = _Call("shoot_f", [n_v], [one], f, lambda name: f_jac)
    G = _Call("shoot_g", [n_v], [dg], g, lambda name: g_jac)
    GF = _Call("shoot_grad_f", [n_v, 0], [one, dv], grad)
    JG = _Call("shoot_jac_g", [n_v, 0], [dg, jg], jac_g)
    H = _Call("shoot_hess_l", [n_v, 0, 1, ng], [ca.Sparsity.upper(n_v)], hess)
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


def linked_solver(model, L, nw, K, outputs, substeps, jit, link, n_link, n_ineq, max_iter):
    """``(solver, keep)`` of :func:`_build_linked_solver`, from the one bounded cache."""
    key = ("linked", structure_key(model), L, nw, K, outputs, substeps, jit, link, n_link,
           n_ineq, max_iter)  # fmt: skip
    return _cached(
        key,
        lambda: _build_linked_solver(
            model, L, nw, K, outputs, substeps, jit, link, n_link, n_ineq, max_iter
        ),
    )


def null_space_basis(Jc: np.ndarray, k: int) -> np.ndarray:
    """A basis ``N`` of the directions that keep the linearised continuity ``Jc dv = 0``.

    ``dv = N w`` with ``w = [dtheta; free initial-state directions]``: the first ``k``
    rows of ``N`` are ``[I 0]``, so ``theta`` keeps its coordinates and the remaining
    columns of ``J N`` are nuisance (eliminated by :func:`.problem.theta_errors`).

    Parameters
    ----------
    Jc : ndarray (m, k + n_delta)
        Jacobian of the linked defects in ``[theta; vec(delta)]`` (full row rank in delta:
        each defect sets the next window's start).
    k : int
        Number of parameters.
    """
    Jc = np.asarray(Jc, dtype=float)
    n = Jc.shape[1]
    if Jc.shape[0] == 0:
        return np.eye(n)
    Ct, Cd = Jc[:, :k], Jc[:, k:]
    import scipy.linalg as sla  # only the linked fits need it (0.25 s to import)

    Zd = sla.null_space(Cd)
    P = -np.linalg.lstsq(Cd, Ct, rcond=None)[0] if k else np.zeros((n - k, 0))
    top = np.hstack([np.eye(k), np.zeros((k, Zd.shape[1]))])
    return np.vstack([top, np.hstack([P, Zd])])
