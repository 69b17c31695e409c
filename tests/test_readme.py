"""Every shell and Python block of the README runs, as a reader would run it.

The blocks are taken from README.md as they are (nothing is filled in by hand) and run in
document order in one fresh folder, so a block may use what an earlier one wrote
(``models/M1`` of the step-by-step, for instance); shell blocks run under ``bash -e``
with this interpreter's ``bin`` folder first on ``PATH`` (where ``coassist`` is).

An HTML comment on the line before a block's fence says how it is tested:

- no mark: runs on every test run (``test_fast_blocks_run``; together well under a minute);
- ``<!-- readme-test: slow -->``: runs with ``pytest -m slow`` (minutes: the main job, the
  step-by-step pipeline at its real sizes); blocks that call ``./dev`` run from the
  repository root, since ``./dev`` is the repository's;
- ``<!-- readme-test: parse-only (why) -->``: needs what a test machine lacks (a robot
  arm, a person at a browser): each ``coassist`` line is parsed by the command's own
  option parser (unknown options, bad values and missing arguments fail) and the
  block is checked by ``bash -n`` (a Python block: compiled); it is not run;
- ``<!-- readme-test: output -->`` on a ``text`` block: the exact output of the Python
  block before it (checked wherever that block runs).

The claims count of "What the main job measured" is checked against its table.

Blocks that moved from the README to a doc page (:data:`CONTINUED`) are checked there the same
way, after the README's; a doc page's synopsis with placeholders (``PLAN.toml``, ``<name>``) is a
``text`` block, not a command.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
import typer

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: Doc pages whose blocks continue the README's (they read what its blocks wrote): run after it, in the same
#: folder, by :func:`test_all_blocks_run`; their parse-only blocks parsed as the README's.
CONTINUED = (ROOT / "docs" / "robots.md", ROOT / "docs" / "study.md")
#: The README's size limit in bytes (22,000, issue 43): what grows beyond it moves to docs/.
README_LIMIT = 22_000
SHELL = ("bash", "sh", "shell")
PYTHON = ("python", "py")
MARKS = ("slow", "parse-only", "output")
BLOCK_TIMEOUT_S = 1800


@dataclass(frozen=True)
class Block:
    line: int  # 1-based line of the opening fence
    language: str
    mark: str | None
    code: str
    page: str = "README.md"

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line} ({self.language} block{'' if self.mark is None else ', ' + self.mark})"


def readme_blocks(text: str | None = None, page: str = "README.md") -> list[Block]:
    """Every fenced block of the README (or of ``text``, named ``page``) with its language and mark."""
    lines = (README.read_text(encoding="utf-8") if text is None else text).splitlines()
    blocks, i = [], 0
    while i < len(lines):
        fence = re.match(r"^(`{3,})\s*([\w+-]*)\s*$", lines[i])
        if not fence:
            i += 1
            continue
        ticks, language = fence.group(1), fence.group(2).lower()
        prev = next((lines[j] for j in range(i - 1, -1, -1) if lines[j].strip()), "")
        mark = re.match(r"^<!--\s*readme-test:\s*([\w-]+)", prev.strip())
        end = next((j for j in range(i + 1, len(lines)) if lines[j].strip() == ticks), None)
        if end is None:
            raise AssertionError(f"{page}:{i + 1}: the code block is never closed")
        code = "\n".join(lines[i + 1 : end]) + "\n"
        blocks.append(Block(i + 1, language, mark.group(1) if mark else None, code, page))
        i = end + 1
    return blocks


def runnable(blocks: list[Block]) -> list[Block]:
    return [b for b in blocks if b.language in SHELL + PYTHON]


def expected_output(blocks: list[Block], block: Block) -> str | None:
    """The text of an ``output`` block right after ``block``, if there is one."""
    index = blocks.index(block)
    if index + 1 < len(blocks) and blocks[index + 1].mark == "output":
        return blocks[index + 1].code
    return None


def run_block(block: Block, cwd: Path, expected: str | None = None) -> None:
    env = {
        **os.environ,
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
        "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1"),
        "MPLBACKEND": "Agg",
    }
    if block.language in SHELL:
        argv = ["bash", "-e", "-o", "pipefail", "-c", block.code]
        run_in = ROOT if re.search(r"(^|\s)\./dev\b", block.code) else cwd
    else:
        argv = [sys.executable, "-c", block.code]
        run_in = cwd
    start = time.perf_counter()
    proc = subprocess.run(argv, cwd=run_in, env=env, capture_output=True, text=True, timeout=BLOCK_TIMEOUT_S)
    print(f"{block.where}: {time.perf_counter() - start:.0f} s\n{proc.stdout[-2000:]}")  # shown with pytest -s
    assert proc.returncode == 0, (
        f"{block.where} failed (exit {proc.returncode}) in {run_in}:\n{block.code}\n"
        f"--- stdout\n{proc.stdout[-4000:]}\n--- stderr\n{proc.stderr[-4000:]}"
    )
    assert "Traceback" not in proc.stderr, f"{block.where} printed a traceback:\n{proc.stderr[-4000:]}"
    if expected is not None:
        assert proc.stdout == expected, f"{block.where}: output differs from the README's:\n{proc.stdout}"


# --------------------------------------------------------------------------- every run


def page_blocks(page: Path) -> list[Block]:
    return readme_blocks(page.read_text(encoding="utf-8"), f"{page.parent.name}/{page.name}")


def test_every_block_is_accounted_for():
    blocks = readme_blocks()
    assert len(runnable(blocks)) >= 4
    for b in [*blocks, *(b for page in CONTINUED for b in page_blocks(page))]:
        assert b.mark in (None, *MARKS), f"{b.where}: unknown readme-test mark {b.mark!r} (known: {MARKS})"
        if b.mark == "output":
            before = blocks[blocks.index(b) - 1]
            assert before.language in PYTHON, f"{b.where}: an output block must follow a Python block"
        if re.search(r"(^|\s)\./dev\b", b.code):
            assert b.mark == "slow", f"{b.where}: ./dev runs for minutes; mark the block slow"
        if b.mark == "parse-only":
            assert b.language in SHELL + PYTHON, f"{b.where}: only shell and Python blocks can be parse-only"


def test_blocks_and_marks_are_read_as_meant():
    """The extractor on a hand-written README: marks, languages, nested fences, blank lines."""
    text = "\n".join(
        [
            "intro",
            "```bash",
            "echo one",
            "```",
            "",
            "<!-- readme-test: slow -->",
            "",
            "```python",
            "print(2)",
            "```",
            "<!-- readme-test: output -->",
            "```text",
            "2",
            "```",
            "````markdown",
            "```bash",
            "not a block",
            "```",
            "````",
        ]
    )
    blocks = readme_blocks(text)
    assert [(b.line, b.language, b.mark, b.code) for b in blocks] == [
        (2, "bash", None, "echo one\n"),
        (8, "python", "slow", "print(2)\n"),
        (12, "text", "output", "2\n"),
        (15, "markdown", None, "```bash\nnot a block\n```\n"),
    ]
    assert expected_output(blocks, blocks[1]) == "2\n"


def test_fast_blocks_run(tmp_path):
    """The unmarked blocks, in order, in one folder (the first look, the library snippet)."""
    blocks = readme_blocks()
    fast = [b for b in runnable(blocks) if b.mark is None]
    assert fast, "no block runs on every test run"
    for block in fast:
        run_block(block, tmp_path, expected_output(blocks, block))


def _parse_coassist(words: list[str], where: str) -> None:
    """Parse one ``coassist …`` command line with the CLI's own parser, without running it."""
    from coassist.cli import app

    group = typer.main.get_command(app)
    parent = group.context_class(group, info_name="coassist")  # typer's own (vendored) click
    command = group.get_command(parent, words[0]) if words else None
    if command is None:
        raise AssertionError(f"{where}: `coassist {' '.join(words)}`: no such command")
    try:
        command.make_context(words[0], list(words[1:]), parent=parent)
    except Exception as exc:  # noqa: BLE001 -- typer vendors click: its UsageError is not click's
        message = exc.format_message() if hasattr(exc, "format_message") else repr(exc)
        raise AssertionError(f"{where}: `coassist {' '.join(words)}`: {message}") from None


def test_parse_only_blocks_parse():
    pages = [readme_blocks(), *(page_blocks(page) for page in CONTINUED)]
    blocks = [b for page in pages for b in page if b.mark == "parse-only"]
    assert any(b.language in PYTHON for b in blocks), "no parse-only Python block: the compile check is idle"
    for block in blocks:
        if block.language in PYTHON:
            compile(block.code, block.where, "exec")  # a SyntaxError names the block
            continue
        syntax = subprocess.run(["bash", "-n", "-c", block.code], capture_output=True, text=True)
        assert syntax.returncode == 0, f"{block.where}: {syntax.stderr}"
        commands = 0
        for line in block.code.splitlines():
            words = shlex.split(line, comments=True)
            if words and Path(words[0]).name == "coassist":
                _parse_coassist(words[1:], block.where)
                commands += 1
        assert commands, f"{block.where}: a parse-only block without a coassist command"


def test_parse_only_catches_bad_lines():
    """The parser check is not vacuous: a misspelt option or a bad value is caught."""
    for words in (["drive", "--wrold", "mujoco"], ["drive", "--rate", "fast"], ["train", "--out", "m"]):
        with pytest.raises(AssertionError, match="coassist"):
            _parse_coassist(words, "test")
    _parse_coassist(["drive", "--world", "mujoco", "--rate", "500"], "test")


def _claim_counts(text: str) -> tuple[int, int, int]:
    """(held, total) as the sentence states them, and held as the table's rows count them."""
    section = text[text.index("## What the main job measured") :]
    section = section[: section.index("\n## ", 5)]
    stated = re.search(r"(\d+) of the (\d+) claims checked hold", section)
    assert stated, "the claims sentence is missing"
    held = total = 0
    # The claims table: the first table of the section (later tables there are measurements, not claims).
    table = section[section.index("| thesis claim |") :]
    table = table[: table.index("\n\n")] if "\n\n" in table else table
    for row in re.findall(r"^\|(.+)\|$", table, flags=re.M):
        cells = [c.strip() for c in row.split("|")]
        if len(cells) < 3 or cells[1] in ("verdict", "---") or set(cells[1]) <= {"-"}:
            continue
        if "(board; heavy)" in cells[0]:  # two claims, each with its own verdict ("holds; **2 of 3**")
            verdicts = [v.strip().strip("*") for v in cells[1].split(";")]
            assert len(verdicts) == 2, f"a (board; heavy) row needs a verdict for each: {row}"
            total += 2
            held += sum(v in ("holds", "hold") for v in verdicts)
            continue
        n = (
            int(m.group(1))
            if (m := re.search(r"\((\d+) claims\)", cells[0]))
            else 2
            if "(board, heavy)" in cells[0]
            else 1
        )
        total += n
        held += n if cells[1].strip("*") in ("holds", "hold") else 0
    assert total == int(stated.group(2)), f"the table has {total} claims, the sentence says {stated.group(2)}"
    return int(stated.group(1)), total, held


def test_claims_count_agrees_with_the_table():
    stated, total, held = _claim_counts(README.read_text(encoding="utf-8"))
    assert stated == held, f"the sentence says {stated} of {total} hold, the table's verdicts count {held}"


# --------------------------------------------------------------------------- pytest -m slow


@pytest.mark.slow
def test_all_blocks_run(tmp_path):
    """Every block but parse-only ones, in order, in one folder: what a reader following the README runs,
    then the blocks of :data:`CONTINUED`.

    The ``./dev`` block (the main job, 10 minutes, and the whole test suite) is run by
    :func:`test_dev_entry_points`.
    """
    blocks = readme_blocks()
    for block in runnable(blocks):
        if block.mark == "parse-only" or re.search(r"(^|\s)\./dev\b", block.code):
            continue
        run_block(block, tmp_path, expected_output(blocks, block))
    for page in CONTINUED:
        blocks = page_blocks(page)
        assert runnable(blocks), f"{page.name} holds no block to run"
        for block in runnable(blocks):
            if block.mark != "parse-only":
                run_block(block, tmp_path, expected_output(blocks, block))


@pytest.mark.slow
def test_dev_entry_points():
    """The set-up block (``./dev run``, ``./dev test``), from the repository root, as written."""
    for block in runnable(readme_blocks()):
        if re.search(r"(^|\s)\./dev\b", block.code):
            run_block(block, ROOT)


def test_the_readme_is_a_manual_not_a_notebook():
    """At most 22,000 bytes: measurements live in docs/performance.md, their history in docs/history.md, the
    reference behind a command in its docs/ page."""
    size = README.stat().st_size
    assert size <= README_LIMIT, (
        f"README.md is {size} bytes (limit {README_LIMIT}); move measurements to docs/performance.md, "
        "details to the docs/ page the README links"
    )
    text = README.read_text(encoding="utf-8")
    assert not re.search(r"\b20\d\d-\d\d-\d\d\b", text), "a dated entry: history goes to docs/history.md"
