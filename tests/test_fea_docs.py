"""Every ``python`` block in docs/verification.md raises the error it documents (see ``doc_examples``)."""
from pathlib import Path

import pytest
from doc_examples import check_example, examples

import fea

DOC = Path(__file__).resolve().parents[1] / "docs" / "verification.md"


def test_verification_doc_has_examples():
    assert len(examples(DOC)) >= 2


@pytest.mark.parametrize("index", range(len(examples(DOC))))
def test_verification_doc_example(index):
    check_example(DOC, index, errors=[fea.FEAInputError])
