"""The README's Python examples run as written."""
import re

import pytest


@pytest.mark.slow
def test_readme_tour_runs(repo, tmp_path, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", (repo / "README.md").read_text(), flags=re.S)
    assert blocks, "the README has no Python example"
    monkeypatch.chdir(tmp_path)
    namespace = {}
    for code in blocks:
        exec(compile(code, "README.md", "exec"), namespace)  # noqa: S102 - our own documentation
    assert namespace["traj"].times[-1] == pytest.approx(1.0)
    assert (tmp_path / "run.h5").exists() and (tmp_path / "deformed.png").exists()
    assert len(namespace["modes"]) == 4
    assert namespace["motion"].times[-1] == pytest.approx(0.05)
    assert namespace["ik"].converged and namespace["swing"].t[-1] == pytest.approx(1.0)
    assert (tmp_path / "finger.png").exists()
    run = namespace["run"]
    assert run.t[-1] == pytest.approx(0.3) and run["chamber"].pressure[-1] > 0
