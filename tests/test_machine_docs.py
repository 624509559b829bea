"""Every ``python`` block in docs/machines.md runs and prints what the document shows (see ``doc_examples``)."""
from pathlib import Path

import pytest
from doc_examples import check_example, examples

DOC = Path(__file__).resolve().parents[1] / "docs" / "machines.md"


def test_docs_have_examples():
    assert len(examples(DOC)) == 3


@pytest.mark.parametrize("index", range(len(examples(DOC))))
def test_docs_example_prints_what_the_docs_show(index):
    check_example(DOC, index)
