"""The runs of a sweep: :class:`SweepCase` (index, parameter values, seed) and their expansion from
parsed ``--vary`` expressions (:func:`make_cases`; the grammar is :mod:`ipcosim.harness.grammar`).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from ipcosim.harness.grammar import Vary, VaryError


@dataclass(frozen=True)
class SweepCase:
    """One run of a sweep: its position, its parameter values and its seed.

    ``params`` maps ``component.variable`` to the value set for this run. ``seed`` is
    handed to the run (for any randomness inside it) and recorded with its results.
    """

    index: int
    params: Mapping[str, float] = field(default_factory=dict)
    seed: int = 0


def case_seed(seed: int, index: int) -> int:
    """The seed of run ``index`` of a sweep seeded with ``seed`` (independent of run order)."""
    return int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1, dtype=np.uint32)[0])


#: The most runs a sweep may have: its cases, its rows and its plan are held in memory (about
#: 2 kB a run), so a sweep is refused above this before anything is allocated.
MAX_RUNS = 100_000


def sweep_size(varies: Sequence[Vary], samples: int) -> int:
    """The number of runs ``varies`` and ``samples`` give, computed without expanding them."""
    size = samples
    for v in varies:
        if not v.is_random:
            size *= int(v.args[2]) if v.kind == "grid" else len(v.args)
    return size


def check_size(varies: Sequence[Vary], samples: int, limit: int = MAX_RUNS) -> None:
    """Refuse a sweep of more than ``limit`` runs, in one line naming the options and the size.

    Raises
    ------
    VaryError
        The product of the grid and list sizes times ``samples`` exceeds ``limit``.
    """
    size = sweep_size(varies, samples)
    if size > limit:
        factors = [f"{v.text or v.name}: {int(v.args[2]) if v.kind == 'grid' else len(v.args)} values"
                   for v in varies if not v.is_random]
        raise VaryError(f"--vary/--samples: {size} runs ({'; '.join(factors + [f'--samples {samples}'])}) is more "
                        f"than a sweep's limit of {limit} runs; use fewer grid points or samples, or split the "
                        f"sweep")


def make_cases(varies: Sequence[Vary], nominal: Mapping[str, float], samples: int | None = None,
               seed: int = 0, fixed: Mapping[str, float] | None = None) -> list[SweepCase]:
    """Expand parsed variations into the list of runs.

    Parameters
    ----------
    varies : sequence of Vary
        Parsed ``--vary`` expressions.
    nominal : mapping
        Nominal value of each varied parameter (``component.variable`` -> value).
    samples : int, optional
        Runs per grid point (default: 100 when a random form is present, else 1).
    seed : int
        Master seed. Run ``i`` draws its random values from its own generator seeded by
        ``(seed, i)``, so the values do not depend on the executor or the order of runs.
    fixed : mapping, optional
        Values set in every run (like ``--set``), recorded with each case.

    Returns
    -------
    list of SweepCase

    Raises
    ------
    VaryError
        ``samples`` < 1, or more than :data:`MAX_RUNS` runs (checked before any is made).
    """
    if samples is None:
        samples = 100 if any(v.is_random for v in varies) else 1
    if samples < 1:
        raise VaryError(f"--samples {samples}: need at least 1 sample")
    check_size(varies, samples)
    grid_varies = [v for v in varies if not v.is_random]
    random_varies = [v for v in varies if v.is_random]
    grids = [v.points(nominal.get(v.name, 1.0)) for v in grid_varies]
    cases: list[SweepCase] = []
    index = 0
    for point in itertools.product(*grids):
        for _ in range(samples):
            cs = case_seed(seed, index)
            rng = np.random.default_rng(cs)
            params: dict[str, float] = dict(fixed or {})
            params.update({v.name: float(x) for v, x in zip(grid_varies, point)})
            for v in random_varies:
                params[v.name] = v.sample(rng, nominal.get(v.name, 1.0))
            cases.append(SweepCase(index=index, params=params, seed=cs))
            index += 1
    return cases
