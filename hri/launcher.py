"""`hri up`: the router and every service as child processes of one command.

It starts the router (unless told to use one that already runs), then each service, prefixes their log lines
with the service name, waits until each has declared its liveliness token, and on Ctrl-C / SIGTERM stops them
in reverse order (SIGTERM, then SIGKILL after a grace period) and exits 0 — no orphans.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import IO, Callable

import zenoh

from common import stack
from common.keys import Keys
from common.robot import ProfileError, load_profile
from common.stack import module_of
from common.transport import DEFAULT_ENDPOINT, live_tokens, open_client

STOP_GRACE_S = 3.0

UP_EXAMPLES = """\
examples:
  hri up                                             # webcam 0, microphone, every service
  hri up --camera data/images/tabletop --speech-input text    # type commands on stdin
  hri up --camera clip.mp4 --speech-input wav --wav commands/
  hri up --no-gesture --vision-backend onnx --model ../shared/models/yolox_nano.onnx   # YOLOX/v5/v8 ONNX, COCO-80
  hri up --fusion-arg=--weights=fixed --no-speech    # any service: --NAME-arg passes it a flag, --no-NAME skips it
  hri up --secure ~/.hri/robot1 ...                  # secured: every service logs in (hri secure init)
  hri up --ros2 --camera none                        # and a ROS 2 node over rmw_zenoh (docs/ros2.md)
  hri up --only router,camera,gesture --listen tcp/0.0.0.0:7447     # host A: the router and part of the stack
  hri up --only vision,speech,fusion --connect tcp/10.0.0.2:7447    # host B: the rest, against A's router
  hri echo 'hri/fusion/**'                            # in another terminal
"""


ROUTER_ARGV = ["hri.cli", "router", "--listen"]  # + the endpoint


# The stack, in start order after the router, is common/stack.py's NODES: each node runs as
# `python -m services.<name>`. `hri up`, the demo and docker-compose.yml (hri/compose.py) start that set; they
# read it at each call, never copy it, so a node added there is started everywhere with no change here.
def stack_nodes() -> tuple[stack.Node, ...]:
    return stack.NODES


def stack_names() -> list[str]:
    return [n.name for n in stack.NODES]


@dataclass
class ServiceSpec:
    name: str
    argv: list[str]  # the module (module_of(name)), then its flags
    stdin: int | IO | None = subprocess.DEVNULL
    env: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.name not in stack_names() or self.argv[:1] != [module_of(self.name)]:
            raise ValueError(
                f"{self.name!r} with argv {self.argv}: a service of the stack ({', '.join(stack_names())}: "
                f"common/stack.py NODES) runs as `python -m {module_of(self.name)}`"
            )


# `hri up`'s flags that mean something to one service, translated into that service's own flags; None: not
# started. A node with no entry here (a new one) starts with no flags but what --<name>-arg passes.
def _camera(args: argparse.Namespace) -> ServiceSpec | None:
    if args.camera is None:
        return None
    cam = ["--source", args.camera, "--cam", args.cam]
    if args.fps:
        cam += ["--fps", str(args.fps)]
    if args.loop:
        cam.append("--loop")
    return ServiceSpec("camera", ["services.camera", *cam])


def _vision(args: argparse.Namespace) -> ServiceSpec | None:
    vision = ["--backend", args.vision_backend]
    if args.model:
        vision += ["--model", args.model]
    if args.vision_labels:
        vision += ["--labels", args.vision_labels]
    return ServiceSpec("vision", ["services.vision", *vision])


def _gesture(args: argparse.Namespace) -> ServiceSpec | None:
    return ServiceSpec("gesture", ["services.gesture", *(["--mirrored"] if args.mirrored else [])])


def _speech(args: argparse.Namespace) -> ServiceSpec | None:
    if args.speech_input == "none":
        return None
    speech = ["--input", args.speech_input]
    stdin: int | IO | None = subprocess.DEVNULL
    if args.speech_input == "text":
        speech = ["--backend", "text"]  # reads stdin; the speech service has no --input text
        stdin = None  # the terminal's stdin goes to the speech service
    elif args.speech_input == "wav":
        if not args.wav:
            raise SystemExit("hri up: --speech-input wav needs --wav FILE_OR_FOLDER")
        speech += ["--wav", *args.wav, "--wait-for", "fusion"]
    if args.speech_backend and args.speech_input != "text":
        speech += ["--backend", args.speech_backend]
    return ServiceSpec("speech", ["services.speech", *speech], stdin=stdin)


def _fusion(args: argparse.Namespace) -> ServiceSpec | None:
    profile = getattr(args, "profile", None)  # the robot's profile (docs/robot.md); the ros2 node relays fusion's
    return ServiceSpec("fusion", ["services.fusion", *(["--profile", profile] if profile else [])])


SPECIAL_FLAGS: dict[str, Callable[[argparse.Namespace], ServiceSpec | None]] = {
    "camera": _camera,
    "vision": _vision,
    "gesture": _gesture,
    "speech": _speech,
    "fusion": _fusion,
}


def services_from_args(args: argparse.Namespace) -> list[ServiceSpec]:
    """The service command lines `hri up`'s flags describe (the router is separate), in the stack's order."""
    specs: list[ServiceSpec] = []
    for node in stack_nodes():
        if getattr(args, f"no_{node.name}", False) or (node.opt_in and not getattr(args, node.name, False)):
            continue
        translate = SPECIAL_FLAGS.get(node.name)
        spec = translate(args) if translate else ServiceSpec(node.name, [node.module])
        if spec is None:
            continue
        spec.argv += getattr(args, f"{node.name}_arg", None) or []  # --<name>-arg, after the translated flags
        specs.append(spec)
    return specs


class Child:
    """One child process, its output relayed line by line with a name prefix."""

    def __init__(
        self, name: str, argv: list[str], out: Callable[[str], None], stdin: int | IO | None, env: dict[str, str]
    ):
        self.name = name
        self.popen = subprocess.Popen(
            argv,
            stdin=stdin,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            env={**os.environ, "PYTHONUNBUFFERED": "1", **env},
            start_new_session=True,
            text=True,
            errors="replace",
        )
        self._relay = threading.Thread(target=self._pump, args=(out,), daemon=True)
        self._relay.start()

    def _pump(self, out: Callable[[str], None]) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            out(f"[{self.name:7s}] {line.rstrip()}")

    def alive(self) -> bool:
        return self.popen.poll() is None

    def stop(self, grace: float = STOP_GRACE_S) -> int | None:
        if self.alive():
            self.popen.send_signal(signal.SIGTERM)
            try:
                self.popen.wait(grace)
            except subprocess.TimeoutExpired:
                os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait(5)
        try:  # anything the child left in its session goes too
            os.killpg(self.popen.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        self._relay.join(1.0)
        return self.popen.returncode


class Launcher:
    """Runs a set of services (and the router) as one group."""

    def __init__(
        self,
        endpoint: str,
        prefix: str,
        start_router: bool,
        out: Callable[[str], None] = print,
        secure: str | None = None,
        listen: list[str] | None = None,
    ):
        self.secure = secure  # a secrets folder: the router enforces it, each service logs in as itself
        self.endpoint = endpoint
        self.listen = listen or [endpoint]  # the router's endpoints (one per network it serves); we use the first
        self.prefix = prefix
        self.start_router = start_router
        self.keys = Keys(prefix)
        self._lock = threading.Lock()
        self._out = out
        self.children: list[Child] = []
        self.session: zenoh.Session | None = None

    def say(self, line: str) -> None:
        with self._lock:
            self._out(line)

    def _start(
        self,
        name: str,
        module_args: list[str],
        stdin: int | IO | None = subprocess.DEVNULL,
        env: dict[str, str] | None = None,
    ) -> Child:
        argv = [sys.executable, "-m", *module_args, *(["--secure", self.secure] if self.secure else [])]
        child = Child(name, argv, self.say, stdin, {"HRI_PREFIX": self.prefix, **(env or {})})
        self.children.append(child)
        return child

    def start(self, specs: list[ServiceSpec], live_timeout: float = 60.0) -> None:
        if self.start_router:
            self._start(
                "router", [*ROUTER_ARGV, self.listen[0], *[a for ep in self.listen[1:] for a in ("--listen", ep)]]
            )
        self.session = _client_session(
            self.endpoint, self.start_router, timeout=30.0, secure=self.secure, prefix=self.prefix
        )
        for spec in specs:
            self._start(spec.name, [*spec.argv, "--connect", self.endpoint], spec.stdin, spec.env)
        self.wait_live([s.name for s in specs], live_timeout)

    def start_service(self, spec: ServiceSpec, live_timeout: float = 60.0) -> Child:
        child = self._start(spec.name, [*spec.argv, "--connect", self.endpoint], spec.stdin, spec.env)
        self.wait_live([spec.name], live_timeout)
        return child

    def live_services(self) -> set[str]:
        assert self.session is not None
        return {service for service, _ in live_tokens(self.session, self.keys)}

    def wait_live(self, names: list[str], timeout: float) -> None:
        deadline = time.monotonic() + timeout
        waiting = set(names)
        while waiting:
            waiting -= self.live_services()
            dead = [c for c in self.children if c.name in waiting and not c.alive()]
            if dead:
                raise RuntimeError(
                    f"{dead[0].name} exited with code {dead[0].popen.returncode} before it came up "
                    f"(its log lines are above, prefixed [{dead[0].name}])"
                )
            if not waiting:
                break
            if time.monotonic() > deadline:
                raise RuntimeError(f"not live after {timeout:.0f} s: {', '.join(sorted(waiting))}")
            time.sleep(0.2)
        self.say(f"[hri up ] live: {', '.join(names)}")

    def stop(self) -> None:
        if self.session is not None:
            self.session.close()
            self.session = None
        for child in reversed(self.children):  # services first, the router last
            code = child.stop()
            if code not in (0, None, -signal.SIGTERM):
                self.say(f"[hri up ] {child.name} exited with code {code}")
        self.children.clear()


def _client_session(
    endpoint: str, router_starting: bool, timeout: float, secure: str | None = None, prefix: str = "hri"
) -> zenoh.Session:
    deadline = time.monotonic() + timeout
    while True:
        try:
            return open_client(endpoint, secure, prefix=prefix)
        except zenoh.ZError:
            if time.monotonic() > deadline:
                hint = "the router did not start" if router_starting else "is `hri router` running there?"
                raise RuntimeError(f"cannot reach the zenoh router at {endpoint}: {hint}") from None
            time.sleep(0.2)


def add_up_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--camera",
        default="0",
        help="camera source: device index, video, image or folder (default 0); 'none' for no camera service",
    )
    p.add_argument("--cam", default="cam0", help="camera id (default cam0)")
    p.add_argument("--fps", type=float, default=None, help="camera publish rate")
    p.add_argument("--loop", action="store_true", help="loop a video file or image folder")
    p.add_argument("--vision-backend", choices=("color", "onnx"), default="color")
    p.add_argument(
        "--model", default=None, help="ONNX detector path for --vision-backend onnx (YOLOX, YOLOv5 or YOLOv8/11 export)"
    )
    p.add_argument(
        "--vision-labels",
        default=None,
        metavar="FILE",
        help='colour -> label JSON for the color backend, e.g. data/demo/labels.json ({"*": "candy"}); '
        "with onnx, the model's class names, one per line (default: COCO-80)",
    )
    p.add_argument("--mirrored", action="store_true", help="the camera image is mirrored (selfie view)")
    p.add_argument(
        "--speech-input",
        choices=("mic", "wav", "zenoh", "text", "none"),
        default="mic",
        help="mic (default), wav files (--wav), AudioChunks over zenoh, text lines on stdin, or none",
    )
    p.add_argument("--wav", nargs="+", default=None, help="WAV files or folders for --speech-input wav")
    p.add_argument(
        "--speech-backend",
        choices=("whisper", "pocketsphinx"),
        default=None,
        help="speech recogniser: whisper (the default: Whisper tiny.en, offline, from a package) or "
        "pocketsphinx (a grammar decoder for small machines)",
    )
    p.add_argument(
        "--profile",
        default=None,
        metavar="FILE",
        help="the robot's profile (TOML, docs/robot.md; e.g. profiles/mobile_manipulator.toml): what it may grasp, "
        "carry, whether it navigates; given to fusion, which puts it on the wire (robot/profile) for the ros2 node",
    )
    for node in stack_nodes():  # every node, a new one too: --<name>-arg and --no-<name>
        p.add_argument(
            f"--{node.name}-arg",
            action="append",
            default=[],
            metavar="ARG",
            help=f"extra argument for the {node.name} service, repeatable (e.g. --{node.name}-arg=--log-level=DEBUG)",
        )
        if node.opt_in:  # off unless asked for
            p.add_argument(
                f"--{node.name}", action="store_true", help=f"also start the {node.name} service: {node.description}"
            )
        else:
            p.add_argument(f"--no-{node.name}", action="store_true", help=f"do not start the {node.name} service")
    p.add_argument(
        "--only",
        type=only_list,
        default=None,
        metavar="NAME[,NAME...]",
        help=f"start only these of router,{','.join(stack_names())} (the rest runs on other hosts); without "
        f"'router' in the list, the services connect to --connect ENDPOINT (default "
        f"{DEFAULT_ENDPOINT})",
    )
    p.add_argument("--live-timeout", type=float, default=90.0, help="seconds to wait for each service to come up")


def only_list(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in ("router", *stack_names())]
    if unknown or not names:
        raise argparse.ArgumentTypeError(
            f"unknown part(s) {unknown or [text]}: name some of router,{','.join(stack_names())}, comma-separated"
        )
    return names


def select(specs: list[ServiceSpec], only: list[str] | None) -> list[ServiceSpec]:
    """The services `--only` keeps (all without it)."""
    return specs if only is None else [s for s in specs if s.name in only]


def starts_router(args: argparse.Namespace) -> bool:
    """`hri up` starts the router unless told to use one (--connect) or --only leaves it out."""
    return not args.connect and (args.only is None or "router" in args.only)


def cmd_up(args: argparse.Namespace) -> int:
    if args.camera == "none":
        args.camera = None
    profile = getattr(args, "profile", None)
    if profile:
        try:  # refused before anything starts (fusion would refuse it too, after the others came up)
            load_profile(profile)
        except ProfileError as exc:
            print(f"hri up: {exc}", file=sys.stderr)
            return 2
    specs = select(services_from_args(args), getattr(args, "only", None))
    # --connect: use a router that already runs; else start one on --listen (default tcp/127.0.0.1:7447)
    endpoint = (args.connect or args.listen or [DEFAULT_ENDPOINT])[0]
    prefix = args.prefix or os.environ.get("HRI_PREFIX") or "hri"
    secure = args.secure or os.environ.get("HRI_SECURE") or None
    launcher = Launcher(endpoint, prefix, start_router=starts_router(args), secure=secure, listen=args.listen)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    code = 0
    try:
        launcher.start(specs, args.live_timeout)
        launcher.say(
            f"[hri up ] all up; watch with: hri echo '{prefix}/fusion/**' "
            f"--connect {launcher.endpoint}   (Ctrl-C stops everything)"
        )
        reported: set[int] = set()
        while not stop.wait(0.5):
            for child in launcher.children:
                if not child.alive() and child.popen.pid not in reported:
                    reported.add(child.popen.pid)
                    launcher.say(f"[hri up ] {child.name} exited with code {child.popen.returncode}")
    except RuntimeError as exc:
        launcher.say(f"[hri up ] {exc}")
        code = 1
    finally:
        launcher.stop()
    launcher.say("[hri up ] stopped")
    return code
