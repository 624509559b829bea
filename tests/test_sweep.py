"""The Dask sweep: a real scheduler with two worker processes on loopback gives what a serial run gives."""
import os
from dataclasses import dataclass
from functools import partial

import numpy as np
import pytest

from twin.errors import TwinInputError
from twin.infra.sweep import cached, run_tasks


@dataclass(frozen=True)
class SolveTask:
    """A small linear solve with a per-process cached factor, as the twin's tasks do with the machine."""

    n: int
    seed: int

    def __call__(self):
        import scipy.linalg as la

        lu = cached(("lu", self.n), lambda: la.lu_factor(np.eye(self.n) * 4 + np.diag(np.ones(self.n - 1), 1)))
        b = np.random.default_rng(self.seed).standard_normal(self.n)
        return {"seed": self.seed, "x": la.lu_solve(lu, b), "pid": os.getpid()}


def _fail(message):
    raise TwinInputError(message)


@pytest.fixture(scope="module")
def cluster():
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address="127.0.0.1:0") as c:
        yield c


def test_two_workers_on_loopback_equal_serial(cluster):
    tasks = [SolveTask(50, s) for s in range(8)]
    serial = run_tasks(tasks, scheduler="serial")
    distributed = run_tasks(tasks, scheduler=cluster.scheduler_address)
    assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
    assert [r["seed"] for r in distributed] == list(range(8))            # results in task order
    for a, b in zip(serial, distributed):
        assert np.array_equal(a["x"], b["x"])
    assert all(r["pid"] != os.getpid() for r in distributed)             # really ran in the workers
    assert all(r["pid"] == os.getpid() for r in serial)


def test_task_errors_keep_their_type_and_message(cluster):
    with pytest.raises(TwinInputError, match="bad channel T99"):
        run_tasks([partial(_fail, "bad channel T99")], scheduler=cluster.scheduler_address)
    with pytest.raises(TwinInputError, match="bad channel T98"):
        run_tasks([partial(_fail, "bad channel T98")], scheduler="serial")


def test_scheduler_argument_is_checked():
    with pytest.raises(TwinInputError, match="scheduler must be"):
        run_tasks([SolveTask(3, 0)], scheduler="fast")
    with pytest.raises(TwinInputError, match="not callable"):
        run_tasks([3], scheduler="serial")
    assert run_tasks([], scheduler="local") == []
    done = []
    run_tasks([SolveTask(3, 0), SolveTask(3, 1)], scheduler="serial", progress=lambda d, t: done.append((d, t)))
    assert done == [(1, 2), (2, 2)]


def test_workers_rebuild_the_machine_from_caches_and_match_serial(cluster, tmp_path):
    """Twin runs as sweep tasks: the workers get names, rebuild the machine from the caches, equal serial."""
    from twin.core.machine import build_machine
    from twin.placement.study import CandidateSpec, MachineSpec, RecordTask

    build_machine("vmc_ram")                       # the caches exist (the workers only read them)
    body = """
[scenario]
name = "{name}"
sample_interval_s = 600.0
time_step_s = 600.0
[ambient]
kind = "constant"
temperature_C = {amb}
[[segments]]
duration_h = 1
spindle_rpm = {rpm}
[[segments]]
duration_h = 1
spindle_rpm = 0
"""
    paths = []
    for name, rpm, amb in (("sw_a", 9000, 20.0), ("sw_b", 3000, 21.0), ("sw_c", 6000, 20.0)):
        path = tmp_path / f"{name}.toml"
        path.write_text(body.format(name=name, rpm=rpm, amb=amb))
        paths.append(str(path))
    tasks = [RecordTask(MachineSpec(), CandidateSpec(("ram",), 30, camera=False), p, ("Z",), None) for p in paths]
    serial = run_tasks(tasks, scheduler="serial")
    remote = run_tasks(tasks, scheduler=cluster.scheduler_address)
    for a, b in zip(serial, remote):
        assert a.scenario == b.scenario
        assert np.array_equal(a.temperatures, b.temperatures) and np.array_equal(a.drift["Z"], b.drift["Z"])
    assert np.ptp(serial[0].drift["Z"]) > np.ptp(serial[1].drift["Z"])      # 9000 rpm moves more than 3000
