"""The command-line examples of docs/models.md print what the document shows (see ``doc_console``)."""
import pytest
from doc_console import ROOT, check_console_examples

DOC = ROOT / "docs" / "models.md"


@pytest.mark.slow
def test_the_command_line_examples_print_what_the_document_shows(tmp_path):
    """About 1 min: the FL_THERMAL commands of the grey-box section."""
    assert check_console_examples(DOC, tmp_path) >= 5
