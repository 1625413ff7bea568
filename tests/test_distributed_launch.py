"""`hri up --only`: part of the stack on each host, against one router."""

from __future__ import annotations

import argparse
import signal
import time

import pytest

from common.schema import FusedCommand
from hri.launcher import add_up_arguments, select, services_from_args, starts_router
from testkit.harness import DATA, Client, type_command
from testkit.netns import netns_fixture

TABLE = DATA / "demo" / "table.png"


def up_args(*flags: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_up_arguments(p)
    p.add_argument("--connect", action="append", default=None)
    return p.parse_args(list(flags))


def test_only_keeps_the_named_services_and_the_router_only_when_named():
    args = up_args("--only", "vision,gesture", "--connect", "tcp/10.0.0.2:7447")
    assert [s.name for s in select(services_from_args(args), args.only)] == ["vision", "gesture"]
    assert not starts_router(args)
    assert starts_router(up_args("--only", "router,camera"))
    assert not starts_router(up_args("--only", "fusion"))  # a router already runs on this host (hri router)
    assert starts_router(up_args())
    everything = up_args()
    assert select(services_from_args(everything), everything.only) == services_from_args(everything)


def test_only_refuses_what_is_not_part_of_the_stack(capsys):
    with pytest.raises(SystemExit):
        up_args("--only", "vision,tracker")
    assert "tracker" in capsys.readouterr().err


netns_group = pytest.fixture(netns_fixture)


@pytest.mark.integration
def test_two_hosts_each_run_part_of_the_stack_with_hri_up(netns_group):
    """The README's two-host example: host A runs the router with camera and vision, host B speech-less fusion."""
    g = netns_group
    net = g.net
    host_a = g.start(
        "up-perception",
        "hri.cli",
        "up",
        "--only",
        "router,camera,vision",
        "--camera",
        str(TABLE),
        "--fps",
        "10",
        "--loop",
        "--vision-labels",
        str(DATA / "demo" / "labels.json"),
        *[a for ep in net.router_listen() for a in ("--listen", ep)],
        connect=False,
        host="router",
    )
    g.wait_router(30)
    host_b = g.start(
        "up-fusion",
        "hri.cli",
        "up",
        "--only",
        "fusion",
        "--speech-input",
        "none",
        "--connect",
        net.endpoint("speech"),
        connect=False,
        host="speech",
    )
    client = Client(g.endpoint)
    try:
        for name in ("camera", "vision", "fusion"):
            client.wait_alive(name, timeout=90)
        results = client.collect("hri/fusion/**")
        time.sleep(1.0)
        type_command(client, "pick up the red one")
        cmd = results.next()
        assert isinstance(cmd, FusedCommand) and cmd.target is not None and cmd.target.color == "red", cmd
        assert "[camera ]" in host_a.output() and "[vision ]" in host_a.output()
        assert "[fusion ]" in host_b.output() and "[vision" not in host_b.output()
    finally:
        client.close()
    for proc in (host_b, host_a):  # Ctrl-C stops each host's part, exit 0
        proc.popen.send_signal(signal.SIGINT)
        assert proc.popen.wait(15) == 0, proc.output()[-2000:]
