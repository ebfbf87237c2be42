"""`fsdecouple report`: a self-contained HTML file and PNG figures from the sample data."""

from __future__ import annotations

import base64
import io
import json
from html.parser import HTMLParser

import numpy as np
import pytest
from conftest import SAMPLE, invoke
from matplotlib.image import imread

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
    # viewable offline: nothing is fetched from anywhere
    assert not [u for u in tree.urls if not u.startswith("data:")]
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


def test_worse_cells_are_highlighted(tmp_path, sample_model, cv_json):
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


def test_report_from_the_model_alone(tmp_path, sample_model):
    html = tmp_path / "r.html"
    invoke(["report", sample_model, "-o", html, "--png", tmp_path / "png"])
    text = html.read_text(encoding="utf-8")
    tree = parse(text)
    assert {"fig-omega", "fig-chi"} <= set(tree.ids) and "fig-residuals" not in tree.ids
    assert "pass --calib CALIB" in text and "No cross-validation results" in text
    assert sorted(p.name for p in (tmp_path / "png").iterdir()) == ["figure6_omega.png",
                                                                   "figure7_chi.png"]


def test_report_with_calib_only_has_in_sample_residuals(tmp_path, sample_model):
    html = tmp_path / "r.html"
    invoke(["report", sample_model, "--calib", SAMPLE / "calibration", "-o", html])
    tree = parse(html.read_text(encoding="utf-8"))
    assert "fig-residuals" in tree.ids
    assert "in-sample" in html.read_text(encoding="utf-8")


def test_report_refuses_to_overwrite_without_force(tmp_path, sample_model):
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


def test_fit_mentions_the_report_command(tmp_path):
    r = invoke(["fit", SAMPLE / "calibration", "-o", tmp_path / "m.json"])
    assert "fsdecouple report" in r.stdout


def test_readme_ends_its_main_command_with_a_report_and_shows_a_figure():
    readme = (SAMPLE.parent / "README.md").read_text(encoding="utf-8")
    main = next(ln for ln in readme.splitlines() if ln.startswith("python3 -m venv") and " fit " in ln)
    assert main.endswith(
        "report model.json --cv cv.json --calib sample_data/calibration -o report.html --force"
    )
    assert "](docs/figure7.png)" in readme
    assert_figure_ok(imread(SAMPLE.parent / "docs" / "figure7.png"))


def test_report_copes_with_a_minimal_cv_and_absent_methods(tmp_path, sample_model, cv_json):
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


def test_held_out_labels_name_the_repetition(tmp_path, sample_model, cv_json):
    """test_set is the held-out repetition's number: round 2 holds out reps 3 and 4."""
    doc = json.loads(cv_json.read_text())
    assert doc["folds"][1] == [3, 4]
    invoke(["report", sample_model, "--cv", cv_json, "-o", tmp_path / "r.html"])
    text = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert "test I (rep 3)" in text and "test II (rep 4)" in text
