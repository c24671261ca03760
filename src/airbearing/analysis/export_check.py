"""Exported C controllers checked against a logged closed-loop run.

The exported ``NAME_step`` (:mod:`airbearing.design.export`) is compiled with its CSV
harness by the system's C compiler; each row of the log (the ``y`` then ``r`` columns that
``NAME.json`` names) goes in, the commands come out and are compared with the log's
``u`` columns. The simulation's controller is the very Function the C was generated from,
so in double precision the only differences are rounding (bound :data:`DOUBLE_BOUND`); in
float the controller's states (attitude estimate, integrals) drift by float rounding over
a run (bound :data:`FLOAT_BOUND`, measured, see docs/how-to/export.md).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from airbearing.design.export import ExportSpec, c_sources
from airbearing.errors import InputError
from airbearing.io.log import Log, read_log

__all__ = ["DOUBLE_BOUND", "FLOAT_BOUND", "CFLAGS", "CompiledStep", "ReplayCheck",
           "find_compiler", "compile_harness", "replay_check"]  # fmt: skip

#: Largest command difference accepted in double precision (units of the command).
DOUBLE_BOUND = 1e-9
#: Largest command difference accepted in float (units of the command: rad/s, m, A m^2).
#: Measured on cmg-yaw's 90 and 180 deg ideal slews, 40 s, all four steering laws, seed 001's
#: and tuned gains: at most 1.5e-5 rad/s (of the 1.13 rad/s rate limit; float rounding in
#: the attitude estimate and integral, amplified near singular gimbal sets), and on the
#: balancing runs: 2e-9 A m^2, 1e-11 m; a bound 7 times the worst measured.
FLOAT_BOUND = 1e-4
#: The flags every export must compile with.
CFLAGS = ("-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror")


def find_compiler() -> str:
    """The C compiler: ``$CC``, else ``cc``, ``gcc`` or ``clang`` on the PATH.

    Raises
    ------
    InputError
        None found.
    """
    env = os.environ.get("CC")
    for cand in ([env] if env else []) + ["cc", "gcc", "clang"]:
        path = shutil.which(cand)
        if path:
            return path
    raise InputError(
        "no C compiler found ($CC, cc, gcc or clang): install one (e.g. apt-get install gcc) "
        "to compile and check the exported controller"
    )


def compile_harness(files: dict, name: str, folder: Path, compiler: str | None = None) -> Path:
    """Write ``files`` (name -> text) to ``folder`` and build ``NAME.c`` with ``NAME_main.c``
    (flags :data:`CFLAGS`, ``-O2``, libm); returns the executable's path.

    Raises
    ------
    RuntimeError
        The compiler refused the code (its first lines of output in the message).
    """
    cc = compiler or find_compiler()
    folder = Path(folder)
    for fname, text in files.items():
        (folder / fname).write_text(text, encoding="utf-8")
    exe = folder / f"{name}_bench"
    cmd = [cc, *CFLAGS, "-O2", str(folder / f"{name}.c"), str(folder / f"{name}_main.c"), "-lm",
           "-o", str(exe)]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        msg = (proc.stderr or proc.stdout).strip().splitlines()[:5]
        raise RuntimeError(f"{cc} could not compile {name}.c: {' | '.join(msg)}")
    return exe


@dataclass(frozen=True)
class ReplayCheck:
    """What replaying a log through the compiled step gave.

    Attributes
    ----------
    max_diff : float
        Largest absolute command difference over all rows and commands (units of each).
    per_command : dict
        Command name -> its largest absolute difference.
    rows : int
    bound : float
        The bound of the precision (:data:`DOUBLE_BOUND` or :data:`FLOAT_BOUND`).
    real : str
        The C type the step was compiled with, ``"double"`` or ``"float"``.
    commands : numpy.ndarray or None
        The compiled step's commands, one row per log row.

    Examples
    --------
    A 2 s simulated slew replayed through the exported C (compiled with the system's C
    compiler): the C commands are the simulation's to the bound of ``double``:

    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> run = ab.slew(tb, angle_deg=30.0, duration=2.0, ideal=True)
    >>> check = ab.replay_check(ab.export_spec(tb, "attitude", lowpass=False), run.log)
    >>> check.ok, check.rows, check.bound
    (True, 40, 1e-09)
    >>> sorted(check.to_json())
    ['bound', 'max_diff', 'ok', 'per_command', 'real', 'rows']
    """

    max_diff: float
    per_command: dict
    rows: int
    bound: float
    real: str
    commands: np.ndarray = field(repr=False, default=None)

    @property
    def ok(self) -> bool:
        """Whether every command is within :attr:`bound`."""
        return bool(self.max_diff <= self.bound)

    def to_json(self) -> dict:
        """The ``check`` of ``airbearing export --json``.

        Returns
        -------
        dict
            ``max_diff``, ``bound``, ``ok``, ``rows``, ``real``, ``per_command``.
        """
        return {"max_diff": self.max_diff, "bound": self.bound, "ok": self.ok,
                "rows": self.rows, "real": self.real, "per_command": self.per_command}  # fmt: skip


def _columns(log: Log, names, source: str) -> np.ndarray:
    data = log.data
    missing = [n for n in names if n not in data.columns]
    if missing and missing[0].startswith("qc_"):
        raise InputError(
            f"{source}: no column {missing[0]!r}: a dof-3 slew logs no reference; replay it "
            "from Python with the run's reference (CompiledStep.run)"
        )
    if missing:
        raise InputError(
            f"{source}: no column {', '.join(repr(m) for m in missing)}; the exported controller "
            "reads and writes these log columns (a closed-loop run of this loop, e.g. "
            "'airbearing simulate' or 'airbearing balance -o LOG')"
        )
    return data[list(names)].to_numpy(dtype=float)


class CompiledStep:
    """``NAME_step`` of ``spec`` compiled with its harness in a temporary folder.

    Use as a context manager (the folder is removed on exit), or call :meth:`close`.

    Parameters
    ----------
    spec : ExportSpec
    real : {"double", "float"}
    name : str
        The C name of the temporary build.
    compiler : str, optional
        Default :func:`find_compiler`.
    """

    def __init__(self, spec: ExportSpec, real: str = "double", name: str = "ctl",
                 compiler: str | None = None) -> None:  # fmt: skip
        self.spec, self.real, self.name = spec, real, name
        self._tmp = tempfile.TemporaryDirectory(prefix="airbearing-export-")
        self.files = c_sources(spec, name, real, harness=True)
        self.exe = compile_harness(self.files, name, Path(self._tmp.name), compiler)

    def __enter__(self) -> CompiledStep:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._tmp.cleanup()

    def run(self, rows) -> np.ndarray:
        """Commands ``(n, NU)`` for measurement and reference rows ``(n, NY + NR)``, from
        ``NAME_init``'s state."""
        rows = np.atleast_2d(np.asarray(rows, dtype=float))
        text = "\n".join(",".join(repr(float(v)) for v in row) for row in rows) + "\n"
        proc = subprocess.run([str(self.exe)], input=text, capture_output=True, text=True,
                              check=False)  # fmt: skip
        if proc.returncode != 0:
            raise RuntimeError(f"the compiled controller failed: {proc.stderr.strip()}")
        lines = [ln for ln in proc.stdout.splitlines() if ln.strip()]
        nu = len(self.spec.u)
        got = np.array([[float(v) for v in ln.split(",")] for ln in lines]).reshape(-1, nu)
        if got.shape[0] != rows.shape[0]:
            raise RuntimeError(f"the compiled controller gave {got.shape[0]} rows for {len(rows)}")
        return got

    def check(self, log, source: str = "<log>") -> ReplayCheck:
        """Replay ``log`` (a Log or a log file) and compare with its command columns."""
        if not isinstance(log, Log):
            source = os.fspath(log)
            log = read_log(log)
        spec = self.spec
        ins = _columns(log, [s.name for s in spec.y] + [s.name for s in spec.r], source)
        want = _columns(log, [s.name for s in spec.u], source)
        got = self.run(ins)
        diff = np.abs(got - want)
        per = {s.name: float(diff[:, i].max(initial=0.0)) for i, s in enumerate(spec.u)}
        return ReplayCheck(
            max_diff=float(diff.max(initial=0.0)),
            per_command=per,
            rows=len(want),
            bound=DOUBLE_BOUND if self.real == "double" else FLOAT_BOUND,
            real=self.real,
            commands=got,
        )


def replay_check(spec: ExportSpec, log, *, real: str = "double", name: str = "ctl",
                 compiler: str | None = None) -> ReplayCheck:  # fmt: skip
    """Replay ``log`` row by row through the compiled C of ``spec``.

    Parameters
    ----------
    spec : ExportSpec
    log : Log, str or path-like
        A closed-loop run of the same controller (same testbed, loop, law, gains), from its
        first sample (``NAME_init``'s state is the simulation's initial controller state).
    real : {"double", "float"}
        The C type the step is compiled with; it sets the bound (:data:`DOUBLE_BOUND`,
        :data:`FLOAT_BOUND`).
    name : str
        The C name used for the temporary build.
    compiler : str, optional
        Default :func:`find_compiler`.

    Returns
    -------
    ReplayCheck

    Raises
    ------
    InputError
        No C compiler, a log without the columns the controller reads or writes.

    Examples
    --------
    The check compiles the step (see :class:`ReplayCheck`); a log of another loop is
    refused before any compiling:

    >>> import airbearing as ab
    >>> spec = ab.export_spec("cmg-yaw", "attitude")
    >>> log = ab.spindown(ab.load_testbed("seed004-platform"), duration=1.0).log
    >>> ab.replay_check(spec, log)
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: <log>: ...
    """
    source = "<log>"
    if not isinstance(log, Log):
        source = os.fspath(log)
        log = read_log(log)
    names = [s.name for s in spec.y + spec.r + spec.u]
    _columns(log, names, source)  # before compiling: a log of another loop is bad input
    with CompiledStep(spec, real, name, compiler) as step:
        return step.check(log, source)
