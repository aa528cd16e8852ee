"""`--help` in sections: data and chart, output, validation, starts and workers first, the optimiser grouped
after them; no option lost or printed twice by the sorting, on every command."""

from __future__ import annotations

import re

import pytest
from click.testing import CliRunner

from flowchart2sdnn.cli import main
from flowchart2sdnn.cli.help import SECTIONS, SectionedCommand, section_of

FIRST = ["Data and chart", "Output", "Validation", "Starts and workers"]


def _help(command: str) -> str:
    res = CliRunner().invoke(main, [command, "--help"], terminal_width=100)
    assert res.exit_code == 0, res.output
    return res.output


def _titles(text: str) -> list[str]:
    return re.findall(r"^(\S[^\n]*):$", text, re.M)


@pytest.mark.parametrize("command", sorted(main.commands))
def test_every_option_is_printed_once_under_a_section(command):
    text = _help(command)
    cmd = main.commands[command]
    assert isinstance(cmd, SectionedCommand)
    for param in cmd.params:
        if param.param_type_name != "option" or param.hidden:
            continue
        for flag in param.opts:  # the option's own entry names each of its flags once
            assert len(re.findall(rf"(?<![\w-]){re.escape(flag)}(?![\w-])[ ,/\[]", text)) >= 1, (command, flag)
    entries = re.findall(r"^  (-[^\s,]+(?:, --\S+)?)", text, re.M)  # each entry's first flag(s), as printed
    assert len(entries) == len(set(entries)), entries
    assert len(entries) == len([p for p in cmd.params if p.param_type_name == "option"]) + 1  # and --help


@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_identify_and_diagnose_put_what_a_newcomer_needs_first(command):
    text = _help(command)
    titles = _titles(text)
    assert titles[:4] == FIRST and titles[-1] == "Other" and "Optimiser" in titles[4:], titles
    optimiser = text.index("\nOptimiser:\n")
    first = ("--map", "-o, --output", "--validate", "--split", "--workers", "--seed")
    for flag in first + (("--starts",) if command == "identify" else ()):
        assert text.index(f"  {flag} ") < optimiser, flag
    for flag in ("--max-iter", "--shooting"):
        assert text.index(f"  {flag} ") > optimiser, flag
    assert text.index("  --max-iter ") < text.index("  --shooting ")  # the safety limit heads its section


def test_identify_groups_the_optimiser_and_the_quasi_online_mode():
    text = _help("identify")
    optimiser, online = text.index("\nOptimiser:\n"), text.index("\nQuasi-online:\n")
    for flag in ("--lm-steps", "--lm-bounds", "--curve-start", "--floor-bias / --no-floor-bias",
                 "--shooting-starts"):
        assert optimiser < text.index(f"  {flag}") < online, flag
    for flag in ("--online", "--window", "--average"):
        assert text.index(f"  {flag} ") > online, flag
    assert text.index("  --diagram ") > text.index("  --map ")  # the old spelling last in its section


def test_diagnose_has_its_effect_search_section_before_the_optimiser():
    text = _help("diagnose")
    titles = _titles(text)
    assert titles.index("Effect search") == titles.index("Optimiser") - 1
    search = text.index("\nEffect search:\n")
    for flag in ("--rounds", "--effects", "--criterion", "--alpha", "--refit-iter"):
        assert search < text.index(f"  {flag} ") < text.index("\nOptimiser:\n"), flag


@pytest.mark.parametrize(("command", "usage"), [("identify", "CHART DATA..."), ("diagnose", "CHART DATA..."),
                                                ("batch", "CHART DATA..."), ("simulate", "CHART DATA"),
                                                ("compare", "MODEL DATA..."), ("linearize", "MODEL [DATA]...")])
def test_every_usage_line_names_the_chart_first(command, usage):
    assert _help(command).splitlines()[0].endswith(f"[OPTIONS] {usage}")


def test_an_option_named_nowhere_goes_to_other_and_a_command_can_claim_one():
    assert section_of("no_such_option") == "Other"
    assert section_of("max_iter") == "Optimiser"
    assert section_of("max_iter", {"Effect search": ("max_iter",)}) == "Effect search"
    assert all(SECTIONS.values())


def test_the_group_lists_every_command_once_in_the_order_of_a_first_session():
    res = CliRunner().invoke(main, ["--help"], terminal_width=80)
    assert res.exit_code == 0
    listing = res.output.split("\nCommands:\n", 1)[1].split("\n\n", 1)[0].splitlines()
    names = [line.split()[0] for line in listing]
    assert sorted(names) == sorted(main.commands)  # each once, and each on one line at 80 columns
    first = ["lint", "compile", "excite", "simulate", "identify"]
    assert names[:5] == first and names.index("diagnose") > names.index("identify")
    assert names.index("report") > names.index("batch")
    assert "sdnn COMMAND CHART [DATA...]" in " ".join(res.output.split())
