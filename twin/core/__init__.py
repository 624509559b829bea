"""twin.core: the machine, the scenario and the simulation that everything else composes.

- :mod:`twin.core.machine_definition` — the physics part of a machine TOML (heat sources, convection,
  sensors, camera); :mod:`twin.core.machine` — a built machine (mesh, thermal system, output operators);
- :mod:`twin.core.scenario` — scenario TOML → time-varying loads, ambient and events;
- :mod:`twin.core.simulate` — a scenario through a machine → a :class:`~twin.core.dataset.Dataset`;
- :mod:`twin.core.dataset` — the data contract (CSV + JSON sidecar) shared with models, gap and measured data;
- :mod:`twin.core.noise` — sensor noise and resolution; :mod:`twin.core.deformation` — displacement fields;
  :mod:`twin.core.files` — atomic text files; :mod:`twin.core.clock` — date-time stamps as s, one clock;
  :mod:`twin.core.interrupt` — a Ctrl-C that is raised again where a library swallowed it.

``core`` imports no other twin subpackage but :mod:`twin.errors` (tests/test_architecture.py).
"""
