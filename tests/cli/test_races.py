"""Overwrite races: without --force, an output that appears while a command runs is
never replaced; of concurrent runs to one output exactly one wins."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from conftest import ROOT, SAMPLE, invoke

from fsdecouple.errors import InputError
from fsdecouple.files import outputs
from fsdecouple.files.outputs import atomic_files, atomic_write

pytestmark = pytest.mark.slow  # runs concurrent commands against one output


def _appear_before_placing(monkeypatch, content=b"written by someone else\n"):
    """Make another writer create the output between the start and the final step."""
    real = outputs.place

    def racing(tmp, path, *, force):
        path.write_bytes(content)
        return real(tmp, path, force=force)

    monkeypatch.setattr(outputs, "place", racing)


def _no_renameat2(monkeypatch):
    monkeypatch.setattr(outputs, "_renameat2", None)


def _no_hard_links(monkeypatch):
    _no_renameat2(monkeypatch)

    def link(*a, **k):
        raise OSError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(outputs.os, "link", link)


MECHANISMS = {
    "renameat2": lambda mp: None,
    "link": _no_renameat2,
    "placeholder": _no_hard_links,
}


@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_file_created_meanwhile_is_not_replaced(tmp_path, monkeypatch, mechanism):
    MECHANISMS[mechanism](monkeypatch)
    _appear_before_placing(monkeypatch)
    out = tmp_path / "forces.csv"
    with pytest.raises(InputError, match="appeared while writing; not replaced"), \
            atomic_write(out, force=False) as fh:
        fh.write("ours\n")
    assert out.read_bytes() == b"written by someone else\n"
    assert [p.name for p in tmp_path.iterdir()] == ["forces.csv"]


@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_each_mechanism_writes_a_new_file(tmp_path, monkeypatch, mechanism):
    MECHANISMS[mechanism](monkeypatch)
    out = tmp_path / "forces.csv"
    with atomic_write(out, force=False) as fh:
        fh.write("ours\n")
    assert out.read_text() == "ours\n"
    assert [p.name for p in tmp_path.iterdir()] == ["forces.csv"]


def test_force_still_replaces(tmp_path, monkeypatch):
    _appear_before_placing(monkeypatch)
    out = tmp_path / "forces.csv"
    with atomic_write(out, force=True) as fh:
        fh.write("ours\n")
    assert out.read_text() == "ours\n"


def test_group_takes_back_what_it_placed(tmp_path, monkeypatch):
    """The second file appears meanwhile: the first is removed again, and its new directory."""
    real = outputs.place

    def racing(tmp, path, *, force):
        if path.name == "b.csv":
            path.write_text("theirs\n")
        return real(tmp, path, force=force)

    monkeypatch.setattr(outputs, "place", racing)
    with pytest.raises(InputError, match="b.csv: appeared while writing"), \
            atomic_files(force=False) as group:
        for name in ("sub/a.csv", "b.csv"):
            with group.open(tmp_path / name) as fh:
                fh.write("ours\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.csv"]
    assert (tmp_path / "b.csv").read_text() == "theirs\n"


def test_fit_output_created_meanwhile_exits_2(tmp_path, monkeypatch):
    _appear_before_placing(monkeypatch, b"a model of another run\n")
    out = tmp_path / "model.json"
    r = invoke(["fit", SAMPLE / "calibration", "-o", out, "--no-verdict"], code=2)  # the output is tested
    msg = r.stderr.strip()
    assert len(msg.splitlines()) == 1 and "appeared while writing; not replaced" in msg, msg
    assert out.read_bytes() == b"a model of another run\n"
    assert [p.name for p in tmp_path.iterdir()] == ["model.json"]


@pytest.fixture(scope="module")
def log_and_model(tmp_path_factory, sample_model):
    """300 000 rows: apply takes a second or two writing them, a wide enough window; the
    suite's sample model (a copy, as the tests race to write beside it)."""
    d = tmp_path_factory.mktemp("race")
    rng = np.random.default_rng(1)
    block = rng.uniform(-1.0, 1.0, size=(20_000, 3))
    body = "".join(f"{i},{a:.7f},{b:.7f},{c:.7f}\n" for i, (a, b, c) in enumerate(block))
    log = d / "log.csv"
    log.write_text("t,ux,uy,uz\n" + body * 15)
    model = d / "model.json"
    model.write_bytes(sample_model.read_bytes())
    return log, model


def _apply(model, log, out):
    return subprocess.Popen(
        [sys.executable, "-m", "fsdecouple", "apply", str(model), str(log), "-o", str(out)],
        env={**os.environ, "PYTHONPATH": str(ROOT)}, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )


def test_output_appearing_during_apply_is_kept(tmp_path, log_and_model):
    """Another process creates the output while apply streams its rows."""
    log, model = log_and_model
    out = tmp_path / "forces.csv"
    proc = _apply(model, log, out)
    deadline = time.monotonic() + 60
    while not any(tmp_path.glob(".forces.csv.*.tmp")):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.005)
    out.write_bytes(b"someone else's result\n")
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 2, err.decode()
    lines = err.decode().strip().splitlines()
    assert len(lines) == 1 and "appeared while writing; not replaced" in lines[0], lines
    assert out.read_bytes() == b"someone else's result\n"
    assert [p.name for p in tmp_path.iterdir()] == ["forces.csv"]


def test_concurrent_applies_exactly_one_wins(tmp_path, log_and_model):
    log, model = log_and_model
    out = tmp_path / "forces.csv"
    barrier = threading.Barrier(3)
    procs = []

    def start():
        barrier.wait()
        procs.append(_apply(model, log, out))

    threads = [threading.Thread(target=start) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    results = [(p.wait(timeout=120), p.communicate()[1].decode()) for p in procs]
    codes = sorted(code for code, _ in results)
    assert codes == [0, 2, 2], results
    for code, err in results:
        assert "Traceback" not in err
        if code == 2:
            line = err.strip()
            assert len(line.splitlines()) == 1
            assert "appeared while writing" in line or "already exists" in line, line
    assert len(out.read_text().splitlines()) == 300_001
    assert [p.name for p in tmp_path.iterdir()] == ["forces.csv"]
