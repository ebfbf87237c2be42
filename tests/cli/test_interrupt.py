"""An interrupted `apply` on a large log leaves the previous output as it was."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from conftest import ROOT, SAMPLE


@pytest.fixture(scope="module")
def big_log(tmp_path_factory, sample_model):
    """2 million rows (~70 MB): long enough to be caught mid-write on any machine."""
    d = tmp_path_factory.mktemp("big")
    rng = np.random.default_rng(0)
    block = rng.uniform(-1.0, 1.0, size=(20_000, 3))
    body = "".join(f"{i},{a:.7f},{b:.7f},{c:.7f}\n" for i, (a, b, c) in enumerate(block))
    log = d / "big.csv"
    with open(log, "w") as fh:
        fh.write("t,ux,uy,uz\n")
        for _ in range(100):
            fh.write(body)
    return log, sample_model  # apply only reads it


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL])
def test_interrupted_apply_keeps_previous_output(tmp_path, big_log, sig):
    log, model = big_log
    out = tmp_path / "forces.csv"
    out.write_bytes(b"the previous result\n")
    proc = subprocess.Popen(
        [sys.executable, "-m", "fsdecouple", "apply", str(model), str(log), "-o", str(out),
         "--force"],
        env={**os.environ, "PYTHONPATH": str(ROOT)}, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, preexec_fn=_default_sigint,
    )
    deadline = time.monotonic() + 120
    while not any(p.stat().st_size > 0 for p in tmp_path.glob(".forces.csv.*.tmp")):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "apply never started writing"
        time.sleep(0.02)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGKILL: -9}[sig], err
    assert out.read_bytes() == b"the previous result\n"
    assert b"Traceback" not in err, err.decode()
    left = sorted(p.name for p in tmp_path.iterdir())
    if sig == signal.SIGKILL:
        # nothing can run after SIGKILL: a hidden temporary may stay, never a partial output
        assert "forces.csv" in left
        assert all(n.startswith(".forces.csv.") and n.endswith(".tmp") for n in left if n != "forces.csv")
    else:
        assert left == ["forces.csv"], left


def _default_sigint():
    # a background job's SIGINT is ignored, and an ignored signal stays ignored in a child
    signal.signal(signal.SIGINT, signal.SIG_DFL)


# A readiness marker instead of a fixed sleep (3 s were not enough under load): a
# sitecustomize on the child's path wraps libsvm's svm_train, so that each process
# (the command, and the workers a pool forks or spawns: each runs site) leaves a file
# named by its pid in the marker directory as it starts training a real SVR (the
# 2-point warm-up call cv makes first does not count).  The command itself runs as
# ever, `python -m fsdecouple`.
_SITECUSTOMIZE = """
import os

from libsvm import svmutil

_train = svmutil.svm_train


def svm_train(y, *args, **kw):
    try:
        real = len(y) > 2
    except TypeError:
        real = True
    if real:
        open(os.path.join(os.environ["FSDECOUPLE_TEST_TRAINING"], str(os.getpid())), "a").close()
    return _train(y, *args, **kw)


svmutil.svm_train = svm_train
"""


def _training_env(tmp_path):
    """(the child's environment, the marker directory): see _SITECUSTOMIZE."""
    site = tmp_path.parent / f"{tmp_path.name}-site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(_SITECUSTOMIZE)
    marks = tmp_path.parent / f"{tmp_path.name}-training"
    marks.mkdir()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(site)]),
           "FSDECOUPLE_TEST_TRAINING": str(marks)}
    return env, marks


def _wait_for_training(proc, marks, processes=1, timeout=120):
    """Until ``processes`` processes have started training an SVR (or fail)."""
    deadline = time.monotonic() + timeout
    while len(list(marks.iterdir())) < processes:
        if proc.poll() is not None:
            out, err = proc.communicate()
            raise AssertionError(f"exited {proc.returncode} before training: {(out or b'') + (err or b'')!r}")
        assert time.monotonic() < deadline, "the command never started training"
        time.sleep(0.02)


def _signal_while_training(proc, marks, sig, timeout, processes=1):
    """Once ``processes`` are training (and 0.2 s inside libsvm), send ``sig``; return
    (stdout, stderr, seconds from the signal to the exit)."""
    _wait_for_training(proc, marks, processes)
    time.sleep(0.2)
    proc.send_signal(sig)
    sent = time.monotonic()
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        proc.kill()
    return out, err, time.monotonic() - sent


@pytest.mark.slow
@pytest.mark.parametrize("workers", ["1", "2"])
@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_during_libsvm_training_stops_the_command(tmp_path, sig, code, workers):
    """libsvm prints through a Python callback; a signal handled inside it was ignored by
    ctypes ("Exception ignored on calling ctypes callback function") and training went on
    until SIGKILL.  Now the command stops within seconds, writing nothing."""
    slow = tmp_path / "slow.yaml"
    slow.write_text("svr: {C: 1000000, tolerance: 1.0e-9}\n")  # seconds per SVR
    out = tmp_path / "cv.json"
    env, marks = _training_env(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "fsdecouple", "cv", str(SAMPLE / "calibration"),
                             "-c", str(slow), "--workers", workers, "-o", str(out)],
                            env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, preexec_fn=_default_sigint)
    # on the main thread (1) or a pool's (2), inside libsvm: C = 1e6 takes seconds per SVR
    _, err, took = _signal_while_training(proc, marks, sig, 30)
    assert proc.returncode == code and took < 5, err.decode()[-2000:]
    assert b"Exception ignored" not in err and b"Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["slow.yaml"]


@pytest.mark.slow
def test_sigterm_stops_fit_many_and_its_worker_processes(tmp_path):
    """The pool's workers caught the SystemExit of their sensor and waited for more work,
    and fit-many never exited after SIGTERM.  Now: exit 143 within seconds, no worker
    process left, no model or temporary file written."""
    sensors = tmp_path / "sensors"
    for name in ("a", "b", "c"):
        d = sensors / name
        d.mkdir(parents=True)
        for f in (SAMPLE / "calibration").glob("rep*.csv"):
            (d / f.name).write_bytes(f.read_bytes())
        (d / "sensor.yaml").write_text(f"sensor: {name}\nsvr: {{C: 1000000, tolerance: 1.0e-9}}\n")
    models = tmp_path / "models"
    env, marks = _training_env(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "fsdecouple", "fit-many", str(sensors), "-o",
                             str(models), "--workers", "2"],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    # both workers are training
    _, err, took = _signal_while_training(proc, marks, signal.SIGTERM, 30, processes=2)
    assert proc.returncode == 143 and took < 10, err.decode()[-2000:]
    alive = subprocess.run(["pgrep", "-f", str(sensors)], capture_output=True, text=True).stdout
    assert alive == "", alive
    assert not models.exists()  # the directory it made is not left behind, empty


_SLOW_FITS = """
import pathlib

import pytest
from typer.testing import CliRunner

from fsdecouple.cli import app


@pytest.mark.parametrize("i", range(20))
def test_fit(i, tmp_path):
    pathlib.Path({mark!r}).write_text(str(i))
    r = CliRunner().invoke(app, ["fit", {calib!r}, "-c", {slow!r}, "--no-verdict",
                                 "-o", str(tmp_path / "model.json")])
    assert r.exit_code == 0, r.output
"""


@pytest.mark.slow
def test_ctrl_c_stops_pytest_while_a_command_runs_in_process(tmp_path):
    """CliRunner runs the app in pytest's process, where typer turned the Ctrl-C into
    exit code 130: the running test failed and the suite went on, for minutes.  Now the
    KeyboardInterrupt reaches pytest, which stops (its exit code 2, "interrupted"), and
    does not then wait at exit for the fit's pool threads still inside libsvm (conftest's
    pytest_unconfigure; under load one SVR of this config outlasted the 15 s)."""
    slow = tmp_path / "slow.yaml"
    slow.write_text("svr: {C: 1000000, tolerance: 1.0e-9}\n")  # seconds per SVR: 20 fits take minutes
    mark = tmp_path / "started"
    (tmp_path / "test_fits.py").write_text(_SLOW_FITS.format(
        mark=str(mark), calib=str(SAMPLE / "calibration"), slow=str(slow)))
    env, marks = _training_env(tmp_path)
    # with this suite's conftest (its hooks), as the suite itself runs
    env["PYTHONPATH"] += os.pathsep + str(ROOT / "tests")
    proc = subprocess.Popen([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                             "-p", "conftest", str(tmp_path / "test_fits.py")],
                            cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, preexec_fn=_default_sigint)
    # inside the first fit command
    out, _, took = _signal_while_training(proc, marks, signal.SIGINT, 15)
    out = out.decode()
    assert took < 15
    assert proc.returncode == 2, out[-3000:]  # pytest's ExitCode.INTERRUPTED
    assert "KeyboardInterrupt" in out and mark.read_text() == "0", out[-3000:]
    assert "failed" not in out and "passed" not in out, out[-3000:]


def test_a_stop_that_a_library_turned_into_another_exception_is_still_143(monkeypatch):
    """SIGTERM's handler raises SystemExit(143) wherever Python runs; raised inside a
    library's callback into Python it can come back as another exception, and the command
    once ended with exit 1 and a traceback (a CI run's test above).  A stop is a stop."""
    import importlib

    app = importlib.import_module("fsdecouple.cli.app")  # the module: the package's 'app' is typer's

    def stopped_then_wrapped():
        try:
            app._terminate(signal.SIGTERM, None)
        except SystemExit as stop:
            raise RuntimeError("a library's wrapping of the exit") from stop

    exits = []
    monkeypatch.setattr(app, "_stopped_by", [])
    monkeypatch.setattr(app, "_run", stopped_then_wrapped)
    monkeypatch.setattr(app.os, "_exit", exits.append)
    monkeypatch.setattr(app.signal, "signal", lambda *a: None)  # the suite's own handlers stay
    monkeypatch.setattr(app.gc, "freeze", lambda: None)  # the suite's objects stay collectable
    with pytest.raises(SystemExit):  # os._exit patched: main goes on to its own exit
        app.main()
    assert exits == [143]
    # a stop that a command's error handling turned into exit 2 is a stop too
    def stopped_then_handled():
        with contextlib.suppress(SystemExit):
            app._terminate(signal.SIGTERM, None)
        return 2

    exits.clear()
    monkeypatch.setattr(app, "_run", stopped_then_handled)
    with pytest.raises(SystemExit):
        app.main()
    assert exits == [143]
    # without a stop, such an exception is not hidden (main starts with none recorded)
    monkeypatch.setattr(app, "_run", lambda: (_ for _ in ()).throw(RuntimeError("a bug")))
    with pytest.raises(RuntimeError, match="a bug"):
        app.main()
