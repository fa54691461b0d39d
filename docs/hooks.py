"""MkDocs hook: pages generated at build time from the code, so that they cannot
drift from it: the command-line reference from the parsers of the `jaxchain`
command, and the list of the tests' independent references from the docstrings of
the test files."""

import ast
import os
from pathlib import Path

_MARK = "<!-- the parsers' help, generated -->"
_TESTS = "<!-- the test files' docstrings, generated -->"


def _reference() -> str:
    os.environ["COLUMNS"] = "88"  # argparse wraps to the terminal's width
    import jaxchain
    from jaxchain._cli.main import COMMANDS, build_parser

    jaxchain.configure()  # as the command does before it builds its parser

    parser = build_parser()
    out = ["## jaxchain", "", "```text", parser.format_help().rstrip(), "```", ""]
    commands = parser._subparsers._group_actions[0].choices  # argparse keeps them here
    for name in COMMANDS:
        out += [f"## jaxchain {name}", "", "```text", commands[name].format_help().rstrip(),
                "```", ""]
    return "\n".join(out)


def _tests() -> str:
    out = []
    for path in sorted(Path("tests").glob("test_*.py")):
        doc = ast.get_docstring(ast.parse(path.read_text()))
        if doc:
            out += [f"## `{path.name}`", "", doc, ""]
    return "\n".join(out)


def on_page_markdown(markdown, page, config, files):
    if _MARK in markdown:
        markdown = markdown.replace(_MARK, _reference())
    if _TESTS in markdown:
        markdown = markdown.replace(_TESTS, _tests())
    return markdown
