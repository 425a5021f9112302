"""pythonfmu's wrapper binary: the pinned version is checked and every FMU carries the patched binary."""
from __future__ import annotations

import hashlib
import zipfile
from pathlib import Path

import pytest

from ipcosim.fmus import wrapper
from ipcosim.fmus.pybuild import BuildError, build_one

ROOT = Path(__file__).resolve().parents[1]


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
