"""The ``fsdecouple`` command line: a thin Typer shell over the Python API.

``app.py`` holds the app and what every command shares; ``data.py``, ``model.py``,
``evaluate.py`` and ``run.py`` hold the commands, each parsing its arguments,
calling one library function, rendering the result and choosing the exit code.

May import: every stage.  Nothing below imports the CLI, and only the CLI imports typer.
"""

from . import commands  # noqa: F401 (registers the commands on the app)
from .app import app, main

__all__ = ["app", "main"]
