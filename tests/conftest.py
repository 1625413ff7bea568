import os
import sys

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


def _opencv_threads() -> int | None:
    cv2 = sys.modules.get("cv2")
    return None if cv2 is None else int(cv2.getNumThreads())


@pytest.fixture(autouse=True)
def _process_priority_kept():
    """Every test leaves the test process's CPU priority and OpenCV pool as it found them. A `Service` built in
    process applies its --nice and --cv-threads to the whole process (common/runner.py): once raised, the rest of the
    suite and every service it starts inherit nice 19, and on a loaded machine they starve (docs/foundation.md,
    "The loaded run"). Put back where it can be (lowering niceness needs root), and the test fails saying so."""
    nice, threads = os.nice(0), _opencv_threads()
    yield
    changed = []
    nice_now, threads_now = os.nice(0), _opencv_threads()
    if nice_now != nice:
        changed.append(f"niceness {nice} -> {nice_now}")
        try:
            os.nice(nice - nice_now)
        except OSError:
            pass
    if threads is not None and threads_now != threads:
        changed.append(f"OpenCV threads {threads} -> {threads_now}")
        sys.modules["cv2"].setNumThreads(threads)
    if changed:
        pytest.fail(
            f"this test changed the test process's {' and '.join(changed)}: every later test (and the services it "
            "starts) would inherit it; build a Service in process with --nice 0 --cv-threads 0",
            pytrace=False,
        )
