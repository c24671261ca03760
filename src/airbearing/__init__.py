"""airbearing: control design toolbox for spacecraft attitude simulators on air bearings."""

from airbearing.errors import AirbearingError, InputError, SolverError

__all__ = ["AirbearingError", "InputError", "SolverError", "__version__"]
__version__ = "0.1.0"
