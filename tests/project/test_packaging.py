"""The wheel carries every module and data file the package needs (the packages are listed by hand in
pyproject.toml, because the repository root is the package's folder)."""
from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
OUTSIDE = {"tests", "benchmarks", "examples", "build", "out", "tools", "docs", "ssp", "evidence", "devtools"}


def _config() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def test_every_subpackage_is_listed() -> None:
    listed = set(_config()["packages"])
    found = {"ipcosim"}
    for init in ROOT.rglob("__init__.py"):
        rel = init.parent.relative_to(ROOT)
        if rel.parts and (rel.parts[0] in OUTSIDE or rel.parts[0].startswith(".")):
            continue
        found.add(".".join(("ipcosim", *rel.parts)))
    assert found - listed == set(), f"packages missing from pyproject.toml: {sorted(found - listed)}"
    # a folder of data only (no __init__.py, no module) is listed as a package so that the build takes it as it
    # is: setuptools warns, at every install, of an importable folder it is not told about
    data_only = {name for name in listed - found if _folder(name).is_dir() and not any(_folder(name).glob("*.py"))}
    assert listed - found - data_only == set(), f"listed packages that do not exist: {sorted(listed - found)}"


def test_every_folder_of_package_data_is_a_listed_package() -> None:
    """Package data sits in its own package's folder, never in a subfolder of another's (which setuptools warns
    is an importable package it was not told about)."""
    listed = set(_config()["packages"])
    for pkg, patterns in _config()["package-data"].items():
        assert pkg in listed, f"package data of {pkg}, which is not a listed package"
        for pattern in patterns:
            for match in _folder(pkg).glob(pattern):
                rel = match.parent.relative_to(ROOT)
                inner = ".".join(("ipcosim", *rel.parts))
                assert inner == pkg or any(not part.isidentifier() for part in rel.parts), \
                    f"{match.relative_to(ROOT)}: package data of {pkg} in the importable folder {inner}: list it"


def _folder(package: str) -> Path:
    return ROOT.joinpath(*package.split(".")[1:])


def test_every_non_python_file_the_code_reads_is_package_data() -> None:
    """The native FMUs' hand-written C glue is copied from the package at build time."""
    data = _config()["package-data"]
    patterns = [(pkg, pat) for pkg, pats in data.items() for pat in pats]
    needed = sorted(p.relative_to(ROOT) for p in (ROOT / "harness" / "native" / "c").iterdir() if p.is_file())
    assert needed
    for rel in needed:
        covered = False
        for pkg, pat in patterns:
            base = ROOT.joinpath(*pkg.split(".")[1:])
            covered |= any(match == ROOT / rel for match in base.glob(pat))
        assert covered, f"{rel} is not package data: a wheel would lack it"


@pytest.mark.integration
@pytest.mark.slow
def test_the_wheel_holds_the_kit_not_the_evidence_or_the_tooling(tmp_path) -> None:
    """The built wheel: the package's modules under ``ipcosim/`` only, none of the thesis's evidence
    (``evidence/``), the repository's tooling (``devtools/``) or their former places in the package."""
    import shutil
    import subprocess
    import sys
    import zipfile

    # from a copy without the checkout's generated folders: setuptools reuses a build/lib left by an earlier
    # build, which may still hold modules the sources no longer have
    src = tmp_path / "src"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".git", ".venv", "build", "out", "tools", "*.egg-info"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-q",
                    "-w", str(tmp_path)], check=True, capture_output=True)
    wheel = next(tmp_path.glob("ipcosim-*.whl"))
    names = [n for n in zipfile.ZipFile(wheel).namelist() if n.endswith(".py")]
    assert names and all(n.startswith("ipcosim/") for n in names), [n for n in names if not n.startswith("ipcosim/")]
    moved = ("ipcosim/evidence/", "ipcosim/devtools/", "ipcosim/harness/evidence/", "ipcosim/harness/cli/apidoc.py",
             "ipcosim/harness/scenario/ssp_gen.py")
    assert not [n for n in names if n.startswith(moved)]
    assert "ipcosim/harness/studies/report.py" in names and "ipcosim/harness/scenario/scenarios.py" in names
