"""Error types of the package.

Every problem with user input raises :class:`InputError` with a message that
names the file, key, row or column and what was expected; the CLI prints it on
one line and exits with status 2. Solver failures raise :class:`SolverError`.
"""

__all__ = ["AirbearingError", "InputError", "SolverError"]


class AirbearingError(Exception):
    """Base class of every error raised on purpose by airbearing."""


class InputError(AirbearingError, ValueError):
    """Bad input: a testbed file, a log, a command-line value or an API argument."""


class SolverError(AirbearingError, RuntimeError):
    """A numerical solver (IPOPT, Clarabel, a root finder) failed; the message names the problem."""
