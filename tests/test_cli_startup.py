"""The command line answers `--help` and argument errors without loading the numerical libraries.

Timing is in bench/cli_startup.py; here the cause is checked: which modules the
parser imports, in a fresh interpreter.
"""
import json
import subprocess
import sys

import pytest

HEAVY = ("scipy", "pyvista", "sklearn", "matplotlib", "vtk", "pandas", "numpy", "fea", "skfem", "dask")

PROBE = """
import json, sys
import twin.cli
try:
    twin.cli.main({argv!r})
except SystemExit:
    pass
heavy = sorted({{name.split(".")[0] for name in sys.modules}} & set({heavy!r}))
print(json.dumps(heavy))
"""


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["gap", "diagnose", "--help"],
                                  ["fmu", "export", "--help"], ["train", "--help"], ["run"],
                                  ["place", "--k-max", "many"]])
def test_help_and_argument_errors_import_no_numerical_library(argv):
    done = subprocess.run([sys.executable, "-c", PROBE.format(argv=argv, heavy=HEAVY)], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []
    if argv[-1] != "--help":
        assert "usage:" in done.stderr and "Traceback" not in done.stderr


def test_cli_defaults_agree_with_the_library():
    """The parser keeps copies of library defaults (importing the library would load scipy)."""
    from twin.gap import benchmark
    from twin.gap import cli as cli_gap
    from twin.rom import cli as cli_rom
    from twin.rom import reduction

    assert cli_rom.DEFAULT_ORDER == reduction.DEFAULT_ORDER
    assert (cli_gap.SCENARIO, cli_gap.TRUTH_MESH_SIZE_M) == (benchmark.SCENARIO, benchmark.TRUTH_MESH_SIZE_M)
    assert cli_gap.INDEPENDENT_SCENARIO == benchmark.INDEPENDENT_SCENARIO
