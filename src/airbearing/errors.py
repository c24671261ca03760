"""Error types of the package.

Every problem with user input raises :class:`InputError` with a message that
names the file, key, row or column and what was expected; the CLI prints it on
one line and exits with status 2. Solver failures raise :class:`SolverError`.
"""

__all__ = ["AirbearingError", "InputError", "SolverError"]


class AirbearingError(Exception):
    """Base class of every error raised on purpose by airbearing.

    Examples
    --------
    One ``except`` catches bad input and failed solvers alike:

    >>> import airbearing as ab
    >>> try:
    ...     ab.load_testbed("no-such-testbed")
    ... except ab.AirbearingError as err:
    ...     print(type(err).__name__)
    InputError
    """


class InputError(AirbearingError, ValueError):
    """Bad input: a testbed file, a log, a command-line value or an API argument.

    The message is one line naming the file, key, row, column or argument and what was
    expected; it is also a :class:`ValueError`.

    Examples
    --------
    >>> import airbearing as ab
    >>> ab.load_testbed("no-such-testbed")
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: no-such-testbed: neither an existing testbed file nor a
    built-in testbed; ...
    """


class SolverError(AirbearingError, RuntimeError):
    """A numerical solver (IPOPT, Clarabel, a root finder) failed; the message names the problem.

    It is also a :class:`RuntimeError`, so code written for any failed computation catches it.

    Examples
    --------
    >>> import airbearing as ab
    >>> issubclass(ab.SolverError, RuntimeError), issubclass(ab.SolverError, ab.InputError)
    (True, False)
    """
