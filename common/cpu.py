"""How many cores this process may use, and library thread pools sized for that (issue #34: five services share a
small robot computer; a library that sizes its pool for the whole machine, or spins between runs, steals from the
others). Standard library only; OpenCV is touched only when the process already imported it."""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path


def cgroup_cpu_limit(cpu_max: Path = Path("/sys/fs/cgroup/cpu.max")) -> float | None:
    """The cgroup v2 CPU quota in cores (`docker run --cpus 1.5` -> 1.5), None without one."""
    try:
        quota, period = cpu_max.read_text().split()[:2]
    except (OSError, ValueError):
        return None
    if quota == "max":
        return None
    try:
        return int(quota) / int(period)
    except (ValueError, ZeroDivisionError):
        return None


def available_cores() -> int:
    """Cores this process may run on: its CPU affinity, capped by a container's CPU quota (rounded up), >= 1."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not Linux
        cores = os.cpu_count() or 1
    quota = cgroup_cpu_limit()
    if quota is not None:
        cores = min(cores, math.ceil(quota))
    return max(1, cores)


def limit_opencv_threads(threads: int) -> None:
    """OpenCV's parallel_for pool for this process (0: OpenCV's own choice). A no-op if OpenCV is not loaded."""
    cv2 = sys.modules.get("cv2")
    if cv2 is not None and threads > 0:
        cv2.setNumThreads(threads)


AUTOGROUP = Path("/proc/self/autogroup")


def change_priority(by: int, autogroup: Path = AUTOGROUP) -> str | None:
    """Change this process's niceness by `by` (os.nice): positive yields the CPU to others, negative asks for more,
    which needs root or CAP_SYS_NICE. Returns why it was not done, None when it was (or nothing was asked).

    With the kernel's autogroup scheduling on (most desktop and robot Linux kernels), a session's processes share
    the CPU as one group against every other session, and a thread's niceness counts only inside its own group: the
    services `hri up` starts each lead a session of their own (so that a signal reaches one service), so os.nice
    alone changed nothing between them. A session leader also gives its group the same niceness (its group is its
    own); a process inside someone else's session (a shell's) leaves the group alone."""
    if by == 0:
        return None
    try:
        os.nice(max(-20, min(19, int(by))))
    except OSError as exc:  # EPERM without the capability (a container, a normal user): run at the usual priority
        return f"CPU priority left as it is (--nice {by}: {exc.strerror}; needs root or CAP_SYS_NICE to raise it)"
    return set_autogroup_priority(os.nice(0), autogroup)


def set_autogroup_priority(niceness: int, autogroup: Path = AUTOGROUP) -> str | None:
    """Give this process's autogroup `niceness` when the group is this process's own (it leads its session).
    Returns why it was not done, None when it was or there is nothing to do (no autogroup, not a session leader)."""
    if os.getsid(0) != os.getpid() or not autogroup.exists():
        return None
    try:
        autogroup.write_text(f"{niceness}\n")
    except OSError as exc:
        return f"session CPU priority left as it is (niceness {niceness} for {autogroup}: {exc.strerror})"
    return None
