"""Sets without an unloaded row (issue 32 item 1): each output's offset a fitted unknown
(``zero: intercept``, data/zero.py), carried by the model so a log needs no tare."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from conftest import assert_one_line_error, invoke

from fsdecouple.config import load_config
from fsdecouple.core.modelfile import load_model
from fsdecouple.data.calibration import load_calibration
from fsdecouple.data.init_config import init_config
from fsdecouple.errors import InputError
from fsdecouple.sim.poses import POSITIONS, pose_lines, pose_loads, simulate_poses
from fsdecouple.sim.rig import gauge_mix

LOADS = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
FS = np.array([10.0, 10.0, 10.0, 0.4, 0.4, 0.4])


def linear_poses(path: Path, offsets: np.ndarray, seed: int = 0, noise: float = 0.0,
                 loads: np.ndarray | None = None) -> np.ndarray:
    """A pose file (one row per pose, no timestamp) of a linear 8-gauge sensor with the given
    offsets; returns its loads."""
    f = pose_loads(seed) if loads is None else loads
    rng = np.random.default_rng(seed)
    u = offsets + 300.0 * (f / FS) @ gauge_mix(seed, 8).T + rng.normal(0, noise, (len(f), 8))
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([*(f"s{j}" for j in range(8)), *LOADS])
        for ui, fi in zip(u, f, strict=True):
            w.writerow([*(repr(float(v)) for v in ui), *(repr(float(v)) for v in fi)])
    return f


def read(tmp_path: Path, path: Path, keep_zero: bool = True, **kw):
    cfg = tmp_path / "cfg.yaml"
    init_config(path, cfg, force=True)
    if not keep_zero:  # a config from before zero: intercept
        cfg.write_text("".join(line for line in cfg.read_text().splitlines(True)
                               if not line.startswith("zero:")))
    settings = load_config(cfg)
    return load_calibration(path, settings, **kw), settings


def test_the_offsets_of_a_set_without_a_zero_row_are_fitted(tmp_path):
    offsets = np.random.default_rng(5).uniform(200, 800, 8)
    path = tmp_path / "poses.csv"
    linear_poses(path, offsets)
    calib, settings = read(tmp_path, path, keep_zero=False)
    assert settings.zero is None and calib.zero == "intercept"
    # noiseless linear data: the intercept is the simulator's offset to rounding (the
    # design's condition number times 1e-16 of readings of ~1000)
    got = calib.offsets[list(settings.layout.outputs)].to_numpy()[0]
    np.testing.assert_allclose(got, offsets, rtol=0, atol=1e-9)
    # the corrected outputs are the load responses alone: zero mean over antipodal poses
    raw = calib.points[[f"{o}_raw" for o in settings.layout.outputs]].to_numpy()
    np.testing.assert_allclose(calib.voltages, raw - offsets, atol=1e-9)
    assert any("zero: intercept" in w and "no tare" in w for w in calib.warnings)


def test_a_set_with_zero_rows_keeps_its_zero_correction(tmp_path):
    offsets = np.full(8, 500.0)
    path = tmp_path / "poses.csv"
    f = pose_loads(0)
    f = np.vstack([np.zeros(6), f])  # one unloaded row
    linear_poses(path, offsets, loads=f)
    calib, _ = read(tmp_path, path)
    assert calib.zero != "intercept"


@pytest.mark.slow  # a whole fit: over half a second of CPU
def test_a_config_without_zero_shows_the_intercept_fit_chose(tmp_path):
    """Without a zero row fit takes zero: intercept itself, and its table says so (it said
    "zero offsets: fit", the six-axis default, not used)."""
    from fsdecouple.core.modelfile import load_model
    from fsdecouple.reporting.console import zero_used

    path = tmp_path / "poses.csv"
    linear_poses(path, OFFSETS, noise=0.3)
    _, settings = read(tmp_path, path, keep_zero=False)
    assert settings.zero is None
    invoke(["fit", path, "-c", tmp_path / "cfg.yaml", "-o", tmp_path / "m.json", "--no-verdict",
            "--method", "svr"])
    model = load_model(tmp_path / "m.json")
    assert model.zero is not None and zero_used(model) == "intercept"


def test_the_config_key_forces_the_intercept(tmp_path):
    path = tmp_path / "poses.csv"
    linear_poses(path, np.full(8, 500.0), loads=np.vstack([np.zeros(6), pose_loads(0)]))
    init_config(path, tmp_path / "cfg.yaml")
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(cfg.read_text() + "\nzero: intercept\n")
    calib = load_calibration(path, load_config(cfg))
    assert calib.zero == "intercept"
    assert not any("no row is unloaded" in w for w in calib.warnings)  # asked for: no note


def test_init_writes_zero_intercept_for_a_set_without_an_unloaded_row(tmp_path):
    path = tmp_path / "poses.csv"
    linear_poses(path, np.full(8, 500.0))
    guess = init_config(path, tmp_path / "cfg.yaml")
    text = (tmp_path / "cfg.yaml").read_text()
    assert "zero: intercept" in text
    assert load_config(tmp_path / "cfg.yaml").zero == "intercept"
    assert "zero" in guess.reasons


def test_every_pose_the_same_load_is_refused(tmp_path):
    path = tmp_path / "poses.csv"
    same = np.repeat(pose_loads(0)[:1], 20, axis=0)
    linear_poses(path, np.full(8, 500.0), loads=same, noise=1.0)
    init_config(_ok(tmp_path), tmp_path / "cfg.yaml")  # the config of a good set
    settings = load_config(tmp_path / "cfg.yaml")
    with pytest.raises(InputError, match="cannot separate the outputs' offsets from the loads: "
                                         "every row has the same loads"):
        load_calibration(path, settings)


def _ok(tmp_path: Path) -> Path:
    path = tmp_path / "ok.csv"
    linear_poses(path, np.full(8, 500.0))
    return path


def test_a_load_that_moves_with_the_offset_is_refused(tmp_path):
    # Fz the same non-zero value in every pose: it cannot be told from the offsets
    f = pose_loads(0).copy()
    f[:, 2] = 3.0
    path = tmp_path / "poses.csv"
    linear_poses(path, np.full(8, 500.0), loads=f, noise=1.0)
    init_config(_ok(tmp_path), tmp_path / "cfg.yaml")
    with pytest.raises(InputError, match=r"fz moves with the offset in every row \(a rank-deficient"):
        load_calibration(path, load_config(tmp_path / "cfg.yaml"))


OFFSETS = np.random.default_rng(2).uniform(300, 700, 8)  # counts, of the fitted set below


@pytest.fixture(scope="module")
def fitted_run(tmp_path_factory):
    """``fit --no-verdict`` of a linear pose set with OFFSETS and 0.3 counts of noise, once for
    the tests that read its model file (apply, tare, round trip, export): (model path, the
    command's result).  The config's method is auto; its verdict, when on, chose svr here
    too and wrote the same model (measured: the same zero to the bit), 2.4 s of CPU more."""
    tmp = tmp_path_factory.mktemp("intercept")
    path = tmp / "poses.csv"
    linear_poses(path, OFFSETS, noise=0.3)
    init_config(path, tmp / "cfg.yaml")
    r = invoke(["fit", path, "-c", tmp / "cfg.yaml", "-o", tmp / "m.json", "--no-verdict"])
    return tmp / "m.json", r


@pytest.fixture
def fitted(fitted_run):
    return fitted_run[0]


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_fit_then_apply_without_a_tare_recovers_the_loads(tmp_path, fitted_run):
    # a linear sensor: the model's decoupled forces of a fresh log, with only the model's
    # fitted offsets as its zero, come back to the noise (0.3 counts of ~300 per F.S.)
    offsets = OFFSETS
    fitted, r = fitted_run
    assert "zero: intercept" not in r.stderr  # the config says it: no note
    model = load_model(fitted)
    np.testing.assert_allclose(model.zero, offsets, atol=0.5)
    rng = np.random.default_rng(9)
    f = rng.uniform(-1, 1, (50, 6)) * FS * 0.5
    u = offsets + 300.0 * (f / FS) @ gauge_mix(0, 8).T
    log = tmp_path / "log.csv"
    with log.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([f"s{j}" for j in range(8)])
        w.writerows([[repr(float(v)) for v in row] for row in u])
    invoke(["apply", fitted, log, "-o", tmp_path / "out.csv"])
    with (tmp_path / "out.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    got = np.array([[float(row[c]) for c in ("fx", "fy", "fz", "mx", "my", "mz")] for row in rows])
    # noise 0.3 counts over 48 poses: the slopes and offsets to ~0.1 %, so 1 % F.S. is margin
    assert np.abs(got - f).max(axis=0).max() < 0.01 * FS.max()
    assert (np.abs(got - f) / FS).max() < 0.01


def test_a_dead_gauge_among_eight_is_named(tmp_path):
    poses = simulate_poses(0, samples=20, dead=3)
    path = tmp_path / "poses.csv"
    path.write_text("\n".join(pose_lines(poses)) + "\n")
    init_config(path, tmp_path / "cfg.yaml")
    r = invoke(["fit", path, "-c", tmp_path / "cfg.yaml", "-o", tmp_path / "m.json"], code=2)
    msg = assert_one_line_error(r, "'s3' is constant", "dead")
    for j in (0, 1, 2, 4, 5, 6, 7):
        assert f"'s{j}'" not in msg
    assert not (tmp_path / "m.json").exists()


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_misread_samples_are_rejected_and_counted_per_pose(tmp_path):
    poses = simulate_poses(1, samples=400)
    path = tmp_path / "poses.csv"
    path.write_text("\n".join(pose_lines(poses)) + "\n")
    calib, settings = read(tmp_path, path)
    # every misread is a digit appended (x10 or more): beyond 6 robust sigmas, so the
    # rejected count is at least the misreads the simulator wrote
    # Gaussian noise passes 6 sigma once in 5e8 samples: the rejected are the misreads
    misreads = [int((x > 2 ** 10 - 1).any(axis=1).sum()) for x in poses.samples]
    assert sum(misreads) > 0
    note = next(w for w in calib.warnings if "timestamped samples" in w)
    poses_hit = sum(m > 0 for m in misreads)
    assert f"{sum(misreads)} in {poses_hit} poses" in note
    p = next(i for i, m in enumerate(misreads) if m)  # the first pose with a misread
    assert f"lines {2 + 400 * p}-{401 + 400 * p}: {misreads[p]}" in note
    # the averages sit on the noise-free truth: 1.5 counts of noise over ~400 samples
    raw = calib.points[[f"{o}_raw" for o in settings.layout.outputs]].to_numpy()
    pose = (calib.points["row"].to_numpy() - 2) // 400
    assert np.abs(raw - poses.truth[pose]).max() < 1.0
    # the poses left out are those with a channel within 5 % of an end of 0 .. 1023 that
    # no longer follows the load: beyond 3 robust sigmas of its linear response fitted on
    # the poses not near (rails.py); here re-derived from the clean samples' means
    clean = np.array([x[(x <= 1023).all(axis=1)].mean(axis=0) for x in poses.samples])
    near = (clean <= 0.05 * 1023) | (clean >= 0.95 * 1023)
    out = np.zeros(len(clean), dtype=bool)
    design = np.column_stack([poses.loads, np.ones(len(clean))])
    for j in np.flatnonzero(near.any(axis=0)):
        rest = ~near[:, j]
        b = np.linalg.lstsq(design[rest], clean[rest, j], rcond=None)[0]
        r = clean[:, j] - design @ b
        sigma = 1.4826 * np.median(np.abs(r[rest] - np.median(r[rest])))
        out |= near[:, j] & (np.abs(r) > 3 * sigma)
    assert near.any() and len(calib.points) == len(POSITIONS) * 12 - out.sum()
    np.testing.assert_array_equal(np.sort(pose), np.flatnonzero(~out))
    assert any("within 5% of an end of its range 0 .. 1023 (a 10-bit ADC's" in w
               for w in calib.warnings)




@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_tare_and_zero_still_replace_the_fitted_offsets(tmp_path, fitted):
    model = load_model(fitted)
    log = tmp_path / "log.csv"
    shifted = model.zero + 25.0  # the sensor drifted 25 counts since its calibration
    with log.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([f"s{j}" for j in range(8)])
        w.writerows([[repr(float(v)) for v in shifted]] * 4)

    def forces(*extra):
        out = tmp_path / f"out{len(extra)}.csv"
        invoke(["apply", fitted, log, "-o", out, "--force", *extra])
        with out.open() as fh:
            return np.array([[float(r[c]) for c in ("fx", "fy", "fz", "mx", "my", "mz")]
                             for r in csv.DictReader(fh)])

    # the model's zero leaves the drift as a load; a tare of the log's own rows removes it,
    # and --zero with the drifted zero does the same: both decode a zero-corrected output of
    # 0, as the model does (its chi need not vanish at 0 under an intercept: ~1e-4 F.S.)
    at_zero = model.decouple(np.zeros((1, 8)), rotate=False, exact=True)
    drift = forces()
    assert (np.abs(drift - at_zero) / FS).max() > 0.01
    np.testing.assert_allclose(forces("--tare", "2"), np.repeat(at_zero, 4, axis=0), atol=1e-6)
    np.testing.assert_allclose(forces("--zero", ",".join(repr(float(v)) for v in shifted)),
                               np.repeat(at_zero, 4, axis=0), atol=1e-6)


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_the_fitted_zero_round_trips_and_is_checked(fitted):
    import json

    from fsdecouple.core.modelfile import content_digest, model_from_dict, model_to_dict
    from fsdecouple.errors import ModelFileError

    model = load_model(fitted)
    doc = model_to_dict(model)
    assert doc["format_version"] == 6 and set(doc["zero"]["offsets"]) == {f"s{j}" for j in range(8)}
    np.testing.assert_array_equal(model_from_dict(json.loads(json.dumps(doc))).zero, model.zero)
    del doc["zero"]["offsets"]["s3"]
    doc["integrity"]["digest"] = content_digest(doc)
    with pytest.raises(ModelFileError, match="zero: expected the offsets of outputs s0"):
        model_from_dict(doc)


def test_fit_without_a_config_on_another_rigs_file_points_to_init(tmp_path):
    path = tmp_path / "poses.csv"
    linear_poses(path, np.full(8, 512.0))
    r = invoke(["fit", path, "-o", tmp_path / "m.json"], code=2)
    assert_one_line_error(r, f"fsdecouple init {path} -o sensor.yaml")
    assert "did you mean" not in r.stderr


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_export_puts_the_fitted_offsets_in_the_header(tmp_path, fitted):
    # the header subtracts them itself (tests/export/test_intercept_export.py): no note
    r = invoke(["export", fitted, "-o", tmp_path / "d.h"])
    zero = load_model(fitted).zero
    assert "subtract this model's fitted offsets first" not in r.stdout
    assert f"fsd_zero[8] = {{{float(zero[0])!r}, " in (tmp_path / "d.h").read_text()
