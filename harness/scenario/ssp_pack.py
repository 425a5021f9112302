"""Packs the scenarios of ``ssp/`` into ``<out>/ssp/<scenario>.ssp`` archives that carry their
FMUs (``resources/<Model>.fmu``, from ``<out>/fmus``), so that any SSP tool can run them.
``ipcosim build`` calls :func:`pack_all`. The archives are SSP 1.0 documents, as the scenarios are
written; ``ssp_version="2.0"`` (``ipcosim build --ssp-version 2.0``) declares SSP 2.0 in the SSD and
its parameter files instead, each checked against the 2.0 schema before it is packed.
"""
from __future__ import annotations

import os
import sys
import zipfile
from pathlib import Path

from lxml import etree

from ipcosim.harness.scenario.files import NS, SSD_NAME, parse_xml
from ipcosim.harness.scenario.locations import scenario_names
from ipcosim.harness.scenario.ssp import load_scenario
from ipcosim.harness.support.paths import SCENARIO_DIR

#: The SSP versions an archive can declare (``ipcosim build --ssp-version``).
SSP_VERSIONS = ("1.0", "2.0")
_SCHEMA_OF = {".ssd": "SystemStructureDescription.xsd", ".ssv": "SystemStructureParameterValues.xsd"}


def pack(scenario_dir: Path, fmu_dir: Path, target: Path, ssp_version: str = "1.0") -> Path:
    """Pack one scenario folder into ``target`` (written atomically), its SSD and parameter files
    declaring ``ssp_version``.

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
            if ssp_version != "1.0" and path.suffix in _SCHEMA_OF:
                zf.writestr(name, as_version(path.read_bytes(), ssp_version, f"{path} (as SSP {ssp_version})",
                                             _SCHEMA_OF[path.suffix]))
            else:
                zf.write(path, name)
    os.replace(tmp, target)
    return target


def as_version(data: bytes, ssp_version: str, display: str, schema_file: str) -> bytes:
    """An SSD or SSV document declaring SSP ``ssp_version`` (its root and every parameter set it
    holds), checked against that version's schema."""
    root = etree.fromstring(data)
    root.set("version", ssp_version)
    for pset in root.iter(f"{{{NS['ssv']}}}ParameterSet"):
        pset.set("version", ssp_version)
    text = etree.tostring(root, xml_declaration=True, encoding="UTF-8")
    parse_xml(text, display, schema_file)
    return text


def archive_version(target: Path) -> str | None:
    """The SSP version the SSD of archive ``target`` declares (None if it cannot be read)."""
    try:
        with zipfile.ZipFile(target) as zf:
            return etree.fromstring(zf.read(SSD_NAME)).get("version")
    except (OSError, KeyError, zipfile.BadZipFile, etree.XMLSyntaxError):
        return None


def up_to_date(scenario_dir: Path, fmu_dir: Path, target: Path, ssp_version: str = "1.0") -> bool:
    """Whether the archive ``target`` declares ``ssp_version`` and is newer than every file
    :func:`pack` would put in it."""
    if not target.is_file() or archive_version(target) != ssp_version:
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


def pack_all(out: Path | str = "build", root: Path = SCENARIO_DIR, ssp_version: str = "1.0") -> list[Path]:
    """Pack every scenario of ``root`` into ``<out>/ssp/<name>.ssp`` with the FMUs of ``<out>/fmus``,
    as SSP ``ssp_version`` documents (1.0 or 2.0).

    A scenario whose FMUs are not built is skipped with a note on stderr; an archive newer than
    every file it holds is left as it is. Returns the archives written.
    """
    out = Path(out)
    written = []
    for name in scenario_names(root):
        target = out / "ssp" / f"{name}.ssp"
        try:
            if not up_to_date(root / name, out / "fmus", target, ssp_version):
                written.append(pack(root / name, out / "fmus", target, ssp_version))
        except FileNotFoundError as exc:
            print(f"skipped {name}.ssp: {exc}", file=sys.stderr)
    return written
