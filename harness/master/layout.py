"""The value layout of one run: where every connector's value lives while the run proceeds, and
the arrays the stepping loops read and write.

Real connectors of all components share one ``ctypes`` double vector (per component its
outputs, then its inputs); each component reads its outputs into and sets its inputs from its
own slice of it with one call, and the vector is copied to the record after every step.
Integer and Boolean connectors share one ``c_int64`` vector (per component: integer outputs,
inputs, boolean outputs, inputs), which holds every FMI integer type exactly
(:mod:`~ipcosim.harness.master.integers`); String connectors live in lists per component. A
:class:`~ipcosim.harness.master.plan.Block` is one component's view of these vectors with its
raw FMI functions, a :class:`~ipcosim.harness.master.plan.Channel` its connectors of one
non-Real value type. The layout also names the record's columns (:attr:`Layout.column_types`).

Variables that are not connectors (parameters, calculated parameters, locals) are recorded when a
run names them (:func:`named_variables`): each takes a place after its component's outputs of its
type, so the batched get of every step reads it with them, and its column follows the connectors'.
A run that names none has exactly the connectors' vectors and columns.
"""
from __future__ import annotations

import ctypes
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ipcosim.errors import UsageError, closest
from ipcosim.harness.master import integers
from ipcosim.harness.master.algorithm import GAUSS_SEIDEL
from ipcosim.harness.master.plan import Block, Channel
from ipcosim.harness.master.results import matching
from ipcosim.harness.master.slave import Slave
from ipcosim.harness.master.system import System, Variable, value_type_of

#: numpy type of a record column of each value type (an Integer column: of its type, ``integers.DTYPE``).
COLUMN_DTYPE = {"real": "f8", "integer": "i4", "boolean": "?", "string": "O"}

#: ``start_value(component, variable)``: the value a connector starts the run with.
StartValue = Callable[[str, str], Any]


def named_variables(system: System, patterns: Sequence[str] | None) -> list[tuple[str, Variable]]:
    """The variables beyond the connectors that ``--record`` names: for each name or shell pattern
    (``addP.k1``, ``plant.*``) that matches no connector, every variable ``component.variable``
    it matches that is not a connector, of a type the master carries, in the order named (each once).

    Raises
    ------
    UsageError
        A pattern that matches no variable at all, with the closest names.
    """
    connectors = ["time"] + [f"{i.name}.{v.name}" for i in system.instances for v in i.connectors
                             if value_type_of(v.type) is not None]
    others = {f"{i.name}.{v.name}": (i.name, v) for i in system.instances for v in i.model.variables.values()
              if value_type_of(v.type) is not None and v.causality != "independent"
              and all(v.name != c.name for c in i.connectors)}
    named: dict[str, tuple[str, Variable]] = {}
    for p in patterns or ():
        if matching(connectors, p):
            continue
        hits = matching(list(others), p)
        if not hits:
            raise UsageError(f"--record {p}: no such variable; {closest(p, connectors[1:] + list(others), listing=40)}")
        named.update((name, others[name]) for name in hits)
    return list(named.values())


class Layout:
    """The value vectors of a system's connectors and the record columns they fill.

    Parameters
    ----------
    system : System
        The bound system.
    start_value : callable
        ``start_value(component, variable)``: an input's value before the run (its ``set``
        value, else its bound start), put into the vectors here.
    recorded : sequence of (str, Variable)
        Further variables to record, by component (:func:`named_variables`): read after every
        step with the component's outputs, but not in initialization mode, where FMI 2.0 lets
        an importer get only outputs, states and derivatives.
    """

    def __init__(self, system: System, start_value: StartValue,
                 recorded: Sequence[tuple[str, Variable]] = ()) -> None:
        self.system = system
        self.instances = list(system.instances)
        self.index = {inst.name: i for i, inst in enumerate(self.instances)}
        self.recorded = list(recorded)
        self._place_reals(start_value)
        self._place_typed(start_value)
        self._name_columns()

    def _place_reals(self, start_value: StartValue) -> None:
        """Place every Real connector in the value vector, inputs at their start values."""
        self.real_outputs: list[list[Variable]] = []
        self.real_inputs: list[list[Variable]] = []
        #: Per component, how many of its outputs (the last ones) are recorded variables, not connectors.
        self.real_named: list[int] = []
        offsets = []
        pos = 0
        for inst in self.instances:
            outs = [v for v in inst.outputs if value_type_of(v.type) == "real"]
            named = self._named(inst.name, "real")
            self.real_named.append(len(named))
            outs += named
            ins = [v for v in inst.inputs if value_type_of(v.type) == "real"]
            self.real_outputs.append(outs)
            self.real_inputs.append(ins)
            offsets.append((pos, pos + len(outs)))
            pos += len(outs) + len(ins)
        self.n_values = pos
        self.values_c = (ctypes.c_double * (pos + 1))()  # +1: empty slices still map one element
        self.values = np.ctypeslib.as_array(self.values_c)[:pos]
        self.out_offset = [o for o, _ in offsets]
        self.in_offset = [i for _, i in offsets]
        self.slot: dict[tuple[str, str], int] = {}
        for k, inst in enumerate(self.instances):
            for j, v in enumerate(self.real_outputs[k]):
                self.slot[(inst.name, v.name)] = self.out_offset[k] + j
            for j, v in enumerate(self.real_inputs[k]):
                self.slot[(inst.name, v.name)] = self.in_offset[k] + j
                start = start_value(inst.name, v.name)
                self.values[self.in_offset[k] + j] = float(start) if start is not None else 0.0
        self.output_slots = np.array([self.out_offset[k] + j for k in range(len(self.instances))
                                      for j in range(len(self.real_outputs[k]) - self.real_named[k])], dtype=int)

    def _place_typed(self, start_value: StartValue) -> None:
        """Place the Integer and Boolean connectors in one ``c_int64`` vector (per component:
        integer outputs, inputs, boolean outputs, inputs) and the String connectors in lists
        per component; inputs at their start values."""
        self.typed: list[dict[str, tuple[list[Variable], list[Variable]]]] = []
        self.int_offset: dict[tuple[int, str], int] = {}
        self.strings: dict[int, tuple[list[bytes], list[bytes]]] = {}
        self.tslot: dict[tuple[str, str], tuple[str, int]] = {}  # (value type, int slot or string index)
        #: How many of a component's outputs of a type (the last ones) are recorded variables, by (index, type).
        self.typed_named: dict[tuple[int, str], int] = {}
        #: The sized type (``integers.RANGE``) and ``component.variable`` of each Integer slot.
        self.int_types: dict[int, tuple[str, str]] = {}
        self.string_slots: list[tuple[list[bytes], int]] = []
        pos = 0
        for k, inst in enumerate(self.instances):
            groups = {}
            for value_type in ("integer", "boolean", "string"):
                outs = [v for v in inst.outputs if value_type_of(v.type) == value_type]
                named = self._named(inst.name, value_type)
                outs += named
                ins = [v for v in inst.inputs if value_type_of(v.type) == value_type]
                if not (outs or ins):
                    continue
                self.typed_named[(k, value_type)] = len(named)
                groups[value_type] = (outs, ins)
                if value_type == "string":
                    self._place_strings(k, outs, ins)
                else:
                    self.int_offset[(k, value_type)] = pos
                    for j, v in enumerate(outs + ins):
                        self.tslot[(inst.name, v.name)] = (value_type, pos + j)
                        if value_type == "integer":
                            self.int_types[pos + j] = (integers.integer_type(v.type, inst.model.fmi_version),
                                                       f"{inst.name}.{v.name}")
                    pos += len(outs) + len(ins)
            self.typed.append(groups)
        self.n_ints = pos
        self.ints_c = (ctypes.c_int64 * (pos + 1))()
        self.ints = np.ctypeslib.as_array(self.ints_c)[:pos]
        for (comp, var), (value_type, slot) in self.tslot.items():
            if self.instances[self.index[comp]].model.variables[var].causality == "input":
                self.store(value_type, slot, start_value(comp, var))

    def _named(self, component: str, value_type: str) -> list[Variable]:
        """The recorded variables of ``component`` that are not connectors, of ``value_type``."""
        return [v for c, v in self.recorded if c == component and value_type_of(v.type) == value_type]

    def _place_strings(self, k: int, outs: list[Variable], ins: list[Variable]) -> None:
        """Component ``k``'s String outputs and inputs: one list each, numbered in ``string_slots``."""
        lists: tuple[list[bytes], list[bytes]] = ([b""] * len(outs), [b""] * len(ins))
        self.strings[k] = lists
        for lst, vs in zip(lists, (outs, ins)):
            for j, v in enumerate(vs):
                self.tslot[(self.instances[k].name, v.name)] = ("string", len(self.string_slots))
                self.string_slots.append((lst, j))

    def _name_columns(self) -> None:
        """The record columns: ``time``, then every connector in SSD order, then the other recorded
        variables in the order named. A connected input's
        column is the transformed source value (what the connection delivers at that time):
        ``columns`` (Real: name, slot, (source slot, factor, offset) or None), ``typed_columns``
        (name, value_type, slot, (source slot, mapping) or None) and the value type of every column,
        ``column_types`` (``real``, ``integer``, ``boolean``, ``string``), and its numpy type,
        ``column_dtypes`` (an Integer column: its FMI type's, ``integers.DTYPE``)."""
        self.columns: list[tuple[str, int, tuple[int, float, float] | None]] = []
        self.typed_columns: list[tuple[str, str, int, tuple[int, dict[int, int]] | None]] = []
        self.column_types: dict[str, str] = {"time": "real"}
        self.column_dtypes: dict[str, str] = {"time": COLUMN_DTYPE["real"]}
        for inst in self.instances:
            for v in inst.connectors:
                value_type = value_type_of(v.type)
                if value_type is None:
                    continue
                name = f"{inst.name}.{v.name}"
                self.column_types[name] = value_type
                self.column_dtypes[name] = COLUMN_DTYPE[value_type]
                link = self.system.link_into(inst.name, v.name)
                if value_type == "real":
                    src = (self.slot[(link.src, link.src_var.name)], link.factor, link.offset) if link else None
                    self.columns.append((name, self.slot[(inst.name, v.name)], src))
                else:
                    slot = self.tslot[(inst.name, v.name)][1]
                    if value_type == "integer":
                        self.column_dtypes[name] = integers.DTYPE[self.int_types[slot][0]]
                    typed = (self.tslot[(link.src, link.src_var.name)][1], dict(link.mapping)) if link else None
                    self.typed_columns.append((name, value_type, slot, typed))
        for comp, v in self.recorded:
            value_type = value_type_of(v.type)
            assert value_type is not None  # named_variables names only variables of a carried type
            name = f"{comp}.{v.name}"
            self.column_types[name] = value_type
            self.column_dtypes[name] = COLUMN_DTYPE[value_type]
            if value_type == "real":
                self.columns.append((name, self.slot[(comp, v.name)], None))
                continue
            slot = self.tslot[(comp, v.name)][1]
            if value_type == "integer":
                self.column_dtypes[name] = integers.DTYPE[self.int_types[slot][0]]
            self.typed_columns.append((name, value_type, slot, None))

    def row_fields(self) -> list[tuple[str, str]]:
        """Name and numpy type of every recorded field: ``time``, then ``component.variable``
        (see :data:`COLUMN_DTYPE`; an Integer field has its FMI type's, ``integers.DTYPE``)."""
        return list(self.column_dtypes.items())

    # ------------------------------------------------------------------ values
    def store(self, value_type: str, slot: int, value: Any) -> None:
        """Put a start value into the typed value store.

        Raises
        ------
        IntegerRangeError
            An Integer value that is not an integer, or that the variable's type cannot hold.
        """
        if value_type == "string":
            lst, j = self.string_slots[slot]
            lst[j] = b"" if value is None else (value if isinstance(value, bytes) else str(value).encode())
        elif value_type == "boolean":
            self.ints[slot] = int(bool(value))
        else:
            type_, name = self.int_types[slot]
            try:
                x = integers.exact_integer(value or 0)
            except ValueError:
                raise integers.IntegerRangeError(f"{name}: {value!r} is not an integer") from None
            self.ints[slot] = integers.stored(integers.check(x, type_, name), type_)

    def put(self, component: str, variable: str, value: Any) -> None:
        """Put the value of an input connector into its vector (what the next batched set sends);
        nothing for a variable that is not a connector."""
        slot = self.slot.get((component, variable))
        if slot is not None:
            self.values[slot] = float(value)
        typed = self.tslot.get((component, variable))
        if typed is not None:
            self.store(typed[0], typed[1], value)

    def get(self, component: str, variable: str) -> Any:
        """Current value of a connector: float, int, bool or str."""
        if (component, variable) in self.slot:
            return float(self.values[self.slot[(component, variable)]])
        value_type, slot = self.tslot[(component, variable)]
        if value_type == "string":
            lst, j = self.string_slots[slot]
            return lst[j].decode("utf-8", "replace")
        if value_type == "boolean":
            return bool(self.ints[slot])
        return integers.value(int(self.ints[slot]), self.int_types[slot][0])

    def snapshot_strings(self) -> tuple:
        """The String connectors' current values, in ``string_slots`` order."""
        return tuple(lst[j] for lst, j in self.string_slots)

    def output_at(self, slot: int) -> tuple[int, str]:
        """The component (index) whose output holds value-vector slot ``slot``, and the output's name."""
        for k in range(len(self.instances)):
            if self.out_offset[k] <= slot < self.in_offset[k]:
                return k, self.real_outputs[k][slot - self.out_offset[k]].name
        raise KeyError(slot)

    # ------------------------------------------------------------------ the loops' arrays
    def blocks(self, slaves: list[Slave], multiples: Mapping[str, int], algorithm: str) -> list[Block]:
        """Every component's :class:`Block`: its views of the value vector, value references,
        transfers and raw FMI functions (from its instantiated ``slave``)."""
        blocks = []
        for k, (inst, slave) in enumerate(zip(self.instances, slaves)):
            handle, do_step, get_real, set_real = slave.raw()
            outs, ins = self.real_outputs[k], self.real_inputs[k]
            n_out, n_in = len(outs), len(ins)
            out_values = (ctypes.c_double * max(n_out, 1)).from_buffer(self.values_c, 8 * self.out_offset[k])
            in_values = (ctypes.c_double * max(n_in, 1)).from_buffer(self.values_c, 8 * self.in_offset[k])
            transfers = []
            for j, v in enumerate(ins):
                link = self.system.link_into(inst.name, v.name)
                if link is None:
                    continue
                src = self.index[link.src]
                src_j = [x.name for x in self.real_outputs[src]].index(link.src_var.name)
                transfers.append((j, src, src_j, float(link.factor), float(link.offset)))
            m = multiples[inst.name]
            private = (ctypes.c_double * max(n_out, 1))() if (m > 1 and algorithm != GAUSS_SEIDEL) else None
            blocks.append(Block(index=k, name=inst.name, handle=handle, do_step=do_step, get_real=get_real,
                                set_real=set_real, out_vrs=(ctypes.c_uint * max(n_out, 1))(*[v.vr for v in outs]),
                                in_vrs=(ctypes.c_uint * max(n_in, 1))(*[v.vr for v in ins]),
                                out_values=out_values, in_values=in_values, n_out=n_out, n_in=n_in,
                                multiple=m, private_out=private, transfers=tuple(transfers),
                                n_named=self.real_named[k],
                                channels=self._channels(k, slave, m > 1 and algorithm != GAUSS_SEIDEL)))
        return blocks

    def _channels(self, k: int, slave: Slave, private: bool) -> tuple[Channel, ...]:
        """Component ``k``'s Integer, Boolean and String channels (see :class:`Channel`);
        ``private``: its outputs are read into a private array and published later (Jacobi
        multi-rate)."""
        out = []
        for value_type, (outs, ins) in self.typed[k].items():
            if value_type == "string":
                o_vals, i_vals = self.strings[k]
            else:
                off = self.int_offset[(k, value_type)]
                o_vals = (ctypes.c_int64 * max(len(outs), 1)).from_buffer(self.ints_c, 8 * off)
                i_vals = (ctypes.c_int64 * max(len(ins), 1)).from_buffer(self.ints_c, 8 * (off + len(outs)))
            transfers = []
            for j, v in enumerate(ins):
                link = self.system.link_into(self.instances[k].name, v.name)
                if link is not None:
                    src = self.index[link.src]
                    src_j = [x.name for x in self.typed[src][value_type][0]].index(link.src_var.name)
                    transfers.append((j, src, src_j, dict(link.mapping) or None, self._carrier(value_type, link)))
            own = None
            if private and outs:
                own = [b""] * len(outs) if value_type == "string" else (ctypes.c_int64 * len(outs))()
            get = slave.channel(value_type, outs)[0] if outs else None
            put = slave.channel(value_type, ins)[1] if ins else None
            named = self.typed_named[(k, value_type)]
            connectors = outs[:len(outs) - named]
            init_get = get if not named else (slave.channel(value_type, connectors)[0] if connectors else None)
            out.append(Channel(value_type, get, put, o_vals, i_vals, len(outs), len(ins), tuple(transfers), own,
                               init_get))
        return tuple(out)

    def _carrier(self, value_type: str, link: Any) -> integers.Carrier | None:
        """What an Integer connection does with a value when it is not a plain copy (see
        :class:`integers.Carrier`): when the destination's type cannot hold every value of the
        source's, or a mapping applies; None otherwise (a Boolean or String one: always)."""
        if value_type != "integer":
            return None
        src_t = self.int_types[self.tslot[(link.src, link.src_var.name)][1]][0]
        dst_t = self.int_types[self.tslot[(link.dst, link.dst_var.name)][1]][0]
        if not link.mapping and not integers.narrowing(src_t, dst_t):
            return None
        return integers.Carrier(src_t, dst_t, dict(link.mapping), f"{link.src_name} -> {link.dst_name}")
