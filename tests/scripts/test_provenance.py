"""Provenance: a result names a dirty commit only when the code that computes it differs."""

import subprocess

import pytest

from cslx.provenance import git_sha


def _git(root, *args):
    subprocess.run(["git", *args], cwd=root, check=True, capture_output=True)


@pytest.fixture
def repo(tmp_path):
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "config", "user.email", "t@example.org")
    _git(tmp_path, "config", "user.name", "t")
    for name in ("cslx/a.py", "experiments/b.py", "results/t.md", "README.md"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("x\n")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-q", "-m", "init")
    return tmp_path


def test_results_and_readme_changes_keep_the_commit_clean(repo):
    clean = git_sha(str(repo))
    assert clean != "unknown" and not clean.endswith("-dirty")
    (repo / "results/t.md").write_text("new numbers\n")
    (repo / "README.md").write_text("quoted\n")
    assert git_sha(str(repo)) == clean


@pytest.mark.parametrize("name", ["cslx/a.py", "experiments/b.py"])
def test_code_changes_make_it_dirty(repo, name):
    clean = git_sha(str(repo))
    (repo / name).write_text("changed\n")
    assert git_sha(str(repo)) == clean + "-dirty"


def test_outside_a_repository_is_unknown(tmp_path):
    assert git_sha(str(tmp_path)) == "unknown"
