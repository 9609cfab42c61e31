"""Each setup key's constraint is declared once, in its field's metadata, and that one
declaration validates the value, words the error message (the key, the allowed range,
the unit) and writes the table of keys in docs/reference/setups.md."""

import dataclasses
import re
from pathlib import Path

import pytest

from mitsweep.config import (DEFAULT_SETUP, AtLeast, Between, Integer, OneOf, OrNone,
                             Placement, Positive, Setup, SetupError, Table, setup_from_dict,
                             setup_keys_table)

DOC = Path(__file__).resolve().parents[1] / "docs" / "reference" / "setups.md"
BEGIN, END = "<!-- setup-keys-table: begin", "<!-- setup-keys-table: end -->"

#: The sections (TOML tables), in file order: the fields of a Setup but its name.
SECTIONS = {f.name: type(getattr(DEFAULT_SETUP, f.name))
            for f in dataclasses.fields(Setup) if f.name != "name"}

BASE = {"mirror": {"kind": "conic", "radius": 25.0, "conic": 0.0, "rim_radius": 25.0,
                   "vertex_distance": 327.0},
        "sweep": {"fov_deg": 237.0}}


def _declared():
    """(section, dataclass field) of every key a setup file may hold."""
    for section, cls in SECTIONS.items():
        for f in dataclasses.fields(cls):
            yield section, f
            check = f.metadata.get("check")
            inner = check.check if isinstance(check, OrNone) else check
            if isinstance(inner, Table):
                yield from ((f"{section}.{f.name}", g) for g in dataclasses.fields(inner.cls))


def test_the_docs_table_is_the_declared_one():
    text = DOC.read_text()
    assert BEGIN in text and END in text
    body = text.split(BEGIN, 1)[1].split("-->", 1)[1].split(END, 1)[0]
    assert body.strip() == setup_keys_table().strip(), (
        "docs/reference/setups.md's table of setup keys differs from the code: paste the "
        "output of `python -c 'from mitsweep.config import setup_keys_table as t; "
        "print(t())'` between its markers")


def test_every_key_declares_its_constraint_and_meaning():
    keys = [(section, f) for section, f in _declared()]
    assert len(keys) >= 40   # 45 keys today, placement's two included
    for section, f in keys:
        assert "check" in f.metadata and f.metadata["meaning"], f"{section}.{f.name}"
    table = setup_keys_table()
    for section, f in keys:
        assert f"| `{section}.{f.name}` |" in table


def _violation(check):
    """A value that breaks ``check`` and the start of the message it must give (without
    the unit), or None for a check with no range to break."""
    check = check.check if isinstance(check, OrNone) else check
    if isinstance(check, Positive):
        if check.most is not None:
            return 2.0 * check.most, f"must be in (0, {check.most:g}]"
        return 0.0, "must be > 0"
    if isinstance(check, AtLeast):
        return check.least - 1.0, f"must be >= {check.least:g}"
    if isinstance(check, Between):
        return check.high + 1.0, f"must be in ({check.low:g}, {check.high:g})"
    if isinstance(check, Integer):
        return check.least - 1, f"must be {check.allowed}"
    if isinstance(check, OneOf):
        return ("no such choice" if isinstance(check.choices[0], str) else 7), \
            f"must be {check.allowed}"
    return None


RANGED = [(section, f.name) for section, f in _declared()
          if section in SECTIONS and _violation(f.metadata["check"]) is not None]


@pytest.mark.parametrize("section,key", RANGED, ids=[f"{s}.{k}" for s, k in RANGED])
def test_an_out_of_range_value_is_refused_naming_the_key_range_and_unit(section, key):
    f = next(g for g in dataclasses.fields(SECTIONS[section]) if g.name == key)
    value, says = _violation(f.metadata["check"])
    unit = f.metadata["unit"]
    data = {s: dict(t) for s, t in BASE.items()}
    data.setdefault(section, {})[key] = value
    with pytest.raises(SetupError) as err:
        setup_from_dict(data)
    message = str(err.value)
    assert message.startswith(f"{section}.{key}: {says}"), message
    if unit and not isinstance(f.metadata["check"], OneOf):
        assert message.startswith(f"{section}.{key}: {says} {unit}"), message
    assert message.endswith(f"got {value!r}"), message


def test_a_placement_is_checked_by_its_own_declarations():
    data = {**BASE, "scene": {"placement": {"rotate_deg": [0.0, 1.0]}}}
    with pytest.raises(SetupError, match=re.escape("scene.placement.rotate_deg: must be "
                                                   "[rx, ry, rz] in deg, got [0.0, 1.0]")):
        setup_from_dict(data)
    assert Placement(translate=[1, 2, 3]).translate == (1.0, 2.0, 3.0)


def test_sensor_size_keeps_its_former_name_with_a_warning():
    sensor = setup_from_dict(BASE).sensor
    assert sensor.size == (512 * 0.018, 512 * 0.018)
    with pytest.warns(DeprecationWarning, match="Sensor.size_mm is deprecated"):
        assert sensor.size_mm == sensor.size
