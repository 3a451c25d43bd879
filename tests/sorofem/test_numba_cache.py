"""numba's on-disk cache shared by concurrent processes (sorofem._numba).

Two processes compile different signatures of one ``cache=True`` function at the same time. numba's unlocked
read-modify-write of the cache index lets the index of one process name the data file of the other; a third
process then runs machine code compiled for other argument types. The interleaving that does it is forced here
with delays inside numba's index and data writes (a busy machine produces the same order by preemption).
"""
import subprocess
import sys
import textwrap

import pytest

MODULE = textwrap.dedent("""
    import os, sys, time
    if os.environ.get("LOCK") == "1":
        import sorofem._numba  # noqa: F401  (the lock)
    from numba.core import caching
    import numpy as np
    from numba import njit

    delay_index, delay_data = (float(v) for v in os.environ.get("DELAYS", "0,0").split(","))
    cls = caching.IndexDataCacheFile
    save_index, save_data = cls._save_index, cls._save_data

    def slow_index(self, overloads):
        time.sleep(delay_index)
        save_index(self, overloads)

    def slow_data(self, name, data):
        time.sleep(delay_data)
        save_data(self, name, data)

    cls._save_index, cls._save_data = slow_index, slow_data

    @njit(cache=True)
    def total(a):
        s = 0.0
        for x in a.flat:
            s += x
        return s

    ONE = np.arange(6.0)                          # 1-D, contiguous: sum 15
    TWO = np.arange(6.0).reshape(2, 3)[:, ::2]    # 2-D, strided: [[0, 2], [3, 5]], sum 10

    if __name__ == "__main__":
        if sys.argv[1] == "check":
            print(total(ONE), total(TWO))
        else:
            total(ONE if sys.argv[1] == "one" else TWO)
""")


def _race(tmp_path, python, subprocess_env, lock):
    """Compile both signatures in two processes, A writing its index first and its data last; return what a
    third process computes from the cache."""
    (tmp_path / "racemod.py").write_text(MODULE)
    env = dict(subprocess_env, LOCK="1" if lock else "0", PYTHONPATH=str(tmp_path))
    # A: reads the (empty) index at once, writes its index at +0.5 s and its data at +2 s;
    # B: reads the index within ~0.2 s, writes its index and data at +1 s.
    a = subprocess.Popen([python, "racemod.py", "one"], cwd=tmp_path, env=dict(env, DELAYS="0.5,1.5"))
    b = subprocess.Popen([python, "racemod.py", "two"], cwd=tmp_path, env=dict(env, DELAYS="1.0,0.0"))
    assert a.wait(timeout=300) == 0 and b.wait(timeout=300) == 0
    res = subprocess.run([python, "racemod.py", "check"], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=300)
    return res.returncode, res.stdout.split()


@pytest.mark.slow
def test_concurrent_compiles_of_two_signatures_leave_a_consistent_cache(tmp_path, python, subprocess_env):
    code, out = _race(tmp_path, python, subprocess_env, lock=True)
    assert code == 0 and out == ["15.0", "10.0"], (code, out)


@pytest.mark.slow
def test_without_the_lock_the_same_interleaving_corrupts_the_cache(tmp_path, python, subprocess_env):
    """The control: the harness above does reproduce numba's race (else the first test would prove nothing)."""
    code, out = _race(tmp_path, python, subprocess_env, lock=False)
    if code == 0 and out == ["15.0", "10.0"]:
        pytest.skip("this numba no longer mixes up the cache entries under this interleaving")
    assert code != 0 or out != ["15.0", "10.0"]


READER = textwrap.dedent("""
    import sorofem._numba  # noqa: F401
    import numpy as np
    from numba import njit

    @njit(cache=True)
    def total(a):
        s = 0.0
        for x in a.flat:
            s += x
        return s

    @njit(cache=True)
    def scaled(a, f):
        return a * f

    print(total(np.arange(4.0)), scaled(np.arange(3.0), 2.0).sum(), len(total.stats.cache_hits))
""")


@pytest.mark.skipif(not hasattr(__import__("os"), "geteuid") or __import__("os").geteuid() != 0
                    or not __import__("shutil").which("runuser"), reason="needs root and runuser to act as another user")
def test_another_user_reads_the_cache_it_may_not_write():
    """A kernel module owned by root, its ``__pycache__`` filled by root: user ``nobody`` (no writable home) loads
    the cached kernel and compiles what the cache lacks in memory. Before, numba found no writable cache
    location and every ``cache=True`` function raised "no locator available" at import (so ``import
    soroshapes`` failed for such a user, e.g. a service account)."""
    import os
    import shutil
    import tempfile
    from pathlib import Path
    tmp_path = Path(tempfile.mkdtemp(prefix="soro-cache-"))       # pytest's tmp_path is not readable by nobody
    try:
        _read_as_another_user(tmp_path)
    finally:
        shutil.rmtree(tmp_path, ignore_errors=True)


def _read_as_another_user(tmp_path):
    import os
    import shutil
    import sorofem
    tmp_path.chmod(0o755)
    (tmp_path / "reader.py").write_text(READER)
    # Debian's interpreter (numba and numpy are Debian's) and a copy of sorofem beside the kernel module: the
    # checkout and its venv may sit in a folder user nobody cannot enter (a CI clone in a 0700 mktemp folder)
    shutil.copytree(os.path.dirname(sorofem.__file__), tmp_path / "sorofem",
                    ignore=shutil.ignore_patterns("__pycache__"))
    for p in [tmp_path, *tmp_path.rglob("*")]:
        p.chmod(0o755 if p.is_dir() else 0o644)
    python = getattr(sys, "_base_executable", None) or sys.executable
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    env.pop("NUMBA_CACHE_DIR", None)
    root = subprocess.run([python, "-c", "import reader"], env=env, cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert root.returncode == 0, root.stderr
    # drop the second kernel's cache entry: nobody must compile it and fail to save it, quietly
    for f in (tmp_path / "__pycache__").glob("reader.scaled-*"):
        f.unlink()
    other = subprocess.run(["runuser", "-u", "nobody", "--", "env", f"PYTHONPATH={env['PYTHONPATH']}",
                            "HOME=/nonexistent", python, "-c", "import reader"], cwd="/tmp",
                           capture_output=True, text=True, timeout=300)
    assert other.returncode == 0, other.stderr
    assert other.stdout.split() == ["6.0", "6.0", "1"]       # results right, and total() came from the cache


CALLER = textwrap.dedent("""
    import sys
    import sorofem._numba as nb
    nb._ROOT = sys.argv[1]              # the probe package's folder stands for the folder of the platform's packages
    from probepkg.a import f
    print(f(1.0), len(f.stats.cache_hits))
""")


@pytest.mark.parametrize("stamped", [True, False], ids=["package stamp", "numba's own stamp (control)"])
def test_a_changed_callee_module_recompiles_its_cached_callers(tmp_path, python, subprocess_env, stamped):
    """numba judges a cached kernel by its own file only: ``a.f`` calls ``b.g``, ``b.py`` changes, and numba alone
    still runs the old ``g`` compiled into ``f``'s cache. With the package's sources in the stamp, ``f`` compiles
    again. The control runs the same steps with numba's stamp and shows the stale result."""
    import os
    pkg = tmp_path / "probepkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from sorofem._numba import njit\nfrom .b import g\n\n\n"
                              "@njit(cache=True)\ndef f(x):\n    return g(x) * 10.0\n")
    (pkg / "b.py").write_text("from sorofem._numba import njit\n\n\n@njit(cache=True)\ndef g(x):\n    return x + 1.0\n")
    script = CALLER if stamped else CALLER.replace("nb._ROOT = sys.argv[1]", "nb._ROOT = '/nonexistent'")
    (tmp_path / "caller.py").write_text(script)
    env = dict(subprocess_env, PYTHONPATH=os.pathsep.join([str(tmp_path), os.getcwd()]))
    env.pop("NUMBA_CACHE_DIR", None)

    def run():
        res = subprocess.run([python, "caller.py", str(tmp_path)], cwd=tmp_path, env=env, capture_output=True,
                             text=True, timeout=300)
        assert res.returncode == 0, res.stderr
        value, hits = res.stdout.split()
        return float(value), int(hits)

    assert run() == (20.0, 0)                 # compiled and cached
    assert run() == (20.0, 1)                 # loaded from the cache
    b = pkg / "b.py"
    b.write_text(b.read_text().replace("x + 1.0", "x + 2.0"))
    st = b.stat()
    os.utime(b, ns=(st.st_atime_ns, st.st_mtime_ns + 5_000_000_000))
    value, hits = run()
    if stamped:
        assert (value, hits) == (30.0, 0)     # f compiled again with the new g
    else:
        assert (value, hits) == (20.0, 1)     # numba alone: the stale g inside f's cache
