"""A command that wrote nothing into the output folder it claimed (refused, failed or stopped first) leaves no
folder of its own and no claim file behind; a folder that was there, or anything written, stays."""
from __future__ import annotations

import os
import time
from pathlib import Path

from ipcosim.harness.master.results import COMMAND_FILE, LOCK_FILE, abandon_outputs, claim_output, release_output


def test_folders_the_claim_made_go_when_nothing_was_written(tmp_path: Path) -> None:
    out = tmp_path / "a" / "b" / "c"
    claim_output(out, "identify")
    assert sorted(os.listdir(out)) == sorted([COMMAND_FILE, LOCK_FILE])
    assert abandon_outputs() == [out, tmp_path / "a" / "b", tmp_path / "a"]
    assert sorted(os.listdir(tmp_path)) == []  # tmp_path was there before: it stays
    claim_output(out, "sweep")  # released: the folder can be claimed again, of another kind even
    release_output(out)


def test_a_folder_that_was_there_keeps_what_it_held_and_loses_only_the_claims_files(tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    old = time.time() - 60
    os.utime(mine / "notes.txt", (old, old))
    claim_output(mine, "identify")
    assert abandon_outputs() == []
    assert sorted(os.listdir(mine)) == ["notes.txt"] and (mine / "notes.txt").read_text() == "mine"


def test_a_folder_the_command_wrote_into_keeps_everything(tmp_path: Path) -> None:
    out = tmp_path / "run"
    claim_output(out, "run")
    (out / "results.csv").write_text("time\n0.0\n")  # results so far
    assert abandon_outputs() == []
    assert sorted(os.listdir(out)) == sorted(["results.csv", COMMAND_FILE, LOCK_FILE])
    # a file there before but rewritten by the command counts as written
    again = tmp_path / "again"
    again.mkdir()
    (again / "identified.png").write_text("old")
    os.utime(again / "identified.png", (time.time() - 60,) * 2)
    claim_output(again, "identify")
    (again / "identified.png").write_text("new")
    assert abandon_outputs() == [] and (again / COMMAND_FILE).exists()
    release_output(out)
    release_output(again)
