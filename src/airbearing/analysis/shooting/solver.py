"""The IPOPT solver of the shooting engine: the options every fit shares
(:func:`ipopt_options`), the Gauss-Newton problem on ``z = v / scale`` (:func:`_build_solver`)
with its oracle (:class:`_Oracle`: one compiled evaluation of ``(r, J)`` per iterate) and
the CasADi callbacks that call it (:class:`_Call`). Cached in the one bounded cache
(:mod:`.function_cache`, :func:`_problem_solver`); the constrained and penalised solvers
(:mod:`.constrained`, :mod:`.penalty`) share the options, the oracle's pieces and the callback.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from airbearing.analysis.shooting.buffers import evaluate
from airbearing.analysis.shooting.function_cache import borrowed
from airbearing.analysis.shooting.problem_functions import _problem_functions
from airbearing.analysis.shooting.sparse import gram, scale_columns
from airbearing.analysis.shooting.window_functions import delta_layout, layout_key

#: IPOPT iteration limit (Gauss-Newton on scaled variables converges in a few).
IPOPT_MAX_ITER = 80


#: IPOPT tolerance (scaled variables: a step of 1 moves the residual by ~1 sigma).
IPOPT_TOL = 1e-6


#: IPOPT's acceptable-level test with the objective's change in it: for 2 iterations in a row
#: the scaled optimality error below 1e-2 AND the objective (half the chi-square) changed by
#: less than 1e-10 of itself (4e-7 of a chi-square of 4,300: far below one unit). At such
#: points of a warm-started fit the round-off of a long rollout's gradient kept the dual
#: infeasibility above ``IPOPT_TOL`` and IPOPT backtracked 15-27 times per iteration
#: (docs/benchmarks.md, "Where a dof-3 search spends its time"). That floor grows with the
#: rollout: at the bottom of the grid it was 4.6e-4 on a 2.5 min 50 Hz log (8 sub-steps),
#: above the 1e-4 first chosen, and the fit crept to the iteration limit (80 iterations of 20
#: backtracking steps, the objective flat to 8 digits). A scaled gradient of 1e-2 can lower
#: the objective by about 1e-4 (a step of 1 moves the residual by ~1 sigma): nothing.
OBJECTIVE_STOP = {
    "ipopt.acceptable_tol": 1e-2,
    "ipopt.acceptable_obj_change_tol": 1e-10,
    "ipopt.acceptable_iter": 2,
}


def start_meets_objective_stop(r, J, x0, lbx, ubx) -> bool:
    """Whether a fit's start already meets :data:`OBJECTIVE_STOP`: IPOPT would stop there
    after two acceptable iterates, each evaluating the window Jacobian, for nothing.

    ``r``, ``J``: the residual and its Jacobian (scipy sparse) at the start ``x0`` of the
    scaled variables, bounded by ``lbx``, ``ubx``. True when the scaled gradient ``J^T r``
    is below the acceptable tolerance and the Gauss-Newton step from the start would lower
    the objective ``0.5 |r|^2`` by less than its acceptable relative change, within the
    bounds: that step moves no parameter by more than ``sqrt(2 gain)`` of its standard
    error (a step of 1 in the scaled variables moves the residual by ~1 sigma), which is
    less than 1e-3 of it on a chi-square of 10^4. Free variables only (fixed and unused
    slots, and columns the residual does not depend on, are left out).
    """
    J = sp.csc_matrix(J)
    free = (lbx < ubx) & (J.getnnz(axis=0) > 0)
    # the free columns' sums from J's own (each column's in its order, as of the copy
    # J[:, free], whose Gram matrix scipy made from a CSR copy of it: on an hour of 50 Hz
    # three-axis samples 170 MB at the horizon's last fit)
    g = np.asarray(J.T @ r).ravel()[free]
    small = np.abs(g).max(initial=0.0) < OBJECTIVE_STOP["ipopt.acceptable_tol"]
    if not (np.all(np.isfinite(g)) and small):
        return False
    try:
        G = gram(J)[free][:, free]
        G.sort_indices()
        step = splu(G).solve(g)
    except RuntimeError:  # singular: a direction the data do not fix
        return False
    gain = 0.5 * float(g @ step)
    x1 = x0[free] - step
    inside = np.all((x1 >= lbx[free]) & (x1 <= ubx[free]))
    limit = OBJECTIVE_STOP["ipopt.acceptable_obj_change_tol"] * 0.5 * float(r @ r)
    return bool(inside and np.isfinite(gain) and 0.0 <= gain < limit)


def _problem_solver(model, L, nw, K, outputs, substeps, jit, max_iter=IPOPT_MAX_ITER):
    """``with _problem_solver(...) as (solver, keep)``: the IPOPT solver and the Python
    objects it calls (kept alive), lent by the one bounded cache
    (:func:`.function_cache.borrowed`: its oracle holds the fit in progress)."""
    key = ("solver", layout_key(model, outputs), L, nw, K, outputs, substeps, jit, max_iter)
    return borrowed(key, lambda: _build_solver(model, L, nw, K, outputs, substeps, jit, max_iter))


class _Oracle:
    """The weighted residual ``r`` and its Jacobian at the last point, shared by IPOPT's
    objective, gradient and Gauss-Newton Hessian: one compiled evaluation per iterate."""

    def __init__(self, fr, fj, n_p: int, K: int, n_v: int) -> None:
        self.fr, self.fj = fr, fj
        self.n_p, self.K, self.n_v = n_p, K, n_v
        self.z = self.par = self.r = self.J = self.cur = None

    def set(self, par: np.ndarray) -> None:
        """The solver parameters of the next solve (kept here, not passed through IPOPT:
        converting the log's data vector on every callback would cost more than the fit)."""
        self.cur, self.z = par, None

    def _args(self, z, par):
        n_p, K, n_v = self.n_p, self.K, self.n_v
        pb = par[:n_p]
        S = par[n_p : n_p + n_p * K].reshape(n_p, K, order="F")
        scale = par[n_p + n_p * K : n_p + n_p * K + n_v]
        return z * scale, pb, S, par[n_p + n_p * K + n_v :], scale

    def _same(self, z, par) -> bool:
        return self.z is not None and par is self.par and np.array_equal(z, self.z)

    def release(self) -> None:
        """Forget the last iterate (its Jacobian is large on long logs; the cached solver
        keeps this oracle)."""
        self.z = self.r = self.J = None
        if hasattr(self, "Jc"):
            self.c = self.Jc = None

    def r_at(self, z, par) -> np.ndarray:
        if not self._same(z, par):
            v, pb, S, data, _ = self._args(z, par)
            self.z, self.par, self.J = z.copy(), par, None
            self.r = evaluate(self.fr, v, pb, S, data)[0]
        return self.r

    def rj_at(self, z, par):
        if not (self._same(z, par) and self.J is not None):
            v, pb, S, data, scale = self._args(z, par)
            r, J = self.fj(v, pb, S, data)
            self.z, self.par = z.copy(), par
            self.r = r
            self.J = scale_columns(J, scale)  # scipy CSC (sparse windows)
        return self.r, self.J


class _Call(ca.Callback):
    """A CasADi Function evaluated in Python (optionally with a Jacobian Function)."""

    def __init__(self, name, sizes, out_sp, fn, jac=None) -> None:
        ca.Callback.__init__(self)
        self.sizes, self.out_sp, self.fn, self.jac = sizes, out_sp, fn, jac
        self.construct(name, {})

    def get_n_in(self):
        return len(self.sizes)

    def get_n_out(self):
        return len(self.out_sp)

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.sizes[i], 1)

    def get_sparsity_out(self, i):
        return self.out_sp[i]

    def eval(self, arg):
        # DM.full() converts in C; np.asarray(DM) goes element by element
        return self.fn(*[a.full().ravel() for a in arg])

    def has_jacobian(self):
        return self.jac is not None

    def get_jacobian(self, name, inames, onames, opts):
        return self.jac(name)


def ipopt_options(max_iter: int, objective_stop: bool = False) -> dict:
    """The IPOPT options every fit of the engine shares (quiet, scaled tolerances).

    ``objective_stop``: also stop when the objective has converged (``OBJECTIVE_STOP``),
    for warm-started fits near their optimum only (the process-noise descent): far from it
    a creeping IPOPT meets the same test.
    """
    return {
        # a trial point whose replay is not finite is IPOPT's to reject; CasADi's "NaN
        # detected" lines would only reach a notebook's output
        "show_eval_warnings": False,
        "print_time": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.max_iter": int(max_iter),
        "ipopt.tol": IPOPT_TOL,
        "ipopt.acceptable_tol": 1e-5,
        "ipopt.acceptable_iter": 3,
        "ipopt.mu_strategy": "adaptive",
        **(OBJECTIVE_STOP if objective_stop else {}),
    }


def _build_solver(model, L, nw, K, outputs, substeps, jit, max_iter=IPOPT_MAX_ITER):
    """IPOPT on ``z = v / scale``: objective 0.5 |r|^2, gradient J^T r, Hessian J^T J.

    Gauss-Newton: no second derivatives through the rollout. The objective, its gradient
    and the Hessian come from one compiled evaluation of ``(r, J)`` per iterate (a shared
    :class:`_Oracle`; trial points of the line search evaluate ``r`` alone). The
    objective's derivative in the solver parameters is declared structurally zero: IPOPT
    never uses it (no multipliers of the parameters are computed).
    """
    fr, fj, _ = _problem_functions(model, L, nw, K, outputs, substeps, jit)
    nd = sum(delta_layout(model, outputs))
    n_v = K + nd * nw
    n_p = model.n_p
    n_par = 0  # the solver parameters live in the oracle (:meth:`_Oracle.set`)
    o = _Oracle(fr, fj, n_p, K, n_v)

    def f(z, _par):
        r = o.r_at(z, o.cur)
        with np.errstate(over="ignore", invalid="ignore"):  # a trial step IPOPT rejects
            return [0.5 * float(r @ r)]

    def grad(z, _par):
        r, J = o.rj_at(z, o.cur)
        return [0.5 * float(r @ r), np.asarray(J.T @ r).ravel()]

    def jac_f(name):
        def fn(z, _par, _out):
            r, J = o.rj_at(z, o.cur)
            return [np.asarray(J.T @ r).reshape(1, -1), np.zeros((1, 0))]

        return _Call(name, [n_v, n_par, 1], [ca.Sparsity.dense(1, n_v), ca.Sparsity(1, n_par)], fn)

    def hess(z, _par, lam_f, _lam_g):
        _, J = o.rj_at(z, o.cur)
        return [np.triu(lam_f[0] * (J.T @ J).toarray())]

    F = _Call("nlp_f_cb", [n_v, n_par], [ca.Sparsity.dense(1, 1)], f, jac_f)
    G = _Call(
        "nlp_grad_f", [n_v, n_par], [ca.Sparsity.dense(1, 1), ca.Sparsity.dense(n_v, 1)], grad
    )
    H = _Call("nlp_hess_l", [n_v, n_par, 1, 0], [ca.Sparsity.upper(n_v)], hess)
    z = ca.MX.sym("z", n_v)
    par = ca.MX.sym("par", n_par)
    solver = ca.nlpsol(
        "output_error",
        "ipopt",
        {"x": z, "p": par, "f": F(z, par)},
        {
            "grad_f": G,
            "hess_lag": H,
            "calc_lam_p": False,
            "calc_lam_x": False,
            "calc_multipliers": False,
            **ipopt_options(max_iter),
        },
    )
    return solver, (F, G, H, o)
