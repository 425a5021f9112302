"""pythonfmu's wrapper binary: the pinned version is checked and every FMU carries the patched binary."""
from __future__ import annotations

import hashlib
import zipfile
from pathlib import Path

import pytest

from ipcosim.fmus import wrapper
from ipcosim.fmus.pybuild import BuildError, build_one

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def original() -> bytes:
    return wrapper.check_pythonfmu().read_bytes()


def test_patch_changes_exactly_the_two_documented_sites(original: bytes) -> None:
    patched = wrapper.patch_binary(original)
    changed = [k for k, (a, b) in enumerate(zip(original, patched)) if a != b]
    assert len(patched) == len(original)
    sites = []
    for site in wrapper._SITES:
        at = wrapper._symbol_offset(original, site.symbol) + site.offset
        sites += [at + k for k in range(len(site.old)) if site.old[k] != site.new[k]]
    assert changed == sorted(sites)
    # finalizePythonInterpreter now returns at once (after its endbr64)
    at = wrapper._symbol_offset(original, b"finalizePythonInterpreter")
    assert patched[at:at + 5] == bytes.fromhex("f30f1efac3")
    assert wrapper.patch_binary(patched) == patched  # applying it again changes nothing


def test_a_different_binary_is_refused_naming_the_pinned_version(original: bytes) -> None:
    other = bytearray(original)
    other[100] ^= 0xFF
    with pytest.raises(wrapper.WrapperError, match=r"not pythonfmu 0\.7\.0's libpythonfmu-export\.so"):
        wrapper.patch_binary(bytes(other))


def test_another_pythonfmu_version_fails_the_build_in_one_line(monkeypatch, tmp_path: Path) -> None:
    import pythonfmu

    monkeypatch.setattr(pythonfmu, "__version__", "0.6.9")
    script = ROOT / "controllers" / "fmu_setpoint.py"
    with pytest.raises(BuildError) as info:
        build_one(script, tmp_path)
    message = str(info.value)
    assert "\n" not in message and "fmu_setpoint.py" in message
    assert "pythonfmu 0.6.9 is installed" in message and "pythonfmu==0.7.0" in message
    assert not list(tmp_path.iterdir())


@pytest.mark.integration
def test_built_fmus_carry_the_patched_linux_binary_and_the_shipped_windows_one(plant_fmus, original) -> None:
    shipped_dll = (wrapper.check_pythonfmu().parents[1] / "win64" / "pythonfmu-export.dll").read_bytes()
    for fmu in plant_fmus.values():
        with zipfile.ZipFile(fmu) as z:
            linux = z.read(f"binaries/linux64/{fmu.stem}.so")
            windows = z.read(f"binaries/win64/{fmu.stem}.dll")
        assert hashlib.sha256(linux).hexdigest() == wrapper._PATCHED_SHA256
        assert linux == wrapper.patch_binary(original)
        assert windows == shipped_dll



#: What one instantiate-and-free cycle of a Python FMU may leave behind in its host's Python heap, beyond
#: what the host leaves for any FMU (fmpy keeps some bytes per cycle of a C FMU too).
CYCLE_BYTES = 250


def _cycles(fmu: Path) -> dict[str, float]:
    """``tests/hosts/fmpy_instance_cycles.py`` on ``fmu``: 50 cycles of warm-up, 300 measured."""
    import json
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, str(ROOT / "tests" / "hosts" / "fmpy_instance_cycles.py"), str(fmu),
                           "50", "300"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def host_own_cycle(tmp_path_factory: pytest.TempPathFactory) -> dict[str, float]:
    """The same host's cycles on a small C FMU (``tests/cfmu.py``): what fmpy itself keeps per cycle."""
    import cfmu

    return _cycles(cfmu.build(cfmu.counter(), tmp_path_factory.mktemp("cfmu")))


@pytest.fixture(scope="module")
def cycled_fmus(plant_fmus, project_fmus) -> dict[str, Path]:
    """A plant and a controller (Python flavour), of this run's build."""
    return {"IP02SingleMass": plant_fmus["single-mass"],
            "LQRSingleMass": project_fmus["controllers/fmu_lqr_single_mass.py"]}


#: A host that instantiates an FMU twice, then prints which strings an instantiation interns are not interned
#: (alive) any more: the identifiers and identifier-like string constants of the module file the wrapper compiles
#: at every instantiation, and the FMU's private package name (``pathlib`` interns each part of a path).
INTERNED_HOST = r"""
import io, json, sys, tempfile, tokenize, zipfile, ast
from pathlib import Path
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave
fmu = sys.argv[1]
md = read_model_description(fmu)
unzip = tempfile.mkdtemp()
zipfile.ZipFile(fmu).extractall(unzip)
for k in range(2):
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName=f"i{k}")
    s.instantiate(); s.setupExperiment(startTime=0.0); s.enterInitializationMode(); s.exitInitializationMode()
    s.terminate(); s.freeInstance()
resources = Path(unzip) / "resources"
module = (resources / "slavemodule.txt").read_text().strip()
words = {p.name for p in resources.iterdir() if p.is_dir() and p.name.startswith("_ipcosim_")}
for tok in tokenize.generate_tokens(io.StringIO((resources / (module + ".py")).read_text()).readline):
    if tok.type == tokenize.NAME:
        words.add(tok.string)
    elif tok.type == tokenize.STRING:
        value = ast.literal_eval(tok.string)
        if isinstance(value, str) and value.isidentifier():
            words.add(value)
fresh = {w: "".join(list(w)) for w in words}   # new string objects, interned by nothing
print(json.dumps(sorted(w for w, copy in fresh.items() if sys.intern(copy) is copy)))
import shutil; shutil.rmtree(unzip, ignore_errors=True)
"""


@pytest.mark.integration
@pytest.mark.parametrize("model", ("IP02SingleMass", "LQRSingleMass"))
def test_an_instantiation_interns_no_string_it_then_frees(model: str, cycled_fmus) -> None:
    """Compiling the wrapper's module file and the FMU's paths intern strings; one that nothing keeps alive is made
    and freed again at every instantiation, and each time takes a new entry of the interpreter's table of interned
    strings (a deleted entry is reclaimed only when the table is resized): a host instantiating again and again
    resized that table (0.5-1 MB) every few thousand instantiations and doubled it once, within its first 2,000
    (the private package name was interned and freed three times an instantiation)."""
    import json
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-c", INTERNED_HOST, str(cycled_fmus[model])], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == [], "interned at each instantiation, then freed"


@pytest.mark.integration
@pytest.mark.parametrize("model", ("IP02SingleMass", "LQRSingleMass"))
@pytest.mark.slow
def test_instantiate_and_free_again_and_again_gives_back_what_it_takes(model: str, cycled_fmus,
                                                                       host_own_cycle) -> None:
    """pythonfmu 0.7.0's wrapper evaluates the FMU module again at every instantiation and kept every class that
    made (ipcosim.fmus.wrapper, section 3): 8.5-8.7 KB of the Python heap per cycle, in this host, before the module
    stub; the sys.path string it inserts and keeps a reference to (ipcosim.fmus.fmi_fixes.one_path_entry) about 80 B."""
    measured = _cycles(cycled_fmus[model])
    own = measured["traced_per_cycle"] - host_own_cycle["traced_per_cycle"]
    print(f"{model}: {measured}; the host with a C FMU: {host_own_cycle}; the FMU's own {own:.0f} B per cycle")
    assert own <= CYCLE_BYTES, f"{model}: {own:.0f} B of the host's Python heap per cycle"
