"""Ctrl-C during ``apply --engine dask`` (issue 34): exit 130 and one quiet stop.

A terminal's Ctrl-C reaches the whole process group: each Dask worker printed its own
KeyboardInterrupt traceback and the resource tracker warned of leaked semaphores, 84
lines under the exit code.  The workers start with SIGINT ignored; the client stops them.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from conftest import SAMPLE

pytest.importorskip("distributed")


@pytest.mark.slow  # a cluster of worker processes, logs that take seconds
def test_ctrl_c_during_a_dask_run_is_exit_130_without_worker_tracebacks(sample_model, tmp_path):
    head, *body = (SAMPLE / "task_voltages.csv").read_text().splitlines()
    logs = []
    for k in range(12):
        log = tmp_path / f"log{k:02d}.csv"
        log.write_text(head + "\n" + "\n".join(body * 60) + "\n")
        logs.append(log)
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    env.pop("CI", None)
    p = subprocess.Popen([sys.executable, "-m", "fsdecouple", "apply", sample_model, *logs, "-o",
                          f"{out}/", "--engine", "dask", "--workers", "2", "--tare", "10",
                          "--interval", "0.9"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         env=env, start_new_session=True)
    deadline = time.monotonic() + 120
    while not any(out.glob("*.csv")) and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)  # the cluster is up and working once a first log is in place
    if p.poll() is not None:
        pytest.skip("the run ended before it could be interrupted")
    os.killpg(p.pid, signal.SIGINT)  # as a terminal's Ctrl-C: every process of the group
    _, err = p.communicate(timeout=120)
    text = err.decode(errors="replace")
    assert p.returncode == 130, text[-2000:]
    assert "Traceback" not in text and "leaked" not in text and "KeyboardInterrupt" not in text, \
        text[-2000:]
