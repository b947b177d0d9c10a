"""``--help`` of every command: every character of its docstring and of each option's help text is shown
(rich markup would eat "[section]" or "[dask]"), flags show no "<bool>", the help fits the terminal; and
cli.py keeps each function short (the commands are option declarations and one library call)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner
from typer.utils import get_params_from_function

from gndreplay import cli
from gndreplay.cli import _MARKUP, app

runner = CliRunner()
COMMANDS = {c.callback.__name__: c.callback for c in app.registered_commands if c.callback is not None}
#: White space and the box-drawing characters of rich's panels.
_LAYOUT = re.compile(r"[\s\u2500-\u257f]+")


def rendered(args: list[str], columns: int) -> str:
    res = runner.invoke(app, args, env={"COLUMNS": str(columns)})
    assert res.exit_code == 0, res.output
    return str(res.stdout)


def source_texts(name: str) -> list[str]:
    """The command's docstring and the help text of each of its arguments and options, as written."""
    fn = COMMANDS[name]
    helps = [getattr(p.default, "help", None) for p in get_params_from_function(fn).values()]
    return [fn.__doc__ or "", *(h for h in helps if h)]


def visible(text: str) -> str:
    """What of ``text`` a reader sees: without the intended markup tags and without layout."""
    return _LAYOUT.sub("", _MARKUP.sub("", text))


def test_every_command_is_checked() -> None:
    assert set(COMMANDS) == {"info", "run", "scanmatch", "report", "compare", "simulate", "batch"}


@pytest.mark.parametrize("columns", [250, 80])
@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_help_shows_every_character_of_the_source(name: str, columns: int) -> None:
    shown = visible(rendered([name, "--help"], columns))
    for text in source_texts(name):
        assert visible(text) in shown, f"{name} --help loses part of: {text!r}"


@pytest.mark.parametrize("columns", [250, 80])
def test_scenario_generate_help_shows_every_character_and_the_group_lists_it(columns: int) -> None:
    fn = cli.generate
    helps = [getattr(p.default, "help", None) for p in get_params_from_function(fn).values()]
    shown = visible(rendered(["scenario", "generate", "--help"], columns))
    for text in [fn.__doc__ or "", *(h for h in helps if h)]:
        assert visible(text) in shown, f"scenario generate --help loses part of: {text!r}"
    group = visible(rendered(["scenario", "--help"], 250))
    assert visible((fn.__doc__ or "").strip().split("\n\n")[0]) in group
    assert visible("scenario") in visible(rendered(["--help"], 250))


def test_the_brackets_the_markup_used_to_eat_are_shown() -> None:
    assert "[scanmatch.idc] / [scanmatch.kiss]" in " ".join(rendered(["scanmatch", "--help"], 250).split())
    assert "'x y theta [stop|forward|reverse]'" in rendered(["run", "--help"], 250)
    assert "pip install 'gndreplay[dask]'" in rendered(["batch", "--help"], 250)
    assert "[navigation] mode" in rendered(["simulate", "--help"], 250)


def test_markup_that_is_meant_is_rendered_not_shown() -> None:
    out = rendered(["run", "--help"], 250)
    assert "Examples" in out and "[bold]" not in out and "[/]" not in out


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_flags_show_no_type(name: str) -> None:
    out = rendered([name, "--help"], 100)
    assert "<bool>" not in out and "--help" in out


def test_batch_help_is_readable_and_simulate_shows_its_out_default() -> None:
    assert len(rendered(["batch", "--help"], 100).splitlines()) < 100
    sim = visible(rendered(["simulate", "--help"], 80))
    assert visible("(default out/sim/SCENARIO-PRESET-SEED)") in sim
    assert visible("default office.clf.bz2)") in sim


def test_the_root_help_lists_every_command_with_its_first_line() -> None:
    out = visible(rendered(["--help"], 250))
    for name, fn in COMMANDS.items():
        first = (fn.__doc__ or "").strip().split("\n\n")[0]
        assert visible(name) in out and visible(first) in out, name


def code_lines(path: Path) -> dict[str, int]:
    """Lines of code of each function of ``path`` below its signature, without its docstring, blank lines
    and comments."""
    src = path.read_text()
    lines = src.splitlines()
    tree = ast.parse(src)
    docs: set[int] = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(node, ast.FunctionDef | ast.ClassDef | ast.Module) and body:
            first = body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                docs.update(range(first.lineno, (first.end_lineno or first.lineno) + 1))
    found = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef):
            span = range(node.body[0].lineno, (node.end_lineno or node.lineno) + 1)
            code = [i for i in span if i not in docs and lines[i - 1].strip()
                    and not lines[i - 1].strip().startswith("#")]
            found[f"{node.name}:{node.lineno}"] = len(code)
    return found


def test_cli_functions_stay_short() -> None:
    long = {name: n for name, n in code_lines(Path(cli.__file__)).items() if n > 40}
    assert long == {}, f"cli.py functions over 40 lines of code (option declarations apart): {long}"
