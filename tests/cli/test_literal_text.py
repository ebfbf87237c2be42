"""User text reaches the terminal literally: rich markup and emoji codes are never read.

File names, column names and the sensor name here contain ``[/]`` (a closing tag
that raises rich's MarkupError if parsed), ``[bold]`` (silently dropped if parsed)
and ``:thumbs_up:`` (silently replaced by an emoji).  Every command that prints
them must exit 0 and show them as written.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import FAST_SVR, SAMPLE, invoke

RENAME = {"ux": "ux[/]", "uy": "uy[bold]", "uz": "uz:thumbs_up:",
          "fx": "fx[/]", "fy": "fy[bold]", "fz": "fz[red]"}
SENSOR = "s[/]n[bold]:thumbs_up:"


def _renamed(text: str) -> str:
    head, _, rest = text.partition("\n")
    return ",".join(RENAME.get(c, c) for c in head.split(",")) + "\n" + rest


@pytest.fixture(scope="module")
def tricky(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("lit")
    # a directory 'x[' holding ']...' makes paths that read 'x[/]...': a '/' cannot be
    # part of a file name, but a path can hold the closing tag all the same
    base = root / "x["
    base.mkdir()
    cal = base / "]cal[bold]:thumbs_up:"
    cal.mkdir()
    for f in (SAMPLE / "calibration").iterdir():
        (cal / f.name).write_text(_renamed(f.read_text()))
    log = base / "]log[bold].csv"
    log.write_text(_renamed((SAMPLE / "task_voltages.csv").read_text()) + "\n")  # + a blank row
    cfg = root / "cfg.yaml"
    cols = ", ".join(f'{k}: "{v}"' for k, v in RENAME.items())
    cfg.write_text(f'sensor: "{SENSOR}"\ncolumns: {{{cols}}}\n' + FAST_SVR)
    model = base / "]m[bold].json"
    fit = invoke(["fit", "-c", cfg, cal, "-o", model])
    return {"root": root, "cal": cal, "log": log, "cfg": cfg, "model": model, "fit": fit}


def _literal(r, *texts) -> None:
    shown = r.stdout + r.stderr
    assert "Traceback" not in shown and "MarkupError" not in shown
    assert "\N{THUMBS UP SIGN}" not in shown
    for t in texts:
        assert str(t) in shown, (t, shown)


def test_fit_and_show_print_names_literally(tricky):
    _literal(tricky["fit"], SENSOR, tricky["model"])
    _literal(invoke(["show", tricky["model"]]), SENSOR)


def test_apply_prints_names_and_warnings_literally(tricky):
    out = tricky["log"].parent / "]out[bold].csv"
    r = invoke(["apply", tricky["model"], tricky["log"], "-c", tricky["cfg"], "-o", out])
    _literal(r, out)
    assert "warning:" in r.stderr  # the blank row: a warning that quotes nothing odd
    header = out.read_text().partition("\n")[0]
    assert header.startswith("t,ux[/],uy[bold],uz:thumbs_up:,")


@pytest.mark.slow  # runs cv and renders a report
def test_validate_cv_and_report_print_names_literally(tricky, unrendered):
    _literal(invoke(["validate", tricky["model"], tricky["cal"], "-c", tricky["cfg"]]),
             tricky["cal"], tricky["model"])
    cv = tricky["cal"].parent / "]cv[bold].json"
    _literal(invoke(["cv", "-c", tricky["cfg"], tricky["cal"], "-o", cv]), cv, tricky["cal"])
    html = tricky["cal"].parent / "]r[bold].html"
    _literal(invoke(["report", tricky["model"], "--cv", cv, "-o", html]), html)  # figures not rasterised


def test_errors_quote_names_literally(tricky):
    missing = tricky["cal"].parent / "]nope[bold].csv"
    r = invoke(["apply", tricky["model"], missing, "-o", tricky["root"] / "o.csv"], code=2)
    _literal(r, missing)
    assert r.stderr.startswith("error:")


ESC = "\x1b[2J\x1b[31m"  # clear the screen, then print red


@pytest.mark.slow  # over ~0.6 s: the not-slow run stays under a minute
def test_control_characters_are_shown_escaped_never_sent_raw(tmp_path, sample_model):
    """A clear-screen in a sensor name or a directory name reaches the terminal escaped
    (``\\x1b[2J``), in titles, tables and summary lines alike."""
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text('sensor: "rig\\e[2J\\e[31m"\n' + FAST_SVR)
    model = tmp_path / "m.json"
    fit = invoke(["fit", SAMPLE / "calibration", "-c", cfg, "-o", model, "--no-verdict"])
    shown = invoke(["show", model])
    sensors = tmp_path / f"fleet{ESC}"
    (sensors / f"s{ESC}1").mkdir(parents=True)
    for f in (SAMPLE / "calibration").iterdir():
        (sensors / f"s{ESC}1" / f.name).write_bytes(f.read_bytes())
    (sensors / f"s{ESC}1" / "sensor.yaml").write_text("sensor: one\n" + FAST_SVR)
    many = invoke(["fit-many", sensors, "-o", tmp_path / "models", "--workers", 1])
    for r in (fit, shown, many):
        out = r.stdout + r.stderr
        assert "\x1b" not in out, out
    assert "rig\\x1b[2J\\x1b[31m" in fit.stdout and "rig\\x1b[2J" in shown.stdout
    assert "s\\x1b[2J\\x1b[31m1" in many.stdout + many.stderr


@pytest.mark.slow  # over ~0.6 s: the not-slow run stays under a minute
def test_the_report_shows_a_control_character_escaped(tmp_path, sample_model, unrendered):
    """The HTML report put an ESC and a newline of the sensor's name raw into its <h1> and
    <title>: an ESC is no character of HTML, and the newline folded into a space."""
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text('sensor: "evil\\e[2Jname\\nsecond"\n' + FAST_SVR)
    model = tmp_path / "m.json"
    invoke(["fit", SAMPLE / "calibration", "-c", cfg, "-o", model, "--no-verdict"])
    invoke(["report", model, "-o", tmp_path / "r.html"])
    html = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert "\x1b" not in html and "evil\n" not in html
    assert "<h1>Calibration report: evil\\x1b[2Jname\\nsecond</h1>" in html
    assert "<title>fsdecouple calibration report: evil\\x1b[2Jname\\nsecond</title>" in html


def test_the_console_keeps_unicode_spaces_and_escapes_controls(capsys):
    """A no-break space in a spreadsheet's header is text, shown as it is; an ESC is not."""
    from rich.table import Table

    from fsdecouple.cli.app import console

    table = Table("Fx\u00a0[N]", "a\x1b[2Jb")
    table.add_row("x\u2009y", "z")
    console.print(table)
    out = capsys.readouterr().out
    assert "Fx\u00a0[N]" in out and "x\u2009y" in out
    assert "a\\x1b[2Jb" in out and "\x1b" not in out


def _tables(out: str) -> list[set[int]]:
    """The widths of each table's lines (from its top edge to its bottom edge)."""
    from rich.cells import cell_len

    tables: list[set[int]] = []
    for line in out.splitlines():
        if line.startswith("┏"):
            tables.append(set())
        if tables and line[:1] in "┏┃┡│└":
            tables[-1].add(cell_len(line))
    return tables


def test_a_table_holding_a_newline_or_an_escape_stays_aligned(capsys):
    """A newline in a sensor name split its cell over two rows, and an escaped ESC made its
    row wider than the table: the text is escaped before rich measures it (issue 25)."""
    from rich.table import Table
    from rich.text import Text

    from fsdecouple.cli.app import console

    table = Table("sensor", "γ", title="fleet\nof a\x1b[2Jb")
    table.add_row("left\narm", "1")
    table.add_row(Text("c\x1b[31md", style="bold"), "2")
    table.add_row("plain", "3")
    console.print(table)
    out = capsys.readouterr().out
    assert "\x1b" not in out
    assert "left\\narm" in out and "c\\x1b[31md" in out
    assert "fleet\\nof" in out and "a\\x1b[2Jb" in out  # the title wraps at a space only
    assert [len(w) for w in _tables(out)] == [1], out  # every row as wide as the table
    assert sum(line.startswith("│") for line in out.splitlines()) == 3  # one line a row


@pytest.mark.slow  # fits of the sample: seconds of CPU; the not-slow run stays under a minute
def test_a_newline_in_an_output_or_sensor_name_never_splits_a_line(tmp_path):
    out = tmp_path / "a\nb.json"
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text('sensor: "left\\narm\\e[2J"\n' + FAST_SVR)
    r = invoke(["fit", SAMPLE / "calibration", "-c", cfg, "-o", out, "--no-verdict"])
    lines = r.stdout.splitlines()
    assert "model written to " + str(tmp_path / "a\\nb.json") + " (decouples by svr)" in lines
    assert any(ln.endswith("report " + str(tmp_path / "a\\nb.json") + " -o report.html") for ln in lines)
    title = next(ln for ln in lines if "sensor left" in ln)
    assert "left\\narm\\x1b[2J" in title and "\x1b" not in r.stdout
    assert all(len(w) == 1 for w in _tables(r.stdout)), r.stdout
