"""fusion as a real process reads Persons (issue #33): a person named by place is found among the persons in view."""

from __future__ import annotations

import threading
import time

import pytest

from common.schema import FusedCommand, Person, Persons
from testkit.harness import Client, ProcessGroup

pytestmark = pytest.mark.integration

PEOPLE = [
    Person(id="person-1", bbox=[100.0, 40.0, 120.0, 400.0], score=1.0),
    Person(id="person-2", bbox=[420.0, 40.0, 120.0, 400.0], score=1.0),
]


def test_fusion_targets_the_person_on_the_left_from_persons(group: ProcessGroup) -> None:
    group.router()
    group.service("fusion")
    client = Client(group.endpoint)
    done = threading.Event()

    def publish_persons() -> None:  # the gesture service's Persons at 10 Hz, stamped now
        seq = 0
        while not done.is_set():
            sample = Persons(
                stamp=time.time(), source="gesture/t", seq=seq, cam="cam0", width=640, height=480, persons=PEOPLE
            )
            client.publish("hri/gesture/cam0/persons", sample)
            seq += 1
            time.sleep(0.1)

    publisher = threading.Thread(target=publish_persons, daemon=True)
    try:
        client.wait_alive("fusion", timeout=60)
        commands = client.collect("hri/fusion/command")
        publisher.start()
        time.sleep(1.0)
        res = group.hri("say", "look at the man on the left")
        assert res.returncode == 0, res.stderr
        ((_, command),) = commands.wait(1, timeout=30)
        assert isinstance(command, FusedCommand) and command.intent == "look_at"
        assert command.target is not None and command.target.id == "person-1", command.explanation
    finally:
        done.set()
        publisher.join(timeout=2)
        client.close()
