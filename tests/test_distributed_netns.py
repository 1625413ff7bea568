"""The namespace test hosts themselves: built, reachable only through the router's namespace, always removed."""

from __future__ import annotations

import subprocess
import time

import pytest

from testkit.netns import NAME_PREFIX, Network, cleanup_leftovers, netns_fixture, unavailable

needs_root = pytest.mark.skipif(unavailable() is not None, reason=str(unavailable()))


def test_without_root_the_reason_is_given(monkeypatch):
    monkeypatch.setattr("os.geteuid", lambda: 1000)
    assert "needs root" in unavailable()
    monkeypatch.setattr("shutil.which", lambda name: None)
    assert "`ip` command" in unavailable()


def namespaces() -> set[str]:
    out = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    return {line.split()[0] for line in out.splitlines() if line.strip()}


def routed(ns: str | None, addr: str) -> bool:
    prefix = ["-n", ns] if ns else []
    return subprocess.run(["ip", *prefix, "route", "get", addr], capture_output=True).returncode == 0


def carrier(ns: str | None, ifname: str) -> bool:
    prefix = ["-n", ns] if ns else []
    out = subprocess.run(["ip", *prefix, "link", "show", ifname], capture_output=True, text=True).stdout
    return "LOWER_UP" in out and "NO-CARRIER" not in out


@needs_root
def test_hosts_have_a_route_to_the_router_only_and_a_link_that_can_be_cut():
    net = Network()
    try:
        assert set(net.namespaces.values()) <= namespaces()
        per, sp = net.links["perception"], net.links["speech"]
        assert routed(per.netns, per.router_addr) and routed(sp.netns, sp.router_addr)
        assert not routed(per.netns, sp.host_addr)  # no route between hosts: all traffic goes through the router
        assert carrier(per.netns, per.host_if)
        net.set_link("perception", up=False)
        assert not carrier(per.netns, per.host_if)  # the host sees its link gone, as with a Wi-Fi drop
        assert carrier(sp.netns, sp.host_if)
        net.set_link("perception", up=True)
        assert any(carrier(per.netns, per.host_if) or time.sleep(0.1) for _ in range(20))
    finally:
        net.close()
    assert not set(net.namespaces.values()) & namespaces()


@needs_root
def test_the_fixture_tears_down_when_the_test_fails():
    gen = netns_fixture()
    group = next(gen)
    made = set(group.net.namespaces.values())
    assert made <= namespaces()
    with pytest.raises(RuntimeError):
        gen.throw(RuntimeError("the test failed"))
    assert not made & namespaces()


@needs_root
def test_leftovers_of_a_killed_run_are_removed():
    dead_pid = int(open("/proc/sys/kernel/pid_max").read()) + 1  # no such process
    name = f"{NAME_PREFIX}-{dead_pid}-beef-router"
    subprocess.run(["ip", "netns", "add", name], check=True)
    try:
        assert name in cleanup_leftovers()
        assert name not in namespaces()
    finally:
        subprocess.run(["ip", "netns", "del", name], capture_output=True)
