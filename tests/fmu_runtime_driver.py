"""Drive one extracted FMU's Python class the way pythonfmu's wrapper does, optionally with imports blocked.

Run as a script in a fresh interpreter (``tests/fmus/test_fmu_runtime.py``)::

    python fmu_runtime_driver.py UNZIPPED_DIR SPEC_JSON [--block numpy,scipy,control,fmpy,ipcosim]

``SPEC_JSON`` holds ``{"params": {name: value}, "steps": N, "step_size": h, "watch": [name, ...]}``. The driver puts the
FMU's ``resources/`` first on ``sys.path``, imports the module named in ``slavemodule.txt``,
instantiates its FMU class with ``instance_name``/``resources``/``visible``, runs
setup_experiment, enter/exit initialization and ``steps`` steps with deterministic inputs, and
prints one JSON document: the outputs (and watched parameters) after initialization and after each step, the import
attempts the blocker refused, the blocked names found in ``sys.modules`` at the end, and the
error text if initialization failed.

Only the standard library is imported before the blocker is installed.
"""
from __future__ import annotations

import importlib
import importlib.abc
import json
import math
import sys
from pathlib import Path
from xml.etree import ElementTree


class Blocker(importlib.abc.MetaPathFinder):
    """Refuses, and records, every import of the given top-level packages."""

    def __init__(self, names: set[str]) -> None:
        self.names = names
        self.attempts: list[str] = []

    def find_spec(self, fullname, path=None, target=None):  # noqa: ANN001, ANN201 -- importlib protocol
        if fullname.split(".", 1)[0] in self.names:
            self.attempts.append(fullname)
            raise ModuleNotFoundError(f"No module named {fullname!r} (blocked)", name=fullname)
        return None


def _variables(unzipped: Path) -> list[dict]:
    root = ElementTree.parse(unzipped / "modelDescription.xml").getroot()
    out = []
    for sv in root.iter("ScalarVariable"):
        kind = next(iter(sv)).tag
        out.append({"name": sv.get("name"), "vr": int(sv.get("valueReference")), "causality": sv.get("causality"),
                    "type": kind})
    return out


def _input_value(name: str, k: int, i: int) -> float:
    """Deterministic, smooth test inputs: a few volts for ``voltage``, centimetres / centiradians otherwise."""
    amp = 2.0 if name == "voltage" else (0.05 if name == "reference" else 0.01)
    return amp * math.sin(0.05 * i + 0.7 * k) + (0.02 if name == "reference" else 0.0)


def _set(slave, var: dict, value) -> None:  # noqa: ANN001
    {"Real": slave.set_real, "Integer": slave.set_integer, "Boolean": slave.set_boolean,
     "String": slave.set_string}[var["type"]]([var["vr"]], [value])


def run(unzipped: Path, spec: dict) -> dict:
    resources = unzipped / "resources"
    sys.path.insert(0, str(resources))
    module = importlib.import_module((resources / "slavemodule.txt").read_text().strip())
    cls = next(c for c in vars(module).values()
               if isinstance(c, type) and c.__module__ == module.__name__ and hasattr(c, "do_step"))
    slave = cls(instance_name="driver", resources=str(resources), visible=False)
    variables = _variables(unzipped)
    by_name = {v["name"]: v for v in variables}
    inputs = [v for v in variables if v["causality"] == "input" and v["type"] == "Real"]
    extra = set(spec.get("watch", ()))
    watched = [v for v in variables if v["type"] == "Real"
               and (v["causality"] in ("output", "calculatedParameter") or v["name"] in extra)]
    slave.setup_experiment(0.0)
    slave.enter_initialization_mode()
    for name, value in spec.get("params", {}).items():
        _set(slave, by_name[name], value)
    for k, v in enumerate(inputs):
        slave.set_real([v["vr"]], [_input_value(v["name"], k, 0)])
    try:
        slave.exit_initialization_mode()
    except Exception as exc:  # noqa: BLE001 -- reported to the test
        return {"error": str(exc).strip()}
    rows = [slave.get_real([v["vr"] for v in watched])]
    h = float(spec.get("step_size", 1e-3))
    for i in range(int(spec.get("steps", 20))):
        for k, v in enumerate(inputs):
            slave.set_real([v["vr"]], [_input_value(v["name"], k, i + 1)])
        if not slave.do_step(i * h, h):
            return {"error": f"step {i} failed: {[m.msg for m in slave.log_queue]}"}
        rows.append(slave.get_real([v["vr"] for v in watched]))
    slave.terminate()
    return {"names": [v["name"] for v in watched], "rows": rows}


def main(argv: list[str]) -> int:
    unzipped, spec = Path(argv[1]), json.loads(Path(argv[2]).read_text())
    blocker = None
    if len(argv) > 3 and argv[3] == "--block":
        blocker = Blocker(set(argv[4].split(",")))
        sys.meta_path.insert(0, blocker)
    result = run(unzipped, spec)
    if blocker is not None:
        result["blocked_attempts"] = blocker.attempts
        result["blocked_loaded"] = sorted(m for m in sys.modules if m.split(".", 1)[0] in blocker.names)
    result["modules"] = len(sys.modules)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
