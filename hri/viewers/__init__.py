"""Our samples in the shapes Foxglove and Rerun read (issue #36).

- `foxglove_msgs`: functional core, a contract sample -> Foxglove messages (protobuf built-ins, JSON with a JSON
  Schema generated from the wire contract); used by `hri record` (viewer channels beside the raw msgpack ones)
  and `hri foxglove` (the same channels, live over the Foxglove WebSocket protocol).
- `rerun_log`: functional core, a contract sample -> Rerun archetypes; and the `hri rerun` shell.
- `live`: the `hri foxglove` shell.
"""
