"""Every ``python`` block in docs/verification.md runs; a block documenting an error raises it."""
import re
import textwrap
from pathlib import Path

import pytest

import fea

DOC = Path(__file__).resolve().parents[1] / "docs" / "verification.md"
BLOCKS = [textwrap.dedent(b) for b in re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)]


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_verification_doc_example_runs(index):
    code = compile(BLOCKS[index], f"{DOC.name} block {index + 1}", "exec")
    documented = re.search(r"# FEAInputError: (.*)", BLOCKS[index])
    if documented is None:
        exec(code, {"__name__": "__docs__"})
        return
    with pytest.raises(fea.FEAInputError) as caught:
        exec(code, {"__name__": "__docs__"})
    assert str(caught.value).startswith(documented.group(1)[:40])
