"""The command-line examples of docs/models.md print what the document shows.

The ```` ```console ```` blocks run in document order, from the repository
root's layout (``runs/`` and ``../shared`` beside it, in a temporary folder),
each command on its own line and through a shell, stdout and stderr
together. Where a ```` ```text ```` block follows, its lines (but ``...``)
must appear in the output, in that order: a document may leave lines out,
not change them. A block without one runs only its ``python -c`` lines (they
write the records later blocks read); benchmarks (``bench/``) are the bench
scripts' business.
"""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "models.md"
_BLOCK = re.compile(r"```console\n(.*?)```(?:\s*\n```text\n(.*?)```)?", flags=re.DOTALL)


def _blocks():
    """``[(commands, documented lines or None)]`` of the document, benchmarks left out."""
    found = []
    for commands, printed in _BLOCK.findall(DOC.read_text(encoding="utf-8")):
        lines = [c for c in commands.strip().splitlines() if "bench/" not in c]
        if not printed:
            lines = [c for c in lines if c.startswith("python -c ")]
        if lines:
            found.append((lines, printed.splitlines() if printed else None))
    return found


def _missing(documented, output):
    """The first documented line that is not in ``output`` after the one before it, or None."""
    lines, at = output.splitlines(), 0
    for line in documented:
        if line.strip() == "...":
            continue
        try:
            at = lines.index(line, at) + 1
        except ValueError:
            return line
    return None


@pytest.mark.slow
def test_the_command_line_examples_print_what_the_document_shows(tmp_path):
    """About 1 min: the FL_THERMAL commands of the grey-box section."""
    root = tmp_path / "repository"
    (root / "runs").mkdir(parents=True)
    (tmp_path / "shared").symlink_to(ROOT.parent / "shared")
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
           "OPENBLAS_NUM_THREADS": "1"}
    assert shutil.which("twin", path=env["PATH"])
    checked = 0
    for commands, documented in _blocks():
        output = "".join(
            subprocess.run(command, shell=True, cwd=root, env=env, capture_output=True, text=True,
                           check=False).stdout   # a documented refusal exits 2; its message is the output
            for command in (f"{c} 2>&1" for c in commands))
        if documented is not None:
            assert _missing(documented, output) is None, (commands, _missing(documented, output), output)
            checked += 1
    assert checked >= 5
