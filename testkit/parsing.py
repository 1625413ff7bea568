"""A service's own argument parsing, run alone: `main(flags)` stops right after argparse has parsed them."""

from __future__ import annotations

import argparse
import importlib

import pytest


class Parsed(Exception):
    def __init__(self, namespace: argparse.Namespace):
        super().__init__("parsed")
        self.namespace = namespace


def main_until_parsed(service: str, flags: list[str]) -> argparse.Namespace:
    """`flags` as `services.<service>.__main__.main` parses them (nothing else of `main` runs); argparse's
    SystemExit (a refused flag, --help) passes through."""
    main = importlib.import_module(f"services.{service}.__main__").main
    real = argparse.ArgumentParser.parse_args

    def stop_after_parsing(self, args=None, namespace=None):
        raise Parsed(real(self, args, namespace))

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(argparse.ArgumentParser, "parse_args", stop_after_parsing)
        try:
            main(flags)
        except Parsed as done:
            return done.namespace
    pytest.fail(f"{service}'s main returned without parsing its arguments")
