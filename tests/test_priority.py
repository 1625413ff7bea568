"""CPU priority of the services (issue #34): frame services yield to speech and fusion, which cannot skip."""

from __future__ import annotations

import os
import subprocess
import sys

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
