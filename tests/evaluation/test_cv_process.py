"""How a ``fsdecouple cv`` process ends (fsdecouple/cli/app.py::main).

The interpreter's last cycle collection walked every object pandas, pyarrow and scipy
made: 0.15-0.2 s of CPU after cv on the sample, to free memory the system takes back
anyway.  main() freezes those objects first instead of leaving with ``os._exit``, so
what Python runs at exit (atexit handlers, buffered streams) still runs.
"""

from __future__ import annotations

import os
import subprocess
import sys

from conftest import ROOT


def test_cv_ends_with_its_objects_frozen_and_atexit_handlers_run(tmp_path):
    code = (
        "import atexit, gc, sys\n"
        "from fsdecouple.cli import main\n"
        "atexit.register(lambda: print('atexit: frozen', gc.get_freeze_count() > 0))\n"
        "sys.stdout.write('buffered, not flushed')\n"
        f"sys.argv = ['fsdecouple', 'cv', {str(tmp_path / 'missing')!r}]\n"
        "main()\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 2, r.stderr  # the missing set: bad input, one line
    assert r.stderr.startswith("error: ") and "Traceback" not in r.stderr
    assert r.stdout == "buffered, not flushedatexit: frozen True\n"
