"""MkDocs hook: pages generated at build time from the code, so that they cannot
drift from it: the command-line reference from the parsers of the `jaxchain`
command, and the list of the tests' independent references from the docstrings of
the test files. And the formulas rendered at build time: each formula that
arithmatex marks becomes MathML (latex2mathml), which the browser draws itself, so
that the site needs no script from a CDN and reads offline."""

import ast
import html
import logging
import os
import re
from pathlib import Path

_MARK = "<!-- the parsers' help, generated -->"
_TESTS = "<!-- the test files' docstrings, generated -->"


def _reference() -> str:
    # argparse wraps to the terminal's width: 78 columns fit the page's column on a
    # desktop; on a narrower screen the blocks (class cli-help) wrap their lines
    # (docs/stylesheets/extra.css), so that no option is hidden past the edge
    os.environ["COLUMNS"] = "78"
    import jaxchain
    from jaxchain._cli.main import COMMANDS, build_parser

    jaxchain.configure()  # as the command does before it builds its parser

    parser = build_parser()
    fence = "```{.text .cli-help}"
    out = ["## jaxchain", "", fence, parser.format_help().rstrip(), "```", ""]
    commands = parser._subparsers._group_actions[0].choices  # argparse keeps them here
    for name in COMMANDS:
        out += [f"## jaxchain {name}", "", fence, commands[name].format_help().rstrip(),
                "```", ""]
    return "\n".join(out)


def _tests() -> str:
    out = []
    for path in sorted(Path("tests").glob("test_*.py")):
        doc = ast.get_docstring(ast.parse(path.read_text()))
        if doc:
            out += [f"## `{path.name}`", "", doc, ""]
    return "\n".join(out)


#: A formula as arithmatex (generic mode) writes it: \(...\) in a span, \[...\] in a div.
_FORMULA = re.compile(r'<(span|div) class="arithmatex">\\([(\[])(.*?)\\[)\]]</\1>', re.DOTALL)
_log = logging.getLogger("mkdocs.hooks.math")


def mathml(html_text: str, where: str = "") -> str:
    """`html_text` with each formula of arithmatex replaced by its MathML (inline for
    \\(...\\), a display block for \\[...\\]). A formula that latex2mathml cannot read
    is left as it was and logged as a warning, which fails the strict build; so is a
    formula that arithmatex wrote in another form."""
    from latex2mathml.converter import convert

    def render(match):
        tex = html.unescape(match.group(3)).strip()
        try:
            return convert(tex, display="block" if match.group(2) == "[" else "inline")
        except Exception as error:  # noqa: BLE001 - any failure of the converter
            _log.warning("%s: formula %r not rendered: %s", where, tex, error)
            return match.group(0)

    rendered = _FORMULA.sub(render, html_text)
    if 'class="arithmatex"' in rendered:  # a form of arithmatex's that _FORMULA misses
        _log.warning("%s: a formula left as TeX (arithmatex's output changed?)", where)
    return rendered


def on_page_content(html_text, page, config, files):
    return mathml(html_text, page.file.src_uri)


def on_page_markdown(markdown, page, config, files):
    if _MARK in markdown:
        markdown = markdown.replace(_MARK, _reference())
    if _TESTS in markdown:
        markdown = markdown.replace(_TESTS, _tests())
    return markdown
