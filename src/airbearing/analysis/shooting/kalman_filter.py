"""The Kalman filter of :mod:`.kalman` as CasADi Functions: one sample (predict, update,
likelihood term), a block of :data:`BLOCK` samples with the forward sensitivities of its
carry, compiled once per Model structure, and :class:`_Problem`, the blocks run over a
log's rows (:mod:`.kalman` says what the filter computes and why forward mode)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from airbearing.analysis.shooting.functions import cached, compiled, evaluate, step_function
from airbearing.models.model import Model
from airbearing.models.structure_cache import structure_key

#: Rows per compiled block: the log is padded to a whole number of blocks with rows of no
#: effect (no interval, no measurement); a Python loop runs the blocks (3,900 calls at
#: 10^6 rows).
BLOCK = 256
#: Rows from which the Hessian's block is compiled: below, CasADi's virtual machine
#: evaluates it (measured, dof-1 rotor, 5 variables: 840 us a row in the virtual machine,
#: 28 us compiled, 24 s to compile once per structure; the Hessian is evaluated twice).
HESSIAN_COMPILE_ROWS = 5_000
#: Names of the torque input and of the rate state on a dof-1 bearing.
_TAU, _RATE = "tau_z", "wz"


# ----------------------------------------------------------------------------
# the filter as CasADi Functions


def _sample_expr(model: Model, y_rows: tuple, substeps: int, K: int):
    """One sample of the filter as SX: predict over ``dt`` (or restart), update with ``y``.

    Returns the carry ``c = [x; vec(P); nll]``, the row's data ``d = [u; dt; y; m; r; xs]``
    (``m`` the 0/1 availability of each output, ``r`` 1 at a restart from ``xs``), the
    variables ``z = [theta; log sigma_w; log sigma_y]``, the constants ``k = [p_base;
    vec(S); p0]`` (``p = p_base + S theta``, ``P0 = diag(p0)``) and ``c_next``.
    """
    nx, ny, nu, n_p = model.nx, len(y_rows), model.nu, model.n_p
    c = ca.SX.sym("c", nx + nx * nx + 1)
    x, P, nll = c[:nx], ca.reshape(c[nx : nx + nx * nx], nx, nx), c[-1]
    d = ca.SX.sym("d", nu + 1 + 2 * ny + 1 + nx)
    u, dt = d[:nu], d[nu]
    y, m = d[nu + 1 : nu + 1 + ny], d[nu + 1 + ny : nu + 1 + 2 * ny]
    r, xs = d[nu + 1 + 2 * ny], d[nu + 2 + 2 * ny :]
    z = ca.SX.sym("z", K + 1 + ny)
    k = ca.SX.sym("k", n_p + n_p * K + nx)
    pb, Sm, p0 = k[:n_p], ca.reshape(k[n_p : n_p + n_p * K], n_p, K), k[n_p + n_p * K :]
    p = pb + ca.mtimes(Sm, z[:K]) if K else pb
    lsw, lsy = z[K], z[K + 1 :]
    # predict: the step, its exact Jacobian and the held torque's response
    xs_, us_, ps_ = ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.SX.sym("p", n_p)
    dts_, lsw_ = ca.SX.sym("dt"), ca.SX.sym("lsw")
    xn = step_function(model, substeps)(xs_, us_, ps_, dts_)
    it = model.index(_TAU, "u")[0]
    F = ca.jacobian(xn, xs_)
    b = ca.jacobian(model.f(xs_, us_, ps_)[model.index(_RATE)[0]], us_[it])
    g = ca.jacobian(xn, us_[it]) / b
    Q = ca.exp(2 * lsw_) * ca.mtimes(g, g.T) / ca.fmax(dts_, 1e-12)
    pred = ca.Function("pred", [xs_, us_, ps_, dts_, lsw_], [xn, F, Q])
    xp, Fk, Qk = pred(x, u, p, dt, lsw)
    # a restart takes the start and drops the prediction (which integrates no interval
    # there and may not be finite: a sensor lag divides by the interval)
    x_pr = ca.if_else(r > 0.5, xs, xp)
    P_pr = ca.if_else(r > 0.5, ca.diag(p0), ca.mtimes([Fk, P, Fk.T]) + Qk)
    # update: the available outputs only (a missing one: zero row, unit variance)
    yh = model.h(xs_, us_, ps_)[list(y_rows)]
    meas = ca.Function("meas", [xs_, us_, ps_], [yh, ca.jacobian(yh, xs_)])
    yk, Hk = meas(x_pr, u, p)
    Hm = ca.mtimes(ca.diag(m), Hk)
    e = m * (y - yk)
    Rm = ca.diag(m * ca.exp(2 * lsy))
    S = ca.mtimes([Hm, P_pr, Hm.T]) + Rm + ca.diag(1 - m)
    Kg = ca.mtimes(P_pr, ca.solve(S, Hm).T)
    IKH = ca.DM.eye(nx) - ca.mtimes(Kg, Hm)
    x_up = x_pr + ca.mtimes(Kg, e)
    P_up = ca.mtimes([IKH, P_pr, IKH.T]) + ca.mtimes([Kg, Rm, Kg.T])
    nll_k = ca.log(ca.det(S)) + ca.dot(e, ca.solve(S, e)) + ca.sum1(m) * math.log(2 * math.pi)
    c_next = ca.vertcat(x_up, ca.vec(P_up), nll + 0.5 * nll_k)
    return c, d, z, k, c_next


def _block_function(model: Model, y_rows: tuple, substeps: int, K: int, order: int):
    """``BLOCK`` samples of the filter with the forward sensitivities of its carry to
    ``order``: ``(carry, D, z, k) -> carry`` with ``D`` the rows' data (one column per
    row) and ``carry = [c; vec(dc/dz)]`` (order 1) ``; vec(d vec(dc/dz) / dz)]`` (order 2).

    Forward mode with the few variables ``z`` as directions: the sensitivity of the next
    carry is ``dc'/dc S + dc'/dz`` (CasADi's exact derivatives of the sample), the second
    order the same rule applied to that; the NLL's gradient and Hessian are the last rows.
    """
    c, d, z, k, cn = _sample_expr(model, y_rows, substeps, K)
    nc, nz = c.shape[0], z.shape[0]
    carry, out = [c], [cn]
    if order >= 1:
        S = ca.SX.sym("S", nc, nz)
        Sn = ca.jtimes(cn, c, S) + ca.jacobian(cn, z)
        carry.append(ca.vec(S))
        out.append(ca.vec(Sn))
    if order >= 2:
        T = ca.SX.sym("T", nc * nz, nz)
        vS = ca.vec(Sn)
        Tn = ca.jtimes(vS, c, S) + ca.jtimes(vS, ca.vec(S), T) + ca.jacobian(vS, z)
        carry.append(ca.vec(T))
        out.append(ca.vec(Tn))
    one = ca.Function(
        f"kf_sample{order}", [ca.vertcat(*carry), d, z, k], [ca.vertcat(*out)],
        ["carry", "d", "z", "k"], ["carry_next"],
    )  # fmt: skip
    run = one.mapaccum(f"kf_rows{order}", BLOCK)
    C0, D = ca.MX.sym("carry", one.size1_in(0)), ca.MX.sym("D", d.shape[0], BLOCK)
    Z, Kc = ca.MX.sym("z", nz), ca.MX.sym("k", k.shape[0])
    C = run(C0, D, Z, Kc)  # z and k repeated over the block
    return ca.Function(
        f"kf_block{order}", [C0, D, Z, Kc], [C[:, -1]], ["carry", "D", "z", "k"], ["carry_end"]
    )


def _block_functions(model, y_rows, K, substeps, jit, n_rows: int):
    """The blocks of order 0, 1 and 2, once per structure (any log length): orders 0 and 1
    compiled; order 2 (the Hessian, evaluated twice per fit) compiled from
    :data:`HESSIAN_COMPILE_ROWS` rows on, below that in CasADi's virtual machine."""
    key = ("kalman", structure_key(model), y_rows, K, substeps, jit)
    low = cached(
        key,
        lambda: tuple(
            compiled(_block_function(model, y_rows, substeps, K, o), jit=jit) for o in (0, 1)
        ),
        disk=jit is not False,
    )
    hess_jit = False if n_rows < HESSIAN_COMPILE_ROWS else jit
    hess = cached(
        (*key, "hessian", hess_jit),
        lambda: (compiled(_block_function(model, y_rows, substeps, K, 2), jit=hess_jit),),
        disk=hess_jit is not False,
    )
    return (*low, *hess)


@dataclass(frozen=True, eq=False)
class _Problem:
    """The compiled blocks and the padded rows of one log."""

    blocks: tuple
    D: np.ndarray  # (n_blocks, BLOCK, nd): the rows' data, block after block
    k: np.ndarray  # constants [p_base; vec(S); p0]
    nc: int
    n: int

    def run(self, z, order: int, blocks: int | None = None):
        """The carry after the last row (of the first ``blocks`` blocks): ``c`` and its
        sensitivities up to ``order``."""
        fn = self.blocks[order]
        nz = len(z)
        size = self.nc * (1 + (nz if order >= 1 else 0) + (nz * nz if order >= 2 else 0))
        carry = np.zeros(size)
        for Db in self.D[:blocks]:
            carry = evaluate(fn, carry, Db.T, z, self.k)[0]
        return carry

    def nll(self, z) -> float:
        return float(self.run(z, 0)[self.nc - 1])

    def nll_grad(self, z):
        carry = self.run(z, 1)
        nc = self.nc
        S = carry[nc:].reshape(nc, len(z), order="F")
        return float(carry[nc - 1]), S[nc - 1].copy()

    def hess(self, z, blocks: int | None = None):
        """The NLL's Hessian in ``z`` (over the first ``blocks`` blocks)."""
        carry = self.run(z, 2, blocks)
        nc, nz = self.nc, len(z)
        T = carry[nc + nc * nz :].reshape(nc * nz, nz, order="F")
        H = T[nc - 1 :: nc, :]
        return 0.5 * (H + H.T)
