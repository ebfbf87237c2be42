"""The ``fsdecouple`` command line: a thin Typer shell over the Python API.

``app.py`` holds the app and what every command shares; ``data.py``, ``model.py``,
``evaluate.py`` and ``run.py`` hold the commands, each parsing its arguments,
calling one library function, rendering the result and choosing the exit code.

May import: every stage.  Nothing below imports the CLI, and only the CLI imports typer.
"""

import os

# Before numpy or scipy loads an OpenBLAS: fsdecouple runs whole jobs on its own threads
# and keeps BLAS at one thread (fitting/threads.py), but scipy's own OpenBLAS loads
# inside cv's training, where threadpoolctl's limit does not take; its spinning threads
# cost the sample's cv about 0.9 s of CPU (3.7 s -> 2.8 s).  A value you set is kept.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from . import commands  # noqa: E402, F401 (registers the commands on the app)
from .app import app, main  # noqa: E402

__all__ = ["app", "main"]
