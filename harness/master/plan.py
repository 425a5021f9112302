"""The stepping loop's plan: one tick of a system as a tree of operations (:data:`Op`), shared by
its two renderings, Python (:mod:`ipcosim.harness.master.pyloop`) and C
(:mod:`ipcosim.harness.master.cloop`).

:func:`loop_plan` orders the operations of one tick for the algorithm (Gauss-Seidel or Jacobi,
:mod:`ipcosim.harness.master.algorithm`): one batched set and one batched get per component and
step, the transfers between them, and the multi-rate conditions. A :class:`Block` is one
component's place in the value vector and its raw FMI functions; a :class:`Channel` its
connectors of one non-Real value type; :class:`TypedRecord` where the non-Real values are recorded.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

from ipcosim.harness.master.algorithm import ALGORITHMS, GAUSS_SEIDEL, TimeBase

#: FMI 2.0 name of each value type's getter/setter (for messages).
FMI_NAME = {"integer": "Integer", "boolean": "Boolean", "string": "String"}


@dataclass
class Channel:
    """One component's connectors of one non-Real value type and their bound get/set.

    ``out_values``/``in_values`` are ``c_int64`` array views (Integer, Boolean) or lists of bytes
    (String); ``transfers`` are ``(input index, source block, source output index, mapping,
    carrier)`` with ``mapping`` a dict of an SSP mapping transformation or None, and ``carrier``
    None (a copy) or the :class:`~ipcosim.harness.master.integers.Carrier` an Integer connection
    delivers its value through (range checked, mapped).
    """

    value_type: str
    get: Callable[[Any], int]
    set: Callable[[Any], int]
    out_values: Any
    in_values: Any
    n_out: int
    n_in: int
    transfers: tuple[tuple[int, int, int, dict[int, int] | None, Any], ...] = ()
    private_out: Any = None  # Jacobi multi-rate: outputs are read here and published later
    #: The get of the output connectors alone, for initialization mode (None: there are none);
    #: ``get`` also reads the recorded variables that are not connectors, placed after them.
    init_get: Callable[[Any], int] | None = None


@dataclass
class Block:
    """One component's place in the value vector and its raw FMI functions."""

    index: int
    name: str
    handle: Any
    do_step: Callable[..., int]
    get_real: Callable[..., int]
    set_real: Callable[..., int]
    out_vrs: Any  # ctypes c_uint array
    in_vrs: Any
    out_values: Any  # ctypes c_double array (view into the value vector)
    in_values: Any
    n_out: int
    n_in: int
    multiple: int
    private_out: Any = None  # Jacobi multi-rate: outputs are read here and published later
    # transfers into this component's inputs: (input index, source block, source output index, factor, offset)
    transfers: tuple[tuple[int, int, int, float, float], ...] = ()
    #: Integer, Boolean and String connectors (none in a Real-only system: the loop is then unchanged).
    channels: tuple[Channel, ...] = ()
    #: How many of the outputs, the last ones, are recorded variables that are not connectors (not
    #: read in initialization mode).
    n_named: int = 0


@dataclass
class TypedRecord:
    """Where the loop records the non-Real values: the ``c_int`` vector's rows (row bytes, vector
    address; the rows' address is the loop's ``rbi`` argument) and String rows filled by
    ``snapshot()`` into ``strings[row]`` (a mapping by row number)."""

    int_row_bytes: int = 0
    int_vector: int = 0
    strings: dict | None = None
    snapshot: Callable[[], tuple] | None = None


#: A tick of the loop as a tree of operations, shared by the Python and the C back ends
#: (:func:`loop_plan`). Each is a tuple whose first item names it:
#:
#: - ``("transfer", b, k, src, j, factor, offset)``: Real input ``k`` of block ``b`` from output
#:   ``j`` of block ``src``: ``factor * x + offset``, the product only when ``factor != 1``, the
#:   sum only when ``offset != 0`` (``x + 0.0`` would turn -0.0 into 0.0);
#: - ``("ctransfer", b, c, k, src, j, mapping, carrier)``: the same for channel ``c`` (through
#:   ``mapping``, or through ``carrier`` when it is not None: see :class:`Channel`);
#: - ``("set", b)``, ``("cset", b, c)``: the batched set of the Real inputs / of channel ``c``;
#: - ``("step", b, multiple, last, partial)``: ``do_step`` from ``t`` (``multiple`` None) or from
#:   the start of the period ``(n // m) * m``, with step ``h_b``, or ``hl_b`` on the tick ``last``
#:   (``"end"``: ``N - 1``; ``"period"``: the first tick of the last period) when ``partial``;
#: - ``("get", b, private)``, ``("cget", b, c, private)``: the batched get into the value vector
#:   (or the private outputs of a multi-rate Jacobi component);
#: - ``("publish", b)``, ``("cpublish", b, c)``: the private outputs into the value vector;
#: - ``("if", cond, body)``: ``cond`` ``("end", m, partial)``: ``(n + 1) % m == 0`` (or the last
#:   tick, when ``partial``); ``("start", m)``: ``n % m == 0``.
Op = tuple


def loop_plan(blocks: Sequence[Block], order: Sequence[int], algorithm: str, time: TimeBase) -> list[Op]:
    """The operations of one tick of the stepping loop (see :data:`Op`)."""
    if algorithm not in ALGORITHMS:
        raise ValueError(f"unknown algorithm {algorithm!r}; expected one of {', '.join(ALGORITHMS)}")
    if algorithm == GAUSS_SEIDEL:
        return _gauss_seidel(blocks, order, time)
    return _jacobi(blocks, order, time)


def _partial(b: Block, time: TimeBase) -> bool:
    """Whether the component's last step differs from its regular one."""
    return time.ticks % b.multiple != 0 or time.short_last


def _inputs(b: Block) -> list[Op]:
    """Transfers into the component's inputs, then its batched sets."""
    ops: list[Op] = [("transfer", b.index, k, src, j, factor, offset) for k, src, j, factor, offset in b.transfers]
    for c, ch in enumerate(b.channels):
        ops += [("ctransfer", b.index, c, k, src, j, mapping, carrier) for k, src, j, mapping, carrier in ch.transfers]
    if b.n_in:
        ops.append(("set", b.index))
    return ops + [("cset", b.index, c) for c, ch in enumerate(b.channels) if ch.n_in]


def _outputs(b: Block, private: bool) -> list[Op]:
    ops: list[Op] = [("get", b.index, private)] if b.n_out else []
    return ops + [("cget", b.index, c, private) for c, ch in enumerate(b.channels) if ch.n_out]


def _gauss_seidel(blocks: Sequence[Block], order: Sequence[int], time: TimeBase) -> list[Op]:
    """Each component in order: transfers, set, step (multi-rate: at the end of its period)."""
    plan: list[Op] = []
    for idx in order:
        b = blocks[idx]
        m, partial = b.multiple, _partial(b, time)
        ops = _inputs(b) + [("step", b.index, None if m == 1 else m, "end", partial)] + _outputs(b, False)
        plan += ops if m == 1 else [("if", ("end", m, partial), ops)]
    return plan


def _jacobi(blocks: Sequence[Block], order: Sequence[int], time: TimeBase) -> list[Op]:
    """Every component reads the values of ``t_n``, then all step; multi-rate outputs are
    published at the end of their period (a partial last period starts with the shorter step)."""
    plan: list[Op] = []
    for idx in order:
        b = blocks[idx]
        plan += _inputs(b) if b.multiple == 1 else [("if", ("start", b.multiple), _inputs(b))]
    for idx in order:
        b = blocks[idx]
        m, partial = b.multiple, _partial(b, time)
        ops = [("step", b.index, None, "period", partial)] + _outputs(b, m > 1)
        plan += ops if m == 1 else [("if", ("start", m), ops)]
    for idx in order:
        b = blocks[idx]
        if b.multiple > 1:
            ops = ([("publish", b.index)] if b.n_out else []) + [
                ("cpublish", b.index, c) for c, ch in enumerate(b.channels) if ch.n_out]
            plan += [("if", ("end", b.multiple, _partial(b, time)), ops)]
    return plan


#: The FMI function each failure check names (the C loop reports its position in this tuple).
FUNCTIONS = ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal")
