"""The README's results table quotes its tables exactly.

Every decimal number in a row's "headline" cell must occur in the linked results/*.md file
(numbers written as a goal — after "≤" or "≥" — and the paper's figures quoted as such are
exempt), and every row names the commit it was produced at, which must be the commit
written in that file's provenance. A rerun that changes a table therefore fails this test
until the README is updated with the new numbers.
"""

import os
import re

import pytest

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
_NUMBER = re.compile(r"(?<![\w.≤≥])(?<!≤ )(?<!≥ )(?<!goal )-?\d+\.\d+")


def _rows():
    text = open(os.path.join(ROOT, "README.md"), encoding="utf-8").read()
    start = text.index("## Results")
    section = text[start : text.index("\n## ", start + 1)]
    rows = []
    for line in section.splitlines():
        m = re.match(r"\| \[[^\]]+\]\((results/[\w.]+\.md)\) \| ([^|]*) \| (.*) \|$", line)
        if m:
            rows.append(m.groups())
    return rows


def test_the_readme_has_a_results_table():
    assert len(_rows()) >= 5


@pytest.mark.parametrize("path, produced, headline", _rows(), ids=lambda x: str(x)[:30])
def test_row_quotes_its_table(path, produced, headline):
    table = open(os.path.join(ROOT, path), encoding="utf-8").read()
    commit = re.search(r"at git `([0-9a-f]{7,}(?:-dirty)?)`", table)
    assert commit, f"{path} has no provenance line"
    assert f"`{commit.group(1)}`" in produced, (path, commit.group(1), produced)
    missing = [n for n in _NUMBER.findall(headline) if n not in table]
    assert not missing, f"{path}: README quotes {missing}, which the table does not contain"
