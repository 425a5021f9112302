"""The stepping loop rendered as Python: the plan of :mod:`ipcosim.harness.master.plan` as the source
of one function, with all value references, arrays and functions bound as locals and
conversions folded into constants, so each step does nothing but the FMI calls, the transfers
and one copy of the value vector into the record (its C rendering: :mod:`ipcosim.harness.master.cloop`).
"""
from __future__ import annotations

import ctypes
from typing import Any, Callable, Sequence

from ipcosim.harness.master.algorithm import TimeBase
from ipcosim.harness.master.plan import FMI_NAME, Block, Op, TypedRecord, loop_plan


def generate_loop(blocks: Sequence[Block], order: Sequence[int], algorithm: str, time: TimeBase,
                  record_every: int = 1, typed: TypedRecord | None = None) -> tuple[str, dict[str, Any]]:
    """Python source of the stepping loop and its namespace.

    The generated ``run(n0, n1, rec_address, value_address, row_bytes, int_rec_address=0)`` steps
    ticks ``n0 .. n1-1``; after tick ``n`` it copies the value vector into record row
    ``r = (n + 1) // record_every`` (at ``rec_address + r * row_bytes``; the ``c_int`` vector at
    ``int_rec_address + r * typed.int_row_bytes``) when ``(n + 1) % record_every == 0``. The
    addresses are those of a row 0, which need not exist: a caller that keeps only a window of
    rows passes its first row's address minus the rows before it. It returns None, or
    ``(n, block index, function name, status)`` for the first call that returned more than
    fmi2Warning (or a ``do_step`` that returned :data:`~ipcosim.harness.master.slave.TERMINATE`).
    Every component's last step ends at the stop time: a component whose last period is partial
    (or a run whose last tick is short) takes a shorter last step there.

    The order of the calls comes from :func:`loop_plan` (shared with the C loop of
    :mod:`ipcosim.harness.master.cloop`).
    """
    plan = loop_plan(blocks, order, algorithm, time)
    em = _Emitter(blocks, time)
    em.lines += ["def run(n0, n1, rb, va, rs, rbi=0):", "    for n in range(n0, n1):", f"{IND}t = {time.expr('n')}"]
    em.render(plan, IND)
    _record(em.lines, em.ns, IND, record_every, typed)
    em.lines.append("    return None")
    return "\n".join(em.lines) + "\n", em.ns


IND = "        "


class _Emitter:
    """Python source lines of a loop plan (:func:`loop_plan`) and the namespace they run in."""

    def __init__(self, blocks: Sequence[Block], time: TimeBase) -> None:
        self.blocks, self.time, self.lines = blocks, time, []
        self.ns: dict[str, Any] = {"memmove": ctypes.memmove}
        for b in blocks:
            i = b.index
            self.ns.update({f"c{i}": b.handle, f"ds{i}": b.do_step, f"gr{i}": b.get_real, f"sr{i}": b.set_real,
                            f"vo{i}": b.out_vrs, f"vi{i}": b.in_vrs, f"O{i}": b.out_values, f"I{i}": b.in_values,
                            f"P{i}": b.private_out, f"h{i}": time.span(b.multiple),
                            f"hl{i}": time.last_step(b.multiple)})
            for k, ch in enumerate(b.channels):
                self.ns.update({f"G{i}_{k}": ch.get, f"S{i}_{k}": ch.set, f"O{i}_{k}": ch.out_values,
                                f"I{i}_{k}": ch.in_values, f"P{i}_{k}": ch.private_out})
                self.ns.update({f"M{i}_{k}_{t[0]}": t[3] for t in ch.transfers if t[3]})
                self.ns.update({f"C{i}_{k}_{t[0]}": t[4] for t in ch.transfers if t[4] is not None})

    def render(self, plan: Sequence[Op], indent: str) -> None:
        for op in plan:
            getattr(self, "op_" + op[0])(indent, *op[1:])

    def check(self, indent: str, i: int, call: str, function: str) -> None:
        self.lines += [f"{indent}s = {call}", f"{indent}if s > 1: return (n, {i}, '{function}', s)"]

    def op_if(self, indent: str, cond: tuple, body: Sequence[Op]) -> None:
        if not body:
            return
        if cond[0] == "start":
            self.lines.append(f"{indent}if n % {cond[1]} == 0:")
        else:
            last = f" or n == {self.time.ticks - 1}" if cond[2] else ""
            self.lines.append(f"{indent}if (n + 1) % {cond[1]} == 0{last}:")
        self.render(body, indent + "    ")

    def op_transfer(self, indent: str, i: int, k: int, src: int, j: int, factor: float, offset: float) -> None:
        expr = f"O{src}[{j}]"
        if factor != 1.0:
            expr = f"{factor!r} * {expr}"
        if offset != 0.0:
            expr = f"{expr} + {offset!r}"
        self.lines.append(f"{indent}I{i}[{k}] = {expr}")

    def op_ctransfer(self, indent: str, i: int, c: int, k: int, src: int, j: int, mapping: Any,
                     carrier: Any = None) -> None:
        sc = _channel_index(self.blocks[src], self.blocks[i].channels[c].value_type)
        if carrier is not None:  # checked (raises CarryError naming the connection), mapped
            self.lines.append(f"{indent}I{i}_{c}[{k}] = C{i}_{c}_{k}(O{src}_{sc}[{j}], n)")
        elif mapping:
            self.lines += [f"{indent}x = O{src}_{sc}[{j}]", f"{indent}I{i}_{c}[{k}] = M{i}_{c}_{k}.get(x, x)"]
        else:
            self.lines.append(f"{indent}I{i}_{c}[{k}] = O{src}_{sc}[{j}]")

    def op_set(self, indent: str, i: int) -> None:
        self.check(indent, i, f"sr{i}(c{i}, vi{i}, {self.blocks[i].n_in}, I{i})", "fmi2SetReal")

    def op_cset(self, indent: str, i: int, c: int) -> None:
        self.check(indent, i, f"S{i}_{c}(I{i}_{c})", f"fmi2Set{FMI_NAME[self.blocks[i].channels[c].value_type]}")

    def op_step(self, indent: str, i: int, multiple: int | None, last: str, partial: bool) -> None:
        start = "t" if multiple is None else self.time.expr(f"(n // {multiple}) * {multiple}")
        N, m = self.time.ticks, self.blocks[i].multiple
        tick = N - 1 if last == "end" else ((N - 1) // m) * m
        h = f"(h{i} if n != {tick} else hl{i})" if partial else f"h{i}"
        self.check(indent, i, f"ds{i}(c{i}, {start}, {h}, 1)", "fmi2DoStep")

    def op_get(self, indent: str, i: int, private: bool) -> None:
        target = "P" if private else "O"
        self.check(indent, i, f"gr{i}(c{i}, vo{i}, {self.blocks[i].n_out}, {target}{i})", "fmi2GetReal")

    def op_cget(self, indent: str, i: int, c: int, private: bool) -> None:
        target = "P" if private else "O"
        self.check(indent, i, f"G{i}_{c}({target}{i}_{c})", f"fmi2Get{FMI_NAME[self.blocks[i].channels[c].value_type]}")

    def op_publish(self, indent: str, i: int) -> None:
        self.lines.append(f"{indent}O{i}[:] = P{i}")

    def op_cpublish(self, indent: str, i: int, c: int) -> None:
        self.lines.append(f"{indent}O{i}_{c}[:] = P{i}_{c}[:{self.blocks[i].channels[c].n_out}]")


def _channel_index(block: Block, value_type: str) -> int:
    return next(k for k, ch in enumerate(block.channels) if ch.value_type == value_type)


def _record(L: list[str], ns: dict[str, Any], ind: str, record_every: int, typed: TypedRecord | None) -> None:
    """The lines that copy the values into the record after a tick."""
    rows: list[str] = ["memmove(rb + ROW * rs, va, rs)"]
    if typed is not None and typed.int_row_bytes:
        ns.update({"rsi": typed.int_row_bytes, "vai": typed.int_vector})
        rows.append("memmove(rbi + ROW * rsi, vai, rsi)")
    if typed is not None and typed.strings is not None:
        ns.update({"SREC": typed.strings, "snap": typed.snapshot})
        rows.append("SREC[ROW] = snap()")
    if record_every == 1:
        L.extend(f"{ind}{r.replace('ROW', '(n + 1)')}" for r in rows)
    else:
        L.append(f"{ind}if (n + 1) % {record_every} == 0:")
        L.extend(f"{ind}    {r.replace('ROW', f'((n + 1) // {record_every})')}" for r in rows)


def compile_loop(blocks: Sequence[Block], order: Sequence[int], algorithm: str, time: TimeBase,
                 record_every: int = 1, typed: TypedRecord | None = None) -> tuple[Callable[..., Any], str]:
    """The stepping loop as a function (see :func:`generate_loop`) and its source.

    The source is registered with :mod:`linecache` under a name unique to it, so a traceback
    through the loop shows the generated lines like those of any module.
    """
    import hashlib
    import linecache

    source, ns = generate_loop(blocks, order, algorithm, time, record_every, typed)
    filename = f"<ipcosim stepping loop {hashlib.sha1(source.encode()).hexdigest()[:12]}>"
    linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)
    code = compile(source, filename, "exec")
    exec(code, ns)  # noqa: S102 -- source generated above from the system's structure only
    return ns["run"], source
