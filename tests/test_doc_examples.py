"""Every code example of README.md and docs/*.md runs as written from a clone (issue 12).

Each fenced block is one test, run alone in a fresh temporary folder holding a copy of the clone's
`data/` (so a block may name `data/scenes/knot.json`, and must make any other file it reads itself),
with the repository's Python and its `diffwash` command first on the `PATH`:

- ```` ```python ```` blocks run as a script (`python`), float32 as for a user, not the tests' float64;
- ```` ```bash ````, ```` ```sh ```` blocks run with `bash -euo pipefail`; ```` ```console ```` blocks
  run their `$ ` lines that way, the other lines being output.

Blocks that are not programs say so by their info string: ```` ```text ```` (output, listings),
```` ```json ```` and ```` ```csv ```` (file-format samples; the JSON ones are checked to parse) and
```` ```glsl ```` (shader code for an engine). A runnable block that must not run here (it installs
packages, needs a display or several hosts) is preceded by a comment giving the reason:

    <!-- no-run: installs system packages (CI runs this command itself) -->

A fence without an info string, an info string not listed here, or a `no-run` without a reason fails
`test_every_block_runs_or_says_why`, so no broken example hides behind a skip.
"""

import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import ROOT, SHARED_CACHE

#: The documents whose examples must run.
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: Info strings of blocks that run, and how.
RUN = {"python", "bash", "sh", "console"}
#: Info strings of blocks that are not programs, and why they are not run.
NOT_RUN = {
    "text": "output or a listing, not a command",
    "json": "a file-format sample (checked to parse as JSON)",
    "csv": "a file-format sample",
    "glsl": "shader code for an engine, not a program",
}
#: What a block's temporary folder holds: a copy of these paths of the clone.
COPIED = ("data",)
#: Seconds one block may take.
TIMEOUT = 300

_FENCE = re.compile(r"^(`{3,})\s*(.*?)\s*$")
_NO_RUN = re.compile(r"^<!--\s*no-run\b:?(.*?)-->\s*$")


@dataclass(frozen=True)
class Block:
    """One fenced code block: where it is, its info string, its text, and a `no-run` reason if any."""

    doc: Path
    line: int  # the line of the opening fence, 1-based
    info: str
    text: str
    no_run: str | None  # None: no comment; "": a comment without a reason

    @property
    def where(self) -> str:
        return f"{self.doc.relative_to(ROOT)}:{self.line}"


def blocks(doc: Path) -> list[Block]:
    """The fenced code blocks of a Markdown file, in order (an unclosed fence runs to the end)."""
    lines = doc.read_text(encoding="utf-8").splitlines()
    found, i = [], 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        ticks, info, start = m.group(1), m.group(2), i
        j = start + 1
        while j < len(lines) and lines[j].strip() != ticks:
            j += 1
        k = start - 1
        while k >= 0 and not lines[k].strip():
            k -= 1
        c = _NO_RUN.match(lines[k].strip()) if k >= 0 else None
        no_run = c.group(1).strip() if c else None
        found.append(Block(doc, start + 1, info, "\n".join(lines[start + 1 : j]), no_run))
        i = j + 1
    return found


ALL = [b for d in DOCUMENTS for b in blocks(d)]
RUNNABLE = [b for b in ALL if b.info in RUN and b.no_run is None]


def test_the_documents_have_examples():
    assert (ROOT / "README.md") in DOCUMENTS and len(DOCUMENTS) >= 5
    assert len(RUNNABLE) >= 15


def test_every_block_runs_or_says_why():
    problems = []
    for b in ALL:
        if b.info not in RUN and b.info not in NOT_RUN:
            problems.append(f"{b.where}: info string {b.info!r}: say what the block is, one of {sorted(RUN | set(NOT_RUN))}")
        if b.no_run == "":
            problems.append(f"{b.where}: `<!-- no-run -->` without a reason: write `<!-- no-run: why -->`")
        if b.no_run is not None and b.info not in RUN:
            problems.append(f"{b.where}: `no-run` before a {b.info!r} block, which never runs")
    for doc in DOCUMENTS:
        lines = doc.read_text(encoding="utf-8").splitlines()
        for n, line in enumerate(lines):
            if _NO_RUN.match(line.strip()):
                nxt = next((x for x in lines[n + 1 :] if x.strip()), "")
                if not _FENCE.match(nxt):
                    problems.append(f"{doc.relative_to(ROOT)}:{n + 1}: a `no-run` comment that no code block follows")
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("block", [b for b in ALL if b.info == "json"], ids=lambda b: b.where)
def test_json_sample_parses(block):
    try:
        json.loads(block.text)
    except json.JSONDecodeError as e:
        pytest.fail(f"{block.where}: the JSON sample does not parse: {e}")


def test_the_parser_sees_conventions(tmp_path):
    doc = tmp_path / "x.md"
    doc.write_text("a\n\n```python\nprint(1)\n```\n<!-- no-run: needs a display -->\n\n```bash\nx\n```\n```\ny\n```\n")
    b = blocks(doc)
    assert [(x.line, x.info, x.text, x.no_run) for x in b] == [
        (3, "python", "print(1)", None),
        (8, "bash", "x", "needs a display"),
        (11, "", "y", None),
    ]


@pytest.fixture(scope="module")
def shims(tmp_path_factory) -> Path:
    """A folder of `python` and `diffwash` commands that run this repository's Python."""
    bin_dir = tmp_path_factory.mktemp("bin")
    for name, run in (("python", f'exec "{sys.executable}" "$@"'), ("diffwash", f'exec "{sys.executable}" -m diffwash "$@"')):
        (bin_dir / name).write_text(f"#!/bin/sh\n{run}\n")
        (bin_dir / name).chmod(0o755)
    return bin_dir


@pytest.fixture(scope="module")
def jax_cache() -> Path:
    """The compilation cache the blocks of this run share (not the user's): the test processes' shared folder
    (conftest), which both xdist workers' blocks read and write under JAX's lock, so that a Python block reuses what
    a command-line block of the same document compiled before it (README's Python fit block: 25 s cold, 9-10 s after
    its command-line block). The blocks run in float32, the tests in float64: their programs never share a key."""
    return Path(os.environ[SHARED_CACHE])


def _command(block: Block, script: Path) -> list[str]:
    """The command that runs the block's text, written (line numbers kept) to `script`."""
    if block.info == "python":
        # Blank lines first, so that a traceback names the document's own line numbers.
        script.write_text("\n" * block.line + block.text + "\n")
        run = "import sys; exec(compile(open(sys.argv[1]).read(), sys.argv[2], 'exec'), {'__name__': '__main__'})"
        return [sys.executable, "-c", run, str(script), str(block.doc)]
    text = block.text
    if block.info == "console":
        text = "\n".join(line[2:] for line in text.splitlines() if line.startswith("$ "))
    script.write_text(text + "\n")
    return ["bash", "-euo", "pipefail", str(script)]


def run_block(block: Block, folder: Path, shims: Path, jax_cache: Path) -> str | None:
    """Run one block in `folder`/clone (a fresh copy of `COPIED`); None if it succeeded, else why not."""
    work = folder / "clone"
    work.mkdir(parents=True)
    for name in COPIED:
        shutil.copytree(ROOT / name, work / name)
    env = dict(os.environ)
    env.update(
        PATH=f"{shims}{os.pathsep}{env.get('PATH', '')}",
        PYTHONPATH=f"{ROOT}{os.pathsep}{env.get('PYTHONPATH', '')}",
        DIFFWASH_CACHE_DIR=str(jax_cache),  # the commands' cache (`diffwash.enable_compilation_cache`)
        # Python blocks' programs go there too (JAX reads its options from the environment); a size bound turns
        # on the lock that two processes writing one folder need.
        JAX_COMPILATION_CACHE_DIR=str(jax_cache),
        JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0",
        JAX_COMPILATION_CACHE_MAX_SIZE=str(8 << 30),
        MPLBACKEND="Agg",
    )
    env.pop("JAX_ENABLE_X64", None)
    cmd = _command(block, folder / "block")
    try:
        r = subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True, timeout=TIMEOUT, check=False)
    except subprocess.TimeoutExpired:
        return f"{block.where}: the {block.info} block ran past {TIMEOUT} s"
    if r.returncode == 0:
        return None
    out = (r.stdout[-2000:] + "\n" + r.stderr[-4000:]).strip()
    return f"{block.where}: the {block.info} block failed (exit status {r.returncode}):\n{out}"


@pytest.mark.parametrize("block", RUNNABLE, ids=lambda b: f"{b.where}-{b.info}")
def test_example_runs(block, tmp_path, shims, jax_cache):
    failure = run_block(block, tmp_path, shims, jax_cache)
    if failure:
        pytest.fail(failure, pytrace=False)


def test_a_broken_example_is_reported_with_its_line(tmp_path, shims, jax_cache):
    doc = ROOT / "README.md"  # any document: the blocks below are made up, not read from it
    py = Block(doc, 40, "python", "x = 1\nopen('data/no-such-file.csv')", None)
    message = run_block(py, tmp_path / "py", shims, jax_cache)
    assert message.startswith("README.md:40: the python block failed (exit status 1)")
    assert 'README.md", line 42' in message and "no-such-file.csv" in message
    sh = Block(doc, 7, "console", "$ python -c 'print(1)'\n1\n$ python -c 'raise SystemExit(3)'", None)
    message = run_block(sh, tmp_path / "sh", shims, jax_cache)
    assert message.startswith("README.md:7: the console block failed (exit status 3)")
    # The block sees the clone's data, and this repository's diffwash on the PATH and in Python.
    where = "import diffwash, sys; assert diffwash.__file__.startswith(sys.argv[1]), diffwash.__file__"
    ok = Block(doc, 1, "bash", f"test -f data/scenes/knot.json\ncommand -v diffwash\npython -c '{where}' '{ROOT}'", None)
    assert run_block(ok, tmp_path / "ok", shims, jax_cache) is None
