"""Every response kind's make figures targets pass only arguments their analysis script accepts: the yes/no figure
target once passed `--figure`, which analysis/yes_no.py refuses, so `make figures` stopped on a yes/no study while
each script's own test (called with arguments it chose itself) passed. The rule's command line, as psyop.cli.studies
writes it (`"$(ANALYSE)" "$<" {arguments} --out "$@"`), is parsed by the script's own parser."""

from __future__ import annotations

import argparse
import importlib
import shlex
import sys
from pathlib import Path

import pytest

from psyop.cli.studies import targets_for
from psyop.protocol.kinds import KINDS

ANALYSIS = Path(__file__).resolve().parents[2] / "analysis"
MAKE_VARIABLES = {"$(DATA)": "data", "$(RESULTS)": "results", "$(JOBS)": "2", "$(FIGDIR)": "figures"}


class _Parsed(Exception):
    def __init__(self, parser: argparse.ArgumentParser) -> None:
        self.parser = parser


def _parser_of(script: str, monkeypatch: pytest.MonkeyPatch) -> argparse.ArgumentParser:
    """The parser ``analysis/<script>``'s main builds, stopped where it would parse."""
    monkeypatch.syspath_prepend(str(ANALYSIS))
    module = importlib.import_module(Path(script).stem)

    def stop(self: argparse.ArgumentParser, *args: object, **kwargs: object) -> None:
        raise _Parsed(self)

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", stop)
    try:
        module.main([])
    except _Parsed as parsed:
        return parsed.parser
    finally:
        sys.modules.pop(Path(script).stem, None)
    raise AssertionError(f"{script}'s main never parsed its arguments")


CASES = [(kind.name, linear, adaptive) for kind in KINDS.values() for linear in (False, True)
         for adaptive in (False, True)]


@pytest.mark.parametrize(("kind_name", "linear", "adaptive"), CASES)
def test_each_target_passes_only_arguments_its_script_accepts(kind_name: str, linear: bool, adaptive: bool,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    for target in targets_for("mine", KINDS[kind_name], linear, "trials.parquet", adaptive, "level_D"):
        text = f"{target.arguments} --out out.png"
        for variable, value in MAKE_VARIABLES.items():
            text = text.replace(variable, value)
        parser = _parser_of(target.script.removeprefix("analysis/"), monkeypatch)
        monkeypatch.undo()
        _, unknown = parser.parse_known_args(shlex.split(text))
        assert not unknown, f"{kind_name}: {target.script} refuses {unknown} (target {target.output})"
