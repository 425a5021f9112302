"""The wheel carries every module and data file the package needs (the packages are listed by hand in
pyproject.toml, because the repository root is the package's folder)."""
from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUTSIDE = {"tests", "benchmarks", "examples", "build", "out", "tools", "docs", "ssp"}


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
    assert listed - found == set(), f"listed packages that do not exist: {sorted(listed - found)}"


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
