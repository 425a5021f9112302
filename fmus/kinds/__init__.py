"""The plant kinds: one module per kind, registered once, as the control laws are.

Each kind module (``single_mass``, ``double_mass``) declares its :class:`PlantKind`: its parameters
and presets, its states and measured signals, its carts, its dynamics (``ipcosim.fmus.physics``), the
form its integrator advances, and its stand-alone native kernels. Everything that depends on a
plant's kind asks this registry (:func:`get`, :func:`of_params`, :func:`names`, the tables made by
:class:`ByKind`); an unknown kind is an error (:class:`UnknownKindError`), never the single mass.

Adding a kind: one module here declaring ``KIND``, and its line in :func:`_load`. The kind modules
are imported on the first question (they import the physics, which reads this registry), so every
module of the FMU runtime may import the registry at its top.

:func:`plant_kind` says which kind a scenario or component is (a study, the native generator, the
loop analysis and the ``hil`` swap alias ask it).
"""
from __future__ import annotations

from contextlib import contextmanager
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

from ipcosim.errors import IpcosimError, closest
from ipcosim.fmus.kinds import double_mass, single_mass
from ipcosim.fmus.kinds.common import Cart, InternalForm, PlantKind

__all__ = ["Cart", "InternalForm", "PlantKind", "KindError", "UnknownKindError", "register", "ByKind", "KindNames",
           "names", "get", "of_params", "of_model", "registered", "plant_kind", "PLANT_MODELS", "PENDULUM_CART"]


class KindError(IpcosimError, ValueError):
    """A plant kind that cannot be registered."""


class UnknownKindError(IpcosimError, KeyError):
    """A plant kind (or a parameter set's class) that no registered kind declares."""

    def __str__(self) -> str:  # KeyError quotes its argument; we want a plain line
        return str(self.args[0]) if self.args else ""


#: The registry: every kind by name, in the order its module is listed (adding a kind: its module, listed here).
_REGISTRY: dict[str, PlantKind] = {module.KIND.name: module.KIND for module in (single_mass, double_mass)}
#: The registered kinds by their parameter class.
_BY_PARAMS: dict[type, PlantKind] = {k.params: k for k in _REGISTRY.values()}


def _load() -> dict[str, PlantKind]:
    """The registry (kinds registered at run time included: :func:`register`)."""
    return _REGISTRY


def names() -> tuple[str, ...]:
    """The registered kinds' names, in registry order."""
    return tuple(_load())


def get(kind: str) -> PlantKind:
    """The registered kind named ``kind``.

    Raises
    ------
    UnknownKindError
        Naming the kind and the closest registered names.
    """
    registry = _load()
    try:
        return registry[kind]
    except (KeyError, TypeError):
        raise UnknownKindError(f"unknown plant kind {kind!r}; {closest(str(kind), registry)}") from None


def of_params(params: Any) -> PlantKind:
    """The kind whose parameter class ``params`` is an instance of (the class itself, not a base).

    Raises
    ------
    UnknownKindError
        If no registered kind declares that class.
    """
    kind = _BY_PARAMS.get(type(params))
    if kind is not None:
        return kind
    raise UnknownKindError(f"no plant kind has parameters of type {type(params).__name__}; "
                           f"registered: {', '.join(_load())}")


def of_model(model: str) -> PlantKind | None:
    """The kind whose plant FMU is named ``model``, or None."""
    return next((k for k in _load().values() if k.model == model), None)


def register(kind: PlantKind) -> PlantKind:
    """Register a kind of one's own at run time, after the listed ones (a kind's module is listed in
    ``_REGISTRY`` instead when it belongs to the project).

    Raises
    ------
    KindError
        If a kind of that name or model is registered already.
    """
    clash = [k.name for k in _REGISTRY.values() if kind.name == k.name or kind.model == k.model or
             kind.params is k.params]
    if clash:
        raise KindError(f"plant kind {kind.name!r} ({kind.model}): {clash[0]!r} is registered already")
    _REGISTRY[kind.name] = _BY_PARAMS[kind.params] = kind
    return kind


@contextmanager
def registered(kind: PlantKind) -> Iterator[PlantKind]:
    """Register ``kind`` (:func:`register`) for the duration of a ``with`` block."""
    register(kind)
    try:
        yield kind
    finally:
        del _REGISTRY[kind.name], _BY_PARAMS[kind.params]


class ByKind(Mapping[str, Any]):
    """A read-only table over the registered kinds: kind name -> ``attribute(kind)``, read when asked.

    An unknown kind is an :class:`UnknownKindError` (a ``KeyError``: ``in`` and ``.get`` work as on a dict).
    """

    def __init__(self, attribute: Callable[[PlantKind], Any], only: Callable[[PlantKind], bool] | None = None) -> None:
        self._attribute, self._only = attribute, only

    def __getitem__(self, kind: str) -> Any:
        entry = get(kind)
        if self._only is not None and not self._only(entry):
            raise UnknownKindError(f"plant kind {kind!r} has no entry here")
        return self._attribute(entry)

    def __iter__(self) -> Iterator[str]:
        return iter([k.name for k in _load().values() if self._only is None or self._only(k)])

    def __len__(self) -> int:
        return sum(1 for _ in self)

    def __repr__(self) -> str:
        return repr(dict(self))


class KindNames(Sequence[str]):
    """The registered kinds' names as a read-only sequence, read when asked (``KINDS``)."""

    def __getitem__(self, index: Any) -> Any:
        return names()[index]

    def __len__(self) -> int:
        return len(names())

    def __repr__(self) -> str:
        return repr(names())


#: The connector of the cart that carries the pendulum, by plant kind.
PENDULUM_CART: Mapping[str, str] = ByKind(lambda k: k.carts[-1].position)


class _Models(Mapping[str, str]):
    """Plant FMU model name -> kind name, read when asked."""

    def __getitem__(self, model: str) -> str:
        kind = of_model(model)
        if kind is None:
            raise KeyError(model)
        return kind.name

    def __iter__(self) -> Iterator[str]:
        return iter([k.model for k in _load().values()])

    def __len__(self) -> int:
        return len(_load())


#: Model name of each plant FMU -> its plant kind.
PLANT_MODELS: Mapping[str, str] = _Models()


def _by_connectors(connectors: set[str]) -> str | None:
    """The kind with the most of its cart positions among ``connectors`` (None: no cart position there)."""
    hits = [(len(connectors.intersection(c.position for c in k.carts)), k.name) for k in _load().values()]
    best = max(hits, key=lambda h: h[0], default=(0, None))
    return best[1] if best[0] else None


def _by_parameters(parameters: set[str]) -> str | None:
    """The first kind (registry order) whose parameter class has every name in ``parameters``."""
    return next((k.name for k in _load().values() if parameters <= set(k.params.__dataclass_fields__)), None)


def plant_kind(name: str = "", model: str | None = None, connectors: Iterable[str] = (),
               parameters: Iterable[str] | None = None) -> str | None:
    """The plant kind (a registered name) of a scenario or of its plant component.

    Asked in this order, the first that knows answers: the plant FMU's ``model`` name
    (:data:`PLANT_MODELS`); the scenario's ``name`` (or path), which holds the kind in the project's
    names (``double-mass-lqr``, ``pure:single-mass-lqr``); the plant's ``connectors`` (the kind with the
    most of its cart positions there); the plant's ``parameters`` (the first kind whose parameters
    include them all: the double-mass cart alone has the spring ``K``).

    Parameters
    ----------
    name : str
        Scenario name or path.
    model : str, optional
        Model name of the plant component's FMU.
    connectors : iterable of str
        Connector names of the plant component.
    parameters : iterable of str, optional
        Parameter names of the plant component (``K``, ``Mp``...); None: not asked.

    Returns
    -------
    str or None
        The kind, or None when none of these tells it.
    """
    if model is not None and of_model(model) is not None:
        return of_model(model).name  # type: ignore[union-attr]
    for kind in names():
        if kind in name:
            return kind
    found = _by_connectors(set(connectors))
    if found is not None:
        return found
    return _by_parameters(set(parameters)) if parameters is not None else None
