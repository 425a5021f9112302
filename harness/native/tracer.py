"""Symbolic tracer: run a plain-float Python function once per branch with symbolic numbers, emit C.

A :class:`Node` stands for a double (or a C truth value) computed from named leaves (parameters,
inputs, state) and constants. Arithmetic, comparisons, ``abs`` and the ``math`` functions the
models use build an interned expression graph (equal sub-expressions are one node). Where the
Python code branches on a symbolic truth value (``if``, ``and``/``or``, ``min``/``max``,
conditional expressions), ``Node.__bool__`` asks the active :class:`Tracer`, which explores both
outcomes path by path (depth first) and merges the paths' results into C conditional
expressions ``c ? a : b``. The emitted code is straight-line: every node once, in topological
order, then the assignments. Floating-point operations map one to one onto C doubles in the
same order, so the C reproduces the Python results to rounding (exactly, in practice).
"""
from __future__ import annotations

import contextlib
import math
from typing import Any, Callable, Iterator, Sequence

from ipcosim.errors import IpcosimError

#: math functions a traced model may call, with their arity.
MATH_FUNCTIONS = {"sin": 1, "cos": 1, "tan": 1, "tanh": 1, "sinh": 1, "cosh": 1, "sqrt": 1, "exp": 1, "log": 1,
                  "fabs": 1, "floor": 1, "ceil": 1, "atan": 1, "copysign": 2, "fmod": 2, "atan2": 2, "hypot": 2,
                  "pow": 2}
_BINARY = {"+", "-", "*", "/", "<", "<=", ">", ">=", "==", "!="}
_COMPARE = {"<", "<=", ">", ">=", "==", "!="}


class TraceError(IpcosimError, RuntimeError):
    """A model did something the tracer cannot turn into C (names the operation)."""


class Node:
    """One interned expression node; build them with arithmetic, not directly."""

    __slots__ = ("op", "args", "name", "value", "index", "is_bool")

    def __init__(self, op: str, args: tuple[Node, ...] = (), name: str = "", value: float = 0.0,
                 is_bool: bool = False) -> None:
        self.op, self.args, self.name, self.value, self.is_bool = op, args, name, value, is_bool
        self.index = -1

    __hash__ = object.__hash__

    # ---- arithmetic
    def __add__(self, o: Any) -> Node: return _bin("+", self, o)
    def __radd__(self, o: Any) -> Node: return _bin("+", o, self)
    def __sub__(self, o: Any) -> Node: return _bin("-", self, o)
    def __rsub__(self, o: Any) -> Node: return _bin("-", o, self)
    def __mul__(self, o: Any) -> Node: return _bin("*", self, o)
    def __rmul__(self, o: Any) -> Node: return _bin("*", o, self)
    def __truediv__(self, o: Any) -> Node: return _bin("/", self, o)
    def __rtruediv__(self, o: Any) -> Node: return _bin("/", o, self)
    def __mod__(self, o: Any) -> Node: return py_mod(self, o)
    def __rmod__(self, o: Any) -> Node: return py_mod(o, self)
    def __pow__(self, o: Any) -> Node: return call("pow", self, o)
    def __rpow__(self, o: Any) -> Node: return call("pow", o, self)
    def __neg__(self) -> Node: return _intern("neg", (self,))
    def __pos__(self) -> Node: return self
    def __abs__(self) -> Node: return call("fabs", self)

    # ---- comparisons (truth values decided by the tracer only when Python asks for a bool)
    def __lt__(self, o: Any) -> Node: return _bin("<", self, o)
    def __le__(self, o: Any) -> Node: return _bin("<=", self, o)
    def __gt__(self, o: Any) -> Node: return _bin(">", self, o)
    def __ge__(self, o: Any) -> Node: return _bin(">=", self, o)
    def __eq__(self, o: Any) -> Node: return _bin("==", self, o)  # type: ignore[override]
    def __ne__(self, o: Any) -> Node: return _bin("!=", self, o)  # type: ignore[override]

    def __bool__(self) -> bool:
        if _ACTIVE is None:
            raise TraceError("a symbolic value was used as a truth value outside a trace")
        return _ACTIVE.decide(self)

    def __float__(self) -> float:
        raise TraceError("float() of a symbolic value (the model module's float is not hooked)")

    def __repr__(self) -> str:
        return f"Node({self.op}, {self.name or self.value})"


_TABLE: dict[tuple, Node] = {}
_ACTIVE: Tracer | None = None


def _key(n: Node) -> tuple:
    return (n.op, n.name, n.value if n.op == "const" else 0.0, tuple(id(a) for a in n.args))


def _intern(op: str, args: tuple[Node, ...], is_bool: bool = False) -> Node:
    key = (op, "", 0.0, tuple(id(a) for a in args))
    node = _TABLE.get(key)
    if node is None:
        node = _TABLE[key] = Node(op, args, is_bool=is_bool)
    return node


def const(value: float | bool) -> Node:
    """The constant node for a Python number (interned by its exact bits)."""
    v = float(value)
    key = ("const", "", v, (math.copysign(1.0, v), isinstance(value, bool)))
    node = _TABLE.get(key)
    if node is None:
        node = _TABLE[key] = Node("const", value=v, is_bool=isinstance(value, bool))
    return node


def leaf(name: str) -> Node:
    """The named leaf (a parameter, input, state or time): ``name`` is the C expression it reads."""
    key = ("leaf", name, 0.0, ())
    node = _TABLE.get(key)
    if node is None:
        node = _TABLE[key] = Node("leaf", name=name)
    return node


def wrap(x: Any) -> Node:
    """A node for a number or a node."""
    if isinstance(x, Node):
        return x
    if isinstance(x, (bool, int, float)) or type(x).__name__ in ("float64", "int64", "bool_"):
        return const(x.item() if hasattr(x, "item") else x)
    raise TraceError(f"cannot trace a value of type {type(x).__name__}")


def _bin(op: str, a: Any, b: Any) -> Node:
    if not isinstance(a, Node) and not isinstance(b, Node):
        raise TraceError("internal: binary operation without a symbolic operand")
    try:
        a, b = wrap(a), wrap(b)
    except TraceError:
        return NotImplemented  # let numpy or the other operand handle it
    return _intern(op, (a, b), is_bool=op in _COMPARE)


def call(fn: str, *args: Any) -> Node:
    """A call of the C math function ``fn`` (``MATH_FUNCTIONS``)."""
    return _intern("call:" + fn, tuple(wrap(a) for a in args))


def py_mod(a: Any, b: Any) -> Node:
    """Python's float ``a % b`` (the sign of ``b``) from C's ``fmod``, as CPython computes it."""
    r = call("fmod", a, b)
    b = wrap(b)
    fixed = select(_bin("!=", _bin("<", r, 0.0), _bin("<", b, 0.0)), _bin("+", r, b), r)
    return select(_bin("!=", r, 0.0), fixed, call("copysign", 0.0, b))


def select(cond: Node, a: Any, b: Any) -> Any:
    """``cond ? a : b`` on nodes (or equal Python values, returned as they are)."""
    if a is b:
        return a
    if not isinstance(a, Node) and not isinstance(b, Node) and a == b and type(a) is type(b):
        return a
    a, b = wrap(a), wrap(b)
    return _intern("?", (cond, a, b), is_bool=a.is_bool and b.is_bool)


# ============================================================================ hooks


@contextlib.contextmanager
def math_hooks(*modules: Any) -> Iterator[None]:
    """Route ``math.<fn>`` and the given modules' ``float`` builtin through the tracer while active."""
    saved = {name: getattr(math, name) for name in MATH_FUNCTIONS if hasattr(math, name)}

    def hook(name: str, orig: Callable[..., float]) -> Callable[..., Any]:
        def f(*args: Any) -> Any:
            if any(isinstance(a, Node) for a in args):
                return call(name, *args)
            return orig(*args)
        return f

    def sym_float(x: Any = 0.0) -> Any:
        return x if isinstance(x, Node) else float(x)

    for name, orig in saved.items():
        setattr(math, name, hook(name, orig))
    had = [(m, m.__dict__.get("float", _MISSING)) for m in modules]
    for m in modules:
        m.float = sym_float
    try:
        yield
    finally:
        for name, orig in saved.items():
            setattr(math, name, orig)
        for m, old in had:
            if old is _MISSING:
                del m.float
            else:
                m.float = old


_MISSING = object()


# ============================================================================ path exploration


class Tracer:
    """Runs a function once per feasible branch path and merges the results."""

    def __init__(self) -> None:
        self.prefix: list[bool] = []
        self.decisions: list[tuple[Node, bool]] = []
        self._decided: dict[int, bool] = {}

    def decide(self, cond: Node) -> bool:
        if cond.op == "const":
            return bool(cond.value)
        if id(cond) in self._decided:
            return self._decided[id(cond)]
        k = len(self.decisions)
        choice = self.prefix[k] if k < len(self.prefix) else True
        self.decisions.append((cond, choice))
        self._decided[id(cond)] = choice
        return choice

    def run(self, fn: Callable[[], Sequence[Any]], max_paths: int = 4096) -> list[Any]:
        """``fn()`` -> flat sequence of results (nodes or numbers), merged over every branch path."""
        global _ACTIVE
        paths: list[tuple[list[tuple[Node, bool]], list[Any]]] = []
        todo: list[list[bool]] = [[]]
        previous, _ACTIVE = _ACTIVE, self
        try:
            while todo:
                if len(paths) >= max_paths:
                    raise TraceError(f"more than {max_paths} branch paths")
                self.prefix, self.decisions, self._decided = todo.pop(), [], {}
                out = list(fn())
                paths.append((self.decisions, out))
                for k in range(len(self.prefix), len(self.decisions)):
                    if self.decisions[k][1]:
                        todo.append([c for _, c in self.decisions[:k]] + [False])
        finally:
            _ACTIVE = previous
        return _merge(paths, 0)


def _merge(paths: list[tuple[list[tuple[Node, bool]], list[Any]]], depth: int) -> list[Any]:
    decisive = [p for p in paths if len(p[0]) > depth]
    if not decisive:
        if len(paths) != 1:
            raise TraceError("internal: paths do not diverge")
        return paths[0][1]
    cond = decisive[0][0][depth][0]
    yes = [p for p in paths if p[0][depth][1]]
    no = [p for p in paths if not p[0][depth][1]]
    a, b = _merge(yes, depth + 1), _merge(no, depth + 1)
    return [select(cond, x, y) for x, y in zip(a, b)]


def local(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` with its branches merged where it returns, not at the end of the whole trace.

    For pure functions (a clip, a right-hand side): the paths inside ``fn`` become conditional
    expressions of its results, so the code after the call is traced once, not once per path.
    ``fn`` must return a number, a node or a flat tuple/list of them.
    """
    def wrapper(*args: Any) -> Any:
        if _ACTIVE is None or not any(isinstance(a, Node) for a in args):
            return fn(*args)
        shape: list[Any] = []

        def run() -> list[Any]:
            out = fn(*args)
            if not shape:
                shape.append(type(out) if isinstance(out, (tuple, list)) else None)
            return list(out) if shape[0] is not None else [out]

        merged = Tracer().run(run)
        return merged[0] if shape[0] is None else shape[0](merged)
    return wrapper


def trace(fn: Callable[[], Sequence[Any]]) -> list[Any]:
    """Trace ``fn`` (no arguments; builds its own symbolic inputs) over every branch path."""
    return Tracer().run(fn)


# ============================================================================ C emission


def c_double(v: float) -> str:
    """A C double literal that reads back as exactly ``v``."""
    if math.isnan(v):
        return "NAN"
    if math.isinf(v):
        return "HUGE_VAL" if v > 0 else "(-HUGE_VAL)"
    text = repr(v)
    return text if any(ch in text for ch in ".en") else text + ".0"


_C_OP = {"+": "+", "-": "-", "*": "*", "/": "/", "<": "<", "<=": "<=", ">": ">", ">=": ">=", "==": "==",
         "!=": "!="}


def _expr(n: Node, ref: Callable[[Node], str]) -> str:
    if n.op in _C_OP:
        return f"{ref(n.args[0])} {_C_OP[n.op]} {ref(n.args[1])}"
    if n.op == "neg":
        return f"-{ref(n.args[0])}"
    if n.op.startswith("call:"):
        return f"{n.op[5:]}({', '.join(ref(a) for a in n.args)})"
    if n.op == "?":
        c = n.args[0]
        cond = ref(c) if c.is_bool else f"{ref(c)} != 0.0"
        return f"({cond}) ? {ref(n.args[1])} : {ref(n.args[2])}"
    raise TraceError(f"internal: cannot emit {n.op}")


def emit(assignments: Sequence[tuple[str, Any]], indent: str = "    ",
         leaf_ref: Callable[[str], str] = str) -> list[str]:
    """C statements computing every right-hand side, then doing every assignment (simultaneously).

    ``assignments`` are ``(C lvalue, node or number)``; temporaries ``eK`` are declared ``const``;
    ``leaf_ref`` maps a leaf's name to the C expression that reads it.
    """
    order: list[Node] = []
    seen: set[int] = set()
    for _, value in assignments:
        if isinstance(value, Node):
            _topo(value, seen, order)
    names: dict[int, str] = {}

    def ref(n: Node) -> str:
        if n.op == "const":
            return ("1" if n.value else "0") if n.is_bool else c_double(n.value)
        if n.op == "leaf":
            return leaf_ref(n.name)
        return names[id(n)]

    lines = []
    for n in order:
        if n.op in ("const", "leaf"):
            continue
        name = f"e{len(names)}"
        names[id(n)] = name
        lines.append(f"{indent}const {'int' if n.is_bool else 'double'} {name} = {_expr(n, ref)};")
    for _, value in assignments:  # a leaf read as a value is copied first: another assignment may write it
        if isinstance(value, Node) and value.op == "leaf" and id(value) not in names:
            names[id(value)] = name = f"e{len(names)}"
            lines.append(f"{indent}const double {name} = {leaf_ref(value.name)};")
    for target, value in assignments:
        node = wrap(value)
        text = names[id(node)] if node.op == "leaf" else ref(node)
        lines.append(f"{indent}{target} = {'(double)' if node.is_bool else ''}{text};")
    return lines


def _topo(root: Node, seen: set[int], order: list[Node]) -> None:
    stack: list[tuple[Node, bool]] = [(root, False)]
    while stack:
        n, done = stack.pop()
        if done:
            order.append(n)
            continue
        if id(n) in seen:
            continue
        seen.add(id(n))
        stack.append((n, True))
        for a in reversed(n.args):
            if id(a) not in seen:
                stack.append((a, False))


def reset_table() -> None:
    """Forget interned nodes (between models)."""
    _TABLE.clear()
