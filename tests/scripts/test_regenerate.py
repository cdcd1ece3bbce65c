"""The results regeneration driver: every step names a real script, dirty code is refused."""

import importlib.util

import pytest

from experiments import regenerate


def test_every_step_is_an_experiment_with_an_out_option():
    names = [s.name for s in regenerate.STEPS]
    assert len(names) == len(set(names))
    for s in regenerate.STEPS:
        spec = importlib.util.find_spec(f"experiments.{s.module}")
        assert spec is not None, s.module
        source = open(spec.origin, encoding="utf-8").read()
        assert "__main__" in source and "out" in source, s.module


def test_list_prints_each_selected_step(capsys):
    assert regenerate.main(["--list", "--only", "table5", "fig22", "--out", "/tmp/x"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[0] for ln in lines] == ["table5", "fig22"]
    assert all(ln.rstrip().endswith("--out /tmp/x") for ln in lines)


def test_dirty_code_is_refused(monkeypatch, capsys):
    monkeypatch.setattr("cslx.provenance.git_sha", lambda root=None: "abc1234-dirty")
    assert regenerate.main(["--only", "fig07", "--out", "/tmp/never-written"]) == 2
    assert "differs from HEAD" in capsys.readouterr().err


@pytest.mark.parametrize("bad", [["--only", "nope"]])
def test_unknown_step_is_an_error(bad):
    with pytest.raises(SystemExit):
        regenerate.main(bad)
