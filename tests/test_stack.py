"""One description of the stack: `hri/launcher.py` (STACK, ROUTER_ARGV, the router's port in DEFAULT_ENDPOINT) is
the source; docker-compose.yml, `hri up` and the demo are checked against it: the same services, each running its
own module, flags every service's own parser accepts, the same router port. No process is started: each service's
`main` runs only as far as its argument parser."""

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

from common.transport import DEFAULT_ENDPOINT
from hri.launcher import ROUTER_ARGV, STACK, ServiceSpec, add_up_arguments, service_module, services_from_args

ROOT = Path(__file__).resolve().parent.parent
ROUTER_PORT = urlsplit(DEFAULT_ENDPOINT.replace("tcp/", "tcp://")).port


class Parsed(Exception):
    def __init__(self, namespace: argparse.Namespace):
        super().__init__("parsed")
        self.namespace = namespace


def parsed_by_the_service(name: str, flags: list[str]) -> argparse.Namespace:
    """`flags` as the service's own `main` parses them (and nothing else of `main` runs)."""
    main = importlib.import_module(f"{service_module(name)}.__main__").main
    real = argparse.ArgumentParser.parse_args

    def stop_after_parsing(self, args=None, namespace=None):
        raise Parsed(real(self, args, namespace))

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(argparse.ArgumentParser, "parse_args", stop_after_parsing)
        try:
            main(flags)
        except Parsed as done:
            return done.namespace
        except SystemExit as exc:
            pytest.fail(f"{name} rejects {flags} (exit {exc.code}; its usage error is in the captured stderr)")
    pytest.fail(f"{name}'s main returned without parsing its arguments")


def check_specs(specs: list[ServiceSpec], where: str) -> None:
    names = [s.name for s in specs]
    assert names == [n for n in STACK if n in names], f"{where}: {names} not in the stack's order {STACK}"
    for spec in specs:
        assert spec.argv[0] == service_module(spec.name), (where, spec)
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


def test_compose_runs_the_stack_and_nothing_else(compose):
    assert set(compose) == {"router", *STACK}


def test_compose_router_listens_where_the_services_connect(compose):
    router = compose["router"]
    listen = f"tcp/0.0.0.0:{ROUTER_PORT}"
    assert compose_argv(router["command"]) == ["python", "-m", *ROUTER_ARGV, listen]
    assert router["environment"]["HRI_LISTEN"] == listen
    assert [compose_defaults(p).rsplit(":", 1)[1] for p in router["ports"]] == [str(ROUTER_PORT)]
    for name in STACK:
        assert compose_defaults(compose[name]["environment"]["HRI_CONNECT"]) == f"tcp/router:{ROUTER_PORT}", name
        assert compose[name]["depends_on"]["router"]["condition"] == "service_healthy", name


@pytest.mark.parametrize("name", STACK)
def test_compose_runs_each_service_with_flags_it_accepts(compose, name):
    argv = compose_argv(compose[name]["command"])
    assert argv[:3] == ["python", "-m", service_module(name)], argv
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
    assert {s.name for s in started} | {"camera"} == set(STACK)
    check_specs(started, "demo")
    for spec in cameras:
        check_specs([spec], "demo camera")
        assert Path(parsed_by_the_service("camera", spec.argv[1:]).source).is_file(), spec


def test_a_spec_that_is_not_the_stacks_is_refused():
    with pytest.raises(ValueError, match="services.vision"):
        ServiceSpec("vision", ["services.gesture"])
    with pytest.raises(ValueError, match="STACK"):
        ServiceSpec("tracker", ["services.tracker"])
