"""``ipcosim build --native``: every plant, controller and the setpoint as a source-code FMU.

Each ``<Model>.fmu`` holds ``sources/`` (the generated ``model.c``, the shared ``fmi2glue.c``,
``fmi2shared.h`` and ``model.h``, the FMI headers) and a binary for every platform of
:data:`TARGETS` whose compiler is found: ``linux64/<Model>.so`` (a C compiler: ``$CC``, ``cc``,
``gcc``, ``clang``), ``win64/<Model>.dll`` (mingw-w64) and ``aarch64-linux/<Model>.so`` (Debian's
aarch64 GNU/Linux compiler; ``toolchain.find_cross_compiler``), all compiled from the same files
with the same flags (``-std=c99 -Wall -Wextra -pedantic -Werror -O2 -ffp-contract=off``). Two FMI
versions, one generator (:data:`VARIANTS`): FMI 2.0 lists its C files in the model description's
``<SourceFiles>``; FMI 3.0 (``--fmi 3``) adds ``fmi3glue.c`` (the FMI 3.0 functions over the
FMI 2.0 glue, ``fmi3adapter.h``), lists them in ``sources/buildDescription.xml`` and derives its
model description from the FMI 2.0 one (``fmi3.model_description``). The variables are read
from the Python flavour's FMU in ``python_dir`` (built first), so names, value references,
units and start values are the same.
"""
from __future__ import annotations

import json
import shutil
import sys
import tempfile
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path

from ipcosim.errors import IpcosimError
from ipcosim.fmus.kinds import PLANT_MODELS
from ipcosim.harness.native import cgen, fmi3, models
from ipcosim.toolchain import CROSS_COMPILERS, find_compiler, find_cross_compiler, run_compiler

C_DIR = Path(__file__).resolve().parent / "c"
#: The hand-written glue every native FMU carries (``fmi2shared.h``: what it shares with the loop container).
GLUE_FILES = ("fmi2glue.c", "model.h", "fmi2shared.h", "fmi2me.h")
#: The warnings and the floating-point flags every binary is compiled with (every platform alike).
#: Floating-point contraction off: no fused multiply-add where the source has a product and a sum
#: (aarch64 has the instruction, baseline x86-64 has not), so every platform rounds the same.
STRICT = ("-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2", "-ffp-contract=off")
FLAGS = (*STRICT, "-fPIC", "-shared")
#: The Windows DLL: the same flags (position-independent anyway), libgcc linked in (no DLL of it needed).
WIN_FLAGS = (*STRICT, "-shared", "-static-libgcc")
FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
FMI3_HEADERS = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")


@dataclass(frozen=True)
class Variant:
    """One FMI version of the native FMUs: the C file holding a single model's FMI functions
    (``fmi2glue.c``, or ``fmi3glue.c`` over it) and an exported loop's (``container.c``, or
    ``fmi3container.c`` over it), the files both need besides the FMI 2.0 glue, the FMI headers,
    and the binary folder per platform of :data:`TARGETS`."""

    fmi: str
    model_glue: str
    container_glue: str
    extra: tuple[str, ...]
    headers: tuple[str, ...]
    binaries: dict[str, str]


#: FMI 2.0 names x86 folders only (``linux64``: "64-bit x86"); since 2.0.4 (section 2.3) any other platform
#: takes its FMI 3.0 platform tuple, so the ARM library is in ``aarch64-linux`` in both variants.
VARIANTS = {
    "2": Variant("2", "fmi2glue.c", "container.c", (), FMI_HEADERS,
                 {"linux64": "linux64", "win64": "win64", "aarch64": "aarch64-linux"}),
    "3": Variant("3", "fmi3glue.c", "fmi3container.c", ("fmi3adapter.h", "fmi3me.h"), FMI_HEADERS + FMI3_HEADERS,
                 {"linux64": "x86_64-linux", "win64": "x86_64-windows", "aarch64": "aarch64-linux"}),
}
#: Where ``ipcosim build --native --fmi N`` writes (below the build folder).
OUT_DIRS = {"2": "fmus-native", "3": "fmus-native-fmi3"}


class NativeBuildError(IpcosimError, RuntimeError):
    """A native FMU could not be generated or compiled (names the model)."""


@dataclass(frozen=True)
class NativeResult:
    """One native FMU: its file, whether a binary is inside and for which platforms."""

    fmu: Path
    binary: bool
    platforms: tuple[str, ...] = ()


def model_names() -> list[str]:
    """Every model with a native flavour."""
    from ipcosim.controllers.catalog import model_name
    return [*PLANT_MODELS, *(model_name(kind, law) for law, kind in _laws()), "Setpoint"]


def _laws() -> list[tuple[str, str]]:
    """(law, plant kind) of every controller FMU with a native flavour, in the registry's order (the
    identification excitation has none: it looks its multisine up in a table indexed by the sample count,
    which the tracer cannot follow; it runs on the Python flavour)."""
    from ipcosim.controllers.catalog import KINDS, REGISTRY
    return [(law, kind) for law, e in REGISTRY.items() for kind in KINDS if kind in e.sets and e.native]


def native_model(name: str, python_dir: Path) -> models.NativeModel:
    """Trace the model ``name`` from its Python definition (its Python FMU must be in ``python_dir``)."""
    from ipcosim.controllers.catalog import model_name

    fmu = Path(python_dir) / f"{name}.fmu"
    if not fmu.is_file():
        raise NativeBuildError(f"{name}: the Python flavour {fmu} is missing (run `ipcosim build` first)")
    if name in PLANT_MODELS:
        return models.plant_model(name, PLANT_MODELS[name], fmu)
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


def copy_glue(dest: Path, files: tuple[str, ...], variant: Variant) -> None:
    """Copy the hand-written ``files`` (plus the variant's additions) and its FMI headers into ``dest``."""
    for name in dict.fromkeys((*files, *variant.extra)):
        shutil.copy(C_DIR / name, dest / name)
    for name in variant.headers:
        shutil.copy(fmi_header_dir() / name, dest / name)


def write_sources(model: models.NativeModel, dest: Path, variant: Variant = VARIANTS["2"]) -> tuple[list[str], str]:
    """Write ``sources/`` for ``model`` into ``dest``; returns (listed C files, GUID)."""
    dest.mkdir(parents=True, exist_ok=True)
    text, gid = cgen.model_c(model)
    (dest / "model.c").write_text(text)
    copy_glue(dest, (*GLUE_FILES, variant.model_glue), variant)
    return ["model.c", variant.model_glue], gid


def compile_sources(sources: Path, files: list[str], out: Path, cc: str, flags: tuple[str, ...] = FLAGS) -> None:
    """Compile ``files`` in ``sources`` into the shared library ``out``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = [cc, *flags, "-I", str(sources), *(str(sources / f) for f in files), "-o", str(out), "-lm"]
    proc = run_compiler(cmd)
    if proc.returncode != 0 or proc.stderr.strip():
        raise NativeBuildError(f"{out.stem}: {Path(cc).name} failed on the generated sources:\n{proc.stderr.strip()}")


@dataclass(frozen=True)
class Target:
    """One platform the native FMUs carry a binary for: its library's suffix, the compiler flags,
    and the line saying what is missing when its compiler is."""

    platform: str
    suffix: str
    flags: tuple[str, ...]
    missing: str


def _no_cross(platform: str, compiler: str, left: str) -> str:
    variable, _, package = CROSS_COMPILERS[platform]
    return (f"no {compiler} cross compiler found (set {variable}, or install Debian's {package}): "
            f"no {platform} binary, {left}")


#: Every platform, in build order; its binary folder per FMI version is in :data:`VARIANTS`.
TARGETS = (
    Target("linux64", ".so", FLAGS, "no C compiler found (set CC, or install gcc or clang): no linux64 binary"),
    Target("win64", ".dll", WIN_FLAGS, _no_cross("win64", "mingw-w64", "Linux only")),
    Target("aarch64", ".so", FLAGS, _no_cross("aarch64", "aarch64", "x86-64 only")),
)


@dataclass(frozen=True)
class Compilers:
    """The compiler found for each platform of :data:`TARGETS` (None where there is none):
    ``linux64`` the system C compiler, ``win64`` mingw-w64, ``aarch64`` the ARM GNU/Linux compiler."""

    linux64: str | None
    win64: str | None
    aarch64: str | None = None

    @classmethod
    def find(cls) -> "Compilers":
        """The compilers on this machine (``toolchain.find_compiler``, ``find_cross_compiler``)."""
        return cls(find_compiler(), find_cross_compiler("win64"), find_cross_compiler("aarch64"))

    def with_linux64(self, cc: str | None) -> "Compilers":
        """These compilers with ``cc`` (if given) as the linux64 one."""
        return replace(self, linux64=cc or self.linux64)


def compile_binaries(root: Path, files: list[str], identifier: str, variant: Variant,
                     compilers: Compilers) -> list[str]:
    """Compile ``root/sources/files`` into ``root/binaries/<folder>/`` with every compiler in
    ``compilers``; returns the platforms built (of ``linux64``, ``win64``, ``aarch64``)."""
    built = []
    for target in TARGETS:
        cc = getattr(compilers, target.platform)
        if cc:
            out = root / "binaries" / variant.binaries[target.platform] / f"{identifier}{target.suffix}"
            compile_sources(root / "sources", files, out, cc, target.flags)
            built.append(target.platform)
    return built


def write_descriptions(root: Path, fmi2_description: bytes, identifier: str, files: list[str],
                       variant: Variant) -> None:
    """Write the FMU's description files: ``modelDescription.xml`` (FMI 2.0, or FMI 3.0 derived
    from it, with ``sources/buildDescription.xml``)."""
    if variant.fmi == "2":
        (root / "modelDescription.xml").write_bytes(fmi2_description)
        return
    (root / "modelDescription.xml").write_bytes(fmi3.model_description(fmi2_description))
    (root / "sources" / "buildDescription.xml").write_bytes(fmi3.build_description(identifier, files))


def pack(root: Path, target: Path) -> None:
    """Zip the folder ``root`` into the FMU ``target`` (written next to it, then moved in place)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp_fmu = target.with_suffix(".fmu.tmp")
    with zipfile.ZipFile(tmp_fmu, "w", zipfile.ZIP_DEFLATED) as z:
        for path in sorted(root.rglob("*")):
            if path.is_file():
                z.write(path, path.relative_to(root).as_posix())
    tmp_fmu.replace(target)


def build_one(name: str, python_dir: Path, out_dir: Path, compilers: Compilers,
              variant: Variant = VARIANTS["2"]) -> NativeResult:
    """Generate, compile and pack ``<out_dir>/<name>.fmu``."""
    from ipcosim.harness.native.tracer import reset_table

    reset_table()
    model = native_model(name, python_dir)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        files, gid = write_sources(model, root / "sources", variant)
        write_descriptions(root, cgen.model_description(model, gid, files), name, files, variant)
        platforms = compile_binaries(root, files, name, variant, compilers)
        (root / "resources").mkdir()
        (root / "resources" / "native.json").write_text(json.dumps(
            {"model": name, **model.meta, "paths": model.paths, "python_only": model.python_only}, indent=1))
        (root / "documentation").mkdir()
        (root / "documentation" / "native.txt").write_text(_readme(model, files))
        pack(root, out_dir / f"{name}.fmu")
    reset_table()
    return NativeResult(out_dir / f"{name}.fmu", bool(platforms), tuple(platforms))


def compile_line(files: list[str]) -> str:
    """The documentation's one line compiling ``files`` as the build does (on any platform)."""
    return ("Compile: cc -std=c99 -ffp-contract=off -shared -fPIC -I sources "
            + " ".join(f"sources/{f}" for f in files) + " -lm")


def _readme(model: models.NativeModel, files: list[str]) -> str:
    lines = [f"{model.name} (native flavour), generated by ipcosim.harness.native from the Python model.",
             compile_line(files), ""]
    if model.python_only:
        lines.append("Parameters of the Python flavour this flavour lacks (design-only; redesign with "
                     "ipcosim.harness.native.redesign): " + ", ".join(model.python_only))
    return "\n".join(lines) + "\n"


def missing_compilers(compilers: Compilers, what: str) -> list[str]:
    """One line per missing compiler, saying what ``what`` then lacks."""
    return [f"{what}: {t.missing}" for t in TARGETS if getattr(compilers, t.platform) is None]


def build_native(python_dir: Path | str, out_dir: Path | str, names: list[str] | None = None,
                 fmi: str = "2") -> list[NativeResult]:
    """Build the native FMUs (all of ``model_names()`` by default) into ``out_dir``, as FMI ``fmi``
    (``"2"`` or ``"3"``) co-simulation FMUs.

    A missing compiler is said in one line on stderr: without any, the FMUs carry their sources only.
    """
    compilers = Compilers.find()
    for line in missing_compilers(compilers, "ipcosim build --native"):
        print(line, file=sys.stderr)
    return [build_one(n, Path(python_dir), Path(out_dir), compilers, VARIANTS[fmi]) for n in (names or model_names())]
