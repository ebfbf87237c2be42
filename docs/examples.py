"""The example outputs quoted in README.md and on the docs pages, each from a real run.

Every example names its block (``<!-- NAME:start -->`` ... ``<!-- NAME:end -->`` on
its page), the commands it runs, and which part of their output it quotes (the rest
is cut with a ``…`` line).  The commands of one ``group`` run in order in one scratch
directory holding a link to ``sample_data/``, so ``apply model.json`` finds the model
that ``fit`` wrote there.  ``head -N FILE`` is the one command that is not
``fsdecouple``.

``python docs/make_readme_output.py`` runs them all and rewrites the blocks;
``tests/test_docs.py`` runs them again and fails when a block differs from a fresh
run.  Lines marked volatile (the timings of ``cv``) are compared with their digits
masked.
"""

from __future__ import annotations

import re
import shlex
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CUT = "…"


@dataclass(frozen=True)
class Result:
    code: int
    stdout: str
    stderr: str


# runs one command's argv (without the leading 'fsdecouple') in the current directory
Runner = Callable[[Sequence[str]], Result]


def _lines(text: str) -> list[str]:
    return [line.rstrip() for line in text.splitlines()]


def whole(command: str, result: Result) -> list[str]:
    """Every line the command printed on stdout."""
    return _lines(result.stdout)


def errors(command: str, result: Result) -> list[str]:
    """Every line the command printed on stderr (its errors and warnings)."""
    return _lines(result.stderr)


def first_table_and_from(marker: str) -> Callable[[str, Result], list[str]]:
    """The first table, a cut, then every line from the first one starting with ``marker``."""
    def show(command: str, result: Result) -> list[str]:
        lines = _lines(result.stdout)
        end = next(i for i, line in enumerate(lines) if line.startswith("└"))
        start = next(i for i, line in enumerate(lines) if line.startswith(marker))
        return [*lines[:end + 1], CUT, *lines[start:]]
    return show


def matching(pattern: str) -> Callable[[str, Result], list[str]]:
    """A cut, then the lines matching ``pattern`` (a regular expression)."""
    def show(command: str, result: Result) -> list[str]:
        return [CUT, *(line for line in _lines(result.stdout) if re.search(pattern, line))]
    return show


def without(pattern: str) -> Callable[[str, Result], list[str]]:
    """Every stdout line but those matching ``pattern``."""
    def show(command: str, result: Result) -> list[str]:
        return [line for line in _lines(result.stdout) if not re.search(pattern, line)]
    return show


def between(start: str, stop: str) -> Callable[[str, Result], list[str]]:
    """A cut, the lines from the first matching ``start`` up to the next matching ``stop``
    (regular expressions), then a cut."""
    def show(command: str, result: Result) -> list[str]:
        lines = _lines(result.stdout)
        first = next(i for i, line in enumerate(lines) if re.search(start, line))
        last = next(i for i in range(first + 1, len(lines)) if re.search(stop, lines[i]))
        return [CUT, *lines[first:last], CUT]
    return show


def nothing(command: str, result: Result) -> list[str]:
    """No line (a command that only makes the files the next one shows)."""
    return []


def with_cut(show: Callable[[str, Result], list[str]]) -> Callable[[str, Result], list[str]]:
    """``show``'s lines, then a cut: more follows."""
    return lambda command, result: [*show(command, result), CUT]


@dataclass(frozen=True)
class Example:
    name: str                      # the block's marker name
    page: str                      # its page, relative to the repository root
    group: str                     # examples of one group share a scratch directory, in order
    commands: tuple[str, ...]      # as shown after '$ ', each run for real
    show: tuple[Callable[[str, Result], list[str]], ...] = ()  # per command; default: whole
    codes: tuple[int, ...] = (0,)  # the exit codes a command may end with
    volatile: str | None = None    # lines whose figures vary between runs (timings)
    prompt: bool = True            # '$ command' lines shown above their output
    fence: str = "text"


# one cv run serves the README and docs/cv.md (and the suite's cv_json fixture)
SAMPLE_CV = ("fsdecouple cv sample_data/calibration --task sample_data/task_voltages.csv "
             "--task-forces sample_data/task_forces.csv --task-tare 200 --gross-error x:1:5:0.2 "
             "--max-gamma 0.016 -o cv.json")

EXAMPLES: tuple[Example, ...] = (
    Example("readme-fit", "README.md", "sample",
            ("fsdecouple fit sample_data/calibration -o model.json",),
            (first_table_and_from("second-order coupling error"),)),
    Example("readme-apply", "README.md", "sample",
            ("fsdecouple apply model.json sample_data/task_voltages.csv --tare 200 -o forces.csv",
             "head -3 forces.csv")),
    Example("readme-cv", "README.md", "sample", (SAMPLE_CV,),
            (matching(r"^\S+ +worst gamma |^gate: "),)),
    Example("cv-sample-output", "docs/cv.md", "sample", (SAMPLE_CV,),
            (without(r"^cv document written to"),),
            volatile=r"^│ +(initial|linear|rbf-mimo|rbf-siso|svr) │ +[\d.]+ │ +[\d.]+ │$|^training: "),
    Example("readme-report", "README.md", "sample",
            ("fsdecouple report model.json --cv cv.json --calib sample_data/calibration -o report.html",)),
    Example("readme-export", "README.md", "sample",
            ("fsdecouple export model.json -o decoupler.h",)),
    Example("verdict-line", "docs/verdict.md", "loadcell",
            ("fsdecouple fit sample_data/loadcell/calibration.csv -c configs/loadcell.yaml --method auto "
             "-o loadcell.json",),
            (matching(r"^verdict: "),)),
    Example("six-axis-forces", "docs/six-axis.md", "six",
            ("fsdecouple simulate six --components 6",
             "fsdecouple fit six/calibration -c six/sensor.yaml -o model.json",
             "fsdecouple apply model.json six/task_voltages.csv --tare 200 -o wrench.csv",
             "head -2 wrench.csv"),
            (nothing, nothing, nothing, whole), prompt=False),
    Example("temperature-fit", "docs/temperature.md", "thermal",
            ("fsdecouple simulate thermal --temperature",
             "fsdecouple fit thermal/calibration -c thermal/sensor.yaml -o thermal/model.json"),
            (whole, between(r"^ *Temperature terms", r"Assumption checks"))),
    Example("temperature-apply", "docs/temperature.md", "thermal",
            ("fsdecouple apply thermal/model.json thermal/task_voltages.csv -c thermal/sensor.yaml "
             "--tare 200 -o thermal/forces.csv",)),
    Example("rig-file", "docs/rigs.md", "rig",
            ("fsdecouple simulate rig --rig lever-arm", "head -3 rig/calibration.csv"),
            (nothing, with_cut(whole)), prompt=False),
)


def by_name(name: str) -> Example:
    return next(e for e in EXAMPLES if e.name == name)


def _head(argv: Sequence[str]) -> Result:
    n, path = int(argv[1].lstrip("-")), Path(argv[2])
    with open(path, encoding="utf-8") as fh:
        return Result(0, "".join(line for _, line in zip(range(n), fh, strict=False)), "")


def run_command(command: str, runner: Runner) -> Result:
    """One command of an example, in the current directory."""
    argv = shlex.split(command)
    if argv[0] == "head":
        return _head(argv)
    assert argv[0] == "fsdecouple", command
    return runner(argv[1:])


def render(example: Example, results: Sequence[Result]) -> str:
    """The block's text: a fenced block of each command and the part of its output shown."""
    shows = example.show or (whole,) * len(example.commands)
    out: list[str] = []
    for command, result, show in zip(example.commands, results, shows, strict=True):
        if result.code not in example.codes:
            raise RuntimeError(f"{example.name}: '{command}' exited {result.code}\n"
                               f"{result.stdout}\n{result.stderr}")
        shown = show(command, result)
        if example.prompt:
            out.append(f"$ {command}")
        out += shown
    while out and not out[-1]:
        out.pop()
    return f"```{example.fence}\n" + "\n".join(out) + "\n```"


def run(example: Example, runner: Runner, done: dict[str, Result] | None = None) -> str:
    """Run ``example``'s commands in the current directory and render its block.

    ``done``: results of commands already run in this directory (by an earlier example of
    the group, or by the test suite's shared fixtures): a command found there is not run
    again, and what it ran is added."""
    done = {} if done is None else done
    results = []
    for command in example.commands:
        if command not in done:
            done[command] = run_command(command, runner)
        results.append(done[command])
    return render(example, results)


def masked(text: str, volatile: str | None) -> str:
    """``text`` with the digits of its volatile lines masked (and their spacing collapsed)."""
    if volatile is None:
        return text
    return "\n".join(" ".join(re.sub(r"\d+(\.\d+)?", "#", line).split()) if re.search(volatile, line)
                     else line for line in text.splitlines())


def block(example: Example) -> str:
    """The text now between the example's markers on its page."""
    body = (ROOT / example.page).read_text(encoding="utf-8")
    m = re.search(rf"<!-- {re.escape(example.name)}:start -->\n(.*?)\n<!-- {re.escape(example.name)}:end -->",
                  body, re.S)
    if m is None:
        raise LookupError(f"{example.page}: no {example.name} block")
    return m.group(1)
