"""Nothing is written into the installed package.

A non-editable install into a fresh virtual environment, ``fsdecouple fit``, ``apply``
and a call of the compiled table kernel (whose cache once landed next to the
package's files), then every file under the installed package compared
with the wheel's RECORD: one extra file, and a later ``pip install -e .`` into the
same environment leaves a folder behind that shadows the editable package.
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import FAST_CONFIG, ROOT, SAMPLE

pytestmark = pytest.mark.slow


def _run(args, **kw):
    r = subprocess.run([str(a) for a in args], capture_output=True, text=True, timeout=600, **kw)
    assert r.returncode == 0, (args, r.stdout[-2000:], r.stderr[-2000:])
    return r


def _site_packages(venv: Path) -> Path:
    out = _run([venv / "bin" / "python", "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"])
    return Path(out.stdout.strip())


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """A wheel of this checkout installed, without its dependencies, into a fresh venv
    that sees this environment's packages through a .pth line (no downloads)."""
    tmp = tmp_path_factory.mktemp("install")
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", tmp / "dist", ROOT])
    wheel = next((tmp / "dist").glob("fsdecouple-*.whl"))
    venv = tmp / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", venv])
    site = _site_packages(venv)
    here = [p for p in sys.path if p.endswith("site-packages")]
    (site / "zz_outer.pth").write_text("\n".join(here) + "\n")  # after the venv's own
    # without PYTHONPATH: with this checkout on it (as the suite is run from a worktree),
    # pip took the source tree's egg-info for an installed fsdecouple and installed nothing
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    _run([sys.executable, "-m", "pip", "--python", venv / "bin" / "python", "install", "-q",
          "--no-deps", "--no-index", wheel], env=env)
    return venv, site


def test_commands_write_nothing_into_the_installed_package(installed, tmp_path):
    venv, site = installed
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    env["PYTHONPATH"] = ""
    exe = venv / "bin" / "fsdecouple"
    where = _run([venv / "bin" / "python", "-c", "import fsdecouple; print(fsdecouple.__file__)"],
                 env=env, cwd=tmp_path)
    package = site / "fsdecouple"
    assert Path(where.stdout.strip()).parent == package  # the installed copy, not this checkout
    _run([exe, "fit", SAMPLE / "calibration", "-c", FAST_CONFIG, "-o", tmp_path / "model.json",
          "--no-verdict"], env=env, cwd=tmp_path)
    log = SAMPLE / "task_voltages.csv"
    assert len(log.read_text().splitlines()) > 33  # apply of a real log, tared
    _run([exe, "apply", tmp_path / "model.json", log, "--tare", "200", "-o", tmp_path / "f.csv"],
         env=env, cwd=tmp_path)
    # the compiled kernel (a large call, COMPILED_WORK in core/table_path.py; asked
    # for here on a few rows), whose cache must land in the user's cache directory
    big = ("import numpy as np, fsdecouple; "
           f"m = fsdecouple.load_model({str(tmp_path / 'model.json')!r}); "
           "m.decouple(np.full((1000, 3), 0.1), compiled=True)")
    _run([venv / "bin" / "python", "-c", big], env=env, cwd=tmp_path)
    assert any((tmp_path / "cache").rglob("*.nbi")), "the kernel's cache went somewhere else"

    record = next(site.glob("fsdecouple-*.dist-info")) / "RECORD"
    rows = csv.reader(record.read_text().splitlines())
    recorded = {(site / row[0]).resolve() for row in rows if row}
    present = {p.resolve() for p in package.rglob("*") if p.is_file()}
    assert present - recorded == set(), sorted(str(p) for p in present - recorded)
