"""The tool frame (issue 31, item 6): the config's ``frame:`` follows ATIDAQ's convention,
F' = R F, T' = R (T - d x F), checked against ATIDAQ's tool transform (TTM) as
tests/atidaq_reference.py writes it element by element, and the signs of the worked
example of docs/six-axis.md worked out by hand."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from atidaq_reference import Atidaq
from conftest import invoke

from fsdecouple.core.modelfile import load_model
from fsdecouple.errors import ConfigError
from fsdecouple.wrench import Frame, parse_frame

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "ati"


@pytest.mark.parametrize("seed", range(5))
def test_frame_is_atidaq_tool_transform(seed):
    """frame: {angles, displacement} = ATIDAQ's TTM (N, N-m, m: d is converted by ATIDAQ's
    factors, TorqueConv / (ForceConv DistConv) = 1 + 4e-12, hence the tolerance)."""
    rng = np.random.default_rng(seed)
    tt = [*rng.uniform(-0.2, 0.2, 3), *rng.uniform(-180, 180, 3)]
    ref = Atidaq(FIXTURES / "FT_gamma_like.cal")  # N and N-m
    frame = parse_frame({"angles": tt[3:], "displacement": tt[:3]}, "frame", 6)
    assert np.allclose(frame.matrix(), ref._ttm(tt, "m", "degrees"), rtol=0, atol=1e-11)
    # the same transform written with rotation: and the origin r = -R d
    r = np.asarray(frame.rotation)
    same = Frame(frame.rotation, tuple(-r @ np.asarray(tt[:3])))
    assert np.allclose(same.matrix(), frame.matrix(), rtol=0, atol=1e-15)


def test_worked_example_signs():
    """docs/six-axis.md: a 10 N force along the sensor's y, the tool point 0.1 m along x.

    T' = T - d x F = -(0.1 x 10) (x cross y = z) = -1 N·m about z; with R a +90 degree
    turn about z (angles [0, 0, 90] in ATI's convention, R = [[0, 1, 0], [-1, 0, 0],
    [0, 0, 1]]) the force reads along +x and the moment stays -1 N·m about z.
    """
    wrench = np.array([0.0, 10.0, 0.0, 0.0, 0.0, 0.0])
    plain = parse_frame({"displacement": [0.1, 0.0, 0.0]}, "frame", 6).matrix() @ wrench
    assert plain == pytest.approx([0, 10, 0, 0, 0, -1.0], abs=1e-15)
    turned = parse_frame({"angles": [0, 0, 90], "displacement": [0.1, 0, 0]}, "frame", 6)
    np.testing.assert_allclose(turned.rotation, [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], atol=1e-15)
    assert turned.matrix() @ wrench == pytest.approx([10, 0, 0, 0, 0, -1.0], abs=1e-15)


def test_imported_model_with_a_frame_is_atidaq_set_tool_transform(tmp_path):
    """import -c (frame:) = ATIDAQ's SetToolTransform after the basic transform (N-mm, mm)."""
    cal = FIXTURES / "FT_nano_like.cal"
    tt = [3.0, -1.0, 12.5, 15.0, 0.0, -30.0]  # mm and degrees
    (tmp_path / "frame.yaml").write_text(
        f"frame:\n  angles: {tt[3:]}\n  displacement: {tt[:3]}\n")
    invoke(["import", cal, "-o", tmp_path / "m.json", "-c", tmp_path / "frame.yaml"])
    model = load_model(tmp_path / "m.json")
    ref = Atidaq(cal)
    ref.set_tool_transform(tt, "mm")
    u = np.random.default_rng(0).normal(0, 0.3, (100, 6))
    expected = np.array([ref.convert([*row, 0.0]) for row in u])
    assert np.abs(model.decouple(u) - expected).max() <= 1e-12 * 250


def test_bad_frames(tmp_path):
    with pytest.raises(ConfigError, match="give origin or displacement, not both"):
        parse_frame({"origin": [0, 0, 0], "displacement": [0, 0, 0]}, "frame", 6)
    with pytest.raises(ConfigError, match=r"angles: expected \[Rx, Ry, Rz\] in degrees"):
        parse_frame({"angles": [0, 0]}, "frame", 6)
    (tmp_path / "c.yaml").write_text("frame: {angles: [0, 0, 90]}\nfull_scale: {fx: 1}\n")
    r = invoke(["import", FIXTURES / "FT_nano_like.cal", "-o", tmp_path / "m.json", "-c",
                tmp_path / "c.yaml"], code=2)
    assert "import reads only frame:" in r.stderr and not (tmp_path / "m.json").exists()
