"""Where a scenario and its FMUs are found: scenario names resolve to ``ssp/<name>/`` of the project;
FMUs that a folder's SSD references as ``resources/<Model>.fmu`` are looked up in the folder's
``resources/`` first, then in the directories of ``IPCOSIM_FMU_PATH`` and ``build/fmus/``.
"""
from __future__ import annotations

import os
from pathlib import Path, PurePosixPath
from typing import Sequence

from ipcosim.errors import closest
from ipcosim.harness.scenario.errors import ScenarioNotFoundError
from ipcosim.harness.scenario.files import SSD_NAME, ScenarioFiles
from ipcosim.harness.support.paths import BUILD_FMU_DIR, SCENARIO_DIR


# --------------------------------------------------------------------------- resolution
def scenario_names(root: Path = SCENARIO_DIR) -> list[str]:
    """Names of the project's scenarios (folders of ``ssp/`` holding a SystemStructure.ssd)."""
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if (p / SSD_NAME).is_file())


def resolve_location(scenario_or_path: str | os.PathLike[str]) -> Path:
    """The scenario folder or ``.ssp`` archive that a scenario name or path refers to.

    A path (anything with a separator, an ``.ssp``/``.ssd`` suffix, or an existing file or
    folder) is taken as is; a bare name is looked up in the project's ``ssp/`` folder.

    Raises
    ------
    ScenarioNotFoundError
        Naming what was looked for, and the known scenarios.
    """
    text = os.fspath(scenario_or_path)
    path = Path(text)
    looks_like_path = (os.sep in text or "/" in text or path.suffix in (".ssp", ".ssd") or path.exists())
    if looks_like_path:
        if path.is_file() and path.suffix == ".ssd":
            return path.parent
        if path.exists():
            if path.is_dir() and not (path / SSD_NAME).is_file():
                raise ScenarioNotFoundError(f"{text}: folder has no {SSD_NAME}")
            return path
        raise ScenarioNotFoundError(f"scenario path {text!r} does not exist")
    candidate = SCENARIO_DIR / text
    if (candidate / SSD_NAME).is_file():
        return candidate
    raise ScenarioNotFoundError(f"unknown scenario {text!r}; {closest(text, scenario_names(), listing=20)} "
                                f"(`ipcosim list` describes them)")


def fmu_search_path(extra: Sequence[str | os.PathLike[str]] | None = None) -> list[Path]:
    """Directories searched for an FMU a folder scenario does not carry itself: ``extra``, then
    ``IPCOSIM_FMU_PATH`` (os.pathsep-separated), then ``build/fmus`` and ``build/fmus-clocked``."""
    dirs = [Path(d) for d in (extra or [])]
    env = os.environ.get("IPCOSIM_FMU_PATH", "")
    dirs += [Path(d) for d in env.split(os.pathsep) if d]
    dirs.append(BUILD_FMU_DIR)
    dirs.append(BUILD_FMU_DIR.parent / "fmus-clocked")  # the clocked controllers (`ipcosim build --native --fmi 3`)
    return dirs


def resolve_fmu(source: str, src: ScenarioFiles, fmu_dirs: Sequence[Path]) -> Path | None:
    """File of a component's FMU, or None if it cannot be found."""
    if source.startswith("file:"):
        from urllib.parse import unquote, urlparse

        p = Path(unquote(urlparse(source).path))
        return p if p.is_file() else None
    rel = PurePosixPath(source)
    if src.is_archive:
        return None  # archive members are extracted on preparation (see ipcosim.prepare)
    direct = src.location / Path(*rel.parts)
    if direct.is_file():
        return direct.resolve()
    for d in fmu_dirs:
        cand = d / rel.name
        if cand.is_file():
            return cand.resolve()
    return None


