"""Helpers for integration tests: real processes on loopback with free ports, always cleaned up."""

from __future__ import annotations

import json
import os
import queue
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import zenoh

from common.codec import decode
from common.keys import Keys
from common.runner import SamplePublisher
from common.schema import Sample, make_transcript
from common.transport import live_tokens, open_client

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "data"


def missing_services(*names: str) -> list[str]:
    """Services of `names` whose package is not in this checkout yet (for skip markers while they are built)."""
    return [n for n in names if not (ROOT / "services" / n / "__main__.py").exists()]


def requires_services(*names: str):
    import pytest

    missing = missing_services(*names)
    return pytest.mark.skipif(bool(missing), reason=f"service(s) not in this checkout yet: {', '.join(missing)}")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for_port(port: int, timeout: float = 15.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise TimeoutError(f"nothing listens on 127.0.0.1:{port} after {timeout} s")


class Proc:
    """A child process whose output goes to a log file (read it with .output())."""

    def __init__(self, name: str, argv: list[str], env: dict[str, str] | None = None):
        self.name = name
        self.argv = argv
        self.log = tempfile.NamedTemporaryFile(prefix=f"hri-{name}-", suffix=".log", delete=False)
        full_env = {**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})}
        self.popen = subprocess.Popen(
            argv, stdout=self.log, stderr=subprocess.STDOUT, cwd=ROOT, env=full_env, start_new_session=True
        )

    @property
    def pid(self) -> int:
        return self.popen.pid

    def output(self) -> str:
        return Path(self.log.name).read_text(errors="replace")

    def alive(self) -> bool:
        return self.popen.poll() is None

    def terminate(self, timeout: float = 2.0) -> tuple[int | None, float]:
        """SIGTERM, then wait; returns (exit code or None if it had to be killed, seconds taken)."""
        if not self.alive():
            return self.popen.returncode, 0.0
        t0 = time.monotonic()
        self.popen.send_signal(signal.SIGTERM)
        try:
            code = self.popen.wait(timeout)
            return code, time.monotonic() - t0
        except subprocess.TimeoutExpired:
            self.kill()
            return None, time.monotonic() - t0

    def kill(self) -> None:
        try:
            os.killpg(self.popen.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.popen.wait(5)

    def children_gone(self) -> bool:
        """True if nothing is left of this process's session (no orphans)."""
        try:
            os.killpg(self.popen.pid, 0)
        except ProcessLookupError:
            return True
        return False


class ProcessGroup:
    """Starts the router and services on a free port; `close()` stops them all, whatever happened."""

    def __init__(self) -> None:
        self.port = free_port()
        self.endpoint = f"tcp/127.0.0.1:{self.port}"
        self.procs: list[Proc] = []

    def start(self, name: str, *args: str, env: dict[str, str] | None = None, connect: bool = True) -> Proc:
        argv = [sys.executable, "-m", *args]
        if connect:
            argv += ["--connect", self.endpoint]
        proc = Proc(name, argv, env)
        self.procs.append(proc)
        return proc

    def router(self, *, env: dict[str, str] | None = None) -> Proc:
        proc = self.start("router", "hri.cli", "router", "--listen", self.endpoint, connect=False, env=env)
        wait_for_port(self.port)
        return proc

    def service(self, name: str, *args: str, env: dict[str, str] | None = None) -> Proc:
        return self.start(name, f"services.{name}", *args, env=env)

    def hri(self, *args: str, timeout: float = 30.0) -> subprocess.CompletedProcess:
        """Run an `hri` subcommand to completion against this group's router."""
        argv = [sys.executable, "-m", "hri.cli", args[0], "--connect", self.endpoint, *args[1:]]
        return subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=timeout)

    def echo(self, keyexpr: str, count: int, timeout: float = 30.0) -> list[dict[str, Any]]:
        res = self.hri("echo", keyexpr, "--count", str(count), "--timeout", str(timeout), timeout=timeout + 15)
        assert res.returncode == 0, f"hri echo failed ({res.returncode}): {res.stderr[-2000:]}\n{self.logs()}"
        return [json.loads(line) for line in res.stdout.splitlines() if line.strip()]

    def logs(self) -> str:
        return "\n".join(f"----- {p.name} (pid {p.pid}) -----\n{p.output()[-4000:]}" for p in self.procs)

    def close(self) -> None:
        for proc in reversed(self.procs):
            if proc.alive():
                proc.terminate()
            if not proc.children_gone():
                proc.kill()


class Client:
    """An in-test zenoh client: publish contract samples and collect decoded ones."""

    def __init__(self, endpoint: str, prefix: str = "hri", secure: str | None = None, user: str = "cli"):
        self.session = open_client(endpoint, secure, user)
        self.keys = Keys(prefix)
        self._pubs: dict[str, SamplePublisher] = {}
        self._subs: list[Any] = []

    def publish(self, key: str, sample: Sample, realtime: bool = False) -> None:
        pub = self._pubs.get(key)
        if pub is None:
            pub = self._pubs[key] = SamplePublisher(self.session, key, lossless=True, realtime=realtime)
        pub.put(sample)

    def put_raw(self, key: str, payload: bytes) -> None:
        """Arbitrary bytes (malformed samples), never dropped on the way (BLOCK)."""
        self.session.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)

    def collect(self, keyexpr: str) -> "Collector":
        col = Collector(self.keys)
        self._subs.append(self.session.declare_subscriber(keyexpr, col.on_sample))
        return col

    def declare_alive(self, service: str, instance: str = "test") -> None:
        """Stand in for `service` on the bus: its liveliness token, as the service declares it, until close(). A test
        that publishes a modality itself (hands, transcripts) needs it: fusion waits for a live modality's samples
        (their watermark, or its deadline) before it decides, and without a token knows the modality only from
        arrivals. zenoh-python runs each subscription's callbacks on a thread of its own, so samples this client puts
        on two keys may be handled out of the order it sent them (issue #41; docs/foundation.md)."""
        self._subs.append(self.session.liveliness().declare_token(self.keys.alive(service, instance)))

    def stats(self, service: str, timeout: float = 2.0) -> dict[str, Any]:
        from common.schema import Stats

        for reply in self.session.get(self.keys.stats(service, "*"), timeout=timeout):
            if reply.ok is not None:
                return decode(reply.ok.payload.to_bytes(), Stats).to_dict()
        raise AssertionError(f"service {service!r} did not answer a stats query")

    def wait_stats(
        self, service: str, until: Callable[[dict[str, Any]], bool], what: str, timeout: float = 20.0
    ) -> dict[str, Any]:
        """Poll `service`'s stats until `until(stats)` holds (the state a test needs, instead of a fixed sleep);
        the last stats read are in the failure."""
        deadline = time.monotonic() + timeout
        while True:
            stats = self.stats(service)
            if until(stats):
                return stats
            if time.monotonic() > deadline:
                raise AssertionError(f"{service}: {what} not seen within {timeout} s; its stats {stats}")
            time.sleep(0.05)

    def alive(self, timeout: float = 1.0) -> list[tuple[str, str]]:
        return live_tokens(self.session, self.keys, timeout=timeout)

    def wait_alive(self, service: str, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if any(s == service for s, _ in self.alive()):
                return
            time.sleep(0.1)
        raise TimeoutError(f"service {service!r} never declared its liveliness token")

    def wait_matched(self, keys: list[str], timeout: float = 30.0) -> None:
        """Block until the router knows a subscriber for each key. A service declares its liveliness token
        before its subscriptions, so samples put right after `wait_alive` can still be lost."""
        pubs = [self.session.declare_publisher(k) for k in keys]
        deadline = time.monotonic() + timeout
        try:
            while not all(p.matching_status.matching for p in pubs):  # type: ignore[attr-defined]  # zenoh's stub types matching_status as bool; it is a MatchingStatus
                if time.monotonic() > deadline:
                    raise TimeoutError(f"no subscriber matched {keys} within {timeout} s")
                time.sleep(0.05)
        finally:
            for p in pubs:
                p.undeclare()

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        for pub in self._pubs.values():
            pub.undeclare()
        self.session.close()


def type_command(client: Client, text: str, seconds_per_word: float = 0.2) -> None:
    """Publish `text` as a typed command ending now, as `hri say` does (keyboard mic "kbd", confidence 0.95)."""
    client.publish(
        "hri/speech/kbd/transcript",
        make_transcript(
            text, mic="kbd", end=time.time(), confidence=0.95, source="test/kbd", seconds_per_word=seconds_per_word
        ),
    )


class Collector:
    """Decoded samples received on a subscription, in arrival order."""

    def __init__(self, keys: Keys):
        self.keys = keys
        self.items: queue.Queue[tuple[str, Any]] = queue.Queue()
        self.seen: list[tuple[str, Any]] = []

    def on_sample(self, s: zenoh.Sample) -> None:
        key = str(s.key_expr)
        schema = self.keys.schema_for(key)
        self.items.put((key, decode(s.payload.to_bytes(), schema) if schema else s.payload.to_bytes()))

    def wait(
        self, n: int = 1, timeout: float = 10.0, where: Callable[[str, Any], bool] = lambda k, s: True
    ) -> list[tuple[str, Any]]:
        """Block until `n` matching samples have arrived (in total); returns them."""
        deadline = time.monotonic() + timeout
        while True:
            matching = [item for item in self.seen if where(*item)]
            if len(matching) >= n:
                return matching[:n]
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(
                    f"got {len(matching)}/{n} matching samples in {timeout} s "
                    f"(all received: {[k for k, _ in self.seen]})"
                )
            try:
                self.seen.append(self.items.get(timeout=min(left, 0.2)))
            except queue.Empty:
                pass

    def next(self, timeout: float = 30.0) -> Any:
        """The next sample after those already seen (blocks up to `timeout`)."""
        return self.wait(len(self.seen) + 1, timeout=timeout)[-1][1]

    def drain(self, seconds: float = 0.0) -> list[tuple[str, Any]]:
        deadline = time.monotonic() + seconds
        while True:
            try:
                self.seen.append(self.items.get(timeout=max(0.0, deadline - time.monotonic())))
            except queue.Empty:
                return self.seen
