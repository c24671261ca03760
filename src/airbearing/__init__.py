"""airbearing: control design toolbox for spacecraft attitude simulators on air bearings.

Everything a user needs is one attribute of the package, imported on first use (PEP 562),
so ``import airbearing as ab`` is fast and loads no numerical library::

    import airbearing as ab

    tb = ab.load_testbed("cmg-yaw")
    run = ab.slew(tb, angle_deg=90.0, duration=10.0)
    found = ab.discrepancy(tb, [run.log])
    print(found)

``ab.__all__`` lists every name; each section of the API reference documents one group.
"""

from importlib import import_module as _import_module

from airbearing.errors import AirbearingError, InputError, SolverError

__version__ = "0.1.0"

#: Public name -> the module that defines it (imported on first use).
_WHERE: dict[str, str] = {
    # testbeds
    **dict.fromkeys(
        ["Testbed", "load_testbed", "read_testbed", "write_testbed", "testbed_from_dict",
         "testbed_to_dict"],
        "airbearing.io.testbed",
    ),
    **dict.fromkeys(["builtin_names", "builtin_toml"], "airbearing.io.builtins"),
    # logs
    **dict.fromkeys(["Log", "read_log", "write_log"], "airbearing.io.log"),
    **dict.fromkeys(["import_log", "import_log_with_notes"], "airbearing.io.log_import"),
    "read_import_map": "airbearing.io.import_map",
    **dict.fromkeys(["LogQuality"], "airbearing.io.quality"),
    **dict.fromkeys(["LogCheck", "check_log", "plot_log"], "airbearing.api.logs"),
    **dict.fromkeys(["plot", "report"], "airbearing.api.plot"),
    # models and controllers
    **dict.fromkeys(["Model", "build_model"], "airbearing.models.model"),
    **dict.fromkeys(["Controller", "constant_input"], "airbearing.design.controller"),
    **dict.fromkeys(["cmg_attitude_controller", "SEED001_GAINS"], "airbearing.design.attitude"),
    "balancing_controller": "airbearing.design.balancing",
    # simulation and scenarios
    **dict.fromkeys(["SimResult", "simulate"], "airbearing.analysis.simulation.simulate"),
    **dict.fromkeys(
        ["slew", "slew_summary", "free_oscillation", "spindown"],
        "airbearing.analysis.simulation.scenarios",
    ),
    "free_summary": "airbearing.analysis.simulation.summary",
    **dict.fromkeys(["Rehearsal", "rehearsal_log"], "airbearing.analysis.simulation.rehearsal"),
    # identification
    "identify": "airbearing.analysis.identify",
    "Prior": "airbearing.analysis.identification.result",
    "PlatformIdentification": "airbearing.analysis.identification.result",
    "YawIdentification": "airbearing.analysis.identification.yaw_inertia",
    "CMGIdentification": "airbearing.analysis.identification.cmg_inertia",
    # discrepancy and replay
    **dict.fromkeys(["Discrepancy", "discrepancy"], "airbearing.analysis.discrepancy.search"),
    **dict.fromkeys(["Replay", "replay"], "airbearing.analysis.discrepancy.replay"),
    # tuning, linearisation, margins, stability report
    **dict.fromkeys(["Spec", "TuningResult", "tune", "evaluate"], "airbearing.design.tuning"),
    "read_gains": "airbearing.io.gains",
    # C export of the controllers, checked against the simulation
    **dict.fromkeys(["ExportSpec", "export_spec", "c_sources"], "airbearing.design.export"),
    **dict.fromkeys(["ReplayCheck", "replay_check"], "airbearing.analysis.export_check"),
    **dict.fromkeys(["Loop", "make_loop"], "airbearing.design.loops"),
    **dict.fromkeys(["TrimPoint", "trim", "linearise"], "airbearing.design.linearise"),
    **dict.fromkeys(
        ["LoopMargins", "LoopAnalysis", "loop_margins", "analyse_loop"], "airbearing.design.margins"
    ),
    **dict.fromkeys(["stability_report", "report_for_loop"], "airbearing.reporting.stability"),
    # balancing
    **dict.fromkeys(["BalancingRun", "run_balancing"], "airbearing.analysis.balancing.runs"),
    **dict.fromkeys(
        ["Comparison", "Sweep", "compare_methods", "sweep_comparison"],
        "airbearing.analysis.balancing.comparison",
    ),
    **dict.fromkeys(["TwoStepResult", "two_step"], "airbearing.analysis.balancing.two_step"),
    # CMG sizing, envelope, steering study
    **dict.fromkeys(["SizingResult", "size_cluster"], "airbearing.design.sizing"),
    **dict.fromkeys(
        ["momentum_envelope", "singular_surface", "internal_surfaces", "classify_singularity"],
        "airbearing.analysis.cmg.singularity",
    ),
    **dict.fromkeys(
        ["SteeringRun", "compare_slews", "rate_limit_comparison", "momentum_tracking"],
        "airbearing.analysis.cmg.steering_study",
    ),
    # campaigns
    **dict.fromkeys(
        ["Campaign", "parse_campaign", "read_campaign"], "airbearing.analysis.campaign.spec"
    ),
    **dict.fromkeys(["run_campaign", "open_client"], "airbearing.analysis.campaign.runner"),
    # the demo report
    "run_demo": "airbearing.reporting.demo",
}  # fmt: skip

__all__ = ["AirbearingError", "InputError", "SolverError", "__version__", *sorted(_WHERE)]


def __getattr__(name: str):
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'airbearing' has no attribute {name!r}")
    value = getattr(_import_module(module), name)
    globals()[name] = value  # the next access skips this function
    return value


def __dir__() -> list[str]:
    """The public names only (tab completion): ``__all__``, not the helpers of this module."""
    return sorted(__all__)
