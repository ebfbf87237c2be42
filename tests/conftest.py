from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from fsdecouple import load_calibration, load_config
from fsdecouple.fitting.fit import fit
from fsdecouple.sim.simulate import SimulatedSensor, simulate

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "sample_data"


@pytest.fixture(scope="session")
def settings():
    return load_config()


@pytest.fixture(scope="session")
def sim_dir(tmp_path_factory):
    """A freshly simulated data set (seed 7), independent of the committed sample."""
    out = tmp_path_factory.mktemp("sim")
    simulate(out, seed=7)
    return out


@pytest.fixture(scope="session")
def sensor():
    return SimulatedSensor()


@pytest.fixture(scope="session")
def calib(sim_dir, settings):
    return load_calibration(sim_dir / "calibration", settings)


@pytest.fixture(scope="session")
def model(calib, settings):
    return fit(calib, settings)


def invoke(args, code=0, **kw):
    """Run the CLI and assert its exit code, showing its output on failure."""
    from fsdecouple.cli import app

    result = CliRunner().invoke(app, [str(a) for a in args], **kw)
    assert result.exit_code == code, (
        f"exit {result.exit_code}, expected {code}\nstdout:\n{result.stdout}\n"
        f"stderr:\n{result.stderr}\n{result.exception!r}"
    )
    return result


@pytest.fixture(scope="session")
def cv_json(tmp_path_factory):
    """cv.json of the sample data, from a real `fsdecouple cv` run with every option."""
    path = tmp_path_factory.mktemp("cv") / "cv.json"
    invoke(["cv", SAMPLE / "calibration", "-o", path, "--task", SAMPLE / "task_voltages.csv",
            "--task-forces", SAMPLE / "task_forces.csv", "--task-tare", "200",
            "--gross-error", "x:3:5:0.2"])
    return path


@pytest.fixture(scope="session")
def sample_model(tmp_path_factory):
    """A model file fitted on the committed sample data."""
    path = tmp_path_factory.mktemp("model") / "model.json"
    invoke(["fit", SAMPLE / "calibration", "-o", path])
    return path


def assert_one_line_error(r, *needles) -> str:
    """The error contract: one line on stderr starting 'error:', no traceback, the needles in it."""
    msg = r.stderr.strip()
    assert msg.startswith("error:") and len(msg.splitlines()) == 1, msg
    assert "Traceback" not in r.stderr + r.stdout
    for n in needles:
        assert n in msg, (n, msg)
    return msg
