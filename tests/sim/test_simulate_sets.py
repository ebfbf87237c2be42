"""A simulated set is written as one: never an earlier set's leftovers, never two seeds."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from conftest import invoke


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_force_over_a_larger_set_leaves_none_of_its_repetitions(tmp_path):
    """simulate --force of six repetitions over seven left rep7.csv beside them, and the
    next fit read seven repetitions of two seeds."""
    out = tmp_path / "set"
    invoke(["simulate", out, "--repetitions", 7, "--seed", 1])
    (out / "calibration" / "notes.csv").write_text("kept\n")  # not the simulator's
    invoke(["simulate", out, "--seed", 2, "--force"])
    names = sorted(p.name for p in (out / "calibration").iterdir())
    assert names == ["notes.csv", *(f"rep{r}.csv" for r in range(1, 7))]
    invoke(["simulate", tmp_path / "fresh", "--seed", 2])
    fresh = _files(tmp_path / "fresh")
    got = _files(out)
    del got["calibration/notes.csv"]
    assert got == fresh


def test_six_axis_force_over_a_larger_set_too(tmp_path):
    out = tmp_path / "six"
    invoke(["simulate", out, "--components", 6, "--repetitions", 3])
    invoke(["simulate", out, "--components", 6, "--repetitions", 2, "--force"])
    assert sorted(p.name for p in (out / "calibration").iterdir()) == ["rep1.csv", "rep2.csv"]


@pytest.mark.slow  # several processes, several rounds
def test_concurrent_runs_into_one_directory_never_mix_two_seeds(tmp_path):
    for seed in (5, 6):
        invoke(["simulate", tmp_path / f"ref{seed}", "--seed", seed])
    refs = [_files(tmp_path / f"ref{seed}") for seed in (5, 6)]
    out = tmp_path / "shared"
    for _ in range(3):
        procs = [subprocess.Popen([sys.executable, "-m", "fsdecouple", "simulate", str(out),
                                   "--seed", str(seed), "--force"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
                 for seed in (5, 6)]
        for p in procs:
            _, err = p.communicate(timeout=300)
            assert p.returncode == 0, err
        assert _files(out) in refs  # every file of one seed
