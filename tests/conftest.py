import pytest

from testkit.harness import ProcessGroup


@pytest.fixture
def group():
    """A router on a free port plus whatever services the test starts; all stopped at teardown."""
    g = ProcessGroup()
    try:
        yield g
    finally:
        g.close()
