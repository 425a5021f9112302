"""Values given to FMU variables: a value (a string from the command line, or a typed value) as
its variable's type, and a run's ``--set`` values checked against the bound system."""
from __future__ import annotations

from typing import Any, Mapping

from ipcosim.errors import closest
from ipcosim.harness.master import integers
from ipcosim.harness.master.system import System, Variable, value_type_of
from ipcosim.harness.scenario.errors import BindingError, SetError
from ipcosim.harness.scenario.rebuild import rebuild_hint


def convert_value(var: Variable, value: Any, what: str) -> Any:
    """``value`` (a string from the command line or a typed value) as the variable's type.

    Raises
    ------
    BindingError
        ``what`` is not a valid value of the variable's type.
    """
    t = var.type
    value_type = value_type_of(t)
    try:
        if value_type == "real":
            if isinstance(value, bool):
                raise ValueError
            return float(value)
        if value_type == "integer":  # exactly (FMI 3.0: Int8 .. UInt64), in the type's range below
            x = integers.exact_integer(value)
            if t not in integers.RANGE or integers.in_range(x, t):
                return x
        if t == "Boolean":
            if isinstance(value, bool):
                return value
            text = str(value).strip().lower()
            if text in ("true", "1"):
                return True
            if text in ("false", "0"):
                return False
            raise ValueError
        if t == "String":
            return str(value)
    except (TypeError, ValueError):
        raise BindingError(f"{what}: {value!r} is not a valid {t} value") from None
    if value_type == "integer":
        lo, hi = integers.RANGE[t]
        raise BindingError(f"{what}: {value!r} is out of the range of {t} ({lo} .. {hi})")
    raise BindingError(f"{what}: variables of type {t} cannot be set")


def with_set(system: System, set: Mapping[str, Any]) -> tuple[System, dict[tuple[str, str], Any]]:
    """Check a run's ``set`` (``--set comp.var=value``) against the system.

    Returns the system unchanged and the values keyed by (component, variable) with
    values converted to the variables' types.

    Raises
    ------
    SetError
        Unknown component or variable, a variable that cannot be set (output, local,
        constant), a connected input, or a value that does not parse.
    """
    out: dict[tuple[str, str], Any] = {}
    for key, value in set.items():
        comp, sep, var = _split_name(system, str(key))
        if not sep or not comp or not var:
            raise SetError(f"--set {key}={value}: expected COMPONENT.VARIABLE=VALUE")
        try:
            inst = system.instance(comp)
        except KeyError:
            raise SetError(f"--set {key}={value}: no component {comp!r}; "
                               f"{closest(comp, (i.name for i in system.instances))}") from None
        v = inst.model.variables.get(var)
        model_name = inst.model.path.name if inst.model.path else inst.model.name
        where = f"--set {key}={value}: component {comp!r} ({model_name})"
        if v is None:
            settable = (n for n, x in inst.model.variables.items() if x.settable)
            raise SetError(f"{where} has no variable {var!r}; {closest(var, settable)} "
                               f"(`ipcosim describe {system.scenario.name}` lists them){rebuild_hint(inst.model)}")
        if not v.settable:
            raise SetError(f"{where}: {var!r} is {v.causality}/{v.variability} and cannot be set")
        link = system.link_into(comp, var) or next((k for k in system.parameter_links
                                                     if k.dst == comp and k.dst_var.name == var), None)
        if link is not None:
            raise SetError(f"{where}: {v.causality} {var!r} is connected to {link.src_name}; set the source "
                           f"instead")
        try:
            out[(comp, var)] = convert_value(v, value, f"--set {key}")
        except BindingError as exc:
            raise SetError(str(exc)) from None
    return system, out


def _split_name(system: System, key: str) -> tuple[str, str, str]:
    """``component``, ``.``, ``variable`` of ``component.variable``: the longest component name that
    ``key`` starts with (a nested system's component is ``sub.component``), else split at the first dot."""
    names = sorted((i.name for i in system.instances if key.startswith(i.name + ".")), key=len, reverse=True)
    if names:
        return names[0], ".", key[len(names[0]) + 1:]
    return key.partition(".")
