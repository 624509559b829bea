"""FMI semantics of a Python FMU, run in a process of its own by tests/test_fmu.py.

PythonFMU embeds the interpreter's C API in the importer's process; its FMU-state and lifetime calls are
not safe to mix with other FMUs in one long test process, so these checks run here and print JSON:

    python python_fmu_semantics.py <fmu> <T_initial> <ambient_room> <ambient_front> <spindle_rpm>
"""
import json
import sys

from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave


def status(call):
    try:
        call()
        return 0
    except FMICallException as exc:
        return int(exc.status)


def main(path, T_initial, room, front, rpm):
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    names = ["T01", "A_front", "X", "Z"]
    out = {"can_get_and_set_state": bool(md.coSimulation.canGetAndSetFMUstate)}
    f = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="t")
    f.instantiate()
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    inputs = {"T_initial": T_initial, "ambient_room": room, "ambient_front": front, "spindle_speed": rpm}
    f.setReal([vr[n] for n in inputs], list(inputs.values()))
    out["initialization_mode"] = f.getReal([vr[n] for n in names])
    f.exitInitializationMode()
    out["after_initialization"] = f.getReal([vr[n] for n in names])
    for k in range(3):
        f.doStep(60.0 * k, 60.0)
    state = f.getFMUstate()
    runs = []
    for _ in range(2):
        f.setFMUstate(state)
        f.setReal([vr["ambient_room"]], [room + 3.0])
        for k in range(3, 10):
            f.doStep(60.0 * k, 60.0)
        runs.append(f.getReal([vr["Z"], vr["T01"]]))
    f.freeFMUstate(state)
    out["runs_from_one_state"] = runs
    f.terminate()
    out["doStep_after_terminate"] = status(lambda: f.doStep(600.0, 60.0))
    out["set_T_initial_after_initialization"] = status(lambda: f.setReal([vr["T_initial"]], [30.0]))
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv[1], *map(float, sys.argv[2:6]))
