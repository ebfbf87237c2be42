"""The command's process starts every OpenBLAS at one thread (fsdecouple/cli/__init__.py).

scipy's own OpenBLAS loads inside cv's training, where threadpoolctl's limit does not
take; the CLI sets OPENBLAS_NUM_THREADS before numpy or scipy loads, unless you did.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

from conftest import ROOT

PROBE = """
import json, fsdecouple.cli, scipy.linalg
from threadpoolctl import threadpool_info
print(json.dumps({i["filepath"]: i["num_threads"] for i in threadpool_info()
                  if i["internal_api"] == "openblas"}))
"""


def _threads(env_extra: dict[str, str]) -> dict[str, int]:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    env.update(PYTHONPATH=str(ROOT), **env_extra)
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout)


def test_every_openblas_of_the_command_runs_one_thread():
    threads = _threads({})
    assert len(threads) >= 2, threads  # numpy's and scipy's (each wheel ships its own)
    assert set(threads.values()) == {1}, threads


def test_a_value_the_user_set_is_kept():
    assert set(_threads({"OPENBLAS_NUM_THREADS": "2"}).values()) == {2}
