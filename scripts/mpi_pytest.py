"""Run pytest on every MPI rank (``mpirun -n 2 python scripts/mpi_pytest.py -m mpi``).

Rank 0 prints to the terminal and writes the JUnit file; other ranks write their output to
``out/test/mpi-rank<N>.log``. "No tests collected" (pytest exit 5) is turned into a failure, so that an
MPI suite that silently lost its tests cannot pass.
"""
import os
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

# as `python -m pytest` does: the repository first on sys.path, so that `import soroshapes` finds the package
# and not the namespace formed by tests/soroshapes/ (the editable install's finder comes after the path finder)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

rank = MPI.COMM_WORLD.rank
args = sys.argv[1:]
if rank != 0:
    args = [a for a in args if not a.startswith("--junitxml")]
    log = Path("out/test") / f"mpi-rank{rank}.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
code = int(pytest.main(["-p", "no:cacheprovider", *args]))
if code == pytest.ExitCode.NO_TESTS_COLLECTED:
    print(f"[rank {rank}] no MPI test was collected: the MPI suite must not be empty", file=sys.stderr)
    code = 1
codes = MPI.COMM_WORLD.allgather(code)
sys.exit(max(codes))
