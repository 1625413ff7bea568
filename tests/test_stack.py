"""One description of the stack: common/stack.py (NODES) is the source, with the router (ROUTER_ARGV, the port in
DEFAULT_ENDPOINT); docker-compose.yml (written by hri/compose.py), `hri up` and the demo are derived from it and
checked here: the committed compose file is the generated one, every launch runs the stack's services, each its own
module with flags its own parser accepts, the same router port — and a node added to the declaration appears in all
of them with no other edit. No process is started: each service's `main` runs only as far as its argument parser."""

from __future__ import annotations

import argparse
import importlib
import re
import shlex
import sys
from pathlib import Path
from urllib.parse import urlsplit

import pytest
import yaml

from common import stack
from common.stack import module_of
from common.transport import DEFAULT_ENDPOINT
from hri.compose import REGENERATE, compose_text
from hri.launcher import (
    ROUTER_ARGV,
    ServiceSpec,
    add_up_arguments,
    select,
    services_from_args,
    stack_names,
)
from testkit.parsing import main_until_parsed

ROOT = Path(__file__).resolve().parent.parent
ROUTER_PORT = urlsplit(DEFAULT_ENDPOINT.replace("tcp/", "tcp://")).port


def parsed_by_the_service(name: str, flags: list[str]) -> argparse.Namespace:
    """`flags` as the service's own `main` parses them (and nothing else of `main` runs)."""
    try:
        return main_until_parsed(name, flags)
    except SystemExit as exc:
        pytest.fail(f"{name} rejects {flags} (exit {exc.code}; its usage error is in the captured stderr)")


def check_specs(specs: list[ServiceSpec], where: str) -> None:
    names = [s.name for s in specs]
    order = stack_names()
    assert names == [n for n in order if n in names], f"{where}: {names} not in the stack's order {order}"
    for spec in specs:
        assert spec.argv[0] == module_of(spec.name), (where, spec)
        parsed_by_the_service(spec.name, [*spec.argv[1:], "--connect", DEFAULT_ENDPOINT])  # as Launcher adds it


# -- docker-compose.yml --------------------------------------------------------------------------------------
def compose_defaults(text: str) -> str:
    """A compose value with every `${VAR:-default}` (or `${VAR-default}`) at its default, `${VAR}` empty."""
    return re.sub(r"\$\{\w+(?::?-([^}]*))?\}", lambda m: m.group(1) or "", text)


def compose_argv(value: str | list[str]) -> list[str]:
    return shlex.split(compose_defaults(value)) if isinstance(value, str) else [compose_defaults(v) for v in value]


@pytest.fixture(scope="module")
def compose() -> dict:
    return yaml.safe_load((ROOT / "docker-compose.yml").read_text())["services"]


def test_the_committed_compose_file_is_the_generated_one():
    committed = (ROOT / "docker-compose.yml").read_text()
    assert committed == compose_text(), (
        f"docker-compose.yml is not what common/stack.py declares: run `{REGENERATE}` (or `make compose`) "
        "and commit the result; change the file through hri/compose.py or the Node's Container, not by hand"
    )


def test_compose_runs_the_stack_and_nothing_else(compose):
    assert list(compose) == ["router", *stack_names()]


def test_compose_router_listens_where_the_services_connect(compose):
    router = compose["router"]
    listen = f"tcp/0.0.0.0:{ROUTER_PORT}"
    assert compose_argv(router["command"]) == ["python", "-m", *ROUTER_ARGV, listen]
    assert router["environment"]["HRI_LISTEN"] == listen
    assert [compose_defaults(p).rsplit(":", 1)[1] for p in router["ports"]] == [str(ROUTER_PORT)]
    for name in stack_names():
        assert compose_defaults(compose[name]["environment"]["HRI_CONNECT"]) == f"tcp/router:{ROUTER_PORT}", name
        assert compose[name]["depends_on"]["router"]["condition"] == "service_healthy", name


@pytest.mark.parametrize("name", stack_names())
def test_compose_runs_each_service_with_flags_it_accepts(compose, name):
    argv = compose_argv(compose[name]["command"])
    assert argv[:3] == ["python", "-m", module_of(name)], argv
    args = parsed_by_the_service(name, argv[3:])
    assert compose[name]["healthcheck"]["test"][-1] == name  # the check asks for this service's token
    host, inside = compose_defaults(compose[name]["volumes"][0]).split(":")[:2]
    for flag in ("source", "labels"):  # the files the defaults name are shipped under HRI_DATA's default
        value = getattr(args, flag, None)
        if value and value.startswith(inside + "/"):
            assert (ROOT / host / value[len(inside) + 1 :]).exists(), (name, flag, value)


# -- hri up ----------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "flags",
    [
        [],
        ["--camera", "data/images/tabletop", "--speech-input", "text", "--loop", "--fps", "5"],
        ["--speech-input", "wav", "--wav", "a.wav", "b/", "--speech-backend", "whisper", "--mirrored"],
        ["--vision-backend", "onnx", "--model", "m.onnx", "--speech-input", "zenoh", "--fusion-arg=--weights=fixed"],
        ["--vision-labels", "data/demo/labels.json", "--no-gesture", "--speech-input", "none", "--camera", "none"],
        ["--no-camera", "--no-speech", "--gesture-arg=--log-level=DEBUG", "--speech-arg=--log-level=DEBUG"],
        [
            "--camera-arg=--quality=80",
            "--vision-arg=--max-pixels=1000000",
            "--vision-arg=--log-level=DEBUG",
            "--fusion-arg=--log-level=DEBUG",
        ],
    ],
)
def test_hri_up_starts_the_stack_with_flags_every_service_accepts(flags):
    p = argparse.ArgumentParser()
    add_up_arguments(p)
    args = p.parse_args(flags)
    if args.camera == "none":  # as cmd_up does
        args.camera = None
    check_specs(services_from_args(args), f"hri up {' '.join(flags)}")


# -- the demo --------------------------------------------------------------------------------------------------
def test_the_demo_starts_the_stack_with_flags_every_service_accepts(monkeypatch):
    demo = importlib.import_module("demo.__main__")
    started: list[ServiceSpec] = []

    class Started(Exception):
        pass

    class RecordingLauncher:
        def __init__(self, *args, **kwargs):
            self.children = []

        def start(self, specs, live_timeout=60.0):
            started.extend(specs)
            raise Started()

        def stop(self):
            pass

    monkeypatch.setattr(demo, "Launcher", RecordingLauncher)
    monkeypatch.setattr(demo, "speech_audio", lambda text, voice=None: Path("unused.wav"))
    monkeypatch.setattr(sys, "argv", ["demo"])
    with pytest.raises(Started):
        demo.main()
    cameras = [demo.camera_spec(scene) for scene in dict.fromkeys(step.scene for step in demo.SCRIPT)]
    # every node but the opt-in ones, and the robot's voice (the demo's questions are said aloud)
    assert {s.name for s in started} | {"camera"} == {n.name for n in stack.NODES if not n.opt_in} | {"voice"}
    check_specs(started, "demo")
    for spec in cameras:
        check_specs([spec], "demo camera")
        assert Path(parsed_by_the_service("camera", spec.argv[1:]).source).is_file(), spec


def test_a_spec_that_is_not_the_stacks_is_refused():
    with pytest.raises(ValueError, match="services.vision"):
        ServiceSpec("vision", ["services.gesture"])
    with pytest.raises(ValueError, match="NODES"):
        ServiceSpec("tracker", ["services.tracker"])


# -- adding a node ---------------------------------------------------------------------------------------------
ECHO = stack.Node(
    "echo",
    "says back what it heard (a node that exists only in this test)",
    inputs=(stack.Input("transcript"),),
    outputs=("transcript",),
    container=stack.Container("--times 2", note="Twice, to be heard."),
)


@pytest.fixture
def stack_with_echo(monkeypatch):
    """The declaration with one more entry, and nothing else changed."""
    monkeypatch.setattr(stack, "NODES", (*stack.NODES, ECHO))
    stack.check_stack()


def up_args(*flags: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_up_arguments(p)
    return p.parse_args(list(flags))


def test_a_node_declared_once_is_in_compose_hri_up_and_the_demo(stack_with_echo, monkeypatch):
    text = compose_text()
    services = yaml.safe_load(text)["services"]
    assert list(services) == ["router", "camera", "vision", "gesture", "speech", "fusion", "ros2", "voice", "echo"]
    echo = services["echo"]
    assert compose_argv(echo["command"]) == ["python", "-m", "services.echo", "--times", "2"]
    assert echo["command"].endswith("${HRI_ECHO_ARGS:---times 2}")  # replaceable like the others'
    assert "HRI_ECHO_ARGS" in text.split("name: hri-fusion")[0]  # and listed in the header's settings
    assert "# Twice, to be heard." in text
    assert echo["healthcheck"]["test"][-1] == "echo"
    assert compose_defaults(echo["environment"]["HRI_CONNECT"]) == f"tcp/router:{ROUTER_PORT}"

    everything = services_from_args(up_args("--speech-input", "zenoh"))
    assert [s.name for s in everything] == ["camera", "vision", "gesture", "speech", "fusion", "echo"]  # no opt-in
    assert everything[-1] == ServiceSpec("echo", ["services.echo"])
    only = up_args("--only", "router,echo", "--echo-arg=--times=3")
    assert [s.argv for s in select(services_from_args(only), only.only)] == [["services.echo", "--times=3"]]
    assert "echo" not in [s.name for s in services_from_args(up_args("--no-echo"))]

    demo = importlib.import_module("demo.__main__")
    assert demo.demo_services()[-1] == ServiceSpec("echo", ["services.echo"])


def test_an_opt_in_node_starts_only_when_asked_and_has_a_compose_profile():
    ros2 = stack.node("ros2")
    assert ros2.opt_in
    assert "ros2" not in [s.name for s in services_from_args(up_args("--speech-input", "zenoh"))]
    asked = services_from_args(up_args("--speech-input", "zenoh", "--ros2", "--ros2-arg=--domain-id=3"))
    assert asked[-1] == ServiceSpec("ros2", ["services.ros2", "--domain-id=3"])
    with pytest.raises(SystemExit):
        up_args("--no-ros2")  # off already: there is nothing to turn off
    services = yaml.safe_load(compose_text())["services"]
    assert services["ros2"]["profiles"] == ["ros2"]
    assert all("profiles" not in services[n.name] for n in stack.NODES if not n.opt_in)
    demo = importlib.import_module("demo.__main__")
    assert "ros2" not in [s.name for s in demo.demo_services()]


def test_without_the_entry_there_is_no_such_node():
    assert "echo" not in stack_names() and "echo:" not in compose_text()
    with pytest.raises(SystemExit):
        up_args("--only", "echo")
