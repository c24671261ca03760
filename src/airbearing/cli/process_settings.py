"""Process-wide settings of short-lived CLI processes (BLAS threads, malloc, the collector).

Each is called for a command before its heavy imports (:func:`one_blas_thread` by
:func:`airbearing.cli.main`, before the global callback loads numpy with CasADi); none
changes an answer, only where the time goes (one BLAS thread sums in another order: a
search's JSON may differ in its last digits). Kept here so every command that needs one
calls the same code.
"""

from __future__ import annotations

import gc


def one_blas_thread() -> None:
    """One BLAS thread for this process when numpy is not loaded yet.

    The search's dense algebra is small (Fisher and held-out blocks of ~10^4 x 40), and
    the two cores already run CasADi's window threads: OpenBLAS's own threads only
    contend. Measured on the shared 2-core machine (load ~5): the reduced Fisher matrix of
    a 60 s platform fit 97 ms with OpenBLAS's threads against 3.5 ms with one; a whole
    ``airbearing discrepancy`` 6.4-6.6 s CPU against 4.6-6.0 s. A user's own
    ``OPENBLAS_NUM_THREADS`` wins. Measured again (load 5-7): ``discrepancy`` of a 60 s
    three-axis log at 50 Hz 23.0-24.7 s CPU against 16.5-17.6 s. ``identify`` too (same
    JSON): equation-error on 10^6 rows 6.2-6.4 s against 5.6-5.8 s, output-error on 10^3
    rows 9.2-10.2 s against 8.1-8.9 s.
    """
    import os
    import sys

    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def reuse_freed_memory() -> None:
    """Let glibc's malloc keep freed memory for reuse in this short-lived process, and
    Arrow allocate from it too.

    Identifying 10^6-sample logs allocates and frees many arrays of 3-30 MB. By default
    glibc hands such memory back to the system as soon as the top of its heap has twice
    its (adaptive) mmap threshold free, and the next array faults every page in again:
    half of the page faults of a 10^6-row run, 0.3-0.5 s of system time on a loaded
    machine. With a fixed 32 MB mmap threshold and a 1 GB trim threshold the memory is
    reused instead (the peak resident memory stays ~0.7 GB). Only where the C library
    has ``mallopt`` (glibc); elsewhere nothing changes.
    """
    import sys

    if not sys.platform.startswith("linux"):
        return
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return
    m_trim_threshold, m_mmap_threshold = -1, -3  # <malloc.h>
    mallopt(m_mmap_threshold, 32 << 20)
    mallopt(m_trim_threshold, 1 << 30)
    import pyarrow as pa  # (imported by pandas anyway)

    # Arrow's buffers (the Parquet columns) from the same malloc: its default pool
    # (mimalloc) hands freed pages back at once, 0.2-0.4 s of system time per 10^6 rows
    pa.set_memory_pool(pa.system_memory_pool())


#: True while :func:`pause_collection` holds the collector off for this console process.
_PAUSED = {"on": False}


def pause_collection() -> None:
    """Hold the cyclic garbage collector off while a console command imports its libraries.

    Importing makes objects that live until the process ends (modules, classes,
    functions), never garbage, yet every few hundred of them start a collection that
    walks all the older ones: a 60 s discrepancy search's process (~1700 modules) ran ~400
    collections, 0.31 s CPU; paused during the command's imports 0.10 s (measured on the
    shared 2-core machine, load ~6; what is left is during the search's later imports of
    scipy.stats and statsmodels, with the collector on). :func:`collect_after_imports`
    resumes it. Only in a console process (:func:`airbearing.cli.main` without ``argv``):
    it ends after the command.
    """
    if gc.isenabled():
        gc.disable()
        _PAUSED["on"] = True


def collect_after_imports() -> None:
    """After a command's imports: what exists now is kept out of later collections
    (``gc.freeze``) and the collector resumes; nothing when :func:`pause_collection` did
    not pause it (a test calling ``main(argv)``, the API)."""
    if _PAUSED["on"]:
        _PAUSED["on"] = False
        gc.freeze()
        gc.enable()
