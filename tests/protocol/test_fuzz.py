"""Fuzz: mutated protocols never produce a traceback, only a UserError with a location.

1,000+ mutations of the five studies (deleted / duplicated / re-indented lines, values replaced
by random scalars or wrong types, truncation, random bytes) go through the loader in-process;
a protocol that still validates must also compile. A handful go through the real CLI.
"""

from __future__ import annotations

import random
import subprocess
import sys
from pathlib import Path

import pytest

from psyop.errors import UserError
from psyop.protocol import parse_protocol
from psyop.schedule import compile_schedule, trial_count

PROTOCOLS = Path(__file__).resolve().parents[2] / "protocols"
TEXTS = {p.stem: p.read_text() for p in sorted(PROTOCOLS.glob("*.yaml"))}
SCALARS = ["", "-1", "0", "1e999", ".nan", ".inf", "-0.5", "abc", "yes", "null", "~", "[]", "{}", "[1, 2]",
           "{a: 1}", "'quoted'", '"\\u0000"', "&anchor x", "*missing", "!!python/object:os.system", "!!binary aGk=",
           "2020-01-01", "0x1F", "1_000", "[", "{", "'", "|", ">-", "? x", "- x", "999999999999999999999999", "true",
           "ocular", "conventional|ocular", "{D: -1}", "{m: 0}", "{factor: nope_D}", "{kind: disc}", "3.5e-400"]


def _mutate(text: str, rng: random.Random) -> str:
    lines = text.splitlines(keepends=True)
    if not lines:
        return rng.choice(SCALARS)
    op = rng.randrange(9)
    i = rng.randrange(len(lines))
    if op == 0:  # delete a line
        del lines[i]
    elif op == 1:  # duplicate a line (duplicate keys, repeated list items)
        lines.insert(i, lines[i])
    elif op == 2:  # replace a value by a random scalar or wrong type
        line = lines[i]
        if ":" in line:
            key = line.split(":", 1)[0]
            lines[i] = f"{key}: {rng.choice(SCALARS)}\n"
        else:
            lines[i] = rng.choice(SCALARS) + "\n"
    elif op == 3:  # change the indentation
        lines[i] = " " * rng.randrange(0, 9) + lines[i].lstrip(" ")
    elif op == 4:  # truncate the file
        return text[: rng.randrange(len(text) + 1)]
    elif op == 5:  # insert random characters (control characters, surrogates-free unicode, NUL)
        position = rng.randrange(len(text) + 1)
        junk = "".join(chr(rng.choice([0, 1, 7, 9, 27, 0x85, 0xFEFF, 0x2028, rng.randrange(32, 0x3000)]))
                       for _ in range(rng.randrange(1, 6)))
        return text[:position] + junk + text[position:]
    elif op == 6:  # random bytes decoded leniently
        return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 400))).decode("latin-1")
    elif op == 7:  # delete a block: a line and the more-indented lines after it
        indent = len(lines[i]) - len(lines[i].lstrip(" "))
        j = i + 1
        while j < len(lines) and len(lines[j]) - len(lines[j].lstrip(" ")) > indent:
            j += 1
        del lines[i:j]
    else:  # swap two lines
        j = rng.randrange(len(lines))
        lines[i], lines[j] = lines[j], lines[i]
    return "".join(lines)


def _check(text: str) -> str:
    """'ok' or 'error'; anything else escaping fails the test."""
    try:
        protocol = parse_protocol(text, "fuzz.yaml", base_dir=PROTOCOLS)
    except UserError as error:
        assert str(error).strip()
        assert error.location is not None and error.location.startswith("fuzz.yaml")
        assert error.exit_code == 2
        return "error"
    if trial_count(protocol) <= 20_000:
        schedule = compile_schedule(protocol, 0)
        assert len(schedule) == trial_count(protocol)
    return "ok"


def test_1000_mutations_never_raise_anything_but_user_error() -> None:
    rng = random.Random(20201)
    outcomes = {"ok": 0, "error": 0}
    names = sorted(TEXTS)
    for index in range(1200):
        text = TEXTS[names[index % len(names)]]
        for _ in range(rng.choice([1, 1, 1, 2, 3])):
            text = _mutate(text, rng)
        outcomes[_check(text)] += 1
    # the mutations must exercise both paths: many are rejected, some (comments, harmless) survive
    assert outcomes["error"] > 600
    assert outcomes["ok"] > 20


def _mutations_that_fail(count: int, seed: int) -> list[str]:
    rng = random.Random(seed)
    found = []
    names = sorted(TEXTS)
    while len(found) < count:
        text = _mutate(TEXTS[rng.choice(names)], rng)
        try:
            parse_protocol(text, "fuzz.yaml", base_dir=PROTOCOLS)
        except UserError:
            found.append(text)
    return found


def test_cli_subprocess_on_mutated_files(tmp_path: Path) -> None:
    texts = _mutations_that_fail(5, seed=7)
    for index, text in enumerate(texts):
        path = tmp_path / f"m{index}.yaml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
    # one process validates several files in turn so the test stays quick
    script = (
        "import sys; from psyop.cli import main\n"
        "codes = [main(['validate', p]) for p in sys.argv[1:]]\n"
        "print(codes); sys.exit(0 if all(c == 2 for c in codes) else 1)\n"
    )
    result = subprocess.run([sys.executable, "-c", script, *map(str, sorted(tmp_path.glob("m*.yaml")))],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Traceback" not in result.stderr
    assert result.stderr.count("psyop validate: error:") == 5
    single = subprocess.run([sys.executable, "-m", "psyop", "validate", str(tmp_path / "m0.yaml")],
                            capture_output=True, text=True, timeout=120)
    assert single.returncode == 2 and "Traceback" not in single.stderr and str(tmp_path / "m0.yaml") in single.stderr


@pytest.mark.parametrize("raw", [b"\x00\x01\x02", b"\xff\xfe\xfd", "study: caf\u00e9\n".encode("utf-16"), b""])
def test_binary_files_through_the_cli(tmp_path: Path, raw: bytes) -> None:
    from psyop.cli import main

    path = tmp_path / "binary.yaml"
    path.write_bytes(raw)
    assert main(["validate", str(path)]) == 2


def _paths(node, prefix=()):
    yield prefix, node
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _paths(value, prefix + (key,))
    elif isinstance(node, list):
        for index, value in enumerate(node):
            yield from _paths(value, prefix + (index,))


def test_400_grafted_protocols_fail_cleanly_or_compile() -> None:
    """Structurally plausible nonsense: replace a subtree by a subtree of any study (factor sets of
    another study, a scene primitive where a depth belongs, ...). This reaches the cross-section
    checks and the compiler, which random text rarely does."""
    import copy

    import yaml

    rng = random.Random(4242)
    studies = {name: yaml.safe_load(text) for name, text in TEXTS.items()}
    pool = [node for data in studies.values() for _, node in _paths(data)]
    outcomes = {"ok": 0, "error": 0}
    for _ in range(400):
        data = copy.deepcopy(studies[rng.choice(sorted(studies))])
        for _ in range(rng.choice([1, 1, 2])):
            path = rng.choice([p for p, _ in _paths(data) if p])
            parent = data
            for key in path[:-1]:
                parent = parent[key]
            parent[path[-1]] = copy.deepcopy(rng.choice(pool))
        outcomes[_check(yaml.safe_dump(data, sort_keys=False))] += 1
    assert outcomes["error"] > 200 and outcomes["ok"] > 10
