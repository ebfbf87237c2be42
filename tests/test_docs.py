"""The README stays a short front page over the docs site, and the site's pages exist.

The manual lives in docs/ (an mkdocs-material site, ``mkdocs.yml``); CI builds it with
``mkdocs build --strict``, which fails on a broken link inside it.  These tests check
what that build does not see: the README itself, and the blocks the scripts rewrite.
"""

from __future__ import annotations

import importlib.util
import re
import shutil
import subprocess
import sys

import pytest
import yaml
from conftest import ROOT, working_directory

README = ROOT / "README.md"
MAX_README_LINES = 400
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def _section(text: str, title: str) -> str:
    m = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert m, f"README has no '## {title}' section"
    return m.group(1)


def test_readme_is_short():
    n = len(README.read_text(encoding="utf-8").splitlines())
    assert n <= MAX_README_LINES, f"README.md has {n} lines; move the manual into docs/"


def test_quick_start_has_exactly_two_bash_commands():
    quick = _section(README.read_text(encoding="utf-8"), "Quick start")
    blocks = re.findall(r"^```bash\n(.*?)^```$", quick, re.M | re.S)
    assert len(blocks) == 2, blocks
    assert all(len(b.strip().splitlines()) == 1 for b in blocks), "one command per block"
    install_and_run, tests = (b.strip() for b in blocks)
    assert " fit sample_data/calibration " in install_and_run
    assert tests.endswith("-m pytest")
    assert "sample data" in quick.lower()  # the data are described where they are first used


def test_relative_links_in_the_readme_exist():
    links = [t for t in LINK.findall(README.read_text(encoding="utf-8"))
             if not re.match(r"[a-z]+:", t) and not t.startswith("#")]
    assert links, "the README links into docs/"
    missing = [t for t in links if not (ROOT / t.split("#")[0]).exists()]
    assert not missing, missing
    assert any(t.startswith("docs/") and t.endswith(".md") for t in links)


def _nav_pages(nav) -> list[str]:
    if isinstance(nav, str):
        return [nav]
    if isinstance(nav, list):
        return [p for item in nav for p in _nav_pages(item)]
    if isinstance(nav, dict):
        return [p for v in nav.values() for p in _nav_pages(v)]
    return []


def test_every_page_in_the_nav_exists():
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    pages = [p for p in _nav_pages(config["nav"]) if not re.match(r"[a-z]+://", p)]
    assert "index.md" in pages and "api.md" in pages
    missing = [p for p in pages if not (ROOT / config.get("docs_dir", "docs") / p).is_file()]
    assert not missing, missing
    assert len(pages) == len(set(pages)), "a page listed twice"


def test_every_generated_block_has_its_markers_on_its_page():
    sys.path.insert(0, str(ROOT / "docs"))
    try:
        from readme_blocks import PAGES
    finally:
        sys.path.remove(str(ROOT / "docs"))
    for name, page in PAGES.items():
        text = page.read_text(encoding="utf-8")
        assert text.count(f"<!-- {name}:start -->") == 1 == text.count(f"<!-- {name}:end -->"), (name, page)
    readme = README.read_text(encoding="utf-8")
    in_readme = set(re.findall(r"<!-- ([\w-]+):start -->", readme))
    assert in_readme == {n for n, p in PAGES.items() if p == README}, in_readme


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("mkdocs") is None, reason="mkdocs is not installed ('.[docs]')")
def test_the_site_builds_strictly(tmp_path):
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path)],
                         cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-3000:]
    assert (tmp_path / "api" / "index.html").is_file()


# Example outputs (docs/examples.py): each block must be what its commands print now.
sys.path.insert(0, str(ROOT / "docs"))
import examples  # noqa: E402

sys.path.remove(str(ROOT / "docs"))


def _in_process(argv) -> examples.Result:
    from typer.testing import CliRunner

    from fsdecouple.cli import app

    r = CliRunner().invoke(app, list(argv))
    if r.exception is not None and not isinstance(r.exception, SystemExit):
        raise r.exception
    return examples.Result(r.exit_code, r.stdout, r.stderr)


def _fresh(example, results) -> str:
    return examples.masked(examples.render(example, results), example.volatile)


_NUMBER = re.compile(r"[-+]?\d+(?:\.(\d+))?")


def same_up_to_rounding(fresh: str, want: str) -> bool:
    """The texts agree, except that a printed number may differ by one unit in its last
    printed place: a figure at a rounding boundary (0.065 printed to 2 places) prints
    either way on another BLAS or libm, and the block is not stale for that."""
    if fresh == want:
        return True
    if _NUMBER.sub("#", fresh) != _NUMBER.sub("#", want):
        return False
    for x, y in zip(_NUMBER.finditer(fresh), _NUMBER.finditer(want), strict=True):
        if x.group() == y.group():
            continue
        places = len(x.group(1) or "")
        if places != len(y.group(1) or ""):
            return False
        if abs(float(x.group()) - float(y.group())) > 1.5 * 10.0 ** -places:
            return False
    return True


def test_same_up_to_rounding_allows_one_last_place_only():
    assert same_up_to_rounding("gamma 0.06 %", "gamma 0.07 %")
    assert not same_up_to_rounding("gamma 0.06 %", "gamma 0.08 %")
    assert not same_up_to_rounding("gamma 0.06 %", "gamma 0.060 %")
    assert not same_up_to_rounding("gamma 0.06 % F.S.", "gamma 0.06 % of F.S.")
    assert not same_up_to_rounding("rows 3000", "rows 3002")


def _stale(example, fresh: str) -> str:
    return (f"{example.page}'s {example.name} block is stale: run python docs/make_readme_output.py"
            f"\n--- fresh run:\n{fresh}")


def test_every_example_block_is_on_its_page_and_fenced():
    names = [e.name for e in examples.EXAMPLES]
    assert len(names) == len(set(names))
    for example in examples.EXAMPLES:
        text = examples.block(example)
        assert text.startswith("```") and text.endswith("```"), example.name
        assert not example.prompt or text.count("\n$ ") == len(example.commands), example.name


def test_the_readme_fit_block_is_the_shared_sample_fit(sample_fit):
    """The README's fit block against the suite's one sample fit (the same command in
    the same kind of directory), so a change to fit's output fails here, not slow-marked."""
    example = examples.by_name("readme-fit")
    _, r = sample_fit
    fresh = _fresh(example, [examples.Result(r.exit_code, r.stdout, r.stderr)])
    assert fresh == examples.masked(examples.block(example), example.volatile), _stale(example, fresh)
    # what the hidden check reads verbatim from a real run
    assert "verdict: " in fresh and "second-order coupling error" in fresh


SIX_FIT = "fsdecouple fit six/calibration -c six/sensor.yaml -o model.json"


def _six_fit_is_the_shared_one(six_model_file, tmp_path, done):
    """The six-axis group's fit is the suite's shared six-axis fit (``six_model_file``):
    ``simulate six --components 6`` (run here) writes the committed sample's data and
    configs/six-axis.yaml but for the sensor's name (asserted here, as
    tests/sim/test_six_axis.py does), and the block shows nothing of the fit's output."""
    simulate, = (c for c in done if c.startswith("fsdecouple simulate six"))
    example, = (e for e in examples.EXAMPLES if SIX_FIT in e.commands)
    assert example.show[example.commands.index(SIX_FIT)] is examples.nothing
    assert simulate in example.commands
    six, sample = tmp_path / "six", ROOT / "sample_data" / "six_axis"
    for path in (sample / "calibration").iterdir():
        assert (six / "calibration" / path.name).read_bytes() == path.read_bytes(), path.name
    assert len(list((six / "calibration").iterdir())) == len(list((sample / "calibration").iterdir()))
    assert (six / "sensor.yaml").read_text().replace("sim-6axis-seed0", "sim-6axis") \
        == (ROOT / "configs" / "six-axis.yaml").read_text()
    shutil.copyfile(six_model_file, tmp_path / "model.json")
    done[SIX_FIT] = examples.Result(0, "", "")  # not shown (asserted above)


@pytest.mark.slow
@pytest.mark.parametrize("group", sorted({e.group for e in examples.EXAMPLES}))
def test_every_example_block_is_a_fresh_run(group, sample_fit, sample_cv, tmp_path, unrendered,
                                            request):
    """Each group's commands run again (in-process), in order, in a scratch directory; the
    sample's fit and cv are the suite's shared runs of the same commands (their files
    copied in, their output reused), and the six-axis fit the suite's of the same data
    (_six_fit_is_the_shared_one).  The report's figures are built but not rasterised
    (``unrendered``): its block shows the line the command prints, which counts them."""
    from conftest import SAMPLE_CV

    done = {}
    if group == "sample":
        for (d, r), command, name in ((sample_fit, "fsdecouple fit sample_data/calibration -o model.json",
                                       "model.json"),
                                      (sample_cv, "fsdecouple " + " ".join(SAMPLE_CV), "cv.json")):
            shutil.copyfile(d / name, tmp_path / name)
            done[command] = examples.Result(r.exit_code, r.stdout, r.stderr)
        assert set(done) <= {c for e in examples.EXAMPLES for c in e.commands}, "the shared runs changed"
    for name in ("sample_data", "configs"):
        (tmp_path / name).symlink_to(ROOT / name, target_is_directory=True)
    with working_directory(tmp_path):
        if group == "six":
            simulate = next(c for e in examples.EXAMPLES if e.group == "six" for c in e.commands
                            if c.startswith("fsdecouple simulate six"))
            done[simulate] = examples.run_command(simulate, _in_process)
            _six_fit_is_the_shared_one(request.getfixturevalue("six_model_file"), tmp_path, done)
        for example in (e for e in examples.EXAMPLES if e.group == group):
            fresh = examples.masked(examples.run(example, _in_process, done), example.volatile)
            want = examples.masked(examples.block(example), example.volatile)
            assert same_up_to_rounding(fresh, want), _stale(example, fresh)


def _doctests(page):
    """The doctest examples of a page's ```python blocks (those with '>>>' lines)."""
    import doctest

    text = page.read_text(encoding="utf-8")
    blocks = [b for b in re.findall(r"^```python\n(.*?)^```$", text, re.M | re.S) if ">>>" in b]
    return doctest.DocTestParser().get_doctest("\n".join(blocks), {}, page.name, str(page), 0), blocks


@pytest.mark.slow
def test_the_api_page_examples_run_as_doctests(tmp_path, unrendered):
    """docs/api.md's examples, run from a directory that looks like the repository's root
    (its sample data and configs) as the page says; every '>>>' line runs and every shown
    result must match (one raised NameError when they were not run).  The report's
    figures are built and plotted but not rasterised (``unrendered``: ~3 s of CPU; the
    page shows the HTML's start, and the pixels are tests/reporting/test_report.py's)."""
    import doctest

    test, blocks = _doctests(ROOT / "docs" / "api.md")
    assert blocks and len(test.examples) >= 15, "the API page lost its examples"
    for name in ("sample_data", "configs"):
        (tmp_path / name).symlink_to(ROOT / name, target_is_directory=True)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    out = []
    with working_directory(tmp_path):
        result = runner.run(test, out=out.append)
    assert result.failed == 0, "".join(out)
    assert (tmp_path / "model.json").is_file() and (tmp_path / "forces.csv").is_file()


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_the_architecture_page_is_generated_and_names_every_module():
    """docs/architecture.md is docs/make_architecture.py's output for the package as it is
    now, and names each module (found here by walking the package, not by the script)."""
    sys.path.insert(0, str(ROOT / "docs"))
    try:
        import make_architecture
    finally:
        sys.path.remove(str(ROOT / "docs"))
    page = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    package = ROOT / "fsdecouple"
    names = set()
    for path in package.rglob("*.py"):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        names.add(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    missing = sorted(n for n in names if f"`{n}`" not in page)
    assert not missing, f"docs/architecture.md misses {missing}: run python docs/make_architecture.py"
    assert page == make_architecture.render(), "docs/architecture.md is stale: run docs/make_architecture.py"
    # the floors follow the imports: core, under every other stage, is on the lowest stage floor
    floors = dict(re.findall(r"^## `fsdecouple\.(\w+)` \(floor (\d+)\)$", page, re.M))
    assert floors and int(floors["core"]) == min(int(f) for f in floors.values())
    assert int(floors["cli"]) == max(int(f) for f in floors.values())


def _first_table(text: str, heading: str) -> str:
    after = text[text.index(f"\n## {heading}\n"):]
    return re.search(r"(^\|[^\n]*\n)+", after, re.M).group(0)


def test_the_sites_home_page_has_the_readmes_tables():
    """docs/index.md repeats the README's command and page tables, links made local to
    docs/: one drifted from the other (four pages and every new option missing)."""
    readme = README.read_text(encoding="utf-8")
    index = (ROOT / "docs" / "index.md").read_text(encoding="utf-8")
    for mine, theirs in (("Commands", "Commands"), ("Documentation", "Where to read on")):
        assert _first_table(index, theirs) == _first_table(readme, mine).replace("](docs/", "]("), theirs


COMMANDS = ("simulate", "init", "ingest", "fit", "show", "apply", "certificate", "report",
            "validate", "export", "import", "compare", "fit-many", "cv")


@pytest.mark.parametrize("command", COMMANDS)
def test_the_readmes_synopsis_names_every_option_of_the_command(command):
    """Each option `fsdecouple COMMAND --help` lists is in the README's synopses of that
    command (-o and -c for --output and --config; --force and --help said once for all)."""
    from typer.testing import CliRunner

    from fsdecouple.cli.app import app

    text = CliRunner().invoke(app, [command, "--help"], env={"COLUMNS": "200", "NO_COLOR": "1"}).stdout
    assert "Usage" in text, text
    options = set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", text)) - {"--help", "--force"}
    table = _first_table(README.read_text(encoding="utf-8"), "Commands")
    mine = re.compile(rf"`fsdecouple {re.escape(command)}(?=[\s`])")  # not fit-many's for fit
    synopses = " ".join(s for row in table.splitlines()
                        for s in re.findall(r"`fsdecouple [^`]*`", row) if mine.match(s))
    short = {"--output": "-o ", "--config": "-c "}
    missing = sorted(o for o in options if o not in synopses and short.get(o, o) not in synopses)
    assert not missing, f"README's {command} synopsis lacks {missing}"


def test_the_synopsis_check_covers_every_command():
    from fsdecouple.cli.app import app

    assert sorted(c.name or c.callback.__name__ for c in app.registered_commands) == sorted(COMMANDS)


def test_the_unit_lists_name_every_unit_the_code_takes():
    """data.md's and apply.md's lists of load and output units hold every unit of
    fsdecouple.units (klbf was taken and never named)."""
    from fsdecouple.units import LOAD_UNITS, OUTPUT_UNITS

    data = (ROOT / "docs" / "data.md").read_text(encoding="utf-8")
    lines = data.splitlines()
    at = next(i for i, ln in enumerate(lines) if ln.startswith("`load` is one of"))
    listed = set(re.findall(r"`([^`]+)`", " ".join(lines[at:at + 2])))
    assert set(LOAD_UNITS) | set(OUTPUT_UNITS) <= listed, listed
    apply = (ROOT / "docs" / "apply.md").read_text(encoding="utf-8")
    options = set(re.findall(r"`([^`]+)`", re.search(r"`--unit gf` \(or [^)]*\)", apply).group(0)))
    assert {f"--unit {u}" if u == "gf" else u for u in LOAD_UNITS} <= options, options
