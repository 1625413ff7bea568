"""`docker compose up`, for real: docker/ci.sh builds the image, starts the stack under its own project name
and a free host port, checks from the host that frames flow, every service is live and a typed demo command
comes back fused, then takes everything down. Skipped, with the reason, where no Docker engine can run."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from tests.harness import ROOT

pytestmark = pytest.mark.docker

SKIP_CODE = 77
# A cold run (apt, debootstrap, wheels, build) takes a few minutes on 2 shared cores; a warm one ~30 s.
CI_TIMEOUT_S = 1500


def skip_reason(output: str) -> str:
    for line in output.splitlines():
        if line.startswith("SKIP docker: "):
            return line[len("SKIP docker: "):]
    return "docker/ci.sh exited 77 without a reason"


def tail(text: str, lines: int = 60) -> str:
    return "\n".join(text.splitlines()[-lines:])


@pytest.mark.timeout(CI_TIMEOUT_S + 60)
def test_compose_stack_builds_starts_and_answers_from_the_host(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHON": sys.executable, "HRI_COMPOSE_PROJECT": f"hri-fusion-test-{os.getpid()}"}
    env.pop("HRI_ROUTER_PORT", None)  # the script picks a free one
    log = tmp_path / "docker-ci.log"
    with log.open("w") as out:
        proc = subprocess.Popen(["bash", str(ROOT / "docker" / "ci.sh")], cwd=ROOT, env=env, stdout=out,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)
        try:
            proc.wait(CI_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            # SIGTERM to the group: the running step dies, then the script's trap takes the stack down
            # and stops the engine it started
            os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(90)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
            pytest.fail(f"docker/ci.sh did not finish within {CI_TIMEOUT_S} s:\n{tail(log.read_text())}")
    output = log.read_text()
    if proc.returncode == SKIP_CODE:
        pytest.skip(skip_reason(output))
    assert proc.returncode == 0, f"docker/ci.sh failed (exit {proc.returncode}):\n{tail(output)}"
    # the script's own checks passed; make sure they were the real ones, not skipped silently
    assert "frames flow: " in output, tail(output)
    assert '"key":"hri/camera/cam0/frame"' in output, tail(output)
    assert "all docker checks passed" in output, tail(output)
    left_out = [ln for ln in output.splitlines() if "not in this checkout yet" in ln]
    if left_out:  # visible in the warnings summary: the stack ran without some services
        warnings.warn(left_out[0].split("] ", 1)[-1])
