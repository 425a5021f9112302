"""Packs the scenarios of ``ssp/`` into ``<out>/ssp/<scenario>.ssp`` archives that carry their
FMUs (``resources/<Model>.fmu``, from ``<out>/fmus``), so that any SSP tool can run them.
``ipcosim build`` calls :func:`pack_all`.
"""
from __future__ import annotations

import os
import sys
import zipfile
from pathlib import Path

from ipcosim.harness.paths import SCENARIO_DIR
from ipcosim.harness.scenario.ssp import SSD_NAME, load_scenario, scenario_names


def pack(scenario_dir: Path, fmu_dir: Path, target: Path) -> Path:
    """Pack one scenario folder into ``target`` (written atomically).

    Raises
    ------
    FileNotFoundError
        If an FMU the SSD references is not in ``fmu_dir`` (or the folder's resources/).
    """
    members = _members(scenario_dir, fmu_dir)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, path in members.items():
            zf.write(path, name)
    os.replace(tmp, target)
    return target


def up_to_date(scenario_dir: Path, fmu_dir: Path, target: Path) -> bool:
    """Whether the archive ``target`` is newer than every file :func:`pack` would put in it."""
    if not target.is_file():
        return False
    built = target.stat().st_mtime
    return all(p.stat().st_mtime <= built for p in _members(scenario_dir, fmu_dir).values())


def _members(scenario_dir: Path, fmu_dir: Path) -> dict[str, Path]:
    """Archive member name -> file: the SSD, its parameter files and the FMUs it references."""
    scenario = load_scenario(scenario_dir, fmu_dirs=[fmu_dir])
    members: dict[str, Path] = {SSD_NAME: scenario_dir / SSD_NAME}
    for f in sorted(scenario_dir.iterdir()):
        if f.is_file() and f.suffix == ".ssv":
            members[f.name] = f
    for comp in scenario.components:
        candidates = [scenario_dir / comp.source, fmu_dir / Path(comp.source).name]
        fmu = next((c for c in candidates if c.is_file()), None)
        if fmu is None:
            raise FileNotFoundError(f"{scenario.origin}: component {comp.name!r}: {Path(comp.source).name} "
                                    f"not found in {fmu_dir}")
        members[comp.source] = fmu
    return members


def pack_all(out: Path | str = "build", root: Path = SCENARIO_DIR) -> list[Path]:
    """Pack every scenario of ``root`` into ``<out>/ssp/<name>.ssp`` with the FMUs of ``<out>/fmus``.

    A scenario whose FMUs are not built is skipped with a note on stderr; an archive newer than
    every file it holds is left as it is. Returns the archives written.
    """
    out = Path(out)
    written = []
    for name in scenario_names(root):
        target = out / "ssp" / f"{name}.ssp"
        try:
            if not up_to_date(root / name, out / "fmus", target):
                written.append(pack(root / name, out / "fmus", target))
        except FileNotFoundError as exc:
            print(f"skipped {name}.ssp: {exc}", file=sys.stderr)
    return written
