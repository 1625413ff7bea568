"""The tools: the `hri` command (up, router, echo, say, record/replay, view, secure) and what only it uses.

Layers (docs/foundation.md): the contract and the runtime (common/) <- the services <- these tools."""
