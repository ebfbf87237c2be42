"""`fsdecouple init`: a config guessed from a calibration file, with its reasons."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest
import yaml
from conftest import ROOT, SAMPLE, assert_one_line_error, invoke

from fsdecouple.config import settings_from_dict
from fsdecouple.data.guesses import guess_config, nice_ceil
from fsdecouple.errors import InputError

LAB_HEADER = "Fx [gf],Fy [gf],Fz [gf],ch0,ch1,ch2,,,orientation,load on x"
LOADS = (300, 600, 900, 1200)  # gf; 1200 rounds up to 2000
SENS = (1500, 1400, 1300)  # counts per gf, so outputs reach ~1e6 + 1.8e6


def lab_rows() -> list[str]:
    """One zero row and four loads per axis in ADC counts, and a side table
    (orientation, load on x) that runs three rows past the data."""
    rows = []
    for a in range(3):
        for load in (0, *LOADS):
            f = [0, 0, 0]
            f[a] = load
            u = [1_000_000 + SENS[j] * f[j] + 7 * j for j in range(3)]
            rows.append(",".join(map(str, (*f, *u))))
    side = [f"{o},{v}" for o, v in
            [("up", 1), ("down", -1), ("left", 2), ("right", 3)] * 5]
    n = len(rows)
    return [f"{rows[i] if i < n else ',,,,,'},,,{side[i]}" for i in range(len(side))]


def validate(text: str) -> dict:
    """The YAML parses, has a units key of the expected shape, and the rest is a
    config the current parser accepts (it does not know `units` yet)."""
    doc = yaml.safe_load(text)
    assert set(doc["units"]) == {"load", "output"}
    rest = {k: v for k, v in doc.items() if k != "units"}
    settings_from_dict(rest)
    return doc


def test_lab_file_counts_in_gram_force(tmp_path):
    data = tmp_path / "lab.csv"
    data.write_text("\n".join([LAB_HEADER, *lab_rows()]) + "\n")
    out = tmp_path / "sensor.yaml"
    res = invoke(["init", data, "-o", out, "--json"])
    doc = json.loads(res.stdout)
    assert doc["columns"] == {"fx": "Fx [gf]", "fy": "Fy [gf]", "fz": "Fz [gf]",
                              "ux": "ch0", "uy": "ch1", "uz": "ch2"}
    assert doc["units"] == {"load": "gf", "output": "count"}
    # largest |load| 1200 gf on each axis; 2000 (1, 2, 2.5, 5 x 10^k) is 67 % above it,
    # more than the 25 % a full scale may add (issue 32), and 1200 is a round step itself
    assert doc["full_scale"] == {"x": 1200, "y": 1200, "z": 1200}
    assert doc["min_repetitions"] == 1
    assert doc["scaling"] == "full_scale"
    assert doc["csv"] == {"sep": ",", "decimal": "."}
    assert {"orientation", "load on x"} <= set(doc["ignored"])
    assert doc["ignored"].count("") == 2  # the two unnamed gap columns
    # the side table's rows past the data are not data rows
    assert doc["rows"] == 15

    text = out.read_text()
    cfg = validate(text)
    assert cfg["columns"]["ux"] == "ch0" and cfg["full_scale"]["z"] == 1200
    assert "# guessed: 'Fx [gf]': header names fx, unit gf (gram-force)" in text
    assert "'orientation': right of the unnamed column 7: a side table" in text
    assert "Table 2's gamma" in text


def test_paper_layout_is_the_identity(tmp_path):
    out = tmp_path / "sensor.yaml"
    invoke(["init", SAMPLE / "calibration" / "rep1.csv", "-o", out])
    g = guess_config(SAMPLE / "calibration" / "rep1.csv")
    assert g.columns == {k: k for k in ("axis", "fx", "fy", "fz", "ux", "uy", "uz")}
    assert g.units == {"load": "N", "output": "V"}
    assert g.scaling == "none"
    # the sample's peaks are 100, 100 and 150 N (README, Sample data): within 25 % of
    # themselves, so Section 3's full scales (issue 32: rounded up by at most 25 %)
    assert g.full_scale == {"x": 100, "y": 100, "z": 150}
    cfg = validate(out.read_text())
    assert cfg["columns"] == g.columns and cfg["scaling"] == "none"


def test_repetition_column_gives_min_repetitions(tmp_path):
    src = (SAMPLE / "calibration" / "rep1.csv").read_text().splitlines()
    lines = [f"Run,{src[0]}"] + [f"{r},{line}" for r in (1, 2, 3) for line in src[1:]]
    data = tmp_path / "all.csv"
    data.write_text("\n".join(lines) + "\n")
    g = guess_config(data)
    assert g.columns["repetition"] == "Run"
    assert g.min_repetitions == 3


def test_a_directory_of_repetition_files_counts_each_file(tmp_path):
    """init of sample_data/calibration said 'one repetition in this file' and wrote
    min_repetitions: 1 for six files that fit reads as six repetitions: a missing file
    then went unnoticed.  (A directory of one pose a file stays one set:
    tests/sim/test_pose_sets.py.)"""
    from fsdecouple import load_calibration, load_config
    from fsdecouple.data.init_config import guess_layout

    for n in (2, 6):
        cal = tmp_path / f"cal{n}"
        cal.mkdir()
        for r in range(1, n + 1):
            shutil.copy(SAMPLE / "calibration" / f"rep{r}.csv", cal)
        g = guess_layout(cal)
        assert g.min_repetitions == n
        assert g.reasons["min_repetitions"] == (f"no repetition column: each of the {n} files "
                                                "is one repetition")
        invoke(["init", cal, "-o", tmp_path / f"c{n}.yaml"])
        calib = load_calibration(cal, load_config(tmp_path / f"c{n}.yaml"))
        assert calib.repetitions == list(range(1, n + 1))
    # a read cut short counted the files read (80 rows: 2 of the 6)
    assert guess_layout(cal, max_rows=80).min_repetitions == 6
    # a repetition column counts in one file; in a directory fit reads a repetition a file
    runs = tmp_path / "runs"
    runs.mkdir()
    for r in (1, 2, 3):
        lines = (SAMPLE / "calibration" / f"rep{r}.csv").read_text().splitlines()
        (runs / f"rep{r}.csv").write_text("\n".join([f"run,{lines[0]}", *(f"1,{x}" for x in lines[1:])]))
    g = guess_layout(runs)
    assert g.columns["repetition"] == "run" and g.min_repetitions == 3


def test_semicolon_decimal_comma(tmp_path):
    data = tmp_path / "eu.csv"
    data.write_text("Fx (N);Fy (N);Fz (N);u_x;u_y;u_z\n"
                    "0;0;0;0,001;-0,002;0,003\n"
                    "10,5;0;0;0,5;0,01;-0,02\n"
                    "0;20;0;0,02;0,9;0,01\n"
                    "0;0;-30;0,01;0,03;-1,2\n")
    out = tmp_path / "eu.yaml"
    doc = json.loads(invoke(["init", data, "-o", out, "--json"]).stdout)
    assert doc["csv"] == {"sep": ";", "decimal": ","}
    assert doc["columns"]["fx"] == "Fx (N)" and doc["columns"]["uz"] == "u_z"
    assert doc["units"]["load"] == "N"
    # 10,5 read as 10.5 (not 105): rounded up by at most 25 % to 12; 20 and 30 stay
    assert doc["full_scale"] == {"x": 12, "y": 20, "z": 30}
    cfg = validate(out.read_text())
    assert cfg["csv"] == {"sep": ";", "decimal": ","}
    assert settings_from_dict({k: v for k, v in cfg.items() if k != "units"}).sep == ";"


def test_missing_quantity_is_one_line_and_writes_nothing(tmp_path):
    data = tmp_path / "lab.csv"
    data.write_text("Fx [gf],Fy [gf],Fz [gf],ch0,ch1\n0,0,0,1,2\n100,0,0,5,6\n")
    out = tmp_path / "sensor.yaml"
    res = invoke(["init", data, "-o", out], code=2)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert str(data) in lines[0] and "uz" in lines[0] and "ch0" in lines[0]
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [data]  # no temporary file left either
    with pytest.raises(InputError, match=r"no column found for uz .*header: 'Fx \[gf\]'"):
        guess_config(data)


def test_two_candidates_are_reported(tmp_path):
    data = tmp_path / "two.csv"
    data.write_text("fx,force_x,fy,fz,ux,uy,uz\n0,0,0,0,0,0,0\n1,1,1,1,0.5,0.5,0.5\n")
    g = guess_config(data)
    assert g.columns["fx"] == "fx"  # the config's own name wins
    assert any("fx: more than one candidate" in n and "force_x" in n for n in g.notes)
    assert "force_x" in [i.name for i in g.ignored]


def test_duplicated_header_is_ignored(tmp_path):
    data = tmp_path / "dup.csv"
    data.write_text("fx,fy,fz,ux,uy,uz,note,note\n0,0,0,0,0,0,a,b\n1,1,1,1,1,1,c,d\n")
    g = guess_config(data)
    assert [i.reason for i in g.ignored] == ["header name repeated (2 columns)"] * 2


def test_existing_output_needs_force(tmp_path):
    out = tmp_path / "sensor.yaml"
    out.write_text("keep me\n")
    data = SAMPLE / "calibration" / "rep1.csv"
    res = invoke(["init", data, "-o", out], code=2)
    assert "already exists; pass --force" in res.stderr
    assert out.read_text() == "keep me\n"
    invoke(["init", data, "-o", out, "--force"])
    validate(out.read_text())


def test_output_may_not_be_the_data(tmp_path):
    data = tmp_path / "rep1.csv"
    shutil.copy(SAMPLE / "calibration" / "rep1.csv", data)
    res = invoke(["init", data, "-o", data, "--force"], code=2)
    assert "is also an input file" in res.stderr


def test_header_text_is_printed_literally(tmp_path):
    data = tmp_path / "odd.csv"
    data.write_text("fx,fy,fz,ux,uy,uz,[bold]x,[/]\n0,0,0,0,0,0,1,2\n5,0,0,1,0,0,3,4\n")
    out = tmp_path / "odd.yaml"
    res = invoke(["init", data, "-o", out], terminal_width=200)
    assert "[bold]x" in res.stdout and "[/]" in res.stdout
    text = out.read_text()
    validate(text)
    assert "'[bold]x'" in text

    # and in the one-line error that quotes the header
    bad = tmp_path / "bad.csv"
    bad.write_text("fx,fy,fz,ux,uy,[/]\n0,0,0,0,0,0\n")
    res = invoke(["init", bad, "-o", tmp_path / "bad.yaml"], code=2)
    assert "'[/]'" in res.stderr and len(res.stderr.strip().splitlines()) == 1


def test_column_names_read_back_exactly(tmp_path):
    """Header names YAML would misread unquoted (a number, 'yes', a '#') survive."""
    data = tmp_path / "names.csv"
    data.write_text("Fx [N],Fy [N],Fz [N],ux # raw,V2,V3\n0,0,0,0,0,0\n1,1,1,1,1,1\n")
    # 'ux # raw' names no output; V1..V3 are incomplete, so ux is missing
    with pytest.raises(InputError, match="no column found for ux"):
        guess_config(data)
    data.write_text("Fx [N],Fy [N],Fz [N],V1,V2,V3,yes,#c\n0,0,0,0,0,0,1,2\n1,1,1,1,1,1,3,4\n")
    g = guess_config(data)
    assert [g.columns[k] for k in ("ux", "uy", "uz")] == ["V1", "V2", "V3"]
    cfg = validate(g.to_yaml())
    assert cfg["columns"] == g.columns


@pytest.mark.parametrize(("value", "nice"), [
    (1200, 2000), (100, 100), (150, 200), (0.3, 0.5), (2.2, 2.5), (5000.1, 10000), (0.25, 0.25),
])
def test_nice_ceil(value, nice):
    assert nice_ceil(value) == nice


# --- force/torque sensors: components and their prime outputs ----------------------


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_six_axis_sample_gives_its_own_layout_and_fits(tmp_path):
    """The guess for the simulator's file is the simulator's config: same components,
    outputs, full scales and units; and that config fits the sample."""
    from fsdecouple import fit, load_calibration, load_config
    out = tmp_path / "six.yaml"
    doc = json.loads(invoke(["init", SAMPLE / "six_axis" / "calibration" / "rep1.csv", "-o", out,
                             "--json"]).stdout)
    want = yaml.safe_load((ROOT / "configs" / "six-axis.yaml").read_text())
    assert doc["components"] == want["components"] and doc["outputs"] == want["outputs"]
    assert doc["full_scale"] == want["full_scale"]
    written = yaml.safe_load(out.read_text())
    assert written["units"] == want["units"] and written["scaling"] == "none"
    settings = load_config(out)
    model = fit(load_calibration(SAMPLE / "six_axis" / "calibration", settings), settings)
    assert model.layout.loads == tuple(want["components"])


def test_prime_outputs_are_paired_by_the_data_not_the_channel_order(tmp_path):
    """Channels wired in another order (ch0 is mz's bridge, ...), units in the headers:
    each component gets the channel its own sweep drives."""
    from fsdecouple.sim.six_axis import COMPONENTS, OUTPUTS, simulate_calibration, six_axis_sensor

    table = simulate_calibration(six_axis_sensor(4), repetitions=2, seed=4)
    wiring = [5, 2, 0, 4, 1, 3]  # channel k carries output OUTPUTS[wiring[k]]
    headers = {"fx": "Fx [N]", "fy": "Fy [N]", "fz": "Fz [N]",
               "mx": "Tx [N·mm]", "my": "Ty [N·mm]", "mz": "Tz [N·mm]"}
    frame = {"Rep": table["repetition"]}
    for c in COMPONENTS:
        frame[headers[c]] = table[c] * (1000 if c[0] == "m" else 1)  # N·m -> N·mm
    for k, j in enumerate(wiring):
        frame[f"ch{k} [V]"] = table[OUTPUTS[j]]
    frame["operator"] = "AB"
    data = tmp_path / "ft.csv"
    import pandas as pd
    pd.DataFrame(frame).to_csv(data, index=False)
    doc = json.loads(invoke(["init", data, "-o", tmp_path / "ft.yaml", "--json"]).stdout)
    assert doc["components"] == list(COMPONENTS)
    # component a's prime output OUTPUTS[a] sits on the channel k with wiring[k] == a
    assert doc["outputs"] == [f"ch{wiring.index(a)}" for a in range(6)]
    assert doc["columns"]["ch0"] == "ch0 [V]" and doc["columns"]["mx"] == "Tx [N·mm]"
    assert doc["load_units"] == {"fx": "N", "fy": "N", "fz": "N",
                                 "mx": "N·mm", "my": "N·mm", "mz": "N·mm"}
    assert doc["full_scale"]["mx"] == 5000 and doc["full_scale"]["fz"] == 200
    assert doc["min_repetitions"] == 2 and doc["columns"]["repetition"] == "Rep"
    assert "operator" in doc["ignored"]


def test_a_torque_header_without_one_channel_per_component_is_one_line(tmp_path):
    data = tmp_path / "ft.csv"
    data.write_text("Fx,Fy,Fz,Mx,My,Mz,u1,u2,u3,u4,u5\n" + "0,0,0,0,0,0,1,2,3,4,5\n")
    out = tmp_path / "ft.yaml"
    res = invoke(["init", data, "-o", out], code=2)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and str(data) in lines[0] and "u1..u6" in lines[0], res.stderr
    assert not out.exists()


def test_a_three_axis_file_with_moment_columns_still_reads_as_three_axes(tmp_path):
    data = tmp_path / "three.csv"
    shutil.copy(SAMPLE / "calibration" / "rep1.csv", data)
    lines = data.read_text().splitlines()
    data.write_text("\n".join([lines[0] + ",mx,my,mz", *(ln + ",0,0,0" for ln in lines[1:])]) + "\n")
    doc = json.loads(invoke(["init", data, "-o", tmp_path / "s.yaml", "--json"]).stdout)
    assert "components" not in doc and doc["columns"]["ux"] == "ux"
    assert {"mx", "my", "mz"} <= set(doc["ignored"])


@pytest.mark.parametrize("edit, match", [
    (lambda h, rows: (h, [rows[0].replace("-100.000000", "1e300", 1), *rows[1:]]),
     "full_scale: fx: 1e\\+300 is outside"),
    (lambda h, rows: (h.replace("u2", "u_1"), rows), "do not have one name each"),
])
def test_a_guess_that_would_not_load_is_one_line_and_writes_nothing(tmp_path, edit, match):
    header, *rows = (SAMPLE / "six_axis" / "calibration" / "rep1.csv").read_text().splitlines()
    header, rows = edit(header, rows)
    data, out = tmp_path / "ft.csv", tmp_path / "ft.yaml"
    data.write_text("\n".join([header, *rows]) + "\n")
    res = invoke(["init", data, "-o", out], code=2)
    assert len(res.stderr.strip().splitlines()) == 1 and re.search(match, res.stderr), res.stderr
    assert not out.exists() and list(tmp_path.iterdir()) == [data]


def test_an_infinite_reading_is_skipped_not_a_traceback(tmp_path):
    """1e400 matches a number's pattern but reads as inf: left out, never a crash."""
    for src, bad, peak in ((SAMPLE / "calibration" / "rep1.csv", "x,1e400,0,0,1,0,0", 150),
                           (SAMPLE / "six_axis" / "calibration" / "rep1.csv",
                            "fx,1e400,0,0,0,0,0,1,2,3,4,5,6", 200)):
        data = tmp_path / f"{src.parent.parent.name}.csv"
        data.write_text(src.read_text() + bad + "\n")
        doc = json.loads(invoke(["init", data, "-o", tmp_path / f"{data.stem}.yaml", "--json"]).stdout)
        # the largest finite load of each sample is its full scale (the inf row left out)
        assert max(doc["full_scale"].values()) == peak, doc["full_scale"]


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_init_reads_any_input_once_and_within_the_limits(tmp_path):
    """A 200 KB cell or header, /dev/zero, a pipe (`init <(cat f)`, `cat f | init /dev/stdin`):
    one line and exit 2 for the bad ones, the same guess for a pipe as for the file."""
    import subprocess
    import sys

    cell = tmp_path / "cell.csv"
    cell.write_text("fx,fy,fz,ux,uy,uz\n1,2,3," + "4" * 200_000 + ",5,6\n")
    r = invoke(["init", cell, "-o", tmp_path / "a.yaml"], code=2)
    assert_one_line_error(r, "cell.csv, row 2", "field larger")
    header = tmp_path / "header.csv"
    header.write_text("x" * 200_000 + ",fy\n1,2\n")
    assert_one_line_error(invoke(["init", header, "-o", tmp_path / "a.yaml"], code=2), "row 1")
    if Path("/dev/zero").exists():
        assert_one_line_error(invoke(["init", "/dev/zero", "-o", tmp_path / "a.yaml"], code=2),
                              "limit for a calibration file")
    assert not (tmp_path / "a.yaml").exists()
    lab = SAMPLE / "loadcell" / "calibration.csv"
    invoke(["init", lab, "-o", tmp_path / "file.yaml"])
    r = subprocess.run([sys.executable, "-m", "fsdecouple", "init", "/dev/stdin", "-o",
                        str(tmp_path / "pipe.yaml")], input=lab.read_bytes(), capture_output=True)
    assert r.returncode == 0, r.stderr
    pipe, file = (yaml.safe_load((tmp_path / n).read_text()) for n in ("pipe.yaml", "file.yaml"))
    assert pipe.pop("sensor") != file.pop("sensor")  # named after the file: stdin here
    assert pipe == file


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_a_repetition_file_whose_name_is_not_utf8_is_read(tmp_path):
    """A 0xff byte in a repetition's file name was a UnicodeEncodeError inside pyarrow, then
    a refusal; such names are legal (issue 34): read, the byte shown as \\xff."""
    import os

    cal = tmp_path / "cal"
    cal.mkdir()
    for f in (SAMPLE / "calibration").glob("rep*.csv"):
        (cal / f.name).write_bytes(f.read_bytes())
    os.rename(cal / "rep3.csv", os.fsencode(cal) + b"/rep3\xff.csv")
    invoke(["fit", cal, "-o", tmp_path / "out.json", "--no-verdict"])
    assert "rep3\\\\xff.csv" in (tmp_path / "out.json").read_text()  # JSON escapes the backslash
    invoke(["ingest", cal, "-o", tmp_path / "out.csv"])
    assert "rep3\\xff.csv" in (tmp_path / "out.csv").read_text()
