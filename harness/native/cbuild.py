"""``ipcosim build --native``: every plant, controller and the setpoint as an FMI 2.0 source-code FMU.

Each ``<Model>.fmu`` holds ``sources/`` (the generated ``model.c``, the shared ``fmi2glue.c``,
``fmi2shared.h`` and ``model.h``, the FMI 2.0 headers) listed in the model description's
``<SourceFiles>``, and, where a C compiler is found (``$CC``, ``cc``, ``gcc``, ``clang``),
``binaries/linux64/<Model>.so`` compiled with ``-std=c99 -Wall -Wextra -pedantic -Werror``. The
variables are read from the Python flavour's FMU in ``python_dir`` (built first), so names, value references, units and
start values are the same.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

from ipcosim.harness.native import cgen, models
from ipcosim.toolchain import find_compiler

C_DIR = Path(__file__).resolve().parent / "c"
#: The hand-written glue every native FMU carries (``fmi2shared.h``: what it shares with the loop container).
GLUE_FILES = ("fmi2glue.c", "model.h", "fmi2shared.h")
FLAGS = ("-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2", "-fPIC", "-shared")
FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
PLANTS = {"IP02SingleMass": "single-mass", "IP02DoubleMass": "double-mass"}


class NativeBuildError(RuntimeError):
    """A native FMU could not be generated or compiled (names the model)."""


@dataclass(frozen=True)
class NativeResult:
    """One native FMU: its file and whether a binary is inside."""

    fmu: Path
    binary: bool


def model_names() -> list[str]:
    """Every model with a native flavour."""
    from ipcosim.controllers.catalog import model_name
    return [*PLANTS, *(model_name(kind, law) for law, kind in _laws()), "Setpoint"]


def _laws() -> list[tuple[str, str]]:
    """(law, plant kind) of every controller FMU: ``catalog.LAWS`` on both plants, and the swing-up."""
    from ipcosim.controllers.catalog import KINDS, LAWS, PARAMETER_SETS
    return [(law, kind) for law in (*LAWS, *(la for la in PARAMETER_SETS if la not in LAWS)) for kind in KINDS
            if kind in PARAMETER_SETS[law]]


def native_model(name: str, python_dir: Path) -> models.NativeModel:
    """Trace the model ``name`` from its Python definition (its Python FMU must be in ``python_dir``)."""
    from ipcosim.controllers.catalog import model_name

    fmu = Path(python_dir) / f"{name}.fmu"
    if not fmu.is_file():
        raise NativeBuildError(f"{name}: the Python flavour {fmu} is missing (run `ipcosim build` first)")
    if name in PLANTS:
        return models.plant_model(name, PLANTS[name], fmu)
    if name == "Setpoint":
        return models.setpoint_model(fmu)
    for law, kind in _laws():
        if model_name(kind, law) == name:
            return models.law_model(kind, law, fmu)
    raise NativeBuildError(f"no native model named {name!r}")


def fmi_header_dir() -> Path:
    """The FMI 2.0 headers shipped with fmpy."""
    import fmpy
    return Path(fmpy.__file__).parent / "c-code"


def write_sources(model: models.NativeModel, dest: Path) -> tuple[list[str], str]:
    """Write ``sources/`` for ``model`` into ``dest``; returns (listed C files, GUID)."""
    dest.mkdir(parents=True, exist_ok=True)
    text, gid = cgen.model_c(model)
    (dest / "model.c").write_text(text)
    for name in GLUE_FILES:
        shutil.copy(C_DIR / name, dest / name)
    for name in FMI_HEADERS:
        shutil.copy(fmi_header_dir() / name, dest / name)
    return ["model.c", "fmi2glue.c"], gid


def compile_sources(sources: Path, files: list[str], out: Path, cc: str, flags: tuple[str, ...] = FLAGS) -> None:
    """Compile ``files`` in ``sources`` into the shared library ``out``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = [cc, *flags, "-I", str(sources), *(str(sources / f) for f in files), "-o", str(out), "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0 or proc.stderr.strip():
        raise NativeBuildError(f"{out.stem}: {Path(cc).name} failed on the generated sources:\n{proc.stderr.strip()}")


def build_one(name: str, python_dir: Path, out_dir: Path, cc: str | None) -> NativeResult:
    """Generate, compile and pack ``<out_dir>/<name>.fmu``."""
    from ipcosim.harness.native.tracer import reset_table

    reset_table()
    model = native_model(name, python_dir)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        files, gid = write_sources(model, root / "sources")
        (root / "modelDescription.xml").write_bytes(cgen.model_description(model, gid, files))
        if cc:
            compile_sources(root / "sources", files, root / "binaries" / "linux64" / f"{name}.so", cc)
        (root / "resources").mkdir()
        (root / "resources" / "native.json").write_text(json.dumps(
            {"model": name, **model.meta, "paths": model.paths, "python_only": model.python_only}, indent=1))
        (root / "documentation").mkdir()
        (root / "documentation" / "native.txt").write_text(_readme(model))
        out_dir.mkdir(parents=True, exist_ok=True)
        target = out_dir / f"{name}.fmu"
        tmp_fmu = target.with_suffix(".fmu.tmp")
        with zipfile.ZipFile(tmp_fmu, "w", zipfile.ZIP_DEFLATED) as z:
            for path in sorted(root.rglob("*")):
                if path.is_file():
                    z.write(path, path.relative_to(root).as_posix())
        tmp_fmu.replace(target)
    reset_table()
    return NativeResult(target, cc is not None)


def _readme(model: models.NativeModel) -> str:
    lines = [f"{model.name} (native flavour), generated by ipcosim.fmus.native from the Python model.",
             "Compile: cc -std=c99 -shared -fPIC -I sources sources/model.c sources/fmi2glue.c -lm", ""]
    if model.python_only:
        lines.append("Parameters of the Python flavour this flavour lacks (design-only; redesign with "
                     "ipcosim.fmus.native.redesign): " + ", ".join(model.python_only))
    return "\n".join(lines) + "\n"


def build_native(python_dir: Path | str, out_dir: Path | str, names: list[str] | None = None) -> list[NativeResult]:
    """Build the native FMUs (all of ``model_names()`` by default) into ``out_dir``.

    Without a C compiler the FMUs carry their sources only, and a message on stderr says so.
    """
    cc = find_compiler()
    if cc is None:
        print("ipcosim build --native: no C compiler found (set CC, or install gcc or clang): the native FMUs "
              "carry their C sources but no linux64 binary", file=sys.stderr)
    return [build_one(n, Path(python_dir), Path(out_dir), cc) for n in (names or model_names())]
