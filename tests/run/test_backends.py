"""The backend registry: what `psyop run` lists, refuses and builds (psyop.run.backends)."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import pytest
from session_helpers import fast_protocol

from psyop.cli import main as cli_main
from psyop.errors import UserError
from psyop.run import backends as registry
from psyop.run import runner
from psyop.session import loop
from psyop.run.backends import BACKENDS, CATEGORIES, Backend, BackendContext, build, help_text, lookup


def test_every_category_has_backends_and_every_backend_is_well_formed() -> None:
    for category in CATEGORIES:
        names = [b.name for b in registry.backends(category)]
        assert names, category
        assert len(names) == len(set(names)), f"{category}: duplicate names {names}"
    for backend in BACKENDS:
        # usage and argument rule agree: NAME (none), NAME:ARG (required), NAME[:ARG] (optional)
        expected = {False: backend.name, True: backend.name + ":", None: backend.name + "[:"}[backend.takes_arg]
        assert backend.usage == expected if backend.takes_arg is False else backend.usage.startswith(expected), \
            backend.usage
        assert backend.summary and "\n" not in backend.summary


def test_run_help_lists_every_registered_backend_with_its_usage(capsys: pytest.CaptureFixture[str],
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "100000")
    with pytest.raises(SystemExit) as exit_info:
        cli_main(["run", "--help"])
    assert exit_info.value.code == 0
    text = re.sub(r"\s+", " ", capsys.readouterr().out)
    for category in CATEGORIES:
        option = registry.OPTION[category]
        start = text.index(f"{option} {category.upper()}")
        section = text[start:]
        for backend in registry.backends(category):
            assert f"{backend.usage}: {backend.summary}" in section, (option, backend.usage)
            if backend.real_time:
                assert f"{backend.usage}: {backend.summary} (real time: needs --clock real" in section


@pytest.mark.parametrize("category", CATEGORIES)
def test_unknown_name_is_one_line_listing_the_registered_ones(category: registry.Category) -> None:
    with pytest.raises(UserError) as info:
        lookup(category, "nosuchbackend:x")
    message = str(info.value)
    assert "\n" not in message and info.value.exit_code == 2
    for backend in registry.backends(category):
        assert backend.usage in message


def test_cli_unknown_tracker_exits_2_with_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    protocol = fast_protocol(tmp_path, "detection", repetitions=1)
    code = cli_main(["run", str(protocol), "--participant", "P1", "--data", str(tmp_path / "data"),
                     "--no-progress", "--tracker", "eyelink"])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown tracker 'eyelink'" in err[0] and "pupil:HOST:PORT" in err[0]
    assert not (tmp_path / "data").exists() or not any((tmp_path / "data").rglob("*.psylog"))


def test_live_backend_on_the_virtual_clock_is_refused_from_the_registry(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    protocol = fast_protocol(tmp_path, "detection", repetitions=1)
    for option, spec in (("--tracker", "pupil:127.0.0.1:1"), ("--responses", "serial:loop://")):
        code = cli_main(["run", str(protocol), "--participant", "P1", "--data", str(tmp_path / "data"),
                         "--no-progress", option, spec])
        assert code == 2
        assert f"{option} {spec.partition(':')[0]} is a live device" in capsys.readouterr().err


def _context() -> BackendContext:
    return BackendContext(clock=None, seed=0, plan=None, participant="P1", protocol_sha256="",  # type: ignore[arg-type]
                          schedule=None, tracker_faults=None)  # type: ignore[arg-type]


def test_missing_extra_is_one_line_naming_the_pip_install() -> None:
    made: list[str] = []
    fake = (Backend("tracker", "fake", "fake:NAME", "needs a module that is not installed", True,
                    lambda arg, ctx: made.append(arg), extra="lsl", modules=("psyop_no_such_module_xyz",),
                    takes_arg=True),)
    with pytest.raises(UserError) as info:
        build("tracker", "fake:x", _context(), fake)
    assert "pip install 'psyop[lsl]'" in str(info.value) and "\n" not in str(info.value)
    assert made == []  # never constructed
    with pytest.raises(UserError, match="expected fake:NAME"):
        build("tracker", "fake", _context(), fake)


def test_help_text_is_generated_from_the_registry() -> None:
    extra = (Backend("display", "fancy", "fancy", "a display added in one place", True, lambda a, c: None),)
    assert help_text("display", extra) == "fancy: a display added in one place (real time: needs --clock real)"


def test_runner_and_loop_hold_no_backend_if_chain_or_capability_getattr() -> None:
    for module in (runner, loop):
        source = inspect.getsource(module)
        assert "getattr(gaze" not in source and "getattr(self.gaze" not in source
        assert "getattr(pose" not in source
        assert not re.search(r'(kind|name) == "(pupil|serial|keyboard|replay)"', source), module.__name__
