"""The documentation: the site builds without a warning (mkdocs --strict) and reaches every
page, the README's snippets run as written, its timing claims agree with the command's help,
every example states its run time, and git ignores what the demo and mkdocs write."""

from __future__ import annotations

import ast
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import click
import pytest

from calippso.cli import cli

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
FENCE = re.compile(r"^```(\w+)\n(.*?)^```$", re.MULTILINE | re.DOTALL)
DEMO_SECONDS = re.compile(r"about (\d+) s\b")


def _blocks(path: Path, language: str) -> list[str]:
    """The bodies of the fenced code blocks of `language` in `path`."""
    return [body for name, body in FENCE.findall(path.read_text()) if name == language]


def _paragraph(path: Path, words: str) -> str:
    """The paragraph of `path` that contains `words`."""
    return next(part for part in path.read_text().split("\n\n") if words in part)


def test_mkdocs_build_strict(tmp_path):
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings_handlers.python")
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    page = (tmp_path / "site" / "api" / "calippso" / "index.html").read_text()
    assert "jam" in page and "Parameters" in page  # the reference is built from docstrings


def test_readme_python_snippets_run_as_written(tmp_path, monkeypatch, capsys):
    """Each snippet runs in a namespace of its own (its imports as written), in this process:
    a fresh interpreter would add only the imports' ~3 s."""
    monkeypatch.chdir(tmp_path)
    blocks = _blocks(README, "python")
    assert blocks
    for number, block in enumerate(blocks):
        exec(compile(block, f"README.md python block {number + 1}", "exec"),
             {"__name__": "__main__"})


def _parse(args: list[str]) -> click.Context:
    """Parse a ``calippso`` command line (options and their values) without running it."""
    command, name = cli, "calippso"
    while isinstance(command, click.Group):
        name = args.pop(0)
        command = command.get_command(click.Context(cli), name)
        assert command is not None, f"no command {name!r}"
    return command.make_context(name, args)


def test_readme_shell_lines_are_valid_commands(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    lines = [line for block in _blocks(README, "bash") for line in block.splitlines()]
    assert lines
    for line in lines:
        program, *args = shlex.split(line, comments=True)
        assert program == "calippso", line
        for argument in args:  # the files that the lines before write
            if not argument.startswith("-") and Path(argument).suffix:
                Path(argument).touch()
        _parse(args)


GUIDES = sorted((ROOT / "docs").glob("*.md")) + sorted((ROOT / "docs" / "howto").glob("*.md"))


@pytest.mark.parametrize("page", GUIDES, ids=lambda p: p.name)
def test_every_calippso_command_in_the_guides_parses(page, tmp_path, monkeypatch):
    """Each line of a guide's bash blocks that runs `calippso` names commands and options
    the CLI has (a guide that promises an option the CLI lacks fails here)."""
    monkeypatch.chdir(tmp_path)
    for block in _blocks(page, "bash"):
        for line in block.replace("\\\n", " ").splitlines():
            words = shlex.split(line, comments=True)
            if not words or words[0] != "calippso" or "|" in words or "&&" in words:
                continue
            args = words[1:]
            if not args or args[0] in ("--help", "--version") or "--help" in args:
                continue
            for argument in args:   # the files that the lines before write
                if not argument.startswith("-") and Path(argument).suffix:
                    path = Path(argument.replace("*", "0").replace("..", "up"))
                    path.parent.mkdir(parents=True, exist_ok=True)
                    path.touch()
                    args[args.index(argument)] = str(path)
            _parse(args)


def test_containers_guide_names_the_generators_that_take_containers():
    """docs/containers.md's sentence on `calippso generate` lists exactly the generators
    whose command takes --walls and --cylinder."""
    sentence = _paragraph(ROOT / "docs" / "containers.md", "passes it to the generator")
    taking = sentence.split("take walls and a cylinder")[0].split("passes it to the generator")[1]
    listed = set(re.findall(r"`([a-z]+)`", taking))
    generate = cli.get_command(click.Context(cli), "generate")
    context = click.Context(generate)
    with_containers = {
        name for name in generate.list_commands(context)
        if {"walls", "cylinder"} <= {p.name for p in generate.get_command(context, name).params}}
    assert listed == with_containers


def test_demo_time_is_the_same_in_the_help_and_the_docs():
    help_text = cli.get_command(click.Context(cli), "demo").help
    figures = DEMO_SECONDS.findall(help_text)
    assert len(figures) == 2  # the first run (Numba compiles) and the later ones
    assert DEMO_SECONDS.findall(_paragraph(README, "calippso-demo/")) == figures
    assert DEMO_SECONDS.findall(_paragraph(ROOT / "docs" / "index.md", "calippso-demo/")) == figures
    assert re.search(r"about \d+(–\d+)? minutes", _paragraph(README, "run the tests"))


@pytest.mark.parametrize("script", sorted((ROOT / "examples").glob("*.py")), ids=lambda p: p.name)
def test_every_example_states_its_run_time(script):
    docstring = ast.get_docstring(ast.parse(script.read_text()))
    assert re.search(r"^Run time\b.*\d+ s\b", docstring, re.MULTILINE), docstring


def _nav_pages(entries) -> set[str]:
    """The page paths of a mkdocs `nav` (nested lists of {title: page or list})."""
    pages = set()
    for entry in entries:
        for value in entry.values():
            pages |= _nav_pages(value) if isinstance(value, list) else {value}
    return pages


def test_every_page_is_in_the_navigation_and_linked_from_another():
    yaml = pytest.importorskip("yaml")
    docs = ROOT / "docs"
    pages = {path.relative_to(docs).as_posix() for path in docs.rglob("*.md")}
    assert _nav_pages(yaml.safe_load((ROOT / "mkdocs.yml").read_text())["nav"]) == pages
    for page in pages - {"index.md"}:
        linking = [
            other for other in docs.rglob("*.md")
            if other != docs / page
            and f"({Path(os.path.relpath(docs / page, other.parent)).as_posix()}" in other.read_text()
        ]
        assert linking, f"no page links to {page}"


def test_demo_output_and_built_site_are_ignored_by_git():
    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    paths = ["calippso-demo/jammed.npz", "site/index.html"]
    run = subprocess.run(["git", "check-ignore", *paths], cwd=ROOT, capture_output=True, text=True)
    assert run.stdout.split() == paths
