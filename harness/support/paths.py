"""Where ipcosim finds its scenarios and puts what it builds.

Scenarios ship inside the package (``ipcosim/ssp``, package data). Built FMUs and SSP
archives go to ``build/`` of the source checkout when ipcosim runs from one (an editable
install: the package root holds ``pyproject.toml``), and otherwise to a per-user cache
folder, ``$XDG_CACHE_HOME/ipcosim/<version>`` (default ``~/.cache/ipcosim/<version>``), so
that an installed wheel never writes into site-packages.
"""
from __future__ import annotations

import functools
import os
import sys
from pathlib import Path

#: The ``ipcosim`` package folder (the source checkout in an editable install).
PACKAGE_ROOT = Path(__file__).resolve().parents[2]
#: The scenarios shipped with the package: one folder each.
SCENARIO_DIR = PACKAGE_ROOT / "ssp"


def in_checkout() -> bool:
    """True when ipcosim runs from its source checkout (``pyproject.toml`` beside the package)."""
    return (PACKAGE_ROOT / "pyproject.toml").is_file()


@functools.cache
def distribution_version() -> str:
    """The version of the installed ``ipcosim`` distribution (its metadata; ``"dev"`` when ipcosim runs
    from a folder no installation names): ``ipcosim --version``, ``metrics.json``'s ``ipcosim_version``."""
    found = _dist_info_version()
    if found is not None:
        return found
    from importlib import metadata  # 20-25 ms to import (a run's metrics.json asks for the version)

    try:
        return metadata.version("ipcosim")
    except metadata.PackageNotFoundError:
        return "dev"


def _dist_info_version() -> str | None:
    """The ``Version`` of the first ``ipcosim-*.dist-info`` on :data:`sys.path`, found as
    :mod:`importlib.metadata` finds it, without importing it; None where the first distribution
    found is of another form (an ``.egg-info``, one inside a zip file), or none is: the caller asks
    :mod:`importlib.metadata` then."""
    for entry in sys.path:
        try:
            names = os.listdir(entry or ".")
        except NotADirectoryError:
            return None  # a zip file on the path: importlib.metadata looks inside
        except OSError:
            continue
        for name in names:
            stem, _, suffix = name.lower().rpartition(".")
            if suffix not in ("dist-info", "egg-info") or stem.partition("-")[0] != "ipcosim":
                continue
            if suffix == "egg-info":
                return None
            try:
                with open(os.path.join(entry or ".", name, "METADATA"), encoding="utf-8") as fh:
                    for line in fh:
                        if line.startswith("Version:"):
                            return line.partition(":")[2].strip()
                        if not line.strip():
                            break  # the end of the headers
            except OSError:
                pass
            return None
    return None


def default_build_dir() -> Path:
    """The default output folder of ``ipcosim build`` (see the module docstring)."""
    if in_checkout():
        return PACKAGE_ROOT / "build"
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return cache / "ipcosim" / distribution_version()


def user_scenario_dir() -> Path:
    """The user's own scenario folder, ``$XDG_DATA_HOME/ipcosim/scenarios`` (default
    ``~/.local/share/ipcosim/scenarios``): where ``ipcosim tune --install`` puts a shipped
    scenario's copy with its tuned set when ipcosim is an installed wheel (never site-packages)."""
    data = Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share")
    return data / "ipcosim" / "scenarios"


BUILD_DIR = default_build_dir()
BUILD_FMU_DIR = BUILD_DIR / "fmus"
BUILD_SSP_DIR = BUILD_DIR / "ssp"
#: Compiled stepping loops (``loops/<hash>.so``; see :mod:`ipcosim.harness.master.cloop`).
LOOP_DIR = BUILD_DIR / "loops"
#: Compiled identification replays (``replay/<plant>-<hash>.so``; see :mod:`ipcosim.harness.native.replay`).
REPLAY_DIR = BUILD_DIR / "replay"
