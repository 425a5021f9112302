"""The FMI integer types, carried exactly: their ranges, how a value is held in the master's
64-bit integer vector, the record's numpy type of each, and the check that a value fits.

FMI 2.0 has one 32-bit ``Integer`` (and ``Enumeration``, an ``fmi2Integer``); FMI 3.0 has
``Int8`` ... ``UInt64`` (and ``Enumeration``, an ``fmi3Int64``), each with the range of its C type
(FMI 3.0 section 2.2.2). The master keeps every Integer and Boolean connector in one ``int64``
vector: a value of any of these types fits, ``UInt64`` values of 2**63 and above as the same
64 bits (:func:`stored` / :func:`value`). A value that a variable's type cannot hold is an error
(:class:`IntegerRangeError`), never wrapped.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ipcosim.errors import IpcosimError

#: Smallest and largest value of each integer type (FMI 2.0 ``Integer``: a C int).
RANGE: dict[str, tuple[int, int]] = {
    "Integer": (-2 ** 31, 2 ** 31 - 1),
    "Int8": (-2 ** 7, 2 ** 7 - 1), "UInt8": (0, 2 ** 8 - 1),
    "Int16": (-2 ** 15, 2 ** 15 - 1), "UInt16": (0, 2 ** 16 - 1),
    "Int32": (-2 ** 31, 2 ** 31 - 1), "UInt32": (0, 2 ** 32 - 1),
    "Int64": (-2 ** 63, 2 ** 63 - 1), "UInt64": (0, 2 ** 64 - 1),
}
#: numpy type of a record column of each integer type.
DTYPE: dict[str, str] = {"Integer": "i4", "Int8": "i1", "UInt8": "u1", "Int16": "i2", "UInt16": "u2",
                         "Int32": "i4", "UInt32": "u4", "Int64": "i8", "UInt64": "u8"}
_WRAP = 2 ** 64


class IntegerRangeError(IpcosimError, OverflowError):
    """A value that an integer variable's type cannot hold (or that is not an integer)."""


def integer_type(type_: str, fmi_version: str = "2.0") -> str:
    """The sized type of an FMU variable type the master carries as an integer: ``Enumeration``
    is an ``Integer`` in FMI 2.0 and an ``Int64`` in FMI 3.0."""
    if type_ == "Enumeration":
        return "Int64" if fmi_version.startswith("3") else "Integer"
    return type_


def in_range(value: int, type_: str) -> bool:
    lo, hi = RANGE[type_]
    return lo <= value <= hi


def stored(value: int, type_: str) -> int:
    """``value`` as the master's ``int64`` vector holds it (``UInt64`` above 2**63 - 1: the same bits)."""
    return value - _WRAP if type_ == "UInt64" and value >= 2 ** 63 else value


def value(held: int, type_: str) -> int:
    """The value of a variable of ``type_`` that the ``int64`` vector holds as ``held``."""
    return held + _WRAP if type_ == "UInt64" and held < 0 else held


def column(held: np.ndarray, type_: str) -> np.ndarray:
    """An ``int64`` record column of a variable of ``type_`` as its values (``UInt64``: the bits as ``uint64``)."""
    return held.view(np.uint64) if type_ == "UInt64" else held


def exact_integer(x: Any) -> int:
    """``x`` (an int, an integral float, or a decimal text such as ``5000000000``, ``5e9`` or
    ``18446744073709551615``) as an exact int.

    Raises
    ------
    ValueError
        ``x`` is not an integer (a fraction, a non-finite number, a bool, other text).
    """
    if isinstance(x, bool):
        raise ValueError(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        if not float(x).is_integer():
            raise ValueError(x)
        return int(x)
    from decimal import Decimal, InvalidOperation  # text only: a run that gives none does not load decimal

    try:
        d = Decimal(str(x).strip())
    except InvalidOperation:
        raise ValueError(x) from None
    if not d.is_finite() or d != d.to_integral_value():
        raise ValueError(x)
    return int(d)


def check(x: int, type_: str, what: str) -> int:
    """``x`` if a variable of ``type_`` holds it, else :class:`IntegerRangeError` naming ``what``."""
    if not in_range(x, type_):
        lo, hi = RANGE[type_]
        raise IntegerRangeError(f"{what}: {x} is out of the range of {type_} ({lo} .. {hi})")
    return x


def narrowing(src: str, dst: str) -> bool:
    """Whether some value of type ``src`` is not a value of type ``dst``."""
    (a, b), (c, d) = RANGE[src], RANGE[dst]
    return a < c or b > d


class CarryError(IntegerRangeError):
    """A connection that cannot deliver its source's value: the destination's type cannot hold
    it. ``tick``: the communication step in which it had to (None: initialization, or not known);
    ``row``: the record row that holds the value (when the record found it)."""

    def __init__(self, message: str, tick: int | None = None, row: int | None = None) -> None:
        super().__init__(message)
        self.tick, self.row = tick, row


class Carrier:
    """An Integer connection that is not a plain copy of the 64 bits: from a source type into a
    destination type that cannot hold all of its values, or through a mapping transformation
    (applied to the values, not to the bits).

    Parameters
    ----------
    src, dst : str
        The sized types of both ends (``RANGE``).
    mapping : dict
        The SSP mapping transformation (source value -> destination value); values not in it pass.
    name : str
        The connection, ``component.variable -> component.variable``.
    """

    def __init__(self, src: str, dst: str, mapping: dict[int, int], name: str) -> None:
        self.src, self.dst, self.mapping, self.name = src, dst, mapping, name

    def deliver(self, x: int) -> int:
        """The destination's value (its type's range checked) of a source value ``x``."""
        v = self.mapping.get(x, x)
        if not in_range(v, self.dst):
            lo, hi = RANGE[self.dst]
            raise CarryError(f"connection {self.name} cannot carry {x}"
                             + (f" (mapped to {v})" if v != x else "")
                             + f": {self.dst} holds {lo} .. {hi}, the source is {self.src}")
        return v

    def __call__(self, held: int, tick: int | None = None) -> int:
        """What the destination's slot of the ``int64`` vector takes from the source's ``held``."""
        try:
            return stored(self.deliver(value(held, self.src)), self.dst)
        except CarryError as exc:
            exc.tick = tick
            raise
