"""The environment that scripts/bootstrap.sh makes: Debian's numerical stack, consistent requirements,
an idempotent bootstrap, and a clear refusal on a non-Debian system."""
import importlib.metadata as md
import os
import subprocess
import sys
from pathlib import Path

import pytest
from packaging.requirements import Requirement

DEBIAN = "/usr/lib/python3/dist-packages/"
DEBIAN_ROOT = "/usr/lib/"  # DOLFINx and petsc4py live under /usr/lib/petsc/lib/python3/dist-packages


@pytest.mark.parametrize("module", ["numpy", "scipy", "numba", "dolfinx", "petsc4py", "gmsh"])
def test_numerical_stack_is_debians(module):
    mod = __import__(module)
    assert mod.__file__.startswith(DEBIAN_ROOT), f"{module} loaded from {mod.__file__}, expected Debian's /usr/lib"


def test_single_numpy_distribution():
    """A pip-installed numpy next to Debian's would shadow it for some processes and not others."""
    locations = {str(Path(d._path).parent) for d in md.distributions() if d.metadata["Name"].lower() == "numpy"}
    assert locations == {DEBIAN.rstrip("/")}, f"numpy distributions found in {sorted(locations)}"


def _closure(root, extras=()):
    """Requirements reachable from ``root[extras]``, as (parent, Requirement) pairs (markers evaluated)."""
    seen, todo, pairs = set(), [(root, tuple(extras))], []
    while todo:
        name, ex = todo.pop()
        if (name.lower(), ex) in seen:
            continue
        seen.add((name.lower(), ex))
        for text in md.requires(name) or []:
            req = Requirement(text)
            env_ok = any(req.marker is None or req.marker.evaluate({"extra": e}) for e in (ex or ("",)))
            if env_ok:
                pairs.append((name, req))
                todo.append((req.name, tuple(req.extras)))
    return pairs


def test_requirement_closure_is_satisfied():
    """`pip check` restricted to what the project uses (Debian's unrelated system packages are ignored)."""
    problems = []
    for parent, req in _closure("soro", extras=("extras",)):
        try:
            have = md.version(req.name)
        except md.PackageNotFoundError:
            problems.append(f"{parent} requires {req}, which is not installed")
            continue
        if req.specifier and not req.specifier.contains(have, prereleases=True):
            problems.append(f"{parent} requires {req}, but {have} is installed")
    assert not problems, "\n".join(problems)


def test_bootstrap_second_run_changes_nothing(repo):
    venv = Path(sys.prefix)
    if not (venv / ".bootstrap-stamp").exists():
        pytest.skip("not running from the bootstrapped venv")
    site = next(venv.glob("lib/python3*/site-packages"))
    before = sorted((p.name, p.stat().st_mtime_ns) for p in site.iterdir())
    res = subprocess.run(["bash", str(repo / "scripts/bootstrap.sh")], capture_output=True, text=True,
                         env={**os.environ, "SORO_VENV": str(venv)})
    assert res.returncode == 0, res.stderr
    assert "up to date" in res.stdout
    after = sorted((p.name, p.stat().st_mtime_ns) for p in site.iterdir())
    assert after == before


def test_bootstrap_refuses_non_debian(repo, tmp_path):
    (tmp_path / "etc").mkdir()
    res = subprocess.run(["bash", str(repo / "scripts/bootstrap.sh")], capture_output=True, text=True,
                         env={**os.environ, "SORO_BOOTSTRAP_ROOT": str(tmp_path), "SORO_VENV": str(tmp_path / "v")})
    assert res.returncode == 1
    assert "needs Debian" in res.stderr and "container" in res.stderr
    assert not (tmp_path / "v").exists(), "nothing may be created on a refused system"


@pytest.mark.parametrize("codename, says", [
    ("bookworm", "Debian 12 (bookworm): DOLFINx 0.5.2, supported"),
    ("trixie", "Debian 13 (trixie): DOLFINx 0.9, supported"),
    ("forky", "NOT a supported release (Debian 12 and\n  13 are)"),
])
def test_bootstrap_names_the_release_and_whether_it_is_supported(repo, tmp_path, codename, says):
    """On Debian 12 and 13 the bootstrap says which DOLFINx it installs; on anything else with apt-get it says
    that it goes on with the same package names and that the result is untested."""
    venv = Path(sys.prefix)
    if not (venv / ".bootstrap-stamp").exists():
        pytest.skip("not running from the bootstrapped venv")
    (tmp_path / "etc").mkdir()
    (tmp_path / "etc/debian_version").write_text("13.0\n")
    (tmp_path / "etc/os-release").write_text(f'PRETTY_NAME="Debian test"\nVERSION_CODENAME={codename}\n')
    res = subprocess.run(["bash", str(repo / "scripts/bootstrap.sh")], capture_output=True, text=True,
                         env={**os.environ, "SORO_BOOTSTRAP_ROOT": str(tmp_path), "SORO_VENV": str(venv)})
    assert res.returncode == 0, res.stderr
    assert says in res.stdout and "up to date" in res.stdout, res.stdout


def test_trixie_stage_fails_with_a_message_when_the_mirror_is_unreachable(repo, tmp_path):
    """make test-trixie never skips: when debootstrap cannot reach the mirror the stage fails and says what to
    check (here a stand-in debootstrap that fails as the real one does without network)."""
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "debootstrap").write_text("#!/bin/sh\necho 'E: Failed getting release file $3/dists/trixie/Release'\n"
                                      "exit 1\n")
    (fake / "debootstrap").chmod(0o755)
    cache = tmp_path / "cache"
    env = {**os.environ, "PATH": f"{fake}:{os.environ['PATH']}", "SORO_TRIXIE_CACHE": str(cache),
           "SORO_DEBIAN_MIRROR": "http://127.0.0.1:9/debian"}
    res = subprocess.run(["bash", str(repo / "scripts/test-trixie.sh")], capture_output=True, text=True, env=env,
                         timeout=120)
    assert res.returncode != 0
    if os.geteuid() != 0:  # the stage needs chroot: as a user it stops at once and says so
        assert "needs root" in res.stderr, res.stderr
        return
    assert "debootstrap failed" in res.stderr and "http://127.0.0.1:9/debian" in res.stderr, res.stderr
    assert "Failed getting release file" in (cache / "debootstrap.log").read_text()
    assert not (cache / "trixie").exists(), "a failed build must not leave a root that looks usable"


def _junit(path, cases):
    """A JUnit file as pytest writes it: ``cases`` are (classname, name, outcome) with outcome in
    passed/failed/skipped/collection."""
    tags = {"passed": "", "failed": '<failure message="x">x</failure>', "skipped": '<skipped message="x"/>',
            "collection": '<error message="collection failure">x</error>'}
    counts = {k: sum(o == k for *_, o in cases) for k in tags}
    body = "".join(f'<testcase classname="{c}" name="{n}">{tags[o]}</testcase>' for c, n, o in cases)
    path.write_text(f'<testsuites><testsuite name="pytest" errors="{counts["collection"]}" '
                    f'failures="{counts["failed"]}" skipped="{counts["skipped"]}" tests="{len(cases)}">{body}'
                    "</testsuite></testsuites>")
    return str(path)


@pytest.mark.parametrize("cases, code, line, message", [
    ([("a", "t1", "passed"), ("a", "t2", "skipped")], 0, "1 passed, 0 failed, 1 skipped", None),
    ([("a", "t1", "passed"), ("a", "t2", "failed")], 1, "1 passed, 1 failed, 0 skipped", None),
    ([("", "tests.conftest", "collection")], 1, "0 passed, 0 failed, 0 skipped",
     "collection failed for tests.conftest"),
    ([], 1, "0 passed, 0 failed, 0 skipped", "no test ran"),
])
def test_summary_line_names_collection_failures(tmp_path, python, repo, cases, code, line, message):
    """scripts/test_summary.py (the closing line of make test): a suite that could not be collected is reported
    as such, not as a count of failed tests."""
    res = subprocess.run([python, str(repo / "scripts" / "test_summary.py"), _junit(tmp_path / "s.xml", cases)],
                         capture_output=True, text=True)
    assert res.returncode == code and res.stdout.strip() == line
    assert message is None or message in res.stderr


def test_one_conftest(repo):
    """pytest 8 with --doctest-modules imports every conftest.py as a top-level module named `conftest` and
    refuses a second one (the whole suite then collects nothing): fixtures and hooks go in tests/conftest.py."""
    found = sorted(str(p.relative_to(repo)) for p in repo.glob("**/conftest.py")
                   if not ({".venv", "out", ".git"} & set(p.relative_to(repo).parts)))
    assert found == ["tests/conftest.py"], found
