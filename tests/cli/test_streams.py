"""The standard streams: a reader that goes away, a full disk, a stream that is closed.

Exit codes keep their meaning (docs/errors.md): 1 is a failed gate only; a reader of
stdout that went away (``| head``) is 141, as after SIGPIPE; a stream that cannot be
written is an output that cannot be written, 2; a closed stream is no stream.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import SAMPLE

CLI = [sys.executable, "-m", "fsdecouple"]


def _run(args, **kw):
    return subprocess.run([*CLI, *map(str, args)], timeout=120, **kw)


@pytest.mark.slow  # over ~0.6 s: the not-slow run stays under a minute
def test_a_reader_that_goes_away_is_141_not_the_gate_code(sample_model):
    for args in (["show", sample_model], ["--help"]):
        with subprocess.Popen([*CLI, *map(str, args)], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE) as p:
            p.stdout.close()  # as `| head -0`: every write meets a closed pipe
            err = p.stderr.read()
            assert p.wait(timeout=120) == 141, (args, err)
        assert err == b""  # no traceback, no "Exception ignored"


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")
def test_a_full_stdout_or_stderr_is_exit_2(sample_model):
    with open("/dev/full", "w") as full:
        r = _run(["show", sample_model], stdout=full, stderr=subprocess.PIPE, text=True)
        assert r.returncode == 2
        lines = r.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: cannot write the output") \
            and "No space left" in lines[0], r.stderr
        # the error itself cannot be written: still bad input, never the gate's 1
        r = _run(["show", SAMPLE / "no-such-model.json"], stdout=subprocess.PIPE, stderr=full)
        assert r.returncode == 2


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_closed_standard_streams_are_no_streams(sample_model, tmp_path):
    def close(*fds):
        return lambda: [os.close(fd) for fd in fds]

    r = _run(["show", sample_model], preexec_fn=close(0, 1), stderr=subprocess.PIPE, text=True)
    assert r.returncode == 0 and r.stderr == ""
    out = tmp_path / "f.csv"
    r = _run(["apply", sample_model, SAMPLE / "task_voltages.csv", "--tare", 200, "-o", out],
             preexec_fn=close(0, 1, 2))
    assert r.returncode == 0 and len(out.read_text().splitlines()) == 3001


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_an_ascii_locale_gets_tables_and_errors_not_a_traceback(sample_model, tmp_path):
    """LC_ALL=POSIX without UTF-8 mode: the gamma of validate's table could not be encoded."""
    env = {**os.environ, "LC_ALL": "POSIX", "PYTHONUTF8": "0"}
    env.pop("PYTHONIOENCODING", None)
    r = _run(["validate", sample_model, SAMPLE / "calibration"], env=env, capture_output=True)
    assert r.returncode == 0 and b"Traceback" not in r.stderr, r.stderr[-2000:]
    assert b"| ? % F.S. |" in r.stdout  # the gamma of the header, one cell wide
    missing = tmp_path / "n\u00f6pe.json"
    r = _run(["show", missing], env=env, capture_output=True)
    assert r.returncode == 2 and r.stderr.startswith(b"error: ") and b"Traceback" not in r.stderr


@pytest.mark.slow  # interpreters starting up
@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")
def test_a_usage_error_or_a_bare_command_on_a_full_stderr_is_exit_2():
    """The usage error's line was written outside the handler of unwritable streams: exit
    1, the failed-gate code.  A bare ``fsdecouple`` printed its whole help as one error line."""
    with open("/dev/full", "w") as full:
        for args in (["show"], ["show", "--bogus"], ["aply"], [], ["export", "m.json", "-o", "x/"]):
            r = _run(args, stdout=subprocess.PIPE, stderr=full)
            assert r.returncode == 2, args
    r = _run([], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.startswith("Usage: ") and "\n  fit " in r.stderr


@pytest.mark.slow  # interpreters starting up
@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")
def test_a_bare_environment_keeps_exit_2_on_a_full_stream(sample_model):
    """Only PATH and HOME (cron, systemd): without PYTHONUNBUFFERED the error line stayed
    in stderr's buffer and Python's own flush at exit turned exit 2 into 120."""
    env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": os.environ.get("HOME", "/"),
           "PYTHONPATH": os.pathsep.join(sys.path)}
    with open("/dev/full", "w") as full:
        r = _run(["show", SAMPLE / "no-such-model.json"], env=env, stdout=subprocess.PIPE,
                 stderr=full)
        assert r.returncode == 2
        r = _run(["show", sample_model], env=env, stdout=full, stderr=subprocess.PIPE)
        assert r.returncode == 2 and b"Traceback" not in r.stderr, r.stderr
