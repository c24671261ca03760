"""A shooting problem's fit by IPOPT (:class:`IpoptFitting`, the half of
:class:`.ShootingProblem` that fits): the start and its column scaling, the solver set-up
(free, equality-linked or with inequalities, penalised with process noise), the free fit
tried before a bounded one, and the :class:`.Fit` with its errors at the answer."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from airbearing.analysis.shooting.constrained import Inequality, linked_solver, null_space_basis
from airbearing.analysis.shooting.fit import Fit, classify_status, theta_errors
from airbearing.analysis.shooting.functions import IPOPT_MAX_ITER, _problem_solver
from airbearing.analysis.shooting.penalty import penalised_solver
from airbearing.analysis.shooting.problem_arrays import (
    _kept_columns,
    _PerThread,
    pinned_null_space,
    unscale_columns,
)
from airbearing.analysis.shooting.solver import start_meets_objective_stop
from airbearing.analysis.shooting.sparse import stacked_column_norms
from airbearing.errors import SolverError

_ACCEPTABLE = "Solved_To_Acceptable_Level"


class IpoptFitting:
    """The fits of :class:`.ShootingProblem` (its base class): IPOPT with a Gauss-Newton
    Hessian on the problem's residual, its window Jacobian and its data vector."""

    # the fit in progress (:meth:`fit`), each thread's own
    _held = _PerThread(np.zeros(0, dtype=int))  # the entries of vec(delta) it holds
    _start_raw = _PerThread(None)  # the window Jacobian at its start, for its first iterate
    _keep_start = _PerThread(False)  # keep the next start's (a free fit's) for the bounded fit
    _start_kept = _PerThread(None)
    _free_box = _PerThread(None)  # a free fit's bounds (lower, upper) on theta, not imposed
    _used = _PerThread(None)  # its parameter slots (the others' columns left empty)

    def fit(
        self,
        p_base: np.ndarray,
        S: np.ndarray | None = None,
        theta0: np.ndarray | None = None,
        *,
        lower: np.ndarray | None = None,
        upper: np.ndarray | None = None,
        delta0: np.ndarray | None = None,
        name: str = "output error",
        constraint=None,
        max_iter: int | None = None,
        accept_max_iter: bool = False,
    ) -> Fit:
        """Fit the window initial states (and ``theta``) by IPOPT with a Gauss-Newton Hessian.

        With linked windows (:attr:`WindowSet.link`) the continuity of each linked pair is
        an equality constraint, and ``constraint`` adds ``h(theta) >= 0``
        (:mod:`.constrained`); the errors are then those of the constrained problem (the
        continuity eliminated through its null space, the inequalities ignored).

        Parameters
        ----------
        p_base : ndarray (n_p,)
            Parameters with every free entry at its base value.
        S : ndarray (n_p, k), optional
            ``p = p_base + S theta``; None fits the initial states only.
        theta0, lower, upper : ndarray (k,), optional
            Start and bounds of ``theta`` (default 0, unbounded).
        delta0 : ndarray (n_delta, n_windows), optional
            Start of the initial-state perturbations (default 0).
        name : str
            Names the problem in a SolverError.
        constraint : casadi.Function, optional
            ``theta (k,) -> h (m,)``, kept ``>= 0`` (e.g. physical consistency); a start
            outside is allowed (IPOPT moves into the feasible set).
        max_iter : int, optional
            IPOPT iteration limit (default ``IPOPT_MAX_ITER``).
        accept_max_iter : bool
            Take the last iterate when IPOPT stops at its iteration limit (level
            ``"warning"``) instead of raising: a baseline that only has to be a fit, such as
            the nominal replay of a rig far from its model.

        Raises
        ------
        SolverError
            When the status is an error (module doc) or the replay is not finite.
        """
        p_base = np.asarray(p_base, dtype=float)
        S = np.zeros((self.model.n_p, 0)) if S is None else np.asarray(S, dtype=float)
        if (
            (lower is not None or upper is not None)
            and constraint is None
            and self.penalty is not None
        ):
            # interior-point iterations multiply with bounds far from the answer (4-5x on
            # linked pieces): a free fit that ends inside the bounds is the bounded fit too.
            # Its start is the bounded fit's (a start inside the bounds): the window Jacobian
            # there is kept for it (one evaluation less when the free fit leaves the bounds)
            self._start_kept = None
            self._keep_start = True
            try:
                free = self._free_fit(p_base, S, theta0, lower, upper, delta0, name, max_iter)
            finally:
                self._keep_start = False
            if free is not None:
                self._start_kept = None
                return free
        v0, Sp, lb, ub, scale = self._start(p_base, S, theta0, lower, upper, delta0, name)
        if not self._keep_start:  # (the free fit keeps its start for the bounded fit)
            self._start_kept = None
        ineq = None if constraint is None else Inequality(constraint)
        mi = IPOPT_MAX_ITER if max_iter is None else int(max_iter)
        z, stats, r, J, Jc = self._solve(v0, Sp, lb, ub, scale, p_base, ineq, mi)
        status = str(stats.get("return_status", "?"))
        level = classify_status(status)
        if self.objective_stop and self.penalty is not None and status == _ACCEPTABLE:
            level = "converged"  # the objective converged (solver.OBJECTIVE_STOP)
        if accept_max_iter and status == "Maximum_Iterations_Exceeded":
            level = "warning"  # the last iterate, taken as it is (a baseline far from the data)
        if level == "error":
            raise SolverError(f"{name}: IPOPT did not converge ({status})")
        if not np.all(np.isfinite(r)):
            raise SolverError(f"{name}: the fitted replay is not finite")
        box = self._free_box
        if box is not None and self._start_kept is not None:
            th = (z * scale)[: S.shape[1]]
            if np.all((th >= box[0]) & (th <= box[1])):
                # a free fit that ends inside the bounds is the answer (_free_fit): no
                # bounded fit takes the start kept for it (some 87 MB on an hour of 50 Hz
                # three-axis samples, beside the errors' copies of J below)
                self._start_kept = None
        # J handed over (no reference kept here): _result lets go of it once its own copy
        # of the kept columns is made
        J = [J]
        return self._result(z * scale, Sp.shape[1], S, p_base, r, J, Jc, stats, status, level)

    def _start(self, p_base, S, theta0, lower, upper, delta0, name):
        """Start ``v0``, padded ``S``, bounds and the column scaling of a fit."""
        k = S.shape[1]
        nd, nw = self.n_delta, self.windows.n
        d0 = np.zeros((nd, nw)) if delta0 is None else np.asarray(delta0, dtype=float)
        v0, Sp = self._v(d0, S, theta0)
        K = Sp.shape[1]
        lb = np.full(v0.size, -np.inf)
        ub = np.full(v0.size, np.inf)
        if lower is not None:
            lb[:k] = lower
        if upper is not None:
            ub[:k] = upper
        lb[k:K] = ub[k:K] = 0.0  # unused slots
        self._held = self.held(p_base + S @ v0[:k] if k else p_base, S)
        lb[K + self._held] = ub[K + self._held] = 0.0
        v0 = np.clip(v0, lb, ub)
        raw = None
        self._used = k
        if self.link and self.penalty is not None:
            # kept for the solver's first iterate (:meth:`_solve`): the same point
            raw = self._start_raw = self._linked_raw(v0, p_base, Sp)
        if raw is not None and self.meas_whitening is None:
            # the stacked residual's column norms from the window Jacobian's own output
            # (the numbers of the stacked matrix's, which is not made: an hour of samples,
            # it and its square held some 300 MB beside the Jacobian)
            rm, Jm, c, Jc = raw
            r0, J0 = np.r_[rm, self.penalty @ c], None
        else:
            r0, J0 = self._eval(1, v0, p_base, Sp, raw)
        if not np.all(np.isfinite(r0)):
            self._start_raw = None
            raise SolverError(f"{name}: the replay is not finite at the starting point")
        if J0 is None:
            col = stacked_column_norms(Jm, self.penalty @ Jc)
            del Jm, Jc
        else:
            col = np.sqrt(np.asarray(J0.power(2).sum(axis=0)).ravel())
        del J0, raw  # an hour of samples: the Jacobian is 100s of MB
        scale = np.where(col > 0, 1.0 / np.maximum(col, 1e-300), 1.0)
        return v0, Sp, lb, ub, scale

    def _solve(self, v0, Sp, lb, ub, scale, p_base, ineq, mi):
        """IPOPT on the scaled variables: ``(z, stats, r, J, Jc)`` at its last iterate (``J``
        unscaled; ``Jc`` the continuity Jacobian of equality-linked windows, else None)."""
        K = Sp.shape[1]
        n_link = self.link_rows.size
        n_ineq = 0 if ineq is None else ineq.m
        x0, lbx, ubx = v0 / scale, lb / scale, ub / scale
        if self.penalty is not None and self.link:
            if ineq is not None:  # pragma: no cover - programming error
                raise ValueError("process noise and inequality constraints together")
            with penalised_solver(*self._key(K), mi, self.objective_stop) as (solver, keep):
                return self._solve_penalised(solver, keep[-1], x0, lbx, ubx, scale, p_base, Sp)
        if n_link or n_ineq:
            with linked_solver(*self._key(K), self.link, self.link_rows, n_ineq, mi) as (
                solver,
                keep,
            ):
                oracle = keep[-1]
                oracle.set(p_base, Sp, scale, self._data, self.link_rows, ineq)
                lbg = np.zeros(n_link + n_ineq)
                ubg = np.r_[np.zeros(n_link), np.full(n_ineq, np.inf)]
                z = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)["x"].full().ravel()
                oracle.derivatives(z)  # memoised when IPOPT's last iterate had them
                r, J, Jc = oracle.r, oracle.J, oracle.Jc
                oracle.release()
                Jc = unscale_columns(Jc, scale) if n_link else None
                return z, solver.stats(), r, unscale_columns(J, scale), Jc
        with _problem_solver(*self._key(K), mi) as (solver, keep):
            par = np.concatenate([p_base, Sp.reshape(-1, order="F"), scale, self._data])
            oracle = keep[-1]
            oracle.set(par)
            z = solver(x0=x0, lbx=lbx, ubx=ubx)["x"].full().ravel()
            stats = solver.stats()
            if oracle.J is not None and oracle._same(z, par):
                # IPOPT's last iterate was evaluated with its Jacobian: reuse it
                r, J = oracle.r, oracle.J
                oracle.release()
                return z, stats, r, unscale_columns(J, scale), None
            oracle.release()
        r, J = self._eval(1, z * scale, p_base, Sp)
        return z, stats, r, J, None

    def _solve_penalised(self, solver, oracle, x0, lbx, ubx, scale, p_base, Sp):
        """:meth:`_solve` with process noise (linked windows), on a lent solver."""
        oracle.set(p_base, Sp, scale, self._data, self.penalty, self.meas_whitening,
                   keep_raw=self.reuse_last, used=self._used)  # fmt: skip
        raw0, self._start_raw = self._start_raw, None
        if raw0 is not None:
            oracle.prime(x0, raw0)
        del raw0
        if (
            self.objective_stop
            and oracle.z is not None
            and start_meets_objective_stop(oracle.r, oracle.J, x0, lbx, ubx)
        ):
            # started at its optimum (the horizon's answer from its linearisation):
            # IPOPT's acceptable stop, met here, without its two iterations
            z, stats = x0, {"return_status": _ACCEPTABLE, "iter_count": 0}
        else:
            z = solver(x0=x0, lbx=lbx, ubx=ubx)["x"].full().ravel()
            stats = solver.stats()
        r, J = oracle.rj_at(z)
        C = oracle.C  # the defects' Jacobian at the answer (unscaled), for the errors
        if self.reuse_last and oracle.raw is not None:
            at = (z * scale, p_base.copy(), Sp.copy(), self._data_mark())
            self._last = (at, oracle.raw)
        oracle.release()
        return z, stats, r, unscale_columns(J, scale), C

    def _result(self, v, K, S, p_base, r, J, Jc, stats, status, level) -> Fit:
        """The :class:`Fit` at ``v`` with its errors (module doc)."""
        k = S.shape[1]
        nd, nw = self.n_delta, self.windows.n
        penalised = self.penalty is not None and self.link
        keep = np.r_[np.arange(k), np.arange(K, v.size)]
        v = v[keep]
        held = self._held
        # ``J``: the Jacobian, or a list holding it (handed over by :meth:`fit`). Each copy
        # lets go of the one before it (on an hour of 50 Hz three-axis samples 87 MB
        # each: the solver's, its kept columns, the held states zeroed, beside the errors'
        # scaled copy, were the search's peak)
        J = sp.csc_matrix(J.pop() if isinstance(J, list) else J)
        J = _kept_columns(J, k, K)
        J = self._unpinned(J, k, held)
        extra = {"r": r, "J": J, "S": S, "p_base": p_base, "held": held}
        rss = float(r @ r)
        n_free = v.size - held.size
        theta = v[:k]
        if Jc is not None and not penalised:  # errors on continuous trajectories
            N = null_space_basis(Jc[:, keep], k, self.n_delta)
            N = pinned_null_space(N, k + held, k)
            extra["N"] = N
            n_free = N.shape[1]
            Jr, drop = J @ N, None
        else:  # a pinned entry is no nuisance direction (its column is zero): left out
            # of the errors' product (theta_errors's drop), not by a copy of J without it
            Jr, drop = J, k + held
        p = p_base + S @ theta if k else p_base.copy()
        delta = v[k:].reshape(nd, nw, order="F")
        if Jc is not None and penalised:
            # the linearised problem of one trajectory per segment (.errors) takes the
            # measurement rows of J and this: no window Jacobian evaluated again. Kept with
            # what it was evaluated at and on (the point, the problem, its whitening and
            # noise levels)
            C = sp.csc_matrix(Jc)[:, keep]
            at = (theta.copy(), delta.copy(), p.copy(), self.meas_whitening,
                  self._data[-len(self._sigmas()) :].copy())  # fmt: skip
            extra["linearised"] = (self._serial, at, C)
        n_obs = self.n_res + (self.penalty.getnnz(axis=1) > 0).sum() if penalised else self.n_res
        std, cov, reasons = theta_errors(Jr, k, rss / max(n_obs - n_free, 1), drop=drop)
        return Fit(
            theta=theta,
            theta_std=std,
            p=p,
            delta=delta,
            rss=rss,
            n_res=self.n_res,
            n_free=n_free,
            gap=self.gap_of_residual(r),
            iterations=int(stats.get("iter_count", 0)),
            status=status,
            level=level,
            not_identifiable=reasons,
            cov=cov,
            extra=extra,
        )

    def _free_fit(self, p_base, S, theta0, lower, upper, delta0, name, max_iter):
        """The fit without bounds on ``theta`` when it converges inside them, else None."""
        k = S.shape[1]
        lo = np.full(k, -np.inf) if lower is None else np.asarray(lower, dtype=float)
        hi = np.full(k, np.inf) if upper is None else np.asarray(upper, dtype=float)
        th0 = np.zeros(k) if theta0 is None else np.asarray(theta0, dtype=float)
        if not np.all((th0 >= lo) & (th0 <= hi)):
            return None
        self._free_box = (lo, hi)
        try:
            fit = self.fit(p_base, S, th0, delta0=delta0, name=name, max_iter=max_iter)
        except SolverError:
            return None
        finally:
            self._free_box = None
        inside = np.all((fit.theta >= lo) & (fit.theta <= hi))
        return fit if inside else None  # level "warning" is used as a bounded fit would be
