"""The studies' tables in docs/compensation.md are what the studies print today (see ``doc_examples``)."""
import os
import subprocess
import sys
from pathlib import Path

import pytest
from doc_examples import check_example, examples

DOC = Path(__file__).resolve().parents[1] / "docs" / "compensation.md"
HYBRID = [i for i, (code, _) in enumerate(examples(DOC)) if "hybrid_study(" in code]


def test_the_hybrid_tables_are_a_checked_example():
    assert len(HYBRID) == 1
    code, printed = examples(DOC)[HYBRID[0]]
    assert printed and "| Y | hybrid (twin + anfis residual) |" in printed


@pytest.mark.slow
def test_hybrid_example_prints_what_the_docs_show():
    """About 2.5 min: eight simulated records, eight physics predictions, four ANFIS fits."""
    check_example(DOC, HYBRID[0])


@pytest.mark.slow
@pytest.mark.parametrize("study", ["cross-condition", "thesis"])
def test_the_pasted_study_tables_are_what_the_study_prints(study, tmp_path):
    """About 1.5 min each without a record cache: every table row `twin study` prints is in the document."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    run = subprocess.run([Path(sys.executable).parent / "twin", "study", study, "--out", str(tmp_path / study)],
                         capture_output=True, text=True, env=env, check=False)
    assert run.returncode == 0, run.stderr
    rows = [line for line in run.stdout.splitlines() if line.startswith("| ") and not line.startswith("| train")]
    documented = set(DOC.read_text(encoding="utf-8").splitlines())
    assert len(rows) >= 10
    assert [row for row in rows if row not in documented] == []
