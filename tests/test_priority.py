"""CPU priority and thread budgets of the services (issue #34): frame services yield to speech and fusion, which cannot
skip; library thread pools sized for the cores a process may use."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from common.runner import service_parser
from testkit.harness import ROOT


def test_frame_services_are_nicer_than_speech_and_fusion_by_default() -> None:
    nice = {name: service_parser(name, "").parse_args([]).nice for name in ("vision", "gesture", "speech", "fusion")}
    assert nice["vision"] == nice["gesture"] > 0
    assert nice["speech"] == nice["fusion"] == 0
    assert service_parser("vision", "").parse_args(["--nice", "0"]).nice == 0  # a user can turn it off


def test_lower_priority_makes_the_process_nicer_and_never_less_nice() -> None:
    code = "import os\nfrom common.runner import lower_priority\n"
    code += "lower_priority(3)\nlower_priority(0)\nprint(os.nice(0))"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert int(out.stdout) == min(os.nice(0) + 3, 19)


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
