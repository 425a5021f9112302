"""The grammar of the value options: ``--set``/``--swap`` assignments and the ``--vary`` forms.

Assignments (:func:`parse_set`, :func:`parse_pairs`, :func:`parse_numbers`): ``KEY=VALUE`` items
(``COMPONENT.VARIABLE=VALUE`` for ``--set``), given on the command line or as a mapping. A
``--set`` value may be relative to the scenario's: ``1.1*nominal`` or ``nominal*1.1``
(:func:`strip_nominal`), the same scaling the ``--vary`` forms take.

``--vary``: how a sweep varies one scenario parameter.

One expression per parameter, ``COMPONENT.VARIABLE=FORM`` with FORM one of::

    uniform(a, b)          uniform random on [a, b]
    normal(mean, std)      normal random
    grid(start, stop, n)   n evenly spaced values, both ends included
    [v1, v2, ...]          the listed values
    v                      one value (the same as --set)

Any form may be scaled by the parameter's nominal value (its value in the scenario):
``uniform(0.8,1.2)*nominal`` or ``nominal*uniform(0.8,1.2)``. Random forms are sampled
once per run; grid and list forms span a Cartesian product, and each grid point is run
``samples`` times (with fresh random values of the random forms; the expansion into runs is
:func:`ipcosim.harness.studies.cases.make_cases`).

Parsing never evaluates Python: numbers are read with ``float``. A malformed expression or
an unknown parameter raises :class:`VaryError` with one line naming the expression.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from ipcosim.errors import UsageError, closest

#: The form of a ``--set`` item.
SET_FORM = "COMPONENT.VARIABLE=VALUE"


def parse_pairs(option: str, items: Mapping[str, Any] | Sequence[str] | str | None, form: str) -> dict[str, Any]:
    """``{"KEY": value}`` from a mapping, or from ``["KEY=VALUE", ...]`` (the command line's form;
    keys and values stripped).

    Raises
    ------
    UsageError
        ``{option} 'item': expected {form}`` for an item without ``=``, key or value.
    """
    if items is None:
        return {}
    if isinstance(items, Mapping):
        return {str(k): v for k, v in items.items()}
    if isinstance(items, str):
        items = [items]
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = str(item).partition("=")
        if not sep or not key.strip() or not value.strip():
            raise UsageError(f"{option} {item!r}: expected {form}")
        out[key.strip()] = value.strip()
    return out


def parse_numbers(option: str, items: Mapping[str, Any] | Sequence[str] | str | None, form: str) -> dict[str, float]:
    """:func:`parse_pairs` with every value a number.

    Raises
    ------
    UsageError
        As :func:`parse_pairs`, or ``{option} KEY=VALUE: 'VALUE' is not a number``.
    """
    out: dict[str, float] = {}
    for key, value in parse_pairs(option, items, form).items():
        try:
            out[key] = float(value)
        except (TypeError, ValueError):
            raise UsageError(f"{option} {key}={value}: {value!r} is not a number") from None
    return out


def parse_set(items: Mapping[str, Any] | Sequence[str] | str | None, numbers: bool = False) -> dict[str, Any]:
    """``--set COMPONENT.VARIABLE=VALUE`` items: values as given (text from the command line, relative
    ``X*nominal`` included) or, with ``numbers``, as numbers.

    Raises
    ------
    UsageError
        An item that is not ``COMPONENT.VARIABLE=VALUE`` (or, with ``numbers``, not a number).
    """
    out = parse_numbers("--set", items, SET_FORM) if numbers else parse_pairs("--set", items, SET_FORM)
    for key, value in out.items():
        if "." not in key:
            raise UsageError(f"--set {key}={value}: expected {SET_FORM}")
    return out


FORMS_HELP = ("uniform(a,b), normal(mean,std), grid(start,stop,n), [v1,v2,...] or a number, "
              "each optionally '*nominal'")

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*\.[A-Za-z_][A-Za-z0-9_.\[\]]*$")
_CALL = re.compile(r"^([A-Za-z_]\w*)\s*\((.*)\)$")
_DISTRIBUTIONS = {"uniform": 2, "normal": 2, "grid": 3}


class VaryError(UsageError):
    """A ``--vary`` expression that cannot be parsed or names an unknown parameter."""


@dataclass(frozen=True)
class Vary:
    """One parsed ``--vary`` expression.

    Attributes
    ----------
    name : str
        ``component.variable``.
    form : str
        ``uniform``, ``normal``, ``grid``, ``values`` (list or single number).
    args : tuple of float
        The form's arguments (for ``values``: the values).
    relative : bool
        True when the form is scaled by the nominal value.
    text : str
        The expression as given (for messages and metadata).
    """

    name: str
    form: str
    args: tuple[float, ...]
    relative: bool = False
    text: str = ""

    @property
    def is_random(self) -> bool:
        """True for sampled forms (uniform, normal)."""
        return self.form in ("uniform", "normal")

    def points(self, nominal: float) -> list[float]:
        """The values of a grid or list form (absolute, nominal applied)."""
        scale = nominal if self.relative else 1.0
        if self.form == "grid":
            start, stop, n = self.args
            return [float(v) * scale for v in np.linspace(start, stop, int(n))]
        if self.form == "values":
            return [v * scale for v in self.args]
        raise ValueError(f"{self.form} is a random form, it has no points")

    def sample(self, rng: np.random.Generator, nominal: float) -> float:
        """One random value (absolute, nominal applied)."""
        scale = nominal if self.relative else 1.0
        a, b = self.args
        value = rng.uniform(a, b) if self.form == "uniform" else rng.normal(a, b)
        return float(value) * scale


def _number(text: str, expr: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise VaryError(f"--vary {expr!r}: {text.strip()!r} is not a number") from None
    if not math.isfinite(value):
        raise VaryError(f"--vary {expr!r}: {text.strip()!r} is not a finite number")
    return value


def _split_args(text: str, expr: str) -> list[float]:
    parts = [p for p in (s.strip() for s in text.split(","))]
    if parts == [""]:
        return []
    if any(p == "" for p in parts):
        raise VaryError(f"--vary {expr!r}: empty argument in {text!r}")
    return [_number(p, expr) for p in parts]


def parse_vary(expr: str, parameters: Mapping[str, float] | None = None) -> Vary:
    """Parse one ``--vary`` expression.

    Parameters
    ----------
    expr : str
        ``component.variable=FORM`` (see the module docstring).
    parameters : mapping, optional
        Known parameters (``component.variable`` -> nominal value); when given, an unknown
        name is an error and ``*nominal`` needs a numeric nominal value.

    Returns
    -------
    Vary

    Raises
    ------
    VaryError
        One line naming the expression and what is wrong with it.
    """
    name, sep, form = expr.partition("=")
    name, form = name.strip(), form.strip()
    if not sep or not name or not form:
        raise VaryError(f"--vary {expr!r}: expected COMPONENT.VARIABLE=FORM with FORM one of {FORMS_HELP}")
    if not _NAME.match(name):
        raise VaryError(f"--vary {expr!r}: {name!r} is not a COMPONENT.VARIABLE name (e.g. plant.Mp)")
    if parameters is not None and name not in parameters:
        raise VaryError(f"--vary {expr!r}: unknown parameter {name!r}; {closest(name, parameters)}")
    body, relative = strip_nominal(form, f"--vary {expr!r}")
    if relative and parameters is not None:
        nominal = parameters[name]
        if nominal is None or not isinstance(nominal, (int, float)) or not math.isfinite(nominal):
            raise VaryError(f"--vary {expr!r}: {name} has no numeric nominal value to scale")
    if body.startswith("[") and body.endswith("]"):
        values = _split_args(body[1:-1], expr)
        if not values:
            raise VaryError(f"--vary {expr!r}: the list of values is empty")
        return Vary(name, "values", tuple(values), relative, expr)
    call = _CALL.match(body)
    if call:
        dist, args = _distribution(call.group(1), call.group(2), expr)
        return Vary(name, dist, args, relative, expr)
    if "(" in body or ")" in body or "[" in body or "]" in body:
        raise VaryError(f"--vary {expr!r}: malformed form {form!r} (expected {FORMS_HELP})")
    return Vary(name, "values", (_number(body, expr),), relative, expr)


def strip_nominal(form: str, what: str) -> tuple[str, bool]:
    """The form without spaces and without a ``*nominal`` (or ``nominal*``) factor, and whether it had one.

    Raises
    ------
    VaryError
        ``nominal`` anywhere else (``what`` starts the message: the option and the item).
    """
    body = form.replace(" ", "")
    relative = False
    if body.endswith("*nominal"):
        relative, body = True, body[: -len("*nominal")]
    elif body.startswith("nominal*"):
        relative, body = True, body[len("nominal*"):]
    if "nominal" in body:
        raise VaryError(f"{what}: 'nominal' may only multiply the whole form, e.g. uniform(0.8,1.2)*nominal")
    return body, relative


def _distribution(dist: str, argtext: str, expr: str) -> tuple[str, tuple[float, ...]]:
    """A ``dist(args)`` form, checked: a known distribution, its number of arguments, and their ranges."""
    if dist not in _DISTRIBUTIONS:
        raise VaryError(f"--vary {expr!r}: unknown form {dist!r} (expected {FORMS_HELP})")
    args = _split_args(argtext, expr)
    if len(args) != _DISTRIBUTIONS[dist]:
        raise VaryError(f"--vary {expr!r}: {dist} takes {_DISTRIBUTIONS[dist]} arguments, got {len(args)}")
    if dist == "uniform" and not args[0] < args[1]:
        raise VaryError(f"--vary {expr!r}: uniform(a,b) needs a < b")
    if dist == "normal" and not args[1] > 0:
        raise VaryError(f"--vary {expr!r}: normal(mean,std) needs std > 0")
    if dist == "grid":
        if args[2] != int(args[2]) or args[2] < 1:
            raise VaryError(f"--vary {expr!r}: grid(start,stop,n) needs a whole n >= 1")
        if args[2] > 1 and not args[0] != args[1]:
            raise VaryError(f"--vary {expr!r}: grid(start,stop,n) needs start != stop")
    return dist, tuple(args)


def parse_all(exprs: Iterable[str], parameters: Mapping[str, float] | None = None) -> list[Vary]:
    """Parse several expressions; a parameter may be varied only once."""
    varies: list[Vary] = []
    seen: set[str] = set()
    for expr in exprs:
        vary = parse_vary(expr, parameters)
        if vary.name in seen:
            raise VaryError(f"--vary {expr!r}: {vary.name} is varied twice")
        seen.add(vary.name)
        varies.append(vary)
    return varies


