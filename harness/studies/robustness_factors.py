"""What a robustness study varies (:mod:`ipcosim.harness.studies.robustness`): the plant's uncertain quantities by
kind and unit, the default uncertainty of ``compare --robustness`` (:func:`default_vary`), and what decides a loop's
robustness: each factor of ``FACTORS`` alone, then all together (:func:`factor_study`).
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

from ipcosim.fmus.kinds import ByKind, PlantKind
from ipcosim.harness.studies.robustness_summary import summarize

#: The plant parameters of each kind of physical quantity, by their unit (masses, viscous dampings, springs).
QUANTITY_UNITS = {"masses": ("kg",), "dampings": ("N.s/m", "N.m.s/rad"), "spring": ("N/m",)}


def quantities(kind: PlantKind, *groups: str) -> tuple[str, ...]:
    """``plant.<name>`` of each parameter of ``kind`` whose unit is one of ``groups``' (``QUANTITY_UNITS``),
    in the parameter class's order."""
    units = {u for g in groups for u in QUANTITY_UNITS[g]}
    return tuple(f"plant.{f.name}" for f in kind.params.__dataclass_fields__.values() if f.metadata["unit"] in units)


#: Default uncertainty of ``compare --robustness``: masses, friction (viscous damping) and the
#: spring stiffness, each uniform within +-20 % of its nominal value.
DEFAULT_UNCERTAINTY = ByKind(lambda k: quantities(k, "masses", "dampings", "spring"))
DEFAULT_SPREAD = 0.2


def default_vary(kind: str, parameters: Mapping[str, Any] | None = None, spread: float = DEFAULT_SPREAD) -> list[str]:
    """``--vary`` expressions of the default uncertainty for plant ``kind`` (only the
    parameters the scenario has, when ``parameters`` is given)."""
    names = DEFAULT_UNCERTAINTY[kind]
    if parameters is not None:
        names = tuple(n for n in names if n in parameters)
    return [f"{n}=uniform({1 - spread:g},{1 + spread:g})*nominal" for n in names]


#: The factors of :func:`factor_study`, in table order: the plant parameters each draws (uniform within
#: +-``FACTOR_SPREAD`` of nominal, per plant kind), or, for ``lab bench`` and ``delay``, a change of the bench.
FACTORS: dict[str, Mapping[str, tuple[str, ...]]] = {
    "masses": ByKind(lambda k: quantities(k, "masses")),
    "dampings": ByKind(lambda k: quantities(k, "dampings")),
    "spring": ByKind(lambda k: quantities(k, "spring"), only=lambda k: bool(quantities(k, "spring"))),
    "pendulum length": ByKind(lambda k: ("plant.Lp",)),
    "motor Kt, Ra": ByKind(lambda k: ("plant.Kt", "plant.Ra")),
    "lab bench": {},
    "delay": {},
}
#: Relative half-width of each drawn factor (default 0.2).
FACTOR_SPREAD = {"motor Kt, Ra": 0.1}
#: Extra transport delay of the ``delay`` factor [s] (on top of the lab bench's computation delay when both act).
EXTRA_DELAY = 1e-3
#: Relative half-width of the drawn Coulomb friction of the ``lab bench`` factor (the value is fitted, not measured).
FRICTION_SPREAD = 0.2


def factor_runs(kind: str, factors: Sequence[str]) -> tuple[list[str], dict[str, float]]:
    """``(--vary expressions, fixed values)`` of the runs with ``factors`` acting together on plant ``kind``.

    The lab bench is :func:`realism_values` of ``lab`` with each cart's Coulomb friction drawn within
    +-``FRICTION_SPREAD`` of its fitted value; the delay adds ``EXTRA_DELAY`` to the voltage's.
    """
    unknown = [f for f in factors if f not in FACTORS]
    if unknown:
        raise ValueError(f"unknown robustness factor {unknown[0]!r}; known: {', '.join(FACTORS)}")
    vary: list[str] = []
    fixed: dict[str, float] = {}
    for factor in factors:
        spread = FACTOR_SPREAD.get(factor, DEFAULT_SPREAD)
        vary += [f"{n}=uniform({1 - spread:g},{1 + spread:g})*nominal" for n in FACTORS[factor].get(kind, ())]
    if "lab bench" in factors:
        from ipcosim.harness.analysis.residual_cycle import realism_values

        for name, value in realism_values("lab", kind).items():
            if name in ("plant.b", "plant.b1", "plant.b2"):
                lo, hi = value * (1 - FRICTION_SPREAD), value * (1 + FRICTION_SPREAD)
                vary.append(f"{name}=uniform({lo:g},{hi:g})")
            else:
                fixed[name] = value
    if "delay" in factors:
        fixed["plant.input_delay"] = fixed.get("plant.input_delay", 0.0) + EXTRA_DELAY
    return vary, fixed


def factor_cases(spec: Any, kind: str, factors: Sequence[str], samples: int, seed: int = 0) -> list[Any]:
    """The runs of ``factors`` together on ``spec``'s scenario: ``samples`` draws, or one run when nothing is
    drawn (a deterministic bench: repeating it would count one outcome many times)."""
    from ipcosim.harness.api.grammar import parse_all
    from ipcosim.harness.studies.cases import make_cases

    vary, fixed = factor_runs(kind, factors)
    varies = parse_all(vary, spec.parameters)
    return make_cases(varies, spec.parameters, samples=samples if varies else 1, seed=seed, fixed=fixed)


def factor_study(scenario: str, kind: str, parameter_set: str | None = None, samples: int = 200,
                 stop_time: float = 15.0, seed: int = 0, executor: Any = None, fmus: str = "auto",
                 lab_parameter_set: str | None = None) -> dict[str, dict[str, Any]]:
    """Success of one scenario's loop under each factor of ``FACTORS`` alone, then all together.

    Returns ``{factor or "all together": summarize(...)}`` (a factor the plant kind lacks, such as the
    single mass's spring, is left out). The cells with the lab bench (it alone, all together) bind
    ``lab_parameter_set`` (default: ``parameter_set``), the others ``parameter_set``. Runs go through the sweep
    engine on ``executor`` (default: a local pool), on the native flavour where it can run them
    (``ipcosim.harness.studies.specs.study_spec``).
    """
    from ipcosim.harness.studies.specs import for_executor, study_spec
    from ipcosim.harness.studies.sweep import open_executor, run_sweep

    rows = [(f,) for f in FACTORS if f in ("lab bench", "delay") or FACTORS[f].get(kind)] + [tuple(FACTORS)]
    vary, fixed = factor_runs(kind, tuple(FACTORS))
    names = [v.partition("=")[0] for v in vary] + list(fixed)
    sets = {parameter_set, lab_parameter_set or parameter_set}
    specs = {p: study_spec(scenario, fmus, names=names, stop_time=stop_time, parameter_set=p)[0] for p in sets}
    own = executor is None
    executor = open_executor() if own else executor
    out: dict[str, dict[str, Any]] = {}
    try:
        specs = {p: for_executor(spec, executor) for p, spec in specs.items()}
        for factors in rows:
            spec = specs[lab_parameter_set or parameter_set if "lab bench" in factors else parameter_set]
            cases = factor_cases(spec, kind, factors, samples, seed)
            result = run_sweep(spec, cases, executor=executor)
            label = factors[0] if len(factors) == 1 else "all together"
            out[label] = summarize(result.rows, spec.metric_names)
    finally:
        if own:
            executor.close()
    return out


def decisive_factor(summaries: Mapping[str, Mapping[str, Any]], level: float = 0.95) -> str:
    """The factor that breaks a loop first: the one alone with the lowest success rate, if below ``level``;
    else ``none alone``."""
    alone = {k: s["success_rate"] for k, s in summaries.items() if k != "all together"}
    worst = min(alone, key=lambda k: alone[k])
    return worst if alone[worst] < level else "none alone"


def factor_cell(summary: Mapping[str, Any]) -> str:
    """One table cell: the success rate with its Wilson 95 % interval (a single deterministic run: its outcome)."""
    n = summary["runs"]
    if n == 1:
        status = next(iter(summary["counts"]))
        return "ok (1 run)" if status == "ok" else f"{status} (1 run)"
    lo, hi = summary["success_ci95"]
    return f"{100 * summary['success_rate']:.1f} % ({100 * lo:.1f}-{100 * hi:.1f})"
