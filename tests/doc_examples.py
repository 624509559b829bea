"""The code examples of a Markdown document, as tests.

Every ```` ```python ```` block either ends with a comment ``# <Error>: message``
(the example documents an error: running it must raise that error with that
message) or is followed by a ```` ```text ```` block: what the example prints,
exactly.  So an example that stops running, or whose documented output no
longer matches, fails.
"""
import contextlib
import io
import re
import textwrap

import pytest

_EXAMPLE = re.compile(r"```python\n(.*?)```(?:\s*\n```text\n(.*?)```)?", flags=re.S)
_ERROR = re.compile(r"^# (\w+Error): (.*)$", flags=re.M)


def examples(path):
    """[(code, printed output or None)] of the document, in order."""
    return [(textwrap.dedent(code), printed) for code, printed in _EXAMPLE.findall(path.read_text(encoding="utf-8"))]


def check_example(path, index, errors=()):
    """Run example ``index`` of ``path`` and compare with what the document says it prints or raises.

    ``errors``: the exception classes a document may name in a ``# <Error>: message`` line.
    """
    code, printed = examples(path)[index]
    where = f"{path.name} example {index + 1}"
    compiled = compile(code, where, "exec")
    documented = _ERROR.search(code)
    if documented is not None:
        error = {e.__name__: e for e in errors}[documented.group(1)]
        with pytest.raises(error) as caught:
            exec(compiled, {"__name__": "__docs__"})
        assert str(caught.value).startswith(documented.group(2)[:40]), where
        return
    assert printed, f"{where}: no ```text block with its output follows it"
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        exec(compiled, {"__name__": "__docs__"})
    assert buffer.getvalue() == printed, where
