"""The command-line examples of docs/live.md print what the document shows (see ``doc_console``)."""
import pytest
from doc_console import ROOT, check_console_examples

DOC = ROOT / "docs" / "live.md"


@pytest.mark.slow
def test_the_live_demos_print_what_the_document_shows(tmp_path):
    """About 2 min: a twin record replayed through OPC UA, a small placement study and its chosen set, then the
    record again in two sessions, the second resuming from the state the first saved."""
    assert check_console_examples(DOC, tmp_path) == 3
