"""Cameras' MediaPipe graphs built off the frame path (issue #41): at start for the cameras the service is told
about, and on a background thread for a camera it was not, so that no frame waits for a graph to be built.

`GraphSupply` hands a new camera its graphs (services/gesture/core.py `CameraGraphs`, warmed) when they are ready,
and else starts building them on its one builder thread and answers None: the shell skips that camera's frames
(counted) until they are, while every other camera goes on being served. `spares` sets are kept built ahead for
cameras not seen yet (each costs ~300 MB): with one, a new camera is served from its first frame.
"""

from __future__ import annotations

import threading
import time
from typing import Callable, Generic, Protocol, TypeVar


class Closable(Protocol):
    def close(self) -> None: ...


G = TypeVar("G", bound=Closable)


class GraphSupply(Generic[G]):
    """Sets of graphs (`build()` makes one) for cameras not seen yet: ready ones, and one thread building more."""

    def __init__(
        self,
        build: Callable[[], G],
        spares: int = 0,
        on_error: Callable[[BaseException], None] = print,
        on_built: Callable[[float], None] = lambda seconds: None,
        on_change: Callable[[int, int], None] = lambda built, ready: None,
    ):
        self._build = build
        self._spares = spares
        self._on_error = on_error
        self._on_built = on_built  # told how long each background build took
        self._on_change = on_change  # told (built, ready) whenever they change, in order (under the lock)
        self._cond = threading.Condition()
        self._ready: list[G] = []
        self._waiting: set[str] = set()  # cameras that asked and got none (yet)
        self._reserved: dict[str, G] = {}  # built at start for a camera named on the command line
        self._thread: threading.Thread | None = None
        self._closed = False
        self.built = 0  # sets built so far (at start and in the background)

    def prepare(self, cams: list[str], spares_at_start: int) -> None:
        """Build now (before the service declares itself live) the graphs of these named cameras and
        `spares_at_start` sets for cameras to come."""
        for cam in cams:
            self._reserved[cam] = self._build()
            self.built += 1
        for _ in range(spares_at_start):
            self._ready.append(self._build())
            self.built += 1
        with self._cond:
            self._on_change(self.built, len(self._ready))

    def take(self, cam: str) -> G | None:
        """`cam`'s graphs (its own, or a ready set) for its first frame, or None: a set is being built for it (ask
        again on its next frame). Keeps `spares` sets building ahead."""
        with self._cond:
            graphs = self._reserved.pop(cam, None)
            if graphs is None and self._ready:
                graphs = self._ready.pop(0)
            if graphs is None:
                self._waiting.add(cam)
            else:
                self._waiting.discard(cam)
            self._start_builder()
            self._cond.notify_all()
            self._on_change(self.built, len(self._ready))
            return graphs

    @property
    def ready(self) -> int:
        with self._cond:
            return len(self._ready)

    def _wanted(self) -> int:
        return len(self._waiting) + self._spares - len(self._ready)

    def _start_builder(self) -> None:
        if self._thread is None and self._wanted() > 0 and not self._closed:
            self._thread = threading.Thread(target=self._build_while_wanted, name="gesture-graphs", daemon=True)
            self._thread.start()

    def _build_while_wanted(self) -> None:
        while True:
            with self._cond:
                while not self._closed and self._wanted() <= 0:
                    self._cond.wait()
                if self._closed:
                    return
            started = time.monotonic()
            try:
                graphs = self._build()
            except Exception as exc:  # reported, and tried again for the next camera that asks
                self._on_error(exc)
                with self._cond:
                    self._waiting.clear()
                continue
            with self._cond:
                if self._closed:
                    graphs.close()
                    return
                self._ready.append(graphs)
                self.built += 1
                self._on_change(self.built, len(self._ready))
            self._on_built(time.monotonic() - started)

    def close(self) -> None:
        """Close the sets no camera took; a set being built is closed by the builder when it is done."""
        with self._cond:
            self._closed = True
            left = self._ready + list(self._reserved.values())
            self._ready, self._reserved = [], {}
            self._cond.notify_all()
        for graphs in left:
            graphs.close()
