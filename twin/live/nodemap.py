"""The node map of ``twin live``: which OPC UA node carries which sensor, and where the estimates go.

A TOML file::

    [inputs]                       # required
    spindle_speed = "ns=2;s=spindle"     # rpm
    room_air = "ns=2;s=T15"              # °C, an air thermometer in the room

    [thermometers]                 # required: ROM thermometer name = node, °C
    T01 = "ns=2;s=T01"

    [outputs]                      # optional: <axis>, <axis>_band, <axis>_compensation for X, Y, Z (µm)
    Z = "ns=2;s=Z_estimate_um"
    Z_band = "ns=2;s=Z_band95_um"
    Z_compensation = "ns=2;s=Z_compensation_um"

Node ids use the OPC UA string form (``ns=<index>;s=<name>`` or ``ns=<index>;i=<number>``); each key has a node
of its own (an output on a sensor's node is refused).  Every error names the file, the key and the value.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..errors import TwinInputError

try:
    import tomllib
except ModuleNotFoundError:      # Python 3.10
    import tomli as tomllib

INPUTS = ("spindle_speed", "room_air")
AXES = ("X", "Y", "Z")
OUTPUT_KEYS = tuple(f"{a}{s}" for a in AXES for s in ("", "_band", "_compensation"))


@dataclass
class NodeMap:
    """Node ids (OPC UA strings) of the inputs, thermometers and outputs.

    Attributes
    ----------
    inputs : dict
        ``spindle_speed`` (rpm) and ``room_air`` (°C) → node id.
    thermometers : dict
        ROM thermometer name → node id (°C).
    outputs : dict
        ``Z``, ``Z_band``, ``Z_compensation`` … → node id (µm).
    source : str
        The file the map was read from (named in errors).
    """

    inputs: dict
    thermometers: dict
    outputs: dict = field(default_factory=dict)
    source: str = "<node map>"

    def sensors(self) -> list[tuple[str, str]]:
        """(key, node id) of every node read: the inputs, then the thermometers.

        Returns
        -------
        sensors : list of (str, str)
            (key, node id) pairs.
        """
        return [*self.inputs.items(), *self.thermometers.items()]

    def where(self, key: str) -> str:
        """Where a key is, for an error message.

        Parameters
        ----------
        key : str
            An input, thermometer or output key.

        Returns
        -------
        str
            ``file: [section] key = 'node'``.
        """
        for section in ("inputs", "thermometers", "outputs"):
            table = getattr(self, section)
            if key in table:
                return f"{self.source}: [{section}] {key} = {table[key]!r}"
        return f"{self.source}: {key}"

    def check_distinct(self) -> None:
        """Refuse a node that two keys share: an output on a sensor node would write µm into it and read them back
        as °C, two sensors on one node would be one reading taken for two, two outputs would overwrite each other.

        Raises
        ------
        TwinInputError
            Naming the file, the key, its node and the key that has it already.
        """
        from asyncua import ua

        owner = {}          # node → "[section] key" (node ids compared parsed: "ns=2;s=A" is "ns=2; s=A")
        for section in ("inputs", "thermometers", "outputs"):
            for key, text in getattr(self, section).items():
                node = ua.NodeId.from_string(text)
                if node in owner:
                    raise TwinInputError(f"{self.source}: [{section}] {key} = {text!r}: the node of {owner[node]} "
                                         "too; every input, thermometer and output needs a node of its own")
                owner[node] = f"[{section}] {key}"

    def to_toml(self) -> str:
        """The map as the TOML text :func:`load_node_map` reads.

        Returns
        -------
        text : str
            TOML text.
        """
        lines = []
        for section in ("inputs", "thermometers", "outputs"):
            lines += [f"[{section}]"] + [f'{k} = "{v}"' for k, v in getattr(self, section).items()] + [""]
        return "\n".join(lines)


def _node_id(text, where):
    """``text`` if it parses as an OPC UA node id, else an error naming ``where``."""
    from asyncua import ua

    if not isinstance(text, str):
        raise TwinInputError(f"{where}: a node id must be a string like \"ns=2;s=T01\", got {text!r}")
    try:
        ua.NodeId.from_string(text)
    except ua.UaStringParsingError:          # what asyncua raises for any malformed node id string
        raise TwinInputError(f"{where} = {text!r}: not an OPC UA node id (use \"ns=2;s=T01\")") from None
    return text


def load_node_map(path: str | Path) -> NodeMap:
    """Read and check a node map TOML file (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The node map file.

    Returns
    -------
    node_map : NodeMap
        The checked map.

    Raises
    ------
    TwinInputError
        Naming the file, section, key and value: invalid TOML, an unknown section or key, a missing input, no
        thermometer, a node id that does not parse, a node two keys share (:meth:`NodeMap.check_distinct`).
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise TwinInputError(f"{path}: not valid TOML ({exc})") from None
    unknown = set(data) - {"inputs", "thermometers", "outputs"}
    if unknown:
        raise TwinInputError(f"{path}: unknown section(s) {sorted(unknown)}; use [inputs], [thermometers], [outputs]")
    tables = {}
    for section in ("inputs", "thermometers", "outputs"):
        table = data.get(section, {})
        if not isinstance(table, dict):
            raise TwinInputError(f"{path}: [{section}] must be a table of name = \"node id\"")
        tables[section] = {k: _node_id(v, f"{path}: [{section}] {k}") for k, v in table.items()}
    for key in INPUTS:
        if key not in tables["inputs"]:
            raise TwinInputError(f"{path}: [inputs] has no {key} (needs {', '.join(INPUTS)})")
    extra = set(tables["inputs"]) - set(INPUTS)
    if extra:
        raise TwinInputError(f"{path}: [inputs] {sorted(extra)[0]}: unknown input; inputs: {', '.join(INPUTS)}")
    if not tables["thermometers"]:
        raise TwinInputError(f"{path}: [thermometers] is empty; name at least one ROM thermometer (T01 …)")
    bad = [k for k in tables["outputs"] if k not in OUTPUT_KEYS]
    if bad:
        raise TwinInputError(f"{path}: [outputs] {bad[0]}: unknown output; outputs: {', '.join(OUTPUT_KEYS)}")
    node_map = NodeMap(tables["inputs"], tables["thermometers"], tables["outputs"], str(path))
    node_map.check_distinct()
    return node_map
