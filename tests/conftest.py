import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.harness import ProcessGroup  # noqa: E402


@pytest.fixture
def group():
    """A router on a free port plus whatever services the test starts; all stopped at teardown."""
    g = ProcessGroup()
    try:
        yield g
    finally:
        g.close()
