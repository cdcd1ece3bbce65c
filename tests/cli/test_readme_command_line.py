"""The README's "Command line" section names exactly the flags the commands accept."""

import os
import re

from cslx.cli import COMMANDS, build_parser

README = os.path.join(os.path.dirname(__file__), "..", "..", "README.md")


def _section() -> str:
    text = open(README, encoding="utf-8").read()
    start = text.index("## Command line")
    return text[start : text.index("\n## ", start + 1)]


def _synopsis_flags() -> dict[str, set[str]]:
    """Flags per command in the synopsis block (first code block of the section)."""
    block = _section().split("```")[1]
    flags: dict[str, set[str]] = {}
    current = None
    for line in block.splitlines():
        m = re.match(r"cslx (\w+)", line.strip())
        if m:
            current = m.group(1)
            flags[current] = set()
        if current:
            flags[current] |= set(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", line))
    return flags


def _parser_flags() -> dict[str, set[str]]:
    parser = build_parser()
    sub = next(a for a in parser._actions if hasattr(a, "choices") and isinstance(a.choices, dict))
    out = {}
    for name, p in sub.choices.items():
        opts = set()
        for action in p._actions:
            long = [o for o in action.option_strings if o.startswith("--") and o != "--help"]
            if long:
                opts.add(long[0])  # the first spelling is the documented one
        out[name] = opts
    return out


def test_readme_synopsis_lists_every_command_and_flag():
    readme, real = _synopsis_flags(), _parser_flags()
    assert set(readme) == set(COMMANDS)
    for cmd in COMMANDS:
        missing = real[cmd] - readme[cmd]
        unknown = readme[cmd] - real[cmd]
        assert not missing, f"README 'Command line' lacks cslx {cmd} {sorted(missing)}"
        assert not unknown, f"README 'Command line' names flags cslx {cmd} lacks: {sorted(unknown)}"


def test_readme_examples_parse():
    """Every `cslx …` line of the examples parses with the real parser."""
    import shlex

    parser = build_parser()
    examples = _section().split("```")[3]
    lines = [ln.split("#")[0].strip() for ln in examples.splitlines()]
    lines = [ln for ln in lines if ln.startswith("cslx ")]
    assert lines
    for ln in lines:
        args = parser.parse_args(shlex.split(ln)[1:])
        assert args.command in COMMANDS


def test_readme_synopsis_lists_every_choice():
    """An option with fixed choices shows all of them (`--nuisance clean|…|mixed`)."""
    block = _section().split("```")[1]
    chunks = dict(re.findall(r"cslx (\w+)(.*?)(?=\ncslx |\Z)", block, re.S))
    parser = build_parser()
    sub = next(a for a in parser._actions if hasattr(a, "choices") and isinstance(a.choices, dict))
    for name, p in sub.choices.items():
        text = chunks[name]
        for action in p._actions:
            if not action.choices or not action.option_strings:
                continue
            flag = action.option_strings[0]
            m = re.search(re.escape(flag) + r" ([\w|-]+)", text)
            assert m, f"README: cslx {name} {flag} without its choices"
            shown = set(m.group(1).split("|"))
            assert set(action.choices) <= shown, (name, flag, set(action.choices) - shown)
