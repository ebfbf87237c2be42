"""fitting/svr.py loads libsvm without its optional scipy.sparse and numba (issue 30, point 7).

libsvm's Python module imports both if it can, for sparse and numpy input; fsdecouple
passes lists.  Loaded so, they were 0.9 s of the 4.5 s of CPU of ``fit`` on the sample.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from conftest import ROOT

from fsdecouple.config import SVRSettings


def test_svr_trains_without_scipy_or_numba_loaded():
    """In a fresh interpreter: an SVR trains and predicts, and neither library is loaded,
    and libsvm's own model equals one trained from numpy input in a process with scipy."""
    code = (
        "import json, sys\n"
        "from fsdecouple.config import SVRSettings\n"
        "from fsdecouple.fitting.svr import fit_svr\n"
        "import numpy as np\n"
        "x = np.linspace(-1, 1, 40); y = 0.01 * np.sin(3 * x)\n"
        "s = fit_svr(x, y, SVRSettings())\n"
        "print(json.dumps({'loaded': sorted(m for m in ('scipy', 'numba') if m in sys.modules),"
        " 'coef': s.dual_coef.tolist(), 'sv': s.support_vectors.tolist(), 'rho': s.rho}))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         check=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    got = json.loads(out.stdout)
    assert got["loaded"] == []
    # libsvm as its README calls it, from numpy arrays (scipy present): the same model
    pytest.importorskip("scipy.sparse")
    code_np = (
        "import json, scipy.sparse, numpy as np\n"
        "from libsvm import svmutil\n"
        "x = np.linspace(-1, 1, 40); y = 0.01 * np.sin(3 * x)\n"
        f"m = svmutil.svm_train(y, x.reshape(-1, 1), {SVRSettings().libsvm_options()!r})\n"
        "print(json.dumps({'coef': [c[0] for c in m.get_sv_coef()], 'rho': m.rho[0],"
        " 'sv': [r.get(1, 0.0) for r in m.get_SV()]}))\n"
    )
    ref = json.loads(subprocess.run([sys.executable, "-c", code_np], capture_output=True,
                                    text=True, check=True).stdout)
    assert got["coef"] == ref["coef"] and got["sv"] == ref["sv"] and got["rho"] == ref["rho"]

