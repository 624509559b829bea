"""No absolute path of a developer's machine is written into the repository."""
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ABSOLUTE = re.compile(r"(^|[^A-Za-z0-9_.])/(work|tmp|root|home)/")


def test_no_machine_paths_in_the_repository():
    try:
        listed = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                                capture_output=True, text=True, check=True).stdout.split("\n")
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    found = []
    for name in filter(None, listed):
        path = ROOT / name
        if not path.is_file():          # listed but deleted in the work tree
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:      # binary (meshes, operators, images)
            continue
        found += [f"{name}:{i}: {line.strip()}" for i, line in enumerate(text.splitlines(), 1)
                  if ABSOLUTE.search(line)]
    assert not found, "\n".join(found)
