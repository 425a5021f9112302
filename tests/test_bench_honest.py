"""``make bench`` is honest: every module runs and prints, and a missed target makes the exit
status non-zero (``benchmarks.bench.target``)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _bench(tmp_path: Path, body: str, name: str) -> subprocess.CompletedProcess:
    """Run benchmarks.bench on a copy of its runner with one fake bench module."""
    pkg = tmp_path / "benchmarks"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "bench.py").write_text((ROOT / "benchmarks" / "bench.py").read_text())
    (pkg / "targets.py").write_text((ROOT / "benchmarks" / "targets.py").read_text())
    (pkg / f"bench_{name}.py").write_text(body)
    return subprocess.run([sys.executable, "-m", "benchmarks.bench"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=60)


def test_missed_target_fails_after_printing_everything(tmp_path):
    _bench(tmp_path, "from benchmarks.bench import target\n"
                     "def run():\n    return ['fast ' + target('speed', 2.0, 1.0, 'x'), 'last line']\n", "a_slow")
    proc = _bench(tmp_path, "from benchmarks.bench import target\n"
                            "def run():\n    return ['ok ' + target('ratio', 0.5, 1.0, 'x')]\n", "b_fine")
    assert proc.returncode == 1, proc.stdout
    out = proc.stdout
    assert "fast target <= 1x: MISSED" in out and "last line" in out and "ok target <= 1x: met" in out
    assert "TARGET MISSED: speed: 2x, target <= 1x" in out
    assert out.index("== benchmarks.bench_b_fine") < out.rindex("bench: targets missed in benchmarks.bench_a_slow")


def test_all_targets_met_exits_zero(tmp_path):
    proc = _bench(tmp_path, "from benchmarks.bench import target\n"
                            "def run():\n    return [target('rate', 30.0, 20.0, 'x', at_most=False)]\n", "ok")
    assert proc.returncode == 0 and "target >= 20x: met" in proc.stdout, proc.stdout
