"""The command-line examples of a Markdown document, as tests.

The ```` ```console ```` blocks run in document order, from the repository
root's layout (``runs/`` and ``../shared`` beside it, in a temporary folder),
each command on its own line and through a shell, stdout and stderr
together. Where a ```` ```text ```` block follows, its lines (but ``...``)
must appear in the output, in that order: a document may leave lines out,
not change them. Wall-clock figures (``in 19.0 s``, ``(60 samples/s)``) are
the machine's, not the program's, and are not compared. A block without a
```` ```text ```` block runs only its ``python -c`` lines (they write the
records later blocks read); benchmarks (``bench/``) are the bench scripts'
business.
"""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_BLOCK = re.compile(r"```console\n(.*?)```(?:\s*\n```text\n(.*?)```)?", flags=re.DOTALL)
_WALL_CLOCK = re.compile(r"\bin \d+(?:\.\d+)? s\b|\(\d+(?:\.\d+)? samples/s\)")


def console_blocks(document):
    """``[(commands, documented lines or None)]`` of ``document``, benchmarks left out; a command continued
    with a trailing backslash is one line."""
    found = []
    for commands, printed in _BLOCK.findall(document.read_text(encoding="utf-8")):
        joined = re.sub(r"\\\n\s*", "", commands.strip())
        lines = [c for c in joined.splitlines() if "bench/" not in c]
        if not printed:
            lines = [c for c in lines if c.startswith("python -c ")]
        if lines:
            found.append((lines, printed.splitlines() if printed else None))
    return found


def first_missing(documented, output):
    """The first documented line that is not in ``output`` after the one before it, or None."""
    lines, at = [_WALL_CLOCK.sub("…", line) for line in output.splitlines()], 0
    for line in documented:
        if line.strip() == "...":
            continue
        try:
            at = lines.index(_WALL_CLOCK.sub("…", line), at) + 1
        except ValueError:
            return line
    return None


def check_console_examples(document, tmp_path):
    """Run the console blocks of ``document`` (see the module) and return how many printed outputs it checked."""
    root = tmp_path / "repository"
    (root / "runs").mkdir(parents=True)
    (tmp_path / "shared").symlink_to(ROOT.parent / "shared")
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
           "OPENBLAS_NUM_THREADS": "1"}
    assert shutil.which("twin", path=env["PATH"])
    checked = 0
    for commands, documented in console_blocks(document):
        output = "".join(
            subprocess.run(command, shell=True, cwd=root, env=env, capture_output=True, text=True,
                           check=False).stdout   # a documented refusal exits 2; its message is the output
            for command in (f"{c} 2>&1" for c in commands))
        if documented is not None:
            missing = first_missing(documented, output)
            assert missing is None, (commands, missing, output)
            checked += 1
    return checked
