"""tests/ is grouped by the room it tests: no test file at its top, every one in the folder
``devtools/test_rooms.py`` gives it (and that rule checked on made-up files), and
docs/architecture.md says where each room's tests are."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from devtools import test_rooms
from devtools.test_rooms import FOLDERS, OTHER, TESTS, folder_of, room_test_files

ROOT = Path(__file__).resolve().parents[2]


def test_no_test_file_at_the_top_of_tests() -> None:
    assert sorted(p.name for p in TESTS.glob("test_*.py")) == []


def test_every_test_file_is_in_a_room_folder() -> None:
    folders = {p.relative_to(TESTS).parts[0] for p in TESTS.rglob("test_*.py")}
    assert folders - set(OTHER) <= set(FOLDERS), folders - set(OTHER) - set(FOLDERS)
    assert len(room_test_files()) > 80       # the rule below sees the suite, not an empty list


def test_every_test_file_is_in_the_folder_of_its_room() -> None:
    wrong = [f"{p.relative_to(ROOT)}: belongs in tests/{folder_of(p)}/ (python -m devtools.test_rooms --move)"
             for p in room_test_files() if p.parent != TESTS / folder_of(p)]
    assert not wrong, wrong


def _made_up(tmp_path: Path, name: str, source: str) -> Path:
    path = tmp_path / name
    path.write_text(source)
    return path


@pytest.mark.parametrize(("name", "folder"), [
    ("test_hil_new_card.py", "hil"),             # a folder's own name
    ("test_sweep_resume_twice.py", "studies"),   # harness/studies/sweep.py
    ("test_plant_fmu_reset.py", "fmus"),         # fmus/plant_fmu.py, the longest run of words
    ("test_lqr_gains.py", "controllers"),        # controllers/laws/lqr.py, a room's sub-folder
    ("test_rig_watchdog.py", "hil"),             # fmus/hil/rig.py before fmus
    ("test_ssp_archive_errors.py", "scenario"),  # harness/scenario/ssp.py
    ("test_plot_axes.py", "api"),                # harness/api/plot.py, a top-level module of the harness
    ("test_ssp_gen_rows.py", "project"),         # devtools/ssp_gen.py (not harness/scenario/ssp.py)
    ("test_run_exit_status.py", "master"),       # harness/cli/run.py names no room: the imports decide
])
def test_a_file_goes_by_its_name_first(tmp_path: Path, name: str, folder: str) -> None:
    path = _made_up(tmp_path, name, "from ipcosim.harness.cli import main\n"
                                    "from ipcosim.harness.master.results import Result\n")
    assert folder_of(path) == folder


@pytest.mark.parametrize(("source", "folder"), [
    ("from ipcosim.fmus.physics import rhs\nfrom ipcosim.controllers.catalog import make_law\n"
     "def f():\n    from ipcosim.controllers.laws.lqr import LQR\n", "controllers"),   # 2 against 1
    ("import ipcosim\nfrom ipcosim.harness.cli import main\n", "api"),       # the ways in only: 1 against 1, api first
    ("from ipcosim.harness.cli import main\nfrom ipcosim.harness.cli import run\n"
     "from ipcosim.harness.studies.store import read_results\n", "studies"),  # the ways in count for nothing then
    ("from ipcosim.harness import cli\n", "cli"),
    ("from ipcosim.fmus.hil.rig import VirtualRig\nfrom ipcosim.fmus.plant import Plant\n", "hil"),  # a tie: hil first
    ('MODULE = "ipcosim.harness.native.cbuild"\n', "native"),              # a module named in a string
    ("from ipcosim.errors import IpcosimError\nfrom evidence.claims import CLAIMS\n", "evidence"),  # errors: none
    ("import json\n", "project"),
])
def test_an_unnamed_file_goes_by_its_imports(tmp_path: Path, source: str, folder: str) -> None:
    assert folder_of(_made_up(tmp_path, "test_zz_qq.py", source)) == folder


def test_the_command_says_where_a_file_belongs_and_fails_on_one_elsewhere(tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    assert test_rooms.main([str(Path(__file__))]) == 0
    assert capsys.readouterr().out == "tests/project/test_tests_by_room.py -> tests/project/\n"
    stray = _made_up(tmp_path, "test_hil_stray.py", "import json\n")
    assert test_rooms.main([str(stray)]) == 1
    assert capsys.readouterr().out == f"{stray} -> tests/hil/ (not there)\n"


def test_the_architecture_page_says_where_each_rooms_tests_are() -> None:
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    named = set(re.findall(r"`tests/(\w+)/`", text))
    assert set(FOLDERS) | {"conformance"} <= named, set(FOLDERS) - named
    assert named <= set(FOLDERS) | set(OTHER), named - set(FOLDERS) - set(OTHER)
