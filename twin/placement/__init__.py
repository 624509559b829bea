"""twin.placement: ``twin place`` — where to put K thermometers so that a compensation model generalises.

- :mod:`twin.placement.study` — candidates, records, selection methods, scoring and the report;
- :mod:`twin.placement.cli` — the command.
"""
