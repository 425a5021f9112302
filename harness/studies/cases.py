"""The runs of a sweep: :class:`SweepCase` (index, parameter values, seed) and their expansion from
parsed ``--vary`` expressions (:func:`make_cases`, a lazy :class:`CaseStream`; the grammar is
:mod:`ipcosim.harness.api.grammar`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterator, Mapping, Sequence, overload

import numpy as np

from ipcosim.harness.api.grammar import Vary, VaryError


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


#: The most runs a sweep may have, refused above this before anything is made: its memory does not
#: grow with its size (cases made lazily by :class:`CaseStream`, rows kept on disk only), but its disk
#: and time do (about 0.5 kB of ``results.csv`` a run; the plan's hash goes over every run before the
#: first starts), so a size mistyped by a few orders of magnitude is caught.
MAX_RUNS = 100_000


def sweep_size(varies: Sequence[Vary], samples: int) -> int:
    """The number of runs ``varies`` and ``samples`` give, computed without expanding them."""
    size = samples
    for v in varies:
        if not v.is_random:
            size *= int(v.args[2]) if v.form == "grid" else len(v.args)
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
        factors = [f"{v.text or v.name}: {int(v.args[2]) if v.form == 'grid' else len(v.args)} values"
                   for v in varies if not v.is_random]
        raise VaryError(f"--vary/--samples: {size} runs ({'; '.join(factors + [f'--samples {samples}'])}) is more "
                        f"than a sweep's limit of {limit} runs; use fewer grid points or samples, or split the "
                        f"sweep")


class _Linspace:
    """The points of a ``grid(a,b,n)`` form one at a time: point ``k`` is element ``k`` of
    ``numpy.linspace(a, b, n)`` (``a + k * step``, ``b`` itself last), times the nominal value of
    a relative form, as :meth:`Vary.points` gives them all at once."""

    def __init__(self, vary: Vary, nominal: float) -> None:
        start, stop, n = vary.args
        self.start, self.stop, self.n = float(start), float(stop), int(n)
        self.scale = nominal if vary.relative else 1.0
        div = self.n - 1
        self.step = (self.stop - self.start) / div if div > 0 else math.nan

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, k: int) -> float:
        if self.n == 1:
            value = 0.0 * (self.stop - self.start) + self.start
        elif k == self.n - 1:
            value = self.stop
        elif self.step == 0.0:  # numpy's own branch: k / div * delta
            value = k / (self.n - 1) * (self.stop - self.start) + self.start
        else:
            value = k * self.step + self.start
        return float(np.float64(value)) * self.scale


class CaseStream(Sequence[SweepCase]):
    """The runs of a sweep, made one at a time when asked for: run ``i`` is computed from ``i``
    alone (its grid point, its sample and its seed), so iterating the stream, or taking any run
    of it by its number, holds no more than that run in memory, whatever the size of the sweep.

    The order is that of the grid product (the last ``--vary`` fastest), ``samples`` runs per
    grid point. Two streams are equal when they give the same runs (a list of the same cases
    compares equal too).
    """

    def __init__(self, varies: Sequence[Vary], nominal: Mapping[str, float], samples: int, seed: int = 0,
                 fixed: Mapping[str, float] | None = None) -> None:
        self._grid_varies = [v for v in varies if not v.is_random]
        self._random_varies = [v for v in varies if v.is_random]
        self._nominal = {v.name: nominal.get(v.name, 1.0) for v in varies}
        # each list's values, each grid's points computed when asked for; never their product
        self._grids = [_Linspace(v, self._nominal[v.name]) if v.form == "grid" else v.points(self._nominal[v.name])
                       for v in self._grid_varies]
        self._samples = int(samples)
        self._seed = int(seed)
        self._fixed = dict(fixed or {})
        self._len = math.prod(len(g) for g in self._grids) * self._samples

    @property
    def param_names(self) -> list[str]:
        """The parameters every run sets, in the order of its ``params``."""
        names = dict.fromkeys(self._fixed)
        names.update(dict.fromkeys(v.name for v in self._grid_varies))
        names.update(dict.fromkeys(v.name for v in self._random_varies))
        return list(names)

    def __len__(self) -> int:
        return self._len

    def case(self, index: int) -> SweepCase:
        """Run ``index`` (0 <= index < len)."""
        point, rest = [], index // self._samples
        for grid in reversed(self._grids):  # the last grid varies fastest, as in a nested loop
            rest, k = divmod(rest, len(grid))
            point.append(grid[k])
        point.reverse()
        cs = case_seed(self._seed, index)
        params: dict[str, float] = dict(self._fixed)
        params.update({v.name: float(x) for v, x in zip(self._grid_varies, point)})
        if self._random_varies:
            rng = np.random.default_rng(cs)
            for v in self._random_varies:
                params[v.name] = v.sample(rng, self._nominal[v.name])
        return SweepCase(index=index, params=params, seed=cs)

    @overload
    def __getitem__(self, item: int) -> SweepCase: ...

    @overload
    def __getitem__(self, item: slice) -> list[SweepCase]: ...

    def __getitem__(self, item: int | slice) -> SweepCase | list[SweepCase]:
        if isinstance(item, slice):
            return [self.case(i) for i in range(*item.indices(self._len))]
        i = int(item)
        if i < 0:
            i += self._len
        if not 0 <= i < self._len:
            raise IndexError(f"run {item} of a sweep of {self._len} runs")
        return self.case(i)

    def __iter__(self) -> Iterator[SweepCase]:
        return (self.case(i) for i in range(self._len))

    def __eq__(self, other: Any) -> bool:
        if not isinstance(other, Sequence) or isinstance(other, (str, bytes)):
            return NotImplemented
        return len(self) == len(other) and all(a == b for a, b in zip(self, other))

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"CaseStream({self._len} runs)"


def make_cases(varies: Sequence[Vary], nominal: Mapping[str, float], samples: int | None = None,
               seed: int = 0, fixed: Mapping[str, float] | None = None) -> CaseStream:
    """The runs of parsed variations, as a lazy :class:`CaseStream` (no run is made here).

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
    CaseStream

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
    return CaseStream(varies, nominal, samples, seed, fixed)
