"""Settings declared once (common/settings.py): fusion's Config and every service's numeric flags.

The service parsers are the real ones: each service's `main` runs until argparse has parsed its flags (or refused
them) and nothing else of it runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
from typing import Literal

import pytest

from common.settings import (
    OutOfRange,
    Range,
    Setting,
    add_settings,
    check_all,
    declared,
    from_args,
    setting,
    settings_of,
)
from hri import settingsdoc
from services.fusion import __main__ as fusion_main
from services.fusion.core import Config
from testkit.parsing import main_until_parsed


def refusal(service: str, flags: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as exited:
        main_until_parsed(service, flags)
    assert exited.value.code == 2, flags
    return capsys.readouterr().err


# -- fusion's Config -----------------------------------------------------------------------------------------
def test_every_fusion_setting_has_a_description_a_range_and_a_flag():
    parser = fusion_main.build_parser()
    flags = {s.name: s.option for s in declared(parser)}
    for s in settings_of(Config):
        assert len(s.description) > 20 and "\n" not in s.description, s.name
        assert s.range is not None or s.choices is not None or s.kind is bool, f"{s.name} has no range"
        assert flags.get(s.name) == s.option, f"{s.name} has no flag"
        assert s.option in parser.format_help()
    assert len(settings_of(Config)) == len(dataclasses.fields(Config)) >= 13


def test_the_defaults_are_within_their_ranges_and_parse_to_config():
    check_all(Config())
    assert from_args(Config, main_until_parsed("fusion", [])) == Config()


def test_the_old_flag_spellings_still_set_their_fields():
    args = main_until_parsed(
        "fusion",
        [
            "--window-before=1.5",
            "--window-after=0.5",
            "--max-wait=0.8",
            "--weights=fixed",
            "--fallback-most-confident",
            "--dialogue-timeout=4",
        ],
    )
    assert from_args(Config, args) == Config(
        window_before=1.5,
        window_after=0.5,
        max_wait=0.8,
        weights="fixed",
        fallback_most_confident=True,
        dialogue_timeout=4.0,
    )


def test_every_field_is_set_by_its_flag():
    changed = {
        "live_recent_s": ("--live-recent", "3.5"),
        "horizon": ("--horizon", "45"),
        "vision_lookback": ("--vision-lookback", "1"),
        "margin": ("--margin", "0.2"),
        "low_speech_confidence": ("--low-speech-confidence", "0.4"),
        "gesture_min_score": ("--gesture-min-score", "0.6"),
        "episode_gap": ("--episode-gap", "2"),
    }
    flags = [part for flag, value in changed.values() for part in (flag, value)]
    config = from_args(Config, main_until_parsed("fusion", flags))
    for name, (_, value) in changed.items():
        assert getattr(config, name) == float(value), name
    untouched = {f.name for f in dataclasses.fields(Config)} - set(changed)
    assert all(getattr(config, n) == getattr(Config(), n) for n in untouched)


# -- the one range check, through the real service parsers ---------------------------------------------------
REFUSED = [
    ("fusion", ["--max-wait", "-0.1"], "--max-wait", "≥ 0"),
    ("fusion", ["--horizon", "0"], "--horizon", "> 0"),
    ("fusion", ["--margin", "1.5"], "--margin", "0–1"),
    ("fusion", ["--gesture-min-score", "nan"], "--gesture-min-score", "0–1"),
    ("fusion", ["--weights", "equal"], "--weights", "adaptive|fixed"),
    ("fusion", ["--max-skew", "-1"], "--max-skew", "≥ 0"),  # the runner's flags, in every service
    ("vision", ["--conf", "1.2"], "--conf", "0–1"),
    ("vision", ["--iou", "-0.1"], "--iou", "0–1"),
    ("vision", ["--input-scale", "0"], "--input-scale", "> 0"),
    ("vision", ["--timeline-run", "0"], "--timeline-run", "≥ 1"),
    ("gesture", ["--max-hands", "0"], "--max-hands", "≥ 1"),
    ("gesture", ["--start-ms", "-5"], "--start-ms", "≥ 0"),
    ("gesture", ["--idle-end", "0"], "--idle-end", "> 0"),
    ("speech", ["--min-confidence", "1.5"], "--min-confidence", "0–1"),
    ("speech", ["--tail-probability", "1"], "--tail-probability", "(0, 1)"),
    ("speech", ["--beam", "0"], "--beam", "≥ 1"),
    ("speech", ["--partials", "0"], "--partials", "> 0"),
    ("camera", ["--source", "0", "--quality", "101"], "--quality", "1–100"),
    ("camera", ["--source", "0", "--fps", "0"], "--fps", "> 0"),
    ("camera", ["--source", "0", "--count", "0"], "--count", "≥ 1"),
    ("vision", ["--max-pixels", "0"], "--max-pixels", "≥ 1"),
]


@pytest.mark.parametrize("service,flags,flag,range_text", REFUSED, ids=[f"{c[0]}{c[1][-2]}" for c in REFUSED])
def test_an_out_of_range_value_is_refused_naming_the_flag_the_range_and_the_value(
    service, flags, flag, range_text, capsys
):
    err = refusal(service, flags, capsys)
    line = err.strip().splitlines()[-1]
    assert f"argument {flag}:" in line and range_text in line and flags[-1] in line, line


ACCEPTED_AT_THE_BOUNDARY = [
    ("fusion", ["--max-wait", "0", "--margin", "1", "--gesture-min-score", "0"], {"max_wait": 0.0, "margin": 1.0}),
    ("vision", ["--conf", "0", "--iou", "1"], {"conf": 0.0, "iou": 1.0}),
    ("gesture", ["--max-hands", "1", "--start-ms", "0"], {"max_hands": 1, "start_ms": 0.0}),
    ("speech", ["--min-confidence", "1", "--beam", "1", "--command-prior", "0"], {"min_confidence": 1.0, "beam": 1}),
    ("camera", ["--source", "0", "--quality", "1"], {"quality": 1}),
    ("camera", ["--source", "0", "--quality", "100", "--count", "1"], {"quality": 100, "count": 1}),
]


@pytest.mark.parametrize("service,flags,expected", ACCEPTED_AT_THE_BOUNDARY)
def test_a_value_at_an_inclusive_boundary_is_accepted(service, flags, expected):
    args = main_until_parsed(service, flags)
    assert {name: getattr(args, name) for name in expected} == expected
    for name, value in expected.items():
        assert type(getattr(args, name)) is type(value), name  # an int flag stays an int


def test_a_value_that_is_not_a_number_is_refused_as_argparse_words_it(capsys):
    line = refusal("vision", ["--conf", "high"], capsys).strip().splitlines()[-1]
    assert line.endswith("argument --conf: invalid float value: 'high'"), line


@pytest.mark.parametrize("service", ["fusion", "vision", "gesture", "speech", "camera"])
def test_the_help_shows_each_declared_flags_range_and_default(service):
    build = importlib.import_module(f"services.{service}.__main__").build_parser
    parser = build()
    helptext = "".join(parser.format_help().split())  # argparse wraps lines, also after a hyphen
    for s in declared(parser):
        assert "".join(s.help().split()) in helptext, s.option


# -- the declaration helper itself ---------------------------------------------------------------------------
def test_a_range_keeps_or_excludes_its_ends_as_declared():
    closed, open_ = Range.of(at_least=0, at_most=1), Range.of(above=0, below=1)
    assert closed and open_
    assert [closed.contains(v) for v in (-0.01, 0, 0.5, 1, 1.01)] == [False, True, True, True, False]
    assert [open_.contains(v) for v in (0, 1e-9, 0.999, 1)] == [False, True, True, False]
    assert not closed.contains(float("nan"))
    assert (closed.text(), open_.text(), Range.of(above=0).text(), Range.of(at_most=5).text()) == (
        "0–1",
        "(0, 1)",
        "> 0",
        "≤ 5",
    )
    assert Range.of() is None
    with pytest.raises(TypeError):
        Range.of(at_least=0, above=0)
    with pytest.raises(TypeError):
        Range.of(at_least=2, at_most=1)


def test_a_settings_dataclass_stays_a_plain_dataclass_and_every_field_must_be_declared():
    @dataclasses.dataclass(frozen=True)
    class Tiny:
        rate: float = setting(2.0, "samples per second", above=0, flag="--hz")
        hands: int = setting(2, "hands tracked", at_least=1)
        name: str | None = setting(None, "an optional name")

    assert Tiny() == Tiny(2.0, 2, None) and Tiny(rate=-1.0).rate == -1.0  # no check inside the core
    with pytest.raises(OutOfRange, match=r"Tiny.rate: -1 is outside its range > 0"):
        check_all(Tiny(rate=-1.0))
    parser = argparse.ArgumentParser()
    add_settings(parser, Tiny)
    assert from_args(Tiny, parser.parse_args(["--hz", "5", "--hands", "3", "--name", "x"])) == Tiny(5.0, 3, "x")
    rate = settings_of(Tiny)[0]
    assert isinstance(rate, Setting) and rate.option == "--hz" and rate.kind is float

    @dataclasses.dataclass
    class Undeclared:
        rate: float = 2.0

    with pytest.raises(TypeError, match="Undeclared.rate is not declared"):
        settings_of(Undeclared)


# -- the docs' tables ----------------------------------------------------------------------------------------
def test_the_docs_settings_tables_are_current():
    assert settingsdoc.missing() == [], "a page lost its `<!-- settings: NAME -->` block"
    for page in sorted(set(settingsdoc.PAGES.values())):
        text = (settingsdoc.DOCS / page).read_text()
        assert settingsdoc.render(text) == text, f"docs/{page} is stale: run `python -m hri.settingsdoc`"


def test_docs_fusion_md_has_a_row_for_every_config_field():
    section = (settingsdoc.DOCS / "fusion.md").read_text().split("<!-- settings: fusion -->", 1)[1]
    rows = section.split("<!-- /settings -->", 1)[0]
    for s in settings_of(Config):
        assert f"| `{s.option}" in rows and s.description in rows, s.name


def test_a_changed_declaration_makes_the_check_fail(tmp_path, monkeypatch):
    for page in set(settingsdoc.PAGES.values()):
        (tmp_path / page).write_text((settingsdoc.DOCS / page).read_text())
    monkeypatch.setattr(settingsdoc, "DOCS", tmp_path)
    assert settingsdoc.main(["--check"]) == 0
    page = tmp_path / "fusion.md"
    page.write_text(page.read_text().replace("| `--horizon S` | 30 | > 0 |", "| `--horizon S` | 20 | > 0 |"))
    assert settingsdoc.main(["--check"]) == 1
    assert settingsdoc.main([]) == 0 and settingsdoc.main(["--check"]) == 0
    assert "| `--horizon S` | 30 | > 0 |" in page.read_text()


TOOL_REFUSALS = [
    (["echo", "hri/**", "--count", "0"], "--count", "≥ 1"),
    (["say", "--confidence", "1.1", "stop"], "--confidence", "0–1"),
    (["record", "--duration", "0"], "--duration", "> 0"),
    (["replay", "x.mcap", "--speed", "-1"], "--speed", "≥ 0"),
    (["view", "--max-fps", "0"], "--max-fps", "> 0"),
]


@pytest.mark.parametrize("argv,flag,range_text", TOOL_REFUSALS, ids=[a[0][0] for a in TOOL_REFUSALS])
def test_the_hri_tools_refuse_out_of_range_values_the_same_way(argv, flag, range_text, capsys):
    from hri import cli

    with pytest.raises(SystemExit) as exited:
        cli.build_parser().parse_args(argv)
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert exited.value.code == 2 and f"argument {flag}:" in line and range_text in line, line


def test_the_hri_tools_accept_their_boundaries():
    from hri import cli

    assert cli.build_parser().parse_args(["replay", "x.mcap", "--speed", "0"]).speed == 0.0
    assert cli.build_parser().parse_args(["say", "--confidence", "1", "stop"]).confidence == 1.0
    assert cli.build_parser().parse_args(["echo", "hri/**", "--count", "1"]).count == 1


def test_a_literal_field_takes_its_values_as_choices():
    @dataclasses.dataclass(frozen=True)
    class Mode:
        weights: Literal["adaptive", "fixed"] = setting("adaptive", "how modalities are weighed")

    (weights,) = settings_of(Mode)
    assert weights.choices == ("adaptive", "fixed") and weights.kind is str
    parser = argparse.ArgumentParser()
    add_settings(parser, Mode)
    assert from_args(Mode, parser.parse_args(["--weights", "fixed"])) == Mode("fixed")
    with pytest.raises(OutOfRange, match="'equal' is not one of adaptive|fixed"):
        weights.check("equal")


# a flag that cannot be a plain setting: required, several values, or a hidden old spelling
NOT_DECLARED = {"camera": {"--source"}, "speech": {"--wav"}, "vision": {"--names"}}


@pytest.mark.parametrize("service", ["fusion", "vision", "gesture", "speech", "camera"])
def test_every_flag_of_a_service_is_declared_as_a_setting(service):
    from common.runner import service_parser

    def undeclared(parser: argparse.ArgumentParser) -> set[str]:
        return {a.option_strings[-1] for a in parser._actions if a.option_strings and not hasattr(a, "setting")}

    parser = importlib.import_module(f"services.{service}.__main__").build_parser()
    shared = undeclared(service_parser(service, ""))  # --help, --instance, --log-level, the zenoh flags
    assert undeclared(parser) - shared == NOT_DECLARED.get(service, set())
