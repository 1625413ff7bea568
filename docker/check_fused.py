"""Check fusion's answer to the docker demo input, as printed by `hri echo` (one JSON line).

  python docker/check_fused.py FILE --utterance "pick up the red candy" [--grounded]

Always: the answer is about that utterance (its `text`). With --grounded (vision is in the stack): it is a
FusedCommand with intent pick_up whose target is red. Prints a one-line summary; exit 1 with the reason.
"""

from __future__ import annotations

import argparse
import json
import sys


def check(answer: dict, utterance: str, grounded: bool) -> tuple[bool, str]:
    key = answer.get("key", "")
    if answer.get("text") != utterance:
        return False, f"the answer on {key} is about {answer.get('text')!r}, not {utterance!r}"
    if key.endswith("/clarification"):
        summary = f"clarification ({answer.get('reason')}): {answer.get('question')}"
        return (not grounded), summary if not grounded else f"a clarification, not a command: {summary}"
    target = answer.get("target") or {}
    summary = (
        f"command {answer.get('intent')} -> {target.get('label', '-')} ({target.get('color', '-')}) "
        f"confidence {answer.get('confidence', 0):.2f}: {answer.get('explanation', '')}"
    )
    if grounded:
        if answer.get("intent") != "pick_up":
            return False, f"intent is {answer.get('intent')!r}, not 'pick_up': {summary}"
        if target.get("color") != "red":
            return False, f"the target is not red: {summary}"
    return True, summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file")
    parser.add_argument("--utterance", required=True)
    parser.add_argument("--grounded", action="store_true")
    args = parser.parse_args(argv)
    lines = [ln for ln in open(args.file).read().splitlines() if ln.strip()]
    if not lines:
        print(f"check_fused: {args.file} is empty: fusion answered nothing")
        return 1
    ok, summary = check(json.loads(lines[0]), args.utterance, args.grounded)
    print(("fused: " if ok else "check_fused: ") + summary)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
