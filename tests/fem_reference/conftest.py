"""FE contact verification tests: helpers live in fe_cases.py next to this file."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture(scope="session")
def comm():
    from fe_cases import world

    return world()
