"""The README's Python examples run as written, each block alone (a reader copies one block, not the page)."""
import re

import numpy as np
import pytest


def _blocks(repo):
    blocks = re.findall(r"```python\n(.*?)```", (repo / "README.md").read_text(), flags=re.S)
    assert blocks, "the README has no Python example"
    return blocks


def _check_tour(ns, tmp_path):
    import meshio

    assert ns["traj"].times[-1] == pytest.approx(1.0)
    assert (tmp_path / "run.h5").exists() and (tmp_path / "deformed.png").exists()
    assert len(ns["modes"]) == 4
    assert ns["motion"].times[-1] == pytest.approx(0.05)
    # the XDMF survives the snapshot written next to it and opens with 3-component displacement
    with meshio.xdmf.TimeSeriesReader(str(tmp_path / "run.xdmf")) as r:
        points, _ = r.read_points_cells()
        t, point_data, _ = r.read_data(r.num_steps - 1)
    assert t == pytest.approx(1.0)
    u = point_data["displacement"]
    assert u.shape == (len(points), 3) and not u[:, 2].any()
    np.testing.assert_allclose(u[:, :2], ns["traj"].displacement[-1])
    from sorofem.snapshots import Snapshots
    snap = Snapshots(tmp_path / "run.h5")
    assert snap.cavities == ["cavity_0", "cavity_1"] and snap.units["steps/displacement"] == "m"


def _check_topopt(ns, tmp_path):
    assert (tmp_path / "out" / "mbb.png").exists() and len(ns["design"].history) >= 1


def _check_beam(ns, tmp_path):
    assert ns["ik"].converged and ns["swing"].t[-1] == pytest.approx(1.0)
    assert (tmp_path / "finger.png").exists()


def _check_network(ns, tmp_path):
    run = ns["run"]
    assert run.t[-1] == pytest.approx(0.3) and run["chamber"].pressure[-1] > 0


def _check_board(ns, tmp_path):
    assert len(ns["state"].measured) == 2


def _check_vision(ns, tmp_path):
    assert np.linalg.norm(ns["shape"].tip - ns["finger"].positions(ns["q"])[-1]) < 1e-3


def _check_scene(ns, tmp_path):
    assert callable(ns["build"])


CHECKS = [_check_tour, _check_topopt, _check_beam, _check_network, _check_board, _check_vision, _check_scene]


def test_every_block_is_checked(repo):
    assert len(_blocks(repo)) == len(CHECKS), "a README block was added or removed: add or remove its check here"


@pytest.mark.slow
@pytest.mark.parametrize("index", range(len(CHECKS)), ids=[c.__name__[7:] for c in CHECKS])
def test_readme_block_runs_alone(repo, tmp_path, monkeypatch, index):
    """Block ``index`` in a fresh namespace (nothing defined by the blocks before it)."""
    code = _blocks(repo)[index]
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": f"readme_block_{index + 1}"}
    exec(compile(code, f"README.md block {index + 1}", "exec"), namespace)  # noqa: S102 - our own documentation
    CHECKS[index](namespace, tmp_path)
