"""An interrupted `apply` on a large log leaves the previous output as it was."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from conftest import ROOT, SAMPLE

from fsdecouple import load_calibration, load_config
from fsdecouple.core.modelfile import save_model
from fsdecouple.fitting.fit import fit


@pytest.fixture(scope="module")
def big_log(tmp_path_factory):
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
    model = d / "model.json"
    save_model(fit(load_calibration(SAMPLE / "calibration", load_config())), model)
    return log, model


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
        stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 120
    while not any(p.stat().st_size > 0 for p in tmp_path.glob(".forces.csv.*.tmp")):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "apply never started writing"
        time.sleep(0.02)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGKILL: -9}[sig]
    assert out.read_bytes() == b"the previous result\n"
    assert b"Traceback" not in err, err.decode()
    left = sorted(p.name for p in tmp_path.iterdir())
    if sig == signal.SIGKILL:
        # nothing can run after SIGKILL: a hidden temporary may stay, never a partial output
        assert "forces.csv" in left
        assert all(n.startswith(".forces.csv.") and n.endswith(".tmp") for n in left if n != "forces.csv")
    else:
        assert left == ["forces.csv"], left
