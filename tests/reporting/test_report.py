"""`fsdecouple report`: a self-contained HTML file and PNG figures from the sample data."""

from __future__ import annotations

import base64
import io
import json
import re
from html.parser import HTMLParser

import numpy as np
import pytest
from conftest import ROOT, SAMPLE, assert_one_line_error, invoke
from matplotlib.image import imread

pytestmark = pytest.mark.slow  # renders every figure of the report with matplotlib

FIGURES = ("fig-omega", "fig-chi", "fig-residuals")
PNGS = ("figure6_omega.png", "figure7_chi.png", "residuals.png")
TABLES = ("table-summary", "table-provenance", "table-settings", "table-omega", "table-chi",
          "table-gamma-fit", "table-gamma-methods", "table-gamma-svr", "table-gross-error",
          "table-omega-gross", "table-task", "table-checks", "table-cv-checks")
VOID = {"meta", "img", "br", "hr", "link", "input"}


class Tree(HTMLParser):
    """Checks that tags nest and collects ids, images and links."""

    def __init__(self):
        super().__init__()
        self.stack, self.ids, self.imgs, self.urls, self.errors = [], {}, [], [], []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            assert a["id"] not in self.ids, f"duplicate id {a['id']}"
            self.ids[a["id"]] = tag
        if tag == "img":
            self.imgs.append((self.stack[-1] if self.stack else None, a))
        for key in ("src", "href"):
            if key in a:
                self.urls.append(a[key])
        if tag not in VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes <{self.stack[-1] if self.stack else None}>")
        else:
            self.stack.pop()


def parse(text: str) -> Tree:
    t = Tree()
    t.feed(text)
    t.close()
    assert not t.errors and not t.stack, (t.errors[:5], t.stack)
    return t


class Tables(HTMLParser):
    """Every <table id=...> as rows of cells (tag, text, class); nested spans' text joins
    their cell's."""

    def __init__(self):
        super().__init__()
        self.tables: dict[str, list[list[tuple[str, str, str]]]] = {}
        self._table = self._row = self._cell = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "table":
            self._table = self.tables.setdefault(a["id"], [])
        elif tag == "tr" and self._table is not None:
            self._row = []
            self._table.append(self._row)
        elif tag in ("td", "th") and self._row is not None:
            self._cell = [tag, [], a.get("class") or ""]

    def handle_data(self, data):
        if self._cell is not None:
            self._cell[1].append(data)

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self._row.append((self._cell[0], " ".join("".join(self._cell[1]).split()), self._cell[2]))
            self._cell = None
        elif tag == "tr":
            self._row = None
        elif tag == "table":
            self._table = None


def tables_of(text: str) -> dict[str, list[list[tuple[str, str, str]]]]:
    t = Tables()
    t.feed(text)
    t.close()
    return t.tables


def body_rows(rows):
    """Rows with at least one <td>: the table body (header rows are all <th>)."""
    return [r for r in rows if any(tag == "td" for tag, _, _ in r)]


def number(text: str) -> float:
    """The number a cell shows: '▲ 1.23 %' -> 0.0123, '0.0133' -> 0.0133."""
    text = text.replace("▲", "").strip()
    if text.endswith("%"):
        return float(text[:-1]) / 100.0
    return float(text)


def shown(cell_text: str, value: float, decimals: int, percent: bool = True):
    """Assert a cell shows ``value`` to its printed ``decimals`` (half a unit in the last place)."""
    assert cell_text.endswith(" %") == percent, cell_text
    half = 0.5 * 10.0 ** -decimals / (100.0 if percent else 1.0)
    assert abs(number(cell_text) - value) <= half * (1 + 1e-9), (cell_text, value)


def decode_png(src: str) -> np.ndarray:
    prefix = "data:image/png;base64,"
    assert src.startswith(prefix)
    return imread(io.BytesIO(base64.b64decode(src[len(prefix):], validate=True)), format="png")


def assert_figure_ok(img: np.ndarray, min_w=800, min_h=350):
    h, w = img.shape[:2]
    assert w >= min_w and h >= min_h, (w, h)
    # a blank (all-white) image has no spread; a plot's black lines and markers do
    assert img[..., :3].std() > 0.05


@pytest.fixture(scope="module")
def full_report(tmp_path_factory, sample_model, cv_json):
    out = tmp_path_factory.mktemp("report")
    html = out / "report.html"
    r = invoke(["report", sample_model, "--cv", cv_json, "--calib", SAMPLE / "calibration",
                "-o", html, "--png", out / "png"])
    assert "report written to" in r.stdout
    return html, out / "png"


@pytest.fixture(scope="module")
def shown_tables(full_report):
    return tables_of(full_report[0].read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def model_doc(sample_model):
    """The model file as plain JSON: its numbers, read without fsdecouple."""
    return json.loads(sample_model.read_text(encoding="utf-8"))


def test_omega_table_shows_the_model_files_k(shown_tables, model_doc):
    rows = body_rows(shown_tables["table-omega"])
    assert [r[0][1] for r in rows] == ["x", "y", "z"]
    for row in rows:
        omega = model_doc["omega"][row[0][1]]
        k_text, inv_text, r2_text, n_text = (c[1] for c in row[1:])
        # k and 1/k (eq. 13) to 6 significant digits (by magnitude: 0.00123075 count/gf,
        # never 0.0012), R^2 to 6 decimals
        assert float(k_text) == pytest.approx(omega["k"], rel=5e-6)
        assert float(inv_text) == pytest.approx(1.0 / omega["k"], rel=5e-6)
        shown(r2_text, omega["r2"], 6, percent=False)
        assert int(n_text) == model_doc["report"]["n_points"][row[0][1]]
    # the sample sensor is the paper's: 1/k within 0.1 % of eq. (13)
    inverse = [number(r[2][1]) for r in rows]
    np.testing.assert_allclose(inverse, [75.065, 77.788, 125.17], rtol=1e-3)


def test_chi_table_shows_the_model_files_support_vectors_and_ranges(shown_tables, model_doc):
    rows = body_rows(shown_tables["table-chi"])
    assert [r[0][1] for r in rows] == ["χxy", "χxz", "χyx", "χyz", "χzx", "χzy"]
    for row in rows:
        chi = model_doc["chi"][row[0][1][1:]]
        assert row[1][1] == f"u{chi['input_axis']}"
        assert row[2][1] == f"{len(chi['support_vectors'])} / {chi['n_points']}"
        lo, hi = (float(v) for v in row[3][1].split("…"))
        np.testing.assert_allclose([lo, hi], chi["input_range"], rtol=0, atol=0.5e-4)


def test_in_sample_gamma_table_equals_eq_12_recomputed(shown_tables, sample_model):
    """gamma_a = (max|f_b| + max|f_c|) / f_a(FS) over the a sweeps of all repetitions,
    by hand from the calibration points, initial (u / k) and decoupled (model.decouple)."""
    from fsdecouple import load_calibration, load_config, load_model
    model = load_model(sample_model)
    points = load_calibration(SAMPLE / "calibration", load_config()).points
    u = points[["ux", "uy", "uz"]].to_numpy()
    forces = {"initial": u / model.k, "decoupled": model.decouple(u, rotate=False)}
    full_scale = {"x": 100.0, "y": 100.0, "z": 150.0}  # Section 3
    rows = body_rows(shown_tables["table-gamma-fit"])
    assert [r[0][1] for r in rows] == ["x", "y", "z"]
    for a, row in enumerate(rows):
        axis = row[0][1]
        sweep = (points["axis"] == axis).to_numpy()
        for col, f in zip((1, 2), forces.values(), strict=True):
            others = np.abs(np.delete(f[sweep], a, axis=1)).max(axis=0)
            gamma = others.sum() / full_scale[axis]
            shown(row[col][1], gamma, 2)
        # decoupling is what the model is for: after < before on every axis here
        assert number(row[2][1]) < number(row[1][1]) and row[2][2] != "worse"


def test_table_1_and_3_analogues_show_the_cv_records(shown_tables, cv_json):
    doc = json.loads(cv_json.read_text())
    gamma = {(r["round"], r["test_set"], r["method"], r["axis"]): r["value"]
             for r in doc["records"] if r["metric"] == "gamma"}
    methods = doc["methods"]
    held_out = [(rnd, rep) for rnd, fold in enumerate(doc["folds"], 1) for rep in fold]
    rows = body_rows(shown_tables["table-gamma-methods"])
    # one row per held-out repetition: Table 1 has 3 rounds x tests I and II
    assert [(int(r[0][1]), r[1][1]) for r in rows] == [
        (rnd, f"test {'I' if i == 0 else 'II'} (rep {rep})")
        for rnd, fold in enumerate(doc["folds"], 1) for i, rep in enumerate(fold)]
    for row, (rnd, rep) in zip(rows, held_out, strict=True):
        cells = row[2:]
        assert len(cells) == 3 * len(methods)
        for j, (tag, text, cls) in enumerate(cells):
            assert tag == "td"
            axis, method = "xyz"[j // len(methods)], methods[j % len(methods)]
            value = gamma[(rnd, rep, method, axis)]
            shown(text, value, 2)
            worse = method != "initial" and value > gamma[(rnd, rep, "initial", axis)]
            assert (cls == "worse") == worse, (rnd, rep, method, axis)
    # Table 3: the svr columns again, plus the worst held-out gamma per axis
    rows = body_rows(shown_tables["table-gamma-svr"])
    assert len(rows) == len(held_out) + 1 and rows[-1][0][1] == "worst"
    for row, (rnd, rep) in zip(rows[:-1], held_out, strict=True):
        for axis, (_, text, _) in zip("xyz", row[2:], strict=True):
            shown(text, gamma[(rnd, rep, "svr", axis)], 2)
    for axis, (_, text, _) in zip("xyz", rows[-1][2:], strict=True):
        shown(text, max(gamma[(rnd, rep, "svr", axis)] for rnd, rep in held_out), 2)


def test_gross_error_and_task_tables_show_the_cv_records(shown_tables, cv_json):
    doc = json.loads(cv_json.read_text())
    ge = doc["gross_error"]
    clean = {(r["round"], r["test_set"], r["method"], r["axis"]): r["value"] for r in doc["records"]}
    gross = {(r["round"], r["test_set"], r["method"], r["axis"]): r["value"] for r in ge["records"]}
    rows = body_rows(shown_tables["table-gross-error"])
    keys = sorted({(k[0], k[1]) for k in gross if k[2] == "svr"})
    assert [(int(r[0][1]), int(r[1][1].split("rep ")[1].rstrip(")"))) for r in rows] == keys
    for row, (rnd, rep) in zip(rows, keys, strict=True):
        for j, axis in enumerate("xyz"):
            shown(row[2 + 2 * j][1], clean[(rnd, rep, "svr", axis)], 2)
            shown(row[3 + 2 * j][1], gross[(rnd, rep, "svr", axis)], 2)
    rows = body_rows(shown_tables["table-omega-gross"])
    assert len(rows) == len(ge["omega"])
    for row, o in zip(rows, ge["omega"], strict=True):
        assert (int(row[0][1]), row[1][1]) == (o["round"], o["axis"])
        assert float(row[2][1]) == pytest.approx(o["k_clean"], rel=5e-6)
        assert float(row[3][1]) == pytest.approx(o["k_gross"], rel=5e-6)
        shown(row[4][1], o["inverse_clean"], 3, percent=False)
        shown(row[5][1], o["inverse_gross"], 3, percent=False)
        shown(row[6][1].replace("+", ""), o["inverse_gross"] / o["inverse_clean"] - 1, 2)
    task = {(r["round"], r["method"], r["axis"], r["metric"]): r["value"]
            for r in doc["task"]["records"]}
    rows = body_rows(shown_tables["table-task"])
    names = {"initial": "initial (ω⁻¹ only)", "linear": "linear matrix", "rbf-mimo": "MIMO RBF NN",
             "rbf-siso": "SISO RBF NN", "svr": "ε-SVR"}
    assert len(rows) == len({(k[0], k[1]) for k in task})
    for row in rows:
        rnd, method = int(row[0][1]), next(m for m, n in names.items() if n == row[1][1])
        for j, (_, text, _) in enumerate(row[2:]):
            axis, metric = "xyz"[j // 2], ("max_error", "rms_error")[j % 2]
            shown(text, task[(rnd, method, axis, metric)], 3)


def test_tables_of_every_method_scroll_sideways_instead_of_wrapping(full_report):
    """The tables with a row for every method and columns for every component are wider
    than a page for six axes: each sits in the scroll box whose cells do not wrap."""
    text = full_report[0].read_text(encoding="utf-8")
    assert re.search(r"\.scroll\{overflow-x:auto\}\.scroll td\{white-space:nowrap\}", text)
    for tid in ("table-gamma-methods", "table-task"):
        assert f'<div class="scroll"><table id="{tid}">' in text, tid


def test_report_is_self_contained_html_with_every_figure_and_table(full_report):
    html, _ = full_report
    text = html.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>")
    tree = parse(text)
    for fid in FIGURES:
        assert tree.ids.get(fid) == "figure", fid
    assert len(tree.imgs) == len(FIGURES)
    for _, attrs in tree.imgs:
        assert attrs.get("alt")
        assert_figure_ok(decode_png(attrs["src"]))
    for tid in TABLES:
        assert tree.ids.get(tid) == "table", tid
    # viewable offline: nothing is fetched from anywhere, and no link to a certificate
    # whose name the report cannot know (it always linked certificate.html); the command
    # that writes one is named instead
    assert [u for u in tree.urls if not u.startswith("data:")] == []
    assert "fsdecouple certificate MODEL CALIB -o" in text
    assert "http://" not in text and "https://" not in text


def test_report_marks_worse_than_initial_and_shows_badges(full_report):
    text = full_report[0].read_text(encoding="utf-8")
    assert "PASS" in text and 'class="badge' in text
    # a real cv run has every baseline: all columns and the dashed SISO curves
    assert "Not in cv.json (not run)" not in text and "SISO RBF NN curves dashed" in text
    assert "MIMO RBF NN" in text and "linear matrix" in text


def test_png_files_are_sized_and_not_blank(full_report):
    _, png_dir = full_report
    assert sorted(p.name for p in png_dir.iterdir()) == sorted(PNGS)
    for name in PNGS:
        img = imread(png_dir / name)
        assert_figure_ok(img)


def test_worse_cells_are_highlighted(unrendered, tmp_path, sample_model, cv_json):
    doc = json.loads(cv_json.read_text())
    for r in doc["records"]:
        if (r["round"], r["test_set"], r["method"], r["axis"]) == (1, 1, "svr", "y"):
            r["value"] = 0.5
    bad = tmp_path / "cv.json"
    bad.write_text(json.dumps(doc))
    invoke(["report", sample_model, "--cv", cv_json, "-o", tmp_path / "before.html"])
    invoke(["report", sample_model, "--cv", bad, "-o", tmp_path / "r.html"])
    before = (tmp_path / "before.html").read_text(encoding="utf-8").count('class="worse"')
    text = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert text.count('class="worse"') == before + 2  # Table 1 and Table 3 analogues
    assert "▲</span> 50.00 %" in text
    # and they are the cells of that record: round 1, test I (rep 1), gamma_y, svr
    tables = tables_of(text)
    first = body_rows(tables["table-gamma-methods"])[0]
    assert first[1][1] == "test I (rep 1)"
    svr_y = first[2 + len(doc["methods"]) + doc["methods"].index("svr")]
    assert svr_y == ("td", "▲ 50.00 %", "worse")
    assert body_rows(tables["table-gamma-svr"])[0][3] == ("td", "▲ 50.00 %", "worse")


def test_report_from_the_model_alone(unrendered, tmp_path, sample_model):
    html = tmp_path / "r.html"
    invoke(["report", sample_model, "-o", html, "--png", tmp_path / "png"])
    text = html.read_text(encoding="utf-8")
    tree = parse(text)
    assert {"fig-omega", "fig-chi"} <= set(tree.ids) and "fig-residuals" not in tree.ids
    assert "pass --calib CALIB" in text and "No cross-validation results" in text
    assert sorted(p.name for p in (tmp_path / "png").iterdir()) == ["figure6_omega.png",
                                                                   "figure7_chi.png"]


def test_report_with_calib_only_has_in_sample_residuals(unrendered, tmp_path, sample_model):
    html = tmp_path / "r.html"
    r = invoke(["report", sample_model, "--calib", SAMPLE / "calibration", "-o", html])
    tree = parse(html.read_text(encoding="utf-8"))
    assert "fig-residuals" in tree.ids
    assert "in-sample" in html.read_text(encoding="utf-8")
    assert "warning" not in r.stderr


def test_report_of_another_set_says_so_on_the_terminal_too(unrendered, tmp_path, sample_model):
    """Plotting a set the model was not fitted on was said only inside the HTML."""
    import shutil

    other = tmp_path / "other"
    shutil.copytree(SAMPLE / "calibration", other)
    lines = (other / "rep1.csv").read_text().splitlines()
    lines[3] = lines[3][:-1] + ("1" if lines[3][-1] != "1" else "2")  # one digit of one reading
    (other / "rep1.csv").write_text("\n".join(lines) + "\n")
    r = invoke(["report", sample_model, "--calib", other, "-o", tmp_path / "r.html"])
    assert "not exactly the files the model was fitted on" in r.stderr
    assert "digests differ" in (tmp_path / "r.html").read_text(encoding="utf-8")


def test_report_refuses_to_overwrite_without_force(unrendered, tmp_path, sample_model):
    html = tmp_path / "r.html"
    html.write_text("keep")
    r = invoke(["report", sample_model, "-o", html], code=2)
    assert "--force" in r.stderr and html.read_text() == "keep"
    invoke(["report", sample_model, "-o", html, "--force"])
    assert html.read_text().startswith("<!DOCTYPE html>")


@pytest.mark.parametrize("content, match", [
    ("{", "not valid JSON"),
    ('{"format": "fsdecouple.model"}', "not a cv.json"),
    ('{"format": "fsdecouple.cv", "format_version": 99}', "format_version 99"),
])
def test_bad_cv_file_is_one_line_error(tmp_path, sample_model, content, match):
    cv = tmp_path / "cv.json"
    cv.write_text(content)
    r = invoke(["report", sample_model, "--cv", cv, "-o", tmp_path / "r.html"], code=2)
    assert match in r.stderr and not (tmp_path / "r.html").exists()


def test_fit_mentions_the_report_command(sample_fit):
    _, r = sample_fit  # the suite's `fsdecouple fit sample_data/calibration -o model.json`
    assert "calibration report: fsdecouple report model.json -o report.html" in r.stdout


def png_description(png: bytes) -> dict:
    """The ``Description`` text chunk of a PNG, read by the format's own layout."""
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    at = 8
    while at < len(png):
        size, kind = int.from_bytes(png[at:at + 4], "big"), png[at + 4:at + 8]
        data = png[at + 8:at + 8 + size]
        if kind == b"tEXt" and data.startswith(b"Description\x00"):
            return json.loads(data.split(b"\x00", 1)[1].decode("latin-1"))
        at += 12 + size
    raise AssertionError("no Description chunk")


def test_docs_figure_is_the_figure_report_draws_now(tmp_path, sample_model):
    """docs/figure7.png (docs/make_figures.py) shows what `report --calib` draws today:
    the same titles and labels, and every line's points within 1 % of its panel's range:
    what a reader would see move.  The committed figure was fitted on another machine,
    where libsvm may stop elsewhere within its tolerance (epsilon = 1e-4 of the output's
    scale, a few thousandths of a chi's range), so no tighter."""
    invoke(["report", sample_model, "--calib", SAMPLE / "calibration", "-o", tmp_path / "r.html",
            "--png", tmp_path / "png"])
    new = png_description((tmp_path / "png" / "figure7_chi.png").read_bytes())
    old = png_description((ROOT / "docs" / "figure7.png").read_bytes())
    stale = "docs/figure7.png is stale: run python docs/make_figures.py"
    assert old["title"] == new["title"], stale
    assert len(old["panels"]) == len(new["panels"]) == 6, stale
    for p, q in zip(old["panels"], new["panels"], strict=True):
        assert (p["title"], p["xlabel"], p["ylabel"]) == (q["title"], q["xlabel"], q["ylabel"]), stale
        assert [ln["label"] for ln in p["lines"]] == [ln["label"] for ln in q["lines"]], stale
        for axis in ("x", "y"):
            span = np.ptp(np.concatenate([ln[axis] for ln in q["lines"]]))
            for a, b in zip(p["lines"], q["lines"], strict=True):
                np.testing.assert_allclose(a[axis], b[axis], rtol=0, atol=1e-2 * span, err_msg=stale)


def test_readme_ends_its_main_command_with_a_report_and_shows_a_figure():
    readme = (SAMPLE.parent / "README.md").read_text(encoding="utf-8")
    main = next(ln for ln in readme.splitlines() if ln.startswith("python3 -m venv") and " fit " in ln)
    assert main.endswith(
        "report model.json --cv cv.json --calib sample_data/calibration -o report.html --force"
    )
    assert "](docs/figure7.png)" in readme
    assert_figure_ok(imread(SAMPLE.parent / "docs" / "figure7.png"))


def test_report_copes_with_a_minimal_cv_and_absent_methods(unrendered, tmp_path, sample_model, cv_json):
    doc = json.loads(cv_json.read_text())
    for c in doc["curves"]["chi"].values():
        del c["rbf-siso"]
    doc["records"] = [r for r in doc["records"] if r["method"] in ("initial", "svr")]
    without = tmp_path / "svr-only.json"
    without.write_text(json.dumps(doc))
    invoke(["report", sample_model, "--cv", without, "-o", tmp_path / "a.html", "--png", tmp_path / "png"])
    text = (tmp_path / "a.html").read_text(encoding="utf-8")
    assert "no SISO RBF NN curves" in text and "Not in cv.json (not run)" in text
    minimal = {k: doc[k] for k in ("format", "format_version", "folds", "methods", "records")}
    minimal.update(task=None, gross_error=None, points=[], checks=[], curves=None)
    (tmp_path / "min.json").write_text(json.dumps(minimal))
    invoke(["report", sample_model, "--cv", tmp_path / "min.json", "--calib", SAMPLE / "calibration",
            "-o", tmp_path / "b.html"])
    text = (tmp_path / "b.html").read_text(encoding="utf-8")
    tree = parse(text)
    assert {"table-gamma-methods", "table-gamma-svr", "fig-residuals"} <= set(tree.ids)
    assert "No gross-error run" in text and "No combined-load validation" in text


def test_held_out_labels_name_the_repetition(unrendered, tmp_path, sample_model, cv_json):
    """test_set is the held-out repetition's number: round 2 holds out reps 3 and 4."""
    doc = json.loads(cv_json.read_text())
    assert doc["folds"][1] == [3, 4]
    invoke(["report", sample_model, "--cv", cv_json, "-o", tmp_path / "r.html"])
    text = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert "test I (rep 3)" in text and "test II (rep 4)" in text


def test_a_cv_json_of_another_layout_is_refused(tmp_path, sample_model, cv_json):
    """A six-axis cv.json for a 3-axis model was accepted and reported as if it fitted."""
    doc = json.loads(cv_json.read_text())
    rename = {"x": "fx", "y": "fy", "z": "fz"}
    for r in doc["records"]:
        r["axis"] = rename.get(r["axis"], r["axis"])
    cv = tmp_path / "cv6.json"
    cv.write_text(json.dumps(doc))
    r = invoke(["report", sample_model, "--cv", cv, "-o", tmp_path / "r.html"], code=2)
    assert "fx" in r.stderr and "x, y, z" in r.stderr and not (tmp_path / "r.html").exists()


def test_a_cv_json_in_other_units_is_refused(tmp_path, sample_model, cv_json):
    """The cv.json of a lab's load cell (gram-force, counts) under a model in N and V: the
    components match, so it was accepted and its tables shown under the model's units."""
    doc = json.loads(cv_json.read_text())
    doc["settings"]["units"] = {"load": "gf", "output": "count"}
    cv = tmp_path / "lab-cv.json"
    cv.write_text(json.dumps(doc))
    r = invoke(["report", sample_model, "--cv", cv, "-o", tmp_path / "r.html"], code=2)
    assert_one_line_error(r, "lab-cv.json", "gf and count", "N and V")
    assert not (tmp_path / "r.html").exists()


def _report_text(html_text: str) -> str:
    import html as html_module
    import re

    text = re.sub(r"<img[^>]*>|<style.*?</style>", "", html_text, flags=re.S)
    return re.sub(r"\s+", " ", html_module.unescape(re.sub(r"<[^>]+>", " ", text)))


@pytest.mark.slow  # two reports with their figures
def test_the_report_speaks_the_datas_own_units(unrendered, tmp_path):
    """A gf / count load cell's report said k [V/N], input range [V], [mV] and [N] and
    printed 1/k as 0.0012; a six-axis one shows N, N·m and V (mV for small figures) only."""
    import re

    from fsdecouple import build_report, fit, load_calibration, load_config, load_model

    lab = SAMPLE / "loadcell" / "calibration.csv"
    settings = load_config(ROOT / "configs" / "loadcell.yaml")
    calib = load_calibration(lab, settings)
    model = fit(calib, settings)
    text = _report_text(build_report(model, None, calib).html)
    units = set(re.findall(r"\[([^\]]{1,20})\]", text))
    assert units <= {"gf", "count", "count/gf", "gf/count"}, units
    assert "gf/count" in text and "count/gf" in text
    inverse = f"{1 / model.k[0]:.6g}"
    assert inverse in text and len(inverse.replace("0.", "").lstrip("0")) >= 5  # not 0.0012

    six = load_model(ROOT / "tests" / "fixtures" / "golden" / "six-axis-v3.json")
    six_calib = load_calibration(SAMPLE / "six_axis" / "calibration", six.settings)
    text = _report_text(build_report(six, None, six_calib).html)
    units = set(re.findall(r"\[([^\]]{1,20})\]", text))
    assert units <= {"V", "mV", "N / N·m"}, units
    assert "V/N·m" in text and "N·m/V" in text


def test_report_links_the_certificate_it_is_given(tmp_path, sample_model, unrendered):
    """Issue 23: `report` links to the certificate. Its name is the user's: `--certificate`
    links it relative to the report's directory (the two files move together); without it
    the report names the command that writes one, and a file that is no certificate is
    refused in one line."""
    (tmp_path / "out").mkdir()
    (tmp_path / "cert 1.html").write_text("<html></html>")
    invoke(["report", sample_model, "-o", tmp_path / "out" / "r.html",
            "--certificate", tmp_path / "cert 1.html"])
    text = (tmp_path / "out" / "r.html").read_text(encoding="utf-8")
    assert '<a href="../cert%201.html">../cert 1.html</a>' in text
    assert "fsdecouple certificate MODEL CALIB -o" not in text
    r = invoke(["report", sample_model, "-o", tmp_path / "r.html", "--certificate",
                tmp_path / "cert.txt"], 2)
    assert "--certificate" in r.stderr and not (tmp_path / "r.html").exists()
    r = invoke(["report", sample_model, "-o", tmp_path / "r.html", "--certificate",
                tmp_path / "r.html"], 2)  # the report linking itself
    assert "is the report's own file" in r.stderr and not (tmp_path / "r.html").exists()


def test_one_repetition_is_said_in_the_singular(tmp_path):
    """'fitted on repetitions 1' in the report, '1 repetitions' in ingest's title."""
    from fsdecouple.reporting.report import _reps

    assert _reps([1], "repetition") == "repetition 1"
    assert _reps([3, 1], "repetition") == "repetitions 1, 3" and _reps([2, 1]) == "1, 2"
    r = invoke(["ingest", SAMPLE / "loadcell" / "calibration.csv", "-c",
                SAMPLE.parent / "configs" / "loadcell.yaml"])
    assert "1 repetition" in r.stdout and "1 repetitions" not in r.stdout
    # the load cell's offsets are whole counts: shown to a tenth, not to 0.001 count
    assert re.search(r"\+\d{5,}\.\d \u2502", r.stdout) and not re.search(r"\+\d{5,}\.\d{3}", r.stdout)
