"""Every command, registered on the app by importing its module (in the order of --help)."""
# isort: skip_file

from . import data  # noqa: F401  simulate, ingest
from . import model  # noqa: F401  fit, show, export
from . import evaluate  # noqa: F401  cv, validate, report
from . import certificate  # noqa: F401  certificate
from . import apply  # noqa: F401  apply
from . import fleet  # noqa: F401  compare, fit-many
from . import ati  # noqa: F401  import (ATI .cal)
