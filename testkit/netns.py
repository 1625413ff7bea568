"""Test hosts on one machine: Linux network namespaces joined by veth pairs to a router's namespace.

    observer (this test process, the root namespace) --veth-- router ns --veth-- perception ns (camera, vision,
                                                                        \\--veth-- speech ns (speech, fusion)

Every link is its own /30 in 10.77.S.0/24, S chosen per run among subnets not already on this machine, so the
hosts reach each other only through the router (as on a site network where each host talks to its robot's
router). Names carry the run's pid, so `cleanup_leftovers()` removes what a killed run left behind (deleting a
namespace deletes its veth ends, and so their peers). Root is needed (`ip netns add`); `unavailable()` says why
not, for a skip. Processes run as `ip netns exec NS python -m ...` with this interpreter.
"""

from __future__ import annotations

import fcntl
import os
import random
import re
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field

from testkit.harness import Proc, ProcessGroup

NAME_PREFIX = "hrit"  # hrit-{pid}-{run}-{host}
HOSTS = ("observer", "perception", "speech")  # link index 0, 1, 2 (observer: the root namespace)
ROUTER_PORT = 7447
SUBNET_LOCK = "/tmp/hrit-netns-subnet.lock"


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=check)


def unavailable() -> str | None:
    """Why namespaces cannot be used here (a skip reason), or None."""
    if sys.platform != "linux":
        return "network namespaces need Linux"
    if shutil.which("ip") is None:
        return "the `ip` command (iproute2) is not installed"
    if os.geteuid() != 0:
        return "creating network namespaces needs root (run the distributed tests as root, as CI does)"
    probe = f"{NAME_PREFIX}-probe-{os.getpid()}"
    res = _ip("netns", "add", probe, check=False)
    if res.returncode != 0:
        return f"`ip netns add` failed: {res.stderr.strip()}"
    _ip("netns", "del", probe, check=False)
    return None


def cleanup_leftovers() -> list[str]:
    """Delete the namespaces of earlier runs whose process is gone; returns their names."""
    removed = []
    for line in _ip("netns", "list", check=False).stdout.splitlines():
        name = line.split()[0] if line.strip() else ""
        m = re.match(rf"^{NAME_PREFIX}-(\d+)-", name)
        if m and not os.path.exists(f"/proc/{m.group(1)}"):
            _ip("netns", "del", name, check=False)
            removed.append(name)
    return removed


def _free_subnet() -> int:
    used = set(int(x) for x in re.findall(r"inet 10\.77\.(\d+)\.", _ip("-4", "addr").stdout))
    free = [s for s in range(1, 255) if s not in used]
    if not free:
        raise RuntimeError("no free 10.77.S.0/24 subnet on this machine for the test hosts")
    return random.choice(free)


@dataclass
class Link:
    host: str
    netns: str | None  # None: the root namespace
    router_if: str
    host_if: str
    router_addr: str
    host_addr: str


@dataclass
class Network:
    """Namespaces `router`, `perception` and `speech`, linked to the router's; `close()` removes all."""

    run: str = field(default_factory=lambda: f"{os.getpid()}-{random.randrange(16**4):04x}")
    namespaces: dict[str, str] = field(default_factory=dict)
    links: dict[str, Link] = field(default_factory=dict)

    def __post_init__(self) -> None:
        try:
            self._build()
        except Exception:
            self.close()
            raise

    def _build(self) -> None:
        # a subnet counts as taken once the observer's address is in the root namespace (the first link): the whole
        # build holds a machine-wide lock, so two runs at once (pytest -n, two checkouts) never pick the same one
        with open(SUBNET_LOCK, "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            self._build_locked()

    def _build_locked(self) -> None:
        subnet = _free_subnet()
        tag = self.run.split("-")[1]
        for host in ("router", "perception", "speech"):
            name = f"{NAME_PREFIX}-{self.run}-{host}"
            _ip("netns", "add", name)
            self.namespaces[host] = name
            _ip("-n", name, "link", "set", "lo", "up")
        router_ns = self.namespaces["router"]
        for k, host in enumerate(HOSTS):
            ns = self.namespaces.get(host)  # None for the observer
            link = Link(
                host, ns, f"h{tag}{k}r", f"h{tag}{k}h", f"10.77.{subnet}.{4 * k + 1}", f"10.77.{subnet}.{4 * k + 2}"
            )
            # create the pair inside the router's namespace so a failed run leaves nothing in the root one
            _ip("-n", router_ns, "link", "add", link.router_if, "type", "veth", "peer", "name", link.host_if)
            if ns is None:
                _ip("-n", router_ns, "link", "set", link.host_if, "netns", "1")
            else:
                _ip("-n", router_ns, "link", "set", link.host_if, "netns", ns)
            _ip("-n", router_ns, "addr", "add", f"{link.router_addr}/30", "dev", link.router_if)
            _ip("-n", router_ns, "link", "set", link.router_if, "up")
            _ip(*self._in(ns), "addr", "add", f"{link.host_addr}/30", "dev", link.host_if)
            _ip(*self._in(ns), "link", "set", link.host_if, "up")
            self.links[host] = link

    @staticmethod
    def _in(ns: str | None) -> list[str]:
        return ["-n", ns] if ns else []

    def endpoint(self, host: str, port: int = ROUTER_PORT) -> str:
        """The router's endpoint as `host` reaches it."""
        return f"tcp/{self.links[host].router_addr}:{port}"

    def router_listen(self, port: int = ROUTER_PORT) -> list[str]:
        return [self.endpoint(h, port) for h in HOSTS]

    def set_link(self, host: str, up: bool) -> None:
        """Cut (or restore) `host`'s link to the router, as a Wi-Fi drop would: carrier gone on both ends."""
        link = self.links[host]
        _ip("-n", self.namespaces["router"], "link", "set", link.router_if, "up" if up else "down")

    def exec_prefix(self, host: str) -> list[str]:
        ns = self.namespaces.get(host)
        return ["ip", "netns", "exec", ns] if ns else []

    def close(self) -> None:
        for name in self.namespaces.values():
            _ip("netns", "del", name, check=False)
        self.namespaces.clear()


class NetnsGroup(ProcessGroup):
    """The harness's ProcessGroup across namespaces: `start(..., host=...)` runs in that host's namespace and
    connects to the router's address on that host's link."""

    def __init__(self, net: Network, port: int = ROUTER_PORT):
        super().__init__()
        self.net = net
        self.port = port
        self.endpoint = net.endpoint("observer", port)  # what this (root namespace) process connects to

    def start(
        self, name: str, *args: str, env: dict[str, str] | None = None, connect: bool = True, host: str = "observer"
    ) -> Proc:
        argv = [*self.net.exec_prefix(host), sys.executable, "-m", *args]
        if connect:
            argv += ["--connect", self.net.endpoint(host, self.port)]
        proc = Proc(name, argv, env)
        self.procs.append(proc)
        return proc

    def router(self, *extra: str, env: dict[str, str] | None = None) -> Proc:
        listen = [a for ep in self.net.router_listen(self.port) for a in ("--listen", ep)]
        proc = self.start("router", "hri.cli", "router", *listen, *extra, env=env, connect=False, host="router")
        self.wait_router()
        return proc

    def wait_router(self, timeout: float = 15.0) -> None:
        import socket

        addr = self.net.links["observer"].router_addr
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with socket.socket() as s:
                s.settimeout(0.5)
                if s.connect_ex((addr, self.port)) == 0:
                    return
            time.sleep(0.05)
        raise TimeoutError(f"the router does not listen on {addr}:{self.port} after {timeout} s\n{self.logs()}")

    def service(self, name: str, *args: str, env: dict[str, str] | None = None, host: str = "observer") -> Proc:
        return self.start(name, f"services.{name}", *args, env=env, host=host)


def netns_fixture():
    """The body of a pytest fixture: a Network and a NetnsGroup on it, skipped with the reason where namespaces
    cannot be made; processes stopped and namespaces deleted whatever the test did."""
    import pytest

    reason = unavailable()
    if reason:
        pytest.skip(reason)
    cleanup_leftovers()
    net = Network()
    group = NetnsGroup(net)
    try:
        yield group
    finally:
        group.close()
        net.close()
