"""``make bench`` is honest: every module runs and prints, a missed target or a module that cannot run
its subject makes the exit status 1, and the figures land in ``benchmarks/last.json``
(``benchmarks.targets``)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _bench(tmp_path: Path, body: str, name: str) -> subprocess.CompletedProcess:
    """Run benchmarks.bench on a copy of its runner with one fake bench module."""
    pkg = tmp_path / "benchmarks"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    for module in ("bench.py", "targets.py"):
        (pkg / module).write_text((ROOT / "benchmarks" / module).read_text())
    (pkg / f"bench_{name}.py").write_text(body)
    return subprocess.run([sys.executable, "-m", "benchmarks.bench"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=60)


@pytest.mark.slow
def test_missed_target_fails_after_printing_everything(tmp_path):
    _bench(tmp_path, "from benchmarks.targets import target\n"
                     "def run():\n    return ['fast ' + target('a.speed', 2.0, 1.0, 'x', what='a speed'),\n"
                     "            'last line']\n", "a_slow")
    proc = _bench(tmp_path, "from benchmarks.targets import figure, target\n"
                            "def run():\n    return ['ok ' + target('b.ratio', 0.5, 1.0, 'x', what='b ratio'),\n"
                            "            'ref ' + figure('b.lib', 3.0, 'us', anchor='their floor',\n"
                            "                            what='b lib')]\n", "b_fine")
    assert proc.returncode == 1, proc.stdout
    out = proc.stdout
    assert "fast target <= 1x: MISSED" in out and "last line" in out and "ok target <= 1x: met" in out
    assert "TARGET MISSED: a speed (a.speed): 2x, target <= 1x" in out and "ref 3 us" in out
    assert out.index("== benchmarks.bench_b_fine") < out.rindex("bench: targets missed in benchmarks.bench_a_slow")
    last = json.loads((tmp_path / "benchmarks" / "last.json").read_text())["modules"]
    assert last["bench_a_slow"]["status"] == "missed" and last["bench_b_fine"]["status"] == "ok"
    assert last["bench_a_slow"]["figures"]["a.speed"] == {"value": 2.0, "unit": "x", "what": "a speed",
                                                         "limit": 1.0, "at_most": True, "met": False}
    assert last["bench_b_fine"]["figures"]["b.lib"]["anchor"] == "their floor"


@pytest.mark.slow
def test_all_targets_met_exits_zero(tmp_path):
    proc = _bench(tmp_path, "from benchmarks.targets import target\n"
                            "def run():\n    return [target('c.rate', 30.0, 20.0, 'x', at_most=False,\n"
                            "                   what='c')]\n", "ok")
    assert proc.returncode == 0 and "target >= 20x: met" in proc.stdout, proc.stdout


def test_a_bench_that_cannot_run_its_subject_fails(tmp_path):
    proc = _bench(tmp_path, "def run():\n    raise FileNotFoundError('build/ssp/x.ssp missing')\n", "broken")
    assert proc.returncode == 1
    assert "error: FileNotFoundError: build/ssp/x.ssp missing" in proc.stdout
    assert "bench: failed: benchmarks.bench_broken" in proc.stdout


@pytest.mark.slow
def test_a_target_not_measured_is_missed(tmp_path):
    proc = _bench(tmp_path, "from benchmarks.targets import target\n"
                            "def run():\n    return [target('d.p99', float('nan'), 1.0, 'us', what='d p99')]\n", "nan")
    assert proc.returncode == 1 and "d p99 (d.p99): not measured, target <= 1 us" in proc.stdout


def test_an_absolute_limit_scales_with_a_slower_machine_only(monkeypatch):
    sys.path.insert(0, str(ROOT))
    from benchmarks import targets

    monkeypatch.setattr(targets, "FIGURES", {})
    monkeypatch.setattr(targets, "SPEED_MS", 1.5 * targets.REFERENCE_SPEED_MS)
    verdict = targets.target("e.cpu", 14.0, 10.0, "s", what="e", per_speed=True)
    assert verdict == "target <= 15 s (x1.50 for the machine's speed): met"
    assert targets.target("e.rtf", 60.0, 100.0, "x", at_most=False, what="e", per_speed=True).endswith("MISSED")
    assert targets.target("e.ratio", 14.0, 10.0, "x", what="e ratio").endswith("MISSED")  # a ratio is never scaled
    recorded = targets.FIGURES["e.cpu"]
    assert recorded["limit"] == 15.0 and recorded["limit_at_reference"] == 10.0 and recorded["speed_factor"] == 1.5
    assert targets.FIGURES["e.rtf"]["limit"] == 100.0 / 1.5
    monkeypatch.setattr(targets, "SPEED_MS", 0.5 * targets.REFERENCE_SPEED_MS)   # faster: the limit as written
    assert targets.target("f.cpu", 11.0, 10.0, "s", what="f", per_speed=True) == "target <= 10 s: MISSED"
