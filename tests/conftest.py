"""Shared pytest fixtures."""
import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def repo():
    """The repository root."""
    return REPO


@pytest.fixture
def python():
    """The interpreter running the tests (the project's venv under `make test`)."""
    return sys.executable


@pytest.fixture
def subprocess_env():
    """Environment for child processes: MPI allowed as root, no inherited pytest plugins."""
    env = dict(os.environ)
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env
