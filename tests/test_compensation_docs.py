"""The hybrid study's tables in docs/compensation.md are what the study prints today (see ``doc_examples``)."""
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
