"""Output-error refinement of a platform's inertia and CM offset (CasADi, IPOPT).

The equation-error estimate of :mod:`airbearing.analysis.identification.regression`
integrates sampled data with the trapezoidal rule, which biases it by about
0.1-0.2 % on 20 Hz logs. Here the Model's own discrete dynamics
(``Model.rollout``: RK4 with the inputs held over each sample, as the logs
record them) are fitted to the logged attitudes and rates, by multiple shooting:
each log is cut into segments whose initial states are free, continuity at the
segment joints is an equality constraint, and the physical consistency of the
inertia (the second moment about the CM positive semi-definite with a margin,
i.e. the pseudo-inertia LMI, written as its seven principal minors) stays a
constraint. IPOPT solves it with exact CasADi derivatives, started from the
cvxpy answer. The noise levels are re-estimated from the residuals and the fit
repeated (Gaussian maximum likelihood), and the parameter covariance is the
inverse Fisher information of the single-shooting problem (parameters plus each
log's initial state).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from airbearing.analysis.identification.regression import PARAM_NAMES, PlatformData, theta_to_body
from airbearing.errors import InputError, SolverError
from airbearing.io.testbed import Body, Testbed
from airbearing.models import quaternion as quat
from airbearing.models.model import build_model

__all__ = ["OutputErrorResult", "refine_output_error"]

#: Relative spread of the sample interval that still counts as uniform sampling.
DT_TOLERANCE = 1e-3
#: Smallest noise level (rad, rad/s) used to weight residuals, so an ideal log stays finite.
SIGMA_FLOOR = 1e-7
#: Attitude noise (rad) assumed before the residuals are known (the testbed file has none).
SIGMA_Q_START = 1e-3
#: Threads evaluating the segments' rollouts (CasADi map).
THREADS = 2
#: Refit while a re-estimated noise level moves by more than this fraction.
SIGMA_CHANGE = 0.1
_IPOPT_OK = ("Solve_Succeeded",)
_IPOPT_ACCEPTABLE = ("Solved_To_Acceptable_Level",)


@dataclass(frozen=True, eq=False)
class OutputErrorResult:
    """Outcome of :func:`refine_output_error`.

    Attributes
    ----------
    theta : ndarray (9,)
        ``J_xx .. J_yz`` (kg m^2, about CR, sliders at zero) and ``r_x .. r_z`` (m).
    cov : ndarray (9, 9)
        Covariance from the Fisher information with the fitted noise levels
        (zero rows and columns for fixed parameters).
    cov_spec : ndarray (9, 9)
        The same with the gyro noise of the testbed's sensor specification: the
        Cramer-Rao bound for that noise.
    sigma_w, sigma_q : float
        Fitted noise levels: rate (rad/s) and attitude (rad, small angle).
    rms_w, rms_q : float
        RMS of the rate residual (rad/s) and attitude residual (rad).
    x0 : list of ndarray (7,)
        Fitted initial state of each log.
    iterations : int
        IPOPT iterations, all refits together.
    status : str
        IPOPT's return status of the last fit.
    warnings : list of str
    """

    theta: np.ndarray
    cov: np.ndarray
    cov_spec: np.ndarray
    sigma_w: float
    sigma_q: float
    rms_w: float
    rms_q: float
    x0: list
    iterations: int
    status: str
    warnings: list


def _minors(M):
    """The seven principal minors of a symmetric 3x3 (CasADi): all >= 0 <=> M is PSD."""
    return ca.vertcat(
        M[0, 0],
        M[1, 1],
        M[2, 2],
        M[0, 0] * M[1, 1] - M[0, 1] ** 2,
        M[0, 0] * M[2, 2] - M[0, 2] ** 2,
        M[1, 1] * M[2, 2] - M[1, 2] ** 2,
        ca.det(M),
    )


def _segments(n: int, steps: int | None) -> list[tuple[int, int]]:
    """Split ``n`` samples into near-equal segments of about ``steps`` samples: (start, count)."""
    k = 1 if not steps else max(1, int(round(n / steps)))
    edges = np.linspace(0, n, k + 1).round().astype(int)
    return [(int(a), int(b - a)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def _uniform_dt(d: PlatformData) -> float:
    dt = np.diff(d.t)
    h = float(np.median(dt))
    if np.max(np.abs(dt - h)) > DT_TOLERANCE * h:
        raise InputError(
            f"{d.source}: sample intervals vary from {dt.min():.6g} to {dt.max():.6g} s; the "
            "output-error fit needs uniform sampling (use method='equation-error')"
        )
    return h


def _inputs(model, d: PlatformData) -> np.ndarray:
    """Model inputs per sample (nu, N): sliders, dipole, lab field; no disturbance."""
    U = np.zeros((model.nu, d.n))
    U[model.index(["s1", "s2", "s3"], "u")] = d.s.T
    U[model.index(["mx", "my", "mz"], "u")] = d.dipole.T
    U[model.index(["bx_lab", "by_lab", "bz_lab"], "u")] = d.b_lab.T
    return U


def _sparse(nrow, ncol, rows, cols):
    """A CasADi sparsity from unique triplets, and the nonzero slot of each triplet."""
    rows, cols = np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)
    sp = ca.Sparsity.triplet(nrow, ncol, rows.tolist(), cols.tolist())
    order = np.lexsort((rows, cols))  # column-major, as CasADi stores nonzeros
    slot = np.empty(len(rows), dtype=np.int64)
    slot[order] = np.arange(len(rows))
    return sp, slot


class _Callback(ca.Callback):
    """A CasADi Function evaluated in Python (the NLP oracle pieces)."""

    def __init__(self, name, sp_in, sp_out, fn, jacobian=None):
        ca.Callback.__init__(self)
        self._sp_in, self._sp_out, self._fn, self._jac = sp_in, sp_out, fn, jacobian
        self.construct(name, {})

    def has_jacobian(self):
        return self._jac is not None

    def get_jacobian(self, name, inames, onames, opts):
        return self._jac

    def get_n_in(self):
        return len(self._sp_in)

    def get_n_out(self):
        return len(self._sp_out)

    def get_sparsity_in(self, i):
        return self._sp_in[i]

    def get_sparsity_out(self, i):
        return self._sp_out[i]

    def eval(self, arg):
        return self._fn(*[np.asarray(a.full()) for a in arg])


class _Problem:
    """Multiple-shooting least squares with forward sensitivities of the Model's rollout.

    Decision vector ``v = [theta_hat (nf), z_0 (6), z_1 (6), ...]``: the scaled change of
    the free parameters from ``theta0`` and, per segment, a small rotation of the logged
    start attitude (rad) and the start rate (rad/s). One evaluation of the augmented
    rollout (states and their sensitivities to ``z`` and ``theta``, propagated through
    the Jacobian of ``Model.step``) gives the residuals, their Jacobian, the continuity
    defects and their Jacobian; IPOPT gets the gradient, the constraint Jacobian and a
    Gauss-Newton Hessian from it (constrained Gauss-Newton, Bock's multiple shooting).
    """

    def __init__(self, testbed, data, theta0, free, mass, margin, segment, substeps):
        J0, r0 = theta_to_body(theta0)
        tb = testbed.replace(
            body=Body(
                dof=3,
                mass=mass,
                inertia=tuple(map(tuple, J0)),
                cm_offset=tuple(r0),
                torque_noise=testbed.body.torque_noise,
            )
        )
        self.model = model = build_model(tb)
        self.data = data
        self.free = np.asarray(free, dtype=bool)
        self.fidx = np.flatnonzero(self.free)
        self.nf = nf = len(self.fidx)
        self.theta0 = np.asarray(theta0, float)
        self.js = js = float(np.trace(J0) / 3)
        self.scale = np.where(np.arange(9) < 6, js, 1e-3)
        self.mass, self.margin = mass, margin
        self.p_idx = model.index(PARAM_NAMES, "p")
        nx, nu, n_p = model.nx, model.nu, model.n_p
        nt = 6 + 9  # sensitivity columns: z (6), theta_hat (9, all parameters)

        # ---- SX building blocks
        x, S = ca.SX.sym("x", nx), ca.SX.sym("S", nx, nt)
        u, p = ca.SX.sym("u", nu), ca.SX.sym("p", n_p)
        ql, wl, sig = ca.SX.sym("ql", 4), ca.SX.sym("wl", 3), ca.SX.sym("sig", 2)
        self.steps_fn = {}
        self._x, self._S, self._u, self._psym = x, S, u, p
        y = model.h(x, u, p)
        qe = quat.qmul(quat.qconj(ql), y[0:4])
        e = ca.vertcat(2 * qe[0] * qe[1:4] / sig[0], (y[4:7] - wl) / sig[1])  # whitened
        self.res = ca.Function("res", [x, u, p, ql, wl, sig], [e])
        self.res_aug = ca.Function(
            "res_aug",
            [ca.vertcat(x, ca.vec(S)), u, p, ql, wl, sig],
            [e, ca.mtimes(ca.jacobian(e, x), S)],
        )
        qs, z = ca.SX.sym("qs", 4), ca.SX.sym("z", 6)
        x0 = ca.SX.zeros(nx)
        # [1, dtheta/2] normalised: the small rotation dtheta, smooth to every order at 0
        x0[0:4] = quat.qmul(qs, quat.normalize(ca.vertcat(1, z[0:3] / 2)))
        x0[4:7] = z[3:6]
        for i in model.lag_index:  # lagged gyro states start at the rate
            x0[i] = z[3 + "xyz".index(model.x_names[i][-1])]
        S0 = ca.horzcat(ca.jacobian(x0, z), ca.SX.zeros(nx, 9))
        self.start = ca.Function("start", [qs, z], [x0])
        self.start_aug = ca.Function("start_aug", [qs, z], [ca.vertcat(x0, ca.vec(S0))])
        xe, Se = ca.SX.sym("xe", nx), ca.SX.sym("Se", nx, nt)
        xn = self.start(qs, z)
        qd = quat.qmul(quat.qconj(xe[0:4]), xn[0:4])
        c = ca.vertcat(qd[1:4], xe[4:7] - xn[4:7])  # continuity defect (attitude, rate)
        dc_e = ca.mtimes(ca.jacobian(c, xe), Se)
        self.cont = ca.Function("cont", [xe, qs, z], [c])
        self.cont_aug = ca.Function(
            "cont_aug",
            [ca.vertcat(xe, ca.vec(Se)), qs, z],
            [c, dc_e[:, 6:], dc_e[:, :6], ca.jacobian(c, z)],
        )
        # physical consistency: the 7 principal minors of (Sigma_CM - margin I) / js >= 0
        th = ca.SX.sym("th", nf)
        tf = ca.SX(ca.DM(self.theta0))
        for k, i in enumerate(self.fidx):
            tf[i] = tf[i] + self.scale[i] * th[k]
        Jm = ca.vertcat(
            ca.horzcat(tf[0], tf[3], tf[4]),
            ca.horzcat(tf[3], tf[1], tf[5]),
            ca.horzcat(tf[4], tf[5], tf[2]),
        )
        r = tf[6:9]
        sigma_cm = 0.5 * ca.trace(Jm) * ca.SX.eye(3) - Jm - mass * ca.mtimes(r, r.T)
        phys = _minors((sigma_cm - margin * ca.SX.eye(3)) / js)
        lam = ca.SX.sym("lam", 7)
        self.theta_full = ca.Function("theta_full", [th], [tf])
        self.phys = ca.Function(
            "phys",
            [th, lam],
            [phys, ca.jacobian(phys, th), ca.hessian(ca.dot(lam, phys), th)[0]],
        )

        # ---- segments of every log, grouped by (rollout steps, samples, sample interval)
        segs = []
        self.U, self.dts = [], []
        for li, d in enumerate(data):
            dt = _uniform_dt(d)
            self.dts.append(dt)
            self.U.append(_inputs(model, d))
            steps = None if segment is None else max(2, int(round(segment / dt)))
            pieces = _segments(d.n, steps)
            for j, (k0, n) in enumerate(pieces):
                last = j == len(pieces) - 1
                segs.append((li, k0, n, n - 1 if last else n, dt, last))
        self.segs = segs
        self.nseg = nseg = len(segs)
        self.nv = nf + 6 * nseg
        groups: dict = {}
        for j, (_, _, n, steps, dt, _) in enumerate(segs):
            groups.setdefault((n, steps, dt), []).append(j)
        self.groups = []
        for (n, steps, dt), members in groups.items():
            qs_g = np.column_stack([data[segs[j][0]].q[segs[j][1]] for j in members])
            U_g = np.hstack([self.U[segs[j][0]][:, segs[j][1] : segs[j][1] + n] for j in members])
            Q_g = np.hstack([data[segs[j][0]].q[segs[j][1] : segs[j][1] + n].T for j in members])
            W_g = np.hstack([data[segs[j][0]].w[segs[j][1] : segs[j][1] + n].T for j in members])
            plain, aug = self._segment_functions(n, steps, dt, substeps)
            self.groups.append(
                (
                    np.array(members),
                    n,
                    plain.map(len(members), "thread", THREADS),
                    aug.map(len(members), "thread", THREADS),
                    qs_g,
                    U_g,
                    Q_g,
                    W_g,
                )
            )
        # boundaries between consecutive segments of one log
        self.bounds = [j for j in range(nseg) if not segs[j][5]]
        self.ncont = 6 * len(self.bounds)
        self.ng = self.ncont + 7
        self._cache_key = None
        self._build_patterns()

    def _segment_functions(self, n, steps, dt, substeps):
        """Rollout of one segment: plain (residuals, end state) and augmented (+ sensitivities)."""
        model = self.model
        nx = model.nx
        step = model.step(dt, substeps)
        x, S, u, p = self._x, self._S, self._u, self._psym
        xn = step(x, u, p)
        dp = np.zeros((model.n_p, 9))
        dp[self.p_idx, np.arange(9)] = self.scale
        A = ca.jacobian(xn, x)
        B = ca.mtimes(ca.jacobian(xn, p), ca.DM(dp))
        Sn = ca.mtimes(A, S) + ca.horzcat(ca.SX.zeros(nx, 6), B)
        step_aug = ca.Function(
            "step_aug", [ca.vertcat(x, ca.vec(S)), u, p], [ca.vertcat(xn, ca.vec(Sn))]
        )
        pm, z, qs = ca.MX.sym("p", model.n_p), ca.MX.sym("z", 6), ca.MX.sym("qs", 4)
        U, Q = ca.MX.sym("U", model.nu, n), ca.MX.sym("Q", 4, n)
        W, sig = ca.MX.sym("W", 3, n), ca.MX.sym("sig", 2)
        out = []
        for aug in (False, True):
            x0 = self.start_aug(qs, z) if aug else self.start(qs, z)
            fn = step_aug if aug else step
            if steps > 0:
                X = fn.mapaccum(steps)(x0, U[:, :steps], pm)
                cols = ca.horzcat(x0, X[:, : n - 1]) if n > 1 else x0
                x_end = X[:, steps - 1]
            else:
                cols, x_end = x0, ca.MX.zeros(x0.shape[0])
            res = self.res_aug if aug else self.res
            r = res.map(n)(cols, U, ca.repmat(pm, 1, n), Q, W, ca.repmat(sig, 1, n))
            outs = [r[0], r[1], x_end] if aug else [r, x_end]
            out.append(
                ca.Function("segment_aug" if aug else "segment", [pm, z, qs, U, Q, W, sig], outs)
            )
        return out

    def _build_patterns(self):
        nf, nv = self.nf, self.nv
        # constraint Jacobian: continuity rows (theta, z_j, z_j+1), physical rows (theta)
        rows, cols = [], []
        for b, j in enumerate(self.bounds):
            rr = 6 * b + np.arange(6)
            cc = np.r_[0:nf, nf + 6 * j : nf + 6 * j + 12]
            R, C = np.meshgrid(rr, cc, indexing="ij")
            rows.append(R.ravel())
            cols.append(C.ravel())
        R, C = np.meshgrid(self.ncont + np.arange(7), np.arange(nf), indexing="ij")
        rows.append(R.ravel())
        cols.append(C.ravel())
        self.jac_rows, self.jac_cols = np.concatenate(rows), np.concatenate(cols)
        self.jac_sp, self.jac_slot = _sparse(self.ng, nv, self.jac_rows, self.jac_cols)
        # upper triangle of the Hessian: theta-theta, theta-z_j, z_j-z_j
        rows, cols = [], []
        iu = np.triu_indices(nf)
        rows.append(iu[0])
        cols.append(iu[1])
        for j in range(self.nseg):
            zc = nf + 6 * j + np.arange(6)
            R, C = np.meshgrid(np.arange(nf), zc, indexing="ij")
            rows.append(R.ravel())
            cols.append(C.ravel())
            iz = np.triu_indices(6)
            rows.append(zc[iz[0]])
            cols.append(zc[iz[1]])
        self.hess_rows, self.hess_cols = np.concatenate(rows), np.concatenate(cols)
        self.hess_sp, self.hess_slot = _sparse(nv, nv, self.hess_rows, self.hess_cols)

    # ---- evaluation
    def _p(self, th):
        tf = np.asarray(self.theta_full(th)).ravel()
        p = self.model.p0.copy()
        p[self.p_idx] = tf
        return p

    def _split(self, v):
        return v[: self.nf], v[self.nf :].reshape(self.nseg, 6).T

    def evaluate(self, v, sig, derivatives):
        """Residuals per segment, end states and, optionally, their sensitivities."""
        th, Z = self._split(v)
        p = self._p(th)
        E = [None] * self.nseg
        JE = [None] * self.nseg
        XE = [None] * self.nseg
        for members, n, plain, aug, qs_g, U_g, Q_g, W_g in self.groups:
            fn = aug if derivatives else plain
            out = fn(p, Z[:, members], qs_g, U_g, Q_g, W_g, sig)
            e = np.asarray(out[0]).reshape(6, n, len(members), order="F")
            xe = np.asarray(out[-1])
            if derivatives:
                je = np.asarray(out[1]).reshape(6, 15, n, len(members), order="F")
            for k, j in enumerate(members):
                E[j] = e[:, :, k].T.ravel()  # sample-major: [e_q, e_w] per sample
                XE[j] = xe[:, k]
                if derivatives:
                    JE[j] = je[:, :, :, k].transpose(2, 0, 1).reshape(6 * n, 15)
        return E, JE, XE, th, Z

    def constraints(self, v, XE, derivatives, lam_phys=None):
        th, Z = self._split(v)
        nx = self.model.nx
        c = np.zeros(self.ncont)
        blocks = []
        for b, j in enumerate(self.bounds):
            li, k0 = self.segs[j + 1][0], self.segs[j + 1][1]
            qs = self.data[li].q[k0]
            if derivatives:
                cv, dth, dz0, dz1 = self.cont_aug(XE[j], qs, Z[:, j + 1])
                c[6 * b : 6 * b + 6] = np.asarray(cv).ravel()
                blocks.append(
                    np.hstack([np.asarray(dth)[:, self.fidx], np.asarray(dz0), np.asarray(dz1)])
                )
            else:
                c[6 * b : 6 * b + 6] = np.asarray(self.cont(XE[j][:nx], qs, Z[:, j + 1])).ravel()
        lam = np.zeros(7) if lam_phys is None else lam_phys
        g_phys, j_phys, h_phys = self.phys(th, lam)
        g = np.concatenate([c, np.asarray(g_phys).ravel()])
        return g, blocks, np.asarray(j_phys), np.asarray(h_phys)

    def _derivatives(self, v, sig):
        key = (v.tobytes(), sig.tobytes())
        if self._cache_key != key:
            E, JE, XE, th, Z = self.evaluate(v, sig, True)
            self._cache = (E, JE, XE)
            self._cache_key = key
        return self._cache

    def gram(self, JE, rows=slice(None)):
        """Gauss-Newton blocks ``J^T J`` (theta-theta, theta-z_j, z_j-z_j) for residual ``rows``."""
        fi = np.r_[6 + self.fidx]
        Htt = np.zeros((self.nf, self.nf))
        Htz, Hzz = [], []
        for Jj in JE:
            Jj = Jj.reshape(-1, 6, 15)[:, rows, :].reshape(-1, 15)
            Jt, Jz = Jj[:, fi], Jj[:, :6]
            Htt += Jt.T @ Jt
            Htz.append(Jt.T @ Jz)
            Hzz.append(Jz.T @ Jz)
        return Htt, Htz, Hzz

    # ---- the oracle functions IPOPT calls (noise levels fixed per solve in self.sig)
    def f_fn(self, v):
        E, _, _, _, _ = self.evaluate(v.ravel(), self.sig, False)
        return [ca.DM(0.5 * sum(float(e @ e) for e in E))]

    def g_fn(self, v):
        v = v.ravel()
        _, _, XE, _, _ = self.evaluate(v, self.sig, False)
        g, _, _, _ = self.constraints(v, XE, False)
        return [ca.DM(g)]

    def grad_fn(self, v, *_):
        v = v.ravel()
        E, JE, _ = self._derivatives(v, self.sig)
        grad = np.zeros(self.nv)
        fi = 6 + self.fidx
        for j, (e, Jj) in enumerate(zip(E, JE, strict=True)):
            grad[: self.nf] += Jj[:, fi].T @ e
            grad[self.nf + 6 * j : self.nf + 6 * j + 6] = Jj[:, :6].T @ e
        f = 0.5 * sum(float(e @ e) for e in E)
        return [ca.DM(f), ca.DM(grad).T]

    def jac_fn(self, v, *_):
        v = v.ravel()
        _, _, XE = self._derivatives(v, self.sig)
        g, blocks, j_phys, _ = self.constraints(v, XE, True)
        vals = np.concatenate([b.ravel() for b in blocks] + [j_phys.ravel()])
        nz = np.zeros(self.jac_sp.nnz())
        nz[self.jac_slot] = vals
        return [ca.DM(g), ca.DM(self.jac_sp, nz)]

    def hess_fn(self, v, _p, lam_f, lam_g):
        v = v.ravel()
        lam_f = float(np.asarray(lam_f).ravel()[0])
        _, JE, XE = self._derivatives(v, self.sig)
        _, _, _, h_phys = self.constraints(v, XE, False, np.asarray(lam_g).ravel()[self.ncont :])
        Htt, Htz, Hzz = self.gram(JE)
        Htt = lam_f * Htt + h_phys
        iu = np.triu_indices(self.nf)
        iz = np.triu_indices(6)
        vals = [Htt[iu]]
        for j in range(self.nseg):
            vals.append(lam_f * Htz[j].ravel())
            vals.append(lam_f * Hzz[j][iz])
        nz = np.zeros(self.hess_sp.nnz())
        nz[self.hess_slot] = np.concatenate(vals)
        return [ca.DM(self.hess_sp, nz)]

    def solver(self, max_iter):
        nv, ng = self.nv, self.ng
        dv, one, dg = ca.Sparsity.dense(nv, 1), ca.Sparsity.dense(1, 1), ca.Sparsity.dense(ng, 1)
        dp = ca.Sparsity.dense(0, 1)  # the NLP has no parameters
        grad_cb = _Callback("oe_grad_f", [dv, dp], [one, ca.Sparsity.dense(1, nv)], self.grad_fn)
        jac_cb = _Callback("oe_jac_g", [dv, dp], [dg, self.jac_sp], self.jac_fn)
        # f and g know their first derivatives (CasADi asks for them once, for the multipliers)
        f_jac = _Callback(
            "jac_oe_f", [dv, one], [ca.Sparsity.dense(1, nv)], lambda v, _f: self.grad_fn(v)[1:]
        )
        g_jac = _Callback("jac_oe_g", [dv, dg], [self.jac_sp], lambda v, _g: self.jac_fn(v)[1:])
        f_cb = _Callback("oe_f", [dv], [one], self.f_fn, f_jac)
        g_cb = _Callback("oe_g", [dv], [dg], self.g_fn, g_jac)
        hess_cb = _Callback("oe_hess_l", [dv, dp, one, dg], [self.hess_sp], self.hess_fn)
        self._cbs = [grad_cb, jac_cb, f_jac, g_jac, f_cb, g_cb, hess_cb]  # keep them alive
        v = ca.MX.sym("v", nv)
        nlp = {"x": v, "f": f_cb(v), "g": g_cb(v)}
        opts = {
            "ipopt.print_level": 0,
            "print_time": False,
            "ipopt.sb": "yes",
            "ipopt.tol": 1e-9,
            "ipopt.max_iter": max_iter,
            "grad_f": grad_cb,
            "jac_g": jac_cb,
            "hess_lag": hess_cb,
        }
        return ca.nlpsol("output_error", "ipopt", nlp, opts)

    def z_start(self) -> np.ndarray:
        z = np.zeros((6, self.nseg))
        for j, (li, k0, *_rest) in enumerate(self.segs):
            z[3:6, j] = self.data[li].w[k0]
        return z

    def solve(self, v0, sig, max_iter):
        self.sig = np.asarray(sig, float)
        solver = self.solver(max_iter)
        lbg = np.zeros(self.ng)
        ubg = np.concatenate([np.zeros(self.ncont), np.full(7, np.inf)])
        sol = solver(x0=v0, lbg=lbg, ubg=ubg)
        return np.asarray(sol["x"]).ravel(), solver.stats()

    def raw_residuals(self, v, sig):
        """Unwhitened residuals (6, samples): attitude (rad) and rate (rad/s)."""
        E, _, _, _, _ = self.evaluate(v, sig, False)
        R = np.concatenate([e.reshape(-1, 6) for e in E]).T
        return R * np.r_[np.full(3, sig[0]), np.full(3, sig[1])][:, None]

    def covariance(self, v, sig, weights_w=(1.0,)):
        """Covariance of the free parameters (scaled) from the equality-constrained Fisher matrix.

        The Gauss-Newton matrix of the multiple-shooting problem bordered by the continuity
        Jacobian (KKT matrix); its inverse's parameter block equals the inverse Fisher
        information of single shooting (parameters plus each log's initial state).
        ``weight_w`` rescales the rate residuals' information (another gyro noise level).
        """
        import scipy.sparse as sps
        import scipy.sparse.linalg as spla

        E, JE, XE, _, _ = self.evaluate(v, sig, True)
        Hq = self.gram(JE, slice(0, 3))
        Hw = self.gram(JE, slice(3, 6))
        nf, nv = self.nf, self.nv
        _, blocks, _, _ = self.constraints(v, XE, True)
        C = sps.lil_matrix((self.ncont, nv))
        for b, j in enumerate(self.bounds):
            C[6 * b : 6 * b + 6, :nf] = blocks[b][:, :nf]
            C[6 * b : 6 * b + 6, nf + 6 * j : nf + 6 * j + 12] = blocks[b][:, nf:]
        C = C.tocsc()
        out = []
        for ww in weights_w:
            H = sps.lil_matrix((nv, nv))
            H[:nf, :nf] = Hq[0] + ww * Hw[0]
            for j in range(self.nseg):
                zc = slice(nf + 6 * j, nf + 6 * j + 6)
                H[:nf, zc] = Hq[1][j] + ww * Hw[1][j]
                H[zc, :nf] = (Hq[1][j] + ww * Hw[1][j]).T
                H[zc, zc] = Hq[2][j] + ww * Hw[2][j]
            K = sps.bmat([[H.tocsc(), C.T], [C, None]], format="csc")
            rhs = np.zeros((K.shape[0], nf))
            rhs[np.arange(nf), np.arange(nf)] = 1.0
            try:
                sol = spla.splu(K).solve(rhs)
            except RuntimeError as e:
                raise SolverError(
                    f"output-error fit: the Fisher information is singular ({e}); the logs "
                    "cannot separate the parameters"
                ) from e
            cov = sol[:nf, :nf]
            out.append(0.5 * (cov + cov.T))
        return out


def refine_output_error(
    testbed: Testbed,
    data: list[PlatformData],
    theta0,
    *,
    mass: float,
    free=None,
    margin: float = 0.0,
    segment: float | None = 4.0,
    substeps: int = 2,
    sigma_w: float | None = None,
    sigma_q: float | None = None,
    max_iter: int = 200,
    max_refits: int = 3,
) -> OutputErrorResult:
    """Fit the Model's rollouts to the logs, starting from ``theta0``.

    Parameters
    ----------
    testbed : Testbed
        Platform testbed (its sliders, field, sensors and known effects).
    data : list of PlatformData
        The logs (:func:`~airbearing.analysis.identification.regression.prepare_platform_logs`).
    theta0 : array-like (9,)
        Start: ``J_xx .. J_yz`` (kg m^2, about CR, sliders at zero), ``r_x .. r_z`` (m);
        must satisfy the physical-consistency constraint.
    mass : float
        Total mass, kg (known).
    free : array-like of bool (9,), optional
        Which parameters are fitted; the others stay at ``theta0`` (known values).
    margin : float
        Smallest eigenvalue allowed for the second moment about the CM, kg m^2.
    segment : float or None
        Multiple-shooting segment length, s; None fits each log by single shooting.
    substeps : int
        RK4 sub-steps per sample of the Model's rollout.
    sigma_w, sigma_q : float, optional
        Rate (rad/s) and attitude (rad) noise to start the weights with; default the
        testbed's gyro noise and 1e-3 rad. Re-estimated from the residuals.
    max_iter, max_refits : int
        IPOPT iteration limit per fit; number of noise re-estimations.

    Returns
    -------
    OutputErrorResult

    Raises
    ------
    SolverError
        When IPOPT fails (infeasible, iteration limit, numerical trouble).
    """
    free = np.ones(9, bool) if free is None else np.asarray(free, bool)
    theta0 = np.asarray(theta0, float)
    prob = _Problem(testbed, data, theta0, free, mass, margin, segment, substeps)
    spec_w = testbed.sensors.gyro_noise
    sw = sigma_w if sigma_w is not None else (spec_w if spec_w > 0 else 1e-4)
    sq = sigma_q if sigma_q is not None else SIGMA_Q_START
    sig = np.array([max(sq, SIGMA_FLOOR), max(sw, SIGMA_FLOOR)])
    v = np.concatenate([np.zeros(prob.nf), prob.z_start().T.ravel()])
    iterations, warnings = 0, []
    status = ""
    for _ in range(max_refits + 1):
        v, stats = prob.solve(v, sig, max_iter)
        iterations += int(stats.get("iter_count", 0))
        status = stats.get("return_status", "unknown")
        if status in _IPOPT_ACCEPTABLE:
            warnings.append(f"output-error fit: IPOPT stopped at an acceptable level ({status})")
        elif status not in _IPOPT_OK:
            raise SolverError(
                f"output-error fit (IPOPT, {len(data)} logs, {prob.nseg} segments): {status}; "
                "the equation-error estimate may be too far off (try more logs, shorter "
                "segments or method='equation-error')"
            )
        R = prob.raw_residuals(v, sig)
        new = np.array(
            [
                max(float(np.sqrt(np.mean(R[0:3] ** 2))), SIGMA_FLOOR),
                max(float(np.sqrt(np.mean(R[3:6] ** 2))), SIGMA_FLOOR),
            ]
        )
        changed = np.max(np.abs(new / sig - 1)) > SIGMA_CHANGE
        sig = new
        if not changed:
            break
    th = v[: prob.nf]
    theta_full = np.asarray(prob.theta_full(th)).ravel()
    sc = prob.scale[free]
    ratio = (sig[1] / spec_w) ** 2 if spec_w > 0 else 1.0
    if spec_w <= 0:
        warnings.append(
            "testbed sensors.gyro_noise = 0: the Cramer-Rao bound uses the fitted noise"
        )
    c_fit, c_spec = prob.covariance(v, sig, (1.0, ratio))
    cov, cov_spec = np.zeros((9, 9)), np.zeros((9, 9))
    cov[np.ix_(free, free)] = c_fit * np.outer(sc, sc)
    cov_spec[np.ix_(free, free)] = c_spec * np.outer(sc, sc)
    _, Z = prob._split(v)
    x0 = []
    for li, d in enumerate(data):
        j = next(j for j, seg in enumerate(prob.segs) if seg[0] == li)
        x0.append(np.asarray(prob.start(d.q[0], Z[:, j])).ravel())
    return OutputErrorResult(
        theta=theta_full,
        cov=cov,
        cov_spec=cov_spec,
        sigma_w=float(sig[1]),
        sigma_q=float(sig[0]),
        rms_w=float(np.sqrt(np.mean(R[3:6] ** 2))),
        rms_q=float(np.sqrt(np.mean(R[0:3] ** 2))),
        x0=x0,
        iterations=iterations,
        status=status,
        warnings=warnings,
    )
