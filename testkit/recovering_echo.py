"""A consumer across a link that drops: prints every sample on KEY as a JSON line, including those it fetched
from a recovering publisher's cache after its link came back (common/transport.py). For the distributed tests:
`python -m testkit.recovering_echo ENDPOINT KEY [SECRETS_FOLDER]` (prints `ready` once subscribed; with a secrets
folder it logs in as the read-only user cli)."""

from __future__ import annotations

import json
import signal
import sys
import threading

from common.codec import decode
from common.keys import Keys
from common.transport import declare_recovering_subscriber, open_client


def main() -> None:
    endpoint, key = sys.argv[1], sys.argv[2]
    keys = Keys(key.split("/")[0])
    session = open_client(endpoint, sys.argv[3] if len(sys.argv) > 3 else None)
    lock = threading.Lock()

    def on_sample(s) -> None:
        schema = keys.schema_for(str(s.key_expr))
        assert schema is not None, f"{s.key_expr} is not a key of the wire contract"
        sample = decode(s.payload.to_bytes(), schema)
        with lock:
            print(
                json.dumps({"key": str(s.key_expr), "id": getattr(sample, "id", None), "stamp": sample.stamp}),
                flush=True,
            )

    sub = declare_recovering_subscriber(session, key, on_sample)
    print("ready", flush=True)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    stop.wait()
    sub.undeclare()
    session.close()


if __name__ == "__main__":
    main()
