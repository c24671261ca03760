"""Compiled functions of the shooting engine: one window, all windows, the IPOPT solver.

One bounded cache (``CACHE_SIZE`` entries) keyed by the Model's STRUCTURE (the package's
one key, :func:`airbearing.models.structure_cache.structure_key`), the window length, the
number of parameter slots, the output groups and whether windows are linked; compiled
functions go through the on-disk cache of :mod:`airbearing.models.compiled` (a new process
loads them): a large step (dof 3) and its Jacobian once per structure, the window chained
over them; a small one (dof 1) as whole windows (``CHAIN_MIN_INSTRUCTIONS``). The constrained solver
(linked windows, inequalities) is in :mod:`.constrained`, in the same cache.

The work lives in modules named by what they hold, each below this one:

- :mod:`.function_cache`: the one bounded cache (``cached``, ``CACHE_SIZE``), ``compiled``
  (the on-disk cache) and ``jit_available``;
- :mod:`.window_functions`: one window's functions (the step, the start state, the window
  compiled whole or chained over the step, ``delta_layout``, ``DEFAULT_SUBSTEPS``);
- :mod:`.problem_functions`: all windows of a problem (``_problem_functions``, the link
  defects, ``WindowJacobian``, ``map_windows``);
- :mod:`.solver`: IPOPT (``ipopt_options``, ``_problem_solver``, its ``_Oracle`` and the
  ``_Call`` callback, ``IPOPT_MAX_ITER``, ``OBJECTIVE_STOP``);
- :mod:`.sparse`: CasADi sparse matrices as scipy CSC (``to_csc``, ``csc_of``,
  ``scale_columns``, ``vstack_csc``); :mod:`.buffers`: Functions evaluated into NumPy
  (``function_buffer``, ``evaluate``).

This module keeps the constants of a fit's shape and re-exports every name above, so
``from airbearing.analysis.shooting.functions import ...`` works as before.
"""

from __future__ import annotations

from airbearing.analysis.shooting.buffers import evaluate, function_buffer  # noqa: F401 (re-exported)
from airbearing.analysis.shooting.function_cache import (  # noqa: F401 (re-exported)
    _CACHE,
    CACHE_SIZE,
    cached,
    compiled,
    jit_available,
)
from airbearing.analysis.shooting.problem_functions import (  # noqa: F401 (re-exported)
    THREADS,
    WindowJacobian,
    _build_problem,
    _data_shapes,
    _link_function,
    _problem_functions,
    map_windows,
    window_jacobian,
)
from airbearing.analysis.shooting.solver import (  # noqa: F401 (re-exported)
    IPOPT_MAX_ITER,
    IPOPT_TOL,
    OBJECTIVE_STOP,
    _build_solver,
    _Call,
    _Oracle,
    _problem_solver,
    ipopt_options,
)
from airbearing.analysis.shooting.sparse import (  # noqa: F401 (re-exported)
    _PATTERNS,
    _pattern_of,
    csc_of,
    scale_columns,
    to_csc,
    vstack_csc,
)
from airbearing.analysis.shooting.window_functions import (  # noqa: F401 (re-exported)
    CHAIN_MIN_INSTRUCTIONS,
    DEFAULT_SUBSTEPS,
    REPLAY_ORDER,
    _build_chained_window,
    _build_start,
    _build_whole_window,
    _build_window,
    _sample_functions,
    _step_functions,
    _window_functions,
    delta_layout,
    fitting_start_yaw,
    layout_key,
    replay_order,
    start_function,
    step_function,
    yaw_acts,
)

#: Free-parameter slots of a fit: unused slots are fixed at zero, so every fit with up to
#: this many parameters shares one compiled Jacobian (one number of AD directions).
THETA_SLOTS = 6


#: Relative eigenvalue of the reduced Fisher matrix below which a parameter is not identifiable.
FISHER_RCOND = 1e-10


#: Output groups a window can compare.
OUTPUTS = ("rate", "quat", "yaw", "ws")
