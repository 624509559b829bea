"""Ctrl-C in `twin run`, from its first seconds on: one line, exit code 130, no traceback, no result.

A real process gets a real SIGINT at a known phase: while it imports the
numerical libraries (seen through ``python -X importtime``), and while it
simulates (seen through its progress bar).
"""
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

MESSAGE = "twin run: interrupted; no result was written"


def twin_command():
    """The installed ``twin`` script (what a user runs), or the module when the script is absent."""
    script = Path(sys.executable).parent / "twin"
    return [str(script)] if script.exists() else ["-m", "twin.cli"]


class Run:
    """A ``twin run`` process whose stderr is collected as it comes."""

    def __init__(self, out, scenario="etve_160h"):
        self.proc = subprocess.Popen([sys.executable, "-X", "importtime", *twin_command(), "run", scenario,
                                      "--out", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        self.err = b""
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self):
        while chunk := os.read(self.proc.stderr.fileno(), 65536):
            self.err += chunk

    def interrupt_when(self, seen, timeout_s=300):
        """Send SIGINT as soon as ``seen`` is in stderr; return the exit code and stderr."""
        deadline = time.monotonic() + timeout_s
        while seen.encode() not in self.err:
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.proc.kill()
                pytest.fail(f"{seen!r} never appeared on stderr: {self.err.decode()[-2000:]}")
            time.sleep(0.01)
        self.proc.send_signal(signal.SIGINT)
        code = self.proc.wait(timeout=120)
        self.reader.join(timeout=10)
        return code, self.err.decode("utf-8", "replace")


def messages(stderr):
    """The lines of stderr that are neither import timings, progress-bar frames nor notices."""
    lines = [line.strip() for line in stderr.replace("\r", "\n").splitlines()]
    return [line for line in lines if line and not line.startswith(("import time:", "simulating", "twin: "))]


@pytest.mark.parametrize("phase, seen", [("importing scipy", "scipy"), ("simulating", "simulating")])
def test_sigint_exits_with_one_line_and_code_130(phase, seen, tmp_path):
    out = tmp_path / "run"
    code, stderr = Run(out).interrupt_when(seen)
    assert code == 130, stderr[-3000:]
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr[-3000:]
    assert messages(stderr) == [MESSAGE]
    assert list(tmp_path.iterdir()) == []            # no result folder, not even a partial one
    if phase == "simulating":
        assert "step/s" in stderr                    # the bar counts time steps
