"""CPU priority and thread budgets of the services (issue #34): frame services yield to speech and fusion, which cannot
skip; library thread pools sized for the cores a process may use."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from common.runner import service_parser
from testkit.harness import ROOT


def test_frame_services_yield_and_speech_asks_for_more_by_default() -> None:
    nice = {name: service_parser(name, "").parse_args([]).nice for name in ("vision", "gesture", "speech", "fusion")}
    assert nice["vision"] == nice["gesture"] > 0
    assert nice["speech"] < nice["fusion"] == 0
    assert service_parser("vision", "").parse_args(["--nice", "0"]).nice == 0  # a user can turn it off


def _niceness_after(*changes: int) -> tuple[int, list[str | None]]:
    code = "import json, os\nfrom common.cpu import change_priority\n"
    code += f"refused = [change_priority(n) for n in {list(changes)!r}]\nprint(os.nice(0))\nprint(json.dumps(refused))"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    first, second = out.stdout.splitlines()
    return int(first), json.loads(second)


def test_a_process_can_always_yield_and_asks_for_more_only_where_allowed() -> None:
    base = os.nice(0)
    niceness, refused = _niceness_after(3, 0)
    assert niceness == min(base + 3, 19) and refused == [None, None]
    niceness, refused = _niceness_after(-2)
    if refused[0] is None:  # root or CAP_SYS_NICE: raised
        assert niceness == max(base - 2, -20)
    else:  # refused: said why, and the priority is the one it had
        assert niceness == base and "CAP_SYS_NICE" in refused[0]


def test_a_container_quota_caps_the_cores_a_service_sizes_its_pools_for(tmp_path: Path) -> None:
    from common.cpu import available_cores, cgroup_cpu_limit

    limit = tmp_path / "cpu.max"
    limit.write_text("150000 100000\n")  # docker run --cpus 1.5
    assert cgroup_cpu_limit(limit) == 1.5
    limit.write_text("max 100000\n")
    assert cgroup_cpu_limit(limit) is None
    assert cgroup_cpu_limit(tmp_path / "absent") is None
    assert 1 <= available_cores() <= (os.cpu_count() or 1)


def test_services_run_opencv_on_one_thread_unless_told() -> None:
    code = (
        "import cv2\nfrom common.runner import service_parser, Service\n"
        "args = service_parser('vision', '').parse_args([])\nService('vision', args)\nprint(cv2.getNumThreads())"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert int(out.stdout.split()[-1]) == 1
    assert service_parser("gesture", "").parse_args(["--cv-threads", "0"]).cv_threads == 0


def _autogroup_after(change: int, new_session: bool) -> tuple[str, str]:
    """(the child's /proc/self/autogroup before, after) change_priority(change), in a session of its own or not."""
    code = (
        "from pathlib import Path\nfrom common.cpu import change_priority\n"
        "before = Path('/proc/self/autogroup').read_text().strip()\n"
        f"change_priority({change})\nprint(before)\nprint(Path('/proc/self/autogroup').read_text().strip())"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
        start_new_session=new_session,
    )
    before, after = out.stdout.splitlines()
    return before, after


@pytest.mark.skipif(not Path("/proc/self/autogroup").exists(), reason="no autogroup scheduling in this kernel")
def test_a_service_leading_its_session_gives_its_autogroup_the_same_priority() -> None:
    """`hri up` starts each service in a session of its own; with autogroups a thread's niceness counts only inside
    its session's group, so the group must carry it too (else --nice changed nothing between services)."""
    before, after = _autogroup_after(4, new_session=True)
    assert after.endswith("nice 4") and before != after, (before, after)
    # inside another session (a shell's, here pytest's) the group is shared: left alone
    before, after = _autogroup_after(4, new_session=False)
    assert after == before
